// The page's two ways of measuring: "mark points" (the four steps: photos, points, settings, run)
// and "station" (a calibrated station, a folder of photos, the job's table). One switch; the
// elements of each carry data-mode="points" or data-mode="station", and the stylesheet shows
// those of the mode on <main data-mode>. The choice is kept for the tab (sessionStorage).

export type Mode = "points" | "station";

const KEY = "prism.mode";

export class ModeSwitch {
  onChange: (mode: Mode) => void = () => {};

  constructor() {
    for (const radio of this.radios()) {
      radio.addEventListener("change", () => {
        if (radio.checked) this.set(radio.value as Mode);
      });
    }
  }

  private radios(): HTMLInputElement[] {
    return [...document.querySelectorAll<HTMLInputElement>("input[name=work-mode]")];
  }

  get mode(): Mode {
    return document.getElementById("main")!.dataset.mode === "station" ? "station" : "points";
  }

  /** Show `mode`'s steps (the one kept for this tab when none is given). */
  set(mode: Mode = sessionStorage.getItem(KEY) === "station" ? "station" : "points"): void {
    document.getElementById("main")!.dataset.mode = mode;
    sessionStorage.setItem(KEY, mode);
    for (const radio of this.radios()) radio.checked = radio.value === mode;
    this.onChange(mode);
  }
}
