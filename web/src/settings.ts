// Step 3 of the page: tolerance, method, cloud kind, outputs, scale and focal length, read into the
// matching fields of the scan spec; a field left wrong gets a sentence naming it.

import { METRIC } from "./formats";
import type { Scale, ScanSpec } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const value = (id: string) => $<HTMLInputElement | HTMLSelectElement>(id).value;

export type Settings = Pick<ScanSpec, "tolerance" | "method" | "cloud" | "scale" | "focal_px" | "side_face"
  | "nominal" | "tolerance_mm" | "formats">;

export class SettingsForm {
  /** `joint`: several photos of one part are marked, to be measured as one box (a known edge). */
  constructor(private twoPhoto: () => boolean, private joint: () => boolean) {
    $("scale-kind").addEventListener("change", () => this.render());
    $("settings").addEventListener("change", () => this.describe());
    $("quality-settings").addEventListener("change", () => this.describe());
  }

  /** Fold the settings away (a result is shown) or open them; the summary line says what is set. */
  collapse(closed: boolean): void {
    this.describe();
    $<HTMLDetailsElement>("settings-panel").open = !closed;
  }

  private describe(): void {
    const scale = $<HTMLSelectElement>("scale-kind");
    const parts = [`scale: ${scale.selectedOptions[0]?.text.toLowerCase() ?? ""}`];
    const nominal = ["nominal-width", "nominal-height", "nominal-depth"].map(value);
    if (nominal.some((v) => v.trim())) parts.push(`nominal ${nominal.join(" × ")} mm ± ${value("tolerance-mm")}`);
    $("settings-summary").textContent = `(${parts.join("; ")})`;
  }

  /** Several photos of one part are marked: open the settings at a known edge, the scale the
   *  joint fit needs (left as chosen when it is one already). */
  askEdge(): void {
    const kind = $<HTMLSelectElement>("scale-kind");
    if (kind.value !== "edge") {
      kind.value = "edge";
      this.render();
      this.describe();
    }
    $<HTMLDetailsElement>("settings-panel").open = true;
  }

  /** A joint fit's scale: one known edge with its length; else an Error saying so, at the field. */
  private requireEdge(): void {
    const kind = value("scale-kind");
    const length = value("edge-mm").trim();
    if (kind === "edge" && length !== "") return;
    $<HTMLDetailsElement>("settings-panel").open = true;
    $(kind === "edge" ? "edge-mm" : "scale-kind").focus();
    throw new Error("Several photos of one part are measured as one box, which needs one known edge as the " +
      "scale: choose “One known edge” under Scale, which edge it is and its length in mm.");
  }

  paper(): boolean {
    return value("method") === "paper";
  }

  /** Show the fields of the chosen scale (and the side photo's only in two-photo mode). */
  render(): void {
    const kind = value("scale-kind");
    for (const el of document.querySelectorAll<HTMLElement>("[data-scale]")) {
      el.hidden = el.dataset.scale !== kind || ("two" in el.dataset && !this.twoPhoto());
    }
  }

