// Step 2's "Mark another photo of this part": once the seven points are placed on one photo,
// another photo of the same part is shown for its seven points, and so on (part.ts keeps them);
// the list of the part's photos shows each one's points, and a photo can be shown again or
// taken out. Two photos or more are sent as one item with `views` and measured as one box (a
// known edge is needed: the settings ask for it). Not in two-photo mode, not for a video.

import { inPart, partPhotos, PART_MAX, removeFromPart, sevenPlaced, showInPart } from "./part";
import { faceChoice } from "./points";
import { nextPoint, photoShown, state, type PhotoEntry } from "./state";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

export class PartViews {
  /** The part starts (a second photo): the settings ask for a known edge. */
  onStart: () => void = () => {};

  /** `apply` makes a change to the points and brings every view of them up to date; `shown`
   *  does that and fits the photo shown, which changed, to the canvas. */
  constructor(private apply: (change: () => void) => void, private shown: (change: () => void) => void) {
    $("add-view").addEventListener("click", () => this.add());
  }

  private say(text: string): void {
    $("part-status").textContent = text;
  }

  private add(): void {
    const photo = photoShown("front");
    if (!photo || photo.video) return;
    if (state.part.length >= PART_MAX) {
      return this.say(`At most ${PART_MAX} photos of one part are measured together here.`);
    }
    if (!sevenPlaced(state.marks)) {
      if (!state.extra) {
        this.apply(() => {
          state.extra = true;
          $<HTMLInputElement>("extra-corners").checked = true;
        });
        return this.say(`A photo measured with others needs all seven points: place P6 and P7 on ${photo.name} ` +
          "too, then press this again.");
      }
      return this.say(`Place all seven points on ${photo.name} first (${nextPoint()?.toUpperCase()} is next).`);
    }
    const others = state.photos.filter((p) => p.bitmap && !p.video && p.id !== photo.id && !state.part.includes(p.id));
    const next = others.find((p) => !otherSize(p, photo));
    const aside = others[0] !== next ? others[0] : undefined; // the first passed over, of another size
    if (!next) {
      return this.say(aside ? `${otherSize(aside, photo)} Add a photo of that size, then press this again.` :
        "Add the next photo of this part first (“Add photos or a video” above), then press this again.");
    }
    const starting = !inPart();
    this.shown(() => showInPart(next.id));
    if (starting) this.onStart();
    this.say(`${next.name} is shown: mark its seven points.` + (aside ? ` Left aside: ${otherSize(aside, photo)}` : ""));
  }

  /** The front photo was chosen in the list of photos while a part is marked: show it as one of
   *  the part's (added when new). False, and the choice undone, when it cannot be one. */
  follow(): boolean {
    const chosen = state.front;
    const back = state.partShown;
    const photo = photoShown("front");
    let refusal = "";
    const first = state.photos.find((p) => p.id === state.part[0]);
    if (photo?.video) refusal = "A video cannot be one of the photos of a part: remove the part's photos first.";
    else if (photo && first && otherSize(photo, first)) refusal = otherSize(photo, first);
    else if (chosen !== null && !state.part.includes(chosen) && state.part.length >= PART_MAX) {
      refusal = `At most ${PART_MAX} photos of one part are measured together here.`;
    }
    if (refusal || chosen === null) {
      state.front = back;
      this.say(refusal);
      return false;
    }
    this.shown(() => showInPart(chosen));
    return true;
  }

  private remove(id: number): void {
    const wasShown = id === state.partShown;
    const change = () => removeFromPart(id);
    if (wasShown) this.shown(change);
    else this.apply(change);
    this.say(inPart() ? "" : "One photo left: it is measured alone.");
  }

  render(): void {
    const photo = photoShown("front");
    $("add-view").hidden = !photo || Boolean(photo.video) || state.twoPhoto;
    $("part").hidden = !inPart();
    // A part's photos need all seven points, and are photos of one camera in one-photo mode.
    $<HTMLInputElement>("extra-corners").disabled = inPart();
    for (const radio of document.querySelectorAll<HTMLInputElement>("input[name=mode]")) {
      radio.disabled = inPart() && radio.value === "two";
    }
    $<HTMLSelectElement>("second-face").value = faceChoice();
    $("part-list").replaceChildren(...partPhotos().map(({ id, photo: p, view }, k) => {
      const li = document.createElement("li");
      const name = p?.name ?? "a photo no longer listed";
      const placed = Object.keys(view.marks).length;
      const current = id === state.partShown;
      li.dataset.photo = String(id);
      if (current) li.setAttribute("aria-current", "true");
      li.append(`Photo ${k + 1}: ${name}, ${placed} of 7 points${current ? " (shown)" : ""} `);
      if (!current) li.append(button("Show", `Show photo ${k + 1} of this part (${name})`,
        () => this.shown(() => showInPart(id))));
      li.append(button("Remove", `Remove photo ${k + 1} (${name}) from this part`, () => this.remove(id)));
      return li;
    }));
  }
}

/** Why `photo` cannot join a part whose photos are `part`'s size (the service's rule: one camera
 *  at one image size), or "" when it can. */
function otherSize(photo: PhotoEntry, part: PhotoEntry): string {
  const [a, b] = [photo.bitmap, part.bitmap];
  if (!a || !b || (a.width === b.width && a.height === b.height)) return "";
  return `${photo.name} is ${a.width} × ${a.height} pixels, this part's photos ${b.width} × ${b.height} (${part.name}): ` +
    "the photos of one part must come from one camera at one image size.";
}

function button(text: string, label: string, click: () => void): HTMLButtonElement {
  const b = document.createElement("button");
  b.type = "button";
  b.textContent = text;
  b.setAttribute("aria-label", label);
  b.addEventListener("click", click);
  return b;
}
