// The sentence shown above a result measured without a scale: its dimensions are pixels, and a
// number like 412.37 must not be read as millimetres (a photo's item and a video's summary alike).

export function pixelsNote(): HTMLElement {
  const p = document.createElement("p");
  p.className = "pixels-note";
  p.id = "pixels-note";
  p.textContent = "These dimensions are in pixels, not millimetres: the scan had no scale. To measure in mm, " +
    "choose one under Scale (one known edge, millimetres per pixel, or a shooting distance and focal length) " +
    "and scan again.";
  return p;
}