  /** The settings as spec fields; throws an Error whose message says what to fix. */
  read(): Settings {
    const tolerance = number("tolerance", "The colour tolerance", { min: 0, max: 128 })!;
    const focal = number("focal", "The focal length", { positive: true, optional: true });
    if (this.joint()) this.requireEdge();
    const kind = value("scale-kind");
    let scale: Scale | undefined;
    if (kind === "mm_per_px") {
      scale = { kind, front: number("mm-front", "Millimetres per pixel", { positive: true })! };
      const side = this.twoPhoto() ? number("mm-side", "The side photo's millimetres per pixel",
        { positive: true, optional: true }) : undefined;
      if (side !== undefined) scale.side = side;
    } else if (kind === "pinhole") {
      scale = { kind, distance_mm: number("distance", "The shooting distance", { positive: true })! };
      const side = this.twoPhoto() ? number("side-distance", "The side photo's shooting distance",
        { positive: true, optional: true }) : undefined;
      if (side !== undefined) scale.side_distance_mm = side;
      if (focal === undefined) throw new Error("A shooting distance needs the focal length in pixels.");
    } else if (kind === "edge") {
      const edge = value("edge") as "width" | "height" | "depth";
      scale = { kind, edge, length_mm: number("edge-mm", `The ${edge}`, { positive: true })! };
    }
    const settings: Settings = {
      tolerance, method: value("method") as Settings["method"], cloud: value("cloud") as Settings["cloud"],
    };
    if (scale) settings.scale = scale;
    if (focal !== undefined) settings.focal_px = focal;
    if (!this.twoPhoto()) settings.side_face = value("second-face") as Settings["side_face"];
    // Not chosen: none sent, so the service's default applies (PRISM_DEFAULT_FORMATS).
    const formats = value("formats").split(",").filter(Boolean);
    if (formats.length) {
      if (!scale && formats.some((f) => METRIC.includes(f))) {
        $("formats").focus();
        throw new Error("LAZ, the glTF box model, the STEP solid and the drawing are in millimetres and need a " +
          "scale: choose one under Scale, or the cloud as CSV and PLY under Outputs.");
      }
      settings.formats = formats;
    }
    const quality = nominal();
    if (quality) {
      if (!scale) {
        $("scale-kind").focus();
        throw new Error("A nominal size needs a scale (the dimensions in millimetres): choose one under Scale.");
      }
      Object.assign(settings, quality);
    }
    // No default scale: left unchosen, a scan would come back in pixels while the person read
    // millimetres. "None" is a choice like the others.
    if (kind === "") {
      $<HTMLDetailsElement>("settings-panel").open = true;
      $("scale-kind").focus();
      throw new Error("Choose a scale under Scale: one known edge, millimetres per pixel, or a shooting distance " +
        "and focal length give the dimensions in millimetres; “None” gives them in pixels.");
    }
    return settings;
  }
}

/** The nominal size and tolerance, or null when none is given (all fields empty). */
function nominal(): Pick<Settings, "nominal" | "tolerance_mm"> | null {
  const ids = ["nominal-width", "nominal-height", "nominal-depth"];
  const names = ["The nominal width", "The nominal height", "The nominal depth"];
  const tolerance = $<HTMLInputElement>("tolerance-mm");
  if (ids.every((id) => value(id).trim() === "") && tolerance.value.trim() === "") return null;
  const size = ids.map((id, i) => number(id, names[i], { positive: true })!) as [number, number, number];
  const text = tolerance.value.trim();
  const parts = text === "" ? [] : text.split(/[\s,;]+/).filter(Boolean);
  const values = parts.map(Number);
  if (!(parts.length === 1 || parts.length === 3) || values.some((v) => !Number.isFinite(v) || v < 0)) {
    tolerance.focus();
    throw new Error("The tolerance must be one number of millimetres (0 or more), or three: width, height, depth " +
      `(got ${JSON.stringify(text)}).`);
  }
  return { nominal: size, tolerance_mm: values.length === 1 ? values[0] : (values as [number, number, number]) };
}

function number(id: string, what: string,
                rule: { min?: number; max?: number; positive?: boolean; optional?: boolean }): number | undefined {
  const input = $<HTMLInputElement>(id);
  const text = input.value.trim();
  if (text === "") {
    if (rule.optional) return undefined;
    input.focus();
    throw new Error(`${what} is missing.`);
  }
  const v = Number(text);
  let problem = "";
  if (!Number.isFinite(v)) problem = "is not a number";
  else if (rule.positive && v <= 0) problem = "must be more than 0";
  else if (rule.min !== undefined && v < rule.min) problem = `must be at least ${rule.min}`;
  else if (rule.max !== undefined && v > rule.max) problem = `must be at most ${rule.max}`;
  if (problem) {
    input.focus();
    throw new Error(`${what} ${problem} (got ${JSON.stringify(text)}).`);
  }
  return v;
}
