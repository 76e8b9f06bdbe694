// The page's wiring: log in, then the four steps (photos, points, settings, run), or in station
// mode the station, a folder of photos and the job's table; the result and the list of recent
// jobs. Each step lives in its own module; this file only connects them.

import "./style.css";

import { getJson, message, saveKey, savedKey } from "./api";
import { FindPoints } from "./find-points";
import { FramePicker } from "./frame-picker";
import { FrameSelectionForm } from "./frame-selection";
import { History } from "./history";
import { Marking } from "./marking";
import { ModeSwitch } from "./mode";
import { inPart } from "./part";
import { PartViews } from "./part-views";
import { Photos } from "./photos";
import { ResultPanel } from "./result";
import { Runner } from "./run";
import { SettingsForm } from "./settings";
import { StationPhotos } from "./station-photos";
import { StationVerify } from "./station-verify";
import { Stations } from "./stations";
import { clear, clearAll, photoShown, state } from "./state";
import type { JobList } from "./types";

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

const settings = new SettingsForm(() => state.twoPhoto, inPart);
const marking = new Marking(() => settings.paper());
const finder = new FindPoints((change) => marking.changed(change));
const part = new PartViews((change) => marking.changed(change), (change) => {
  marking.changed(change);
  photos.render(); // another front photo: chosen in the list
  marking.show("front"); // and fitted to the canvas
});
const photos = new Photos();
const picker = new FramePicker();
const frames = new FrameSelectionForm(() => photoShown("front")?.video?.info ?? null);
const runner = new Runner(() => settings.read(), (info, marked) => frames.read(info, marked));
const result = new ResultPanel();
const history = new History();
const mode = new ModeSwitch();
const stations = new Stations();
const stationPhotos = new StationPhotos();

// A video's frame picker and frame selection, and the list of a part's photos, follow the points
// and the photo or frame shown.
const pointsChanged = () => {
  picker.render();
  frames.render();
  part.render();
};
part.onStart = () => settings.askEdge();
marking.onChange = pointsChanged;
picker.onShown = () => marking.changed(() => {});
frames.onModeChange = () => marking.changed(() => {});

photos.onChange = (what) => {
  if (what === "front" && inPart()) {
    if (!part.follow()) photos.render(); // not one of the part's photos: the choice is undone
  } else if (what === "front") marking.changed(() => (state.twoPhoto ? clear(["p1", "p2", "p3", "p6"]) : clearAll()));
  if (what === "side") marking.changed(() => clear(["p4", "p5", "p7"]));
  if (what === "mode") {
    settings.render();
    finder.render();
    marking.changed(() => clear(["p4", "p5", "p7"]));
  }
  if (what !== "photos") marking.show(state.shown === "side" && state.twoPhoto ? "side" : "front");
  else marking.refresh();
  pointsChanged();
};
$("method").addEventListener("change", () => marking.refresh());
runner.onAdded = () => marking.changed(clearAll);
runner.onFinished = (job) => {
  settings.collapse(true); // the result takes the settings' place beside the photo
  // A station's job is read as its table (whatever its size), each part's fit on the photo large.
  result.show(job, mode.mode === "station");
  void history.load();
};

stationPhotos.station = () => stations.chosen;
stationPhotos.submit = (items, reference) => runner.run(items, reference);
stations.onChoose = () => stationPhotos.render();
const stationVerify = new StationVerify();
stationVerify.station = () => stations.chosen;
stationVerify.onDone = (said) => stations.load(said);
mode.onChange = (m) => {
  result.overlayLarge(m === "station");
  if (m === "station") void stations.load();
  else {
    marking.refresh(); // the photo's canvas was hidden: fit it again
    marking.marker.fit();
  }
};
history.onOpen = (job) => runner.follow(job);

async function logIn(key: string): Promise<boolean> {
  const error = $("login-error");
  error.textContent = "";
  try {
    await getJson<JobList>("/v1/jobs?limit=1", key); // proves the key before keeping it
  } catch (err) {
    error.textContent = message(err);
    return false;
  }
  saveKey(key);
  $("login-form").hidden = true;
  $("intro").hidden = true;
  $("session").hidden = false;
  $("work-mode").hidden = false;
  $("main").hidden = false;
  settings.render();
  marking.refresh();
  marking.marker.fit();
  mode.set(); // the mode this tab was in
  void history.load();
  return true;
}

$("login-form").addEventListener("submit", (e) => {
  e.preventDefault();
  const input = $<HTMLInputElement>("api-key");
  void logIn(input.value.trim()).then((ok) => {
    if (ok) {
      input.value = "";
      $("files").focus();
    }
  });
});

$("logout").addEventListener("click", () => {
  saveKey(null);
  location.reload(); // forget every photo and job shown, not only the key
});

const kept = savedKey();
if (kept) void logIn(kept);
else $("api-key").focus();
