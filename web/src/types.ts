// The API's shapes (prism_api.schemas) and the scan spec's (prismcore.spec.ScanSpec), as used here.

/** A job's state; an item's or a frame's is one of these but completed_with_failures. */
export type State = "queued" | "running" | "succeeded" | "completed_with_failures" | "failed" | "cancelled";
export const FINAL: readonly State[] = ["succeeded", "completed_with_failures", "failed", "cancelled"];

export interface Upload {
  id: string;
  reference: string;
  size: number;
  name: string;
  /** What the service found the file to be when it stored it (null: not read). */
  probe?: { kind: "image" | "video"; width: number | null; height: number | null; error: string | null } | null;
}

/** A stored station (prism_common.stations.StationPublic): its summary, never the plate. */
export interface Station {
  id: string;
  name: string | null;
  created_at: string;
  image_width: number;
  image_height: number;
  board: { type?: string; dictionary?: string; squares_x?: number; squares_y?: number; square_mm?: number;
    size_mm?: [number, number] } & Record<string, unknown>;
  camera: { fx: number; fy: number; cx: number; cy: number; dist: number[] };
  calibration: { source?: string; rms_px?: number; views?: number; corners?: number } & Record<string, unknown>;
  plane_rms_px: number;
  plane_corners: number;
  camera_height_mm: number;
  has_plate: boolean;
  size: number;
  /** Its last verification with a reference part, in short (null: a summary stored before). */
  verification?: { status: "verified" | "not verified"; text: string; date: string | null;
    tolerance_mm: number | null; bias_mm: Record<string, number> | null;
    repeatability_mm: Record<string, number> | null } | null;
  /** Its scale over the support and what it can hold there. */
  capability?: { mm_per_px: { near: number; far: number }; min_part_mm: number; min_tolerance_mm: number;
    min_tolerance_near_mm: number; rule: string } | null;
}

/** A verification with a reference part (prism_common.stations.VerificationPublic). */
export interface Verification {
  id: string;
  date: string;
  reference_mm: Record<string, number>;
  tolerance_mm: number | null;
  photos: string[];
  dimensions: Record<string, {
    reference_mm: number; mean_mm: number; bias_mm: number; bias_ci95_mm: [number, number];
    repeatability_mm: number; errors_mm: number[]; sigmas_mm: number[]; within_3_sigma: boolean[];
    grr_percent: number | null; verified: boolean; failures: string[];
  }>;
  verified: boolean;
  rule: string;
  decided_by: string[];
}

export interface StationList {
  stations: Station[];
}

export interface VideoInfo {
  id: string;
  frame_count: number;
  fps: number;
  width: number;
  height: number;
  codec: string;
  duration_s: number;
}

export type Dimension = "width" | "height" | "depth";

export interface DimensionStats {
  median: number;
  min: number;
  max: number;
  spread: number;
  std: number | null;
  relative_spread: number | null;
}

/** A video item's summary.json (prismcore.video.summary.summarize). */
export interface Summary {
  frames: { selected: number; measured: number; failed: number };
  unit: string | null;
  dimensions: Partial<Record<Dimension, DimensionStats>>;
  per_frame: ({ frame: number; time_s?: number } & Record<Dimension, number>)[];
  failed: { frame: number; error: string }[];
}

export type Verdict = "pass" | "fail" | "uncertain";
export const VERDICTS: readonly Verdict[] = ["pass", "fail", "uncertain"];

/** One dimension against its nominal (prismcore.quality.verdicts.DimensionVerdict), mm. */
export interface DimensionVerdict {
  nominal_mm: number;
  measured_mm: number;
  deviation_mm: number;
  tolerance_mm: number;
  sigma_mm: number | null;
  interval_mm: [number, number];
  verdict: Verdict;
}

/** report.json's quality block: the part's verdict against its nominal size. */
export interface Quality {
  verdict: Verdict;
  k: number;
  counts: Record<Verdict, number>;
  dimensions: Partial<Record<Dimension, DimensionVerdict>>;
}

/** An item's views (a video's frames) measured as ONE box (prism_common.public.JointPublic). */
export interface Joint {
  views: {
    index: number;
    name: string;
    click_rms_px: number;
    line_rms_px: number;
    alone: Record<Dimension, number>;
    disagreement: number | null;
  }[];
  left_out: { index: number; name: string; reason: string }[];
  focal_std_px: number | null;
  distortion_kappa: number;
}

export interface Result {
  /** Points in the cloud; 0 for a joint fit, which makes none. */
  points: number;
  dimensions: Record<Dimension, number> & { unit: string };
  point_loss: number;
  warnings: string[];
  summary?: Summary | null;
  /** One standard deviation of each dimension, in its unit. */
  uncertainty?: Record<Dimension, number> | null;
  focal_px?: number | null;
  focal_source?: string | null;
  fit_rms_px?: number | null;
  side_face?: string | null;
  quality?: Quality | null;
  /** "clicked" (given in the spec) or "auto" (found by the service's search). */
  points_source?: string | null;
  points_confidence?: number | null;
  /** The dimension a known edge gave (its length, not a measurement): shown "(given)". */
  given_dimension?: Dimension | null;
  /** Several views measured as one box: those used and those left out (null otherwise). */
  joint?: Joint | null;
}

export interface Frame {
  index: number;
  state: State;
  error: string | null;
  result: Result | null;
  downloads: Record<string, string>;
}

export interface Item {
  index: number;
  state: State;
  error: string | null;
  result: Result | null;
  downloads: Record<string, string>;
  frames: Frame[];
}

export interface Job {
  id: string;
  state: State;
  progress: number;
  /** Items finished (succeeded or failed) so far, of item_count. */
  items_done: number;
  /** Of items_done, the items that failed (never 0 in a completed_with_failures job). */
  items_failed: number;
  created_at: string;
  started_at: string | null;
  finished_at: string | null;
  client_reference: string | null;
  error: string | null;
  item_count: number;
  verdicts?: Record<Verdict, number>;
  items: Item[];
}

/** GET /v1/jobs/{id}/results.json: a row per item, then per frame of a video item. */
export interface ResultsTable {
  job_id: string;
  client_reference: string | null;
  state: State;
  verdicts: Record<Verdict, number>;
  columns: string[];
  rows: ResultRow[];
}

export type ResultRow = Record<string, string | number | boolean | null> & {
  item: number;
  frame: number | null;
  state: State;
  verdict: Verdict | null;
};

export interface JobList {
  jobs: Job[];
  next_cursor: string | null;
}

/** GET /v1/uploads/{id}/points: the box the service's search found, or why none. */
export interface FoundPoints {
  id: string;
  frame: number | null;
  hint: [number, number] | null;
  width: number;
  height: number;
  points: Partial<Record<PointName, Point>> | null;
  side_face: "right" | "left" | "top" | null;
  confidence: number;
  reason: string | null;
  warnings: string[];
  faces: Point[][];
}

export type Point = [number, number];
export type PointName = "p1" | "p2" | "p3" | "p4" | "p5" | "p6" | "p7";

export type Scale =
  | { kind: "mm_per_px"; front: number; side?: number }
  | { kind: "pinhole"; distance_mm: number; side_distance_mm?: number }
  | { kind: "edge"; edge: "width" | "height" | "depth"; length_mm: number };

export interface FrameSelection {
  every?: number;
  start_s?: number;
  end_s?: number;
  indices?: number[];
  sharpest?: number;
}

export type PointSet = Partial<Record<PointName, Point>>;

/** One photo of a part measured as one box (prismcore.spec.ViewSpec): all seven points. */
export interface ViewSpec {
  image: string;
  points: PointSet;
  side_face?: "auto" | "right" | "left" | "top";
  name?: string;
}

export interface ScanSpec {
  /** With `views`, left out: the first view's photo is the item's image. */
  image?: string;
  side_image?: string;
  /** "auto": the worker finds them (prismcore.locate.search), around `auto_points.hint` if given. */
  points?: PointSet | "auto";
  auto_points?: { hint?: Point };
  frames?: FrameSelection;
  frame_points?: Record<string, PointSet>;
  /** The frame `points` were marked on: the service tracks them to the frames selected. */
  points_frame?: number;
  /** "joint": a video's frames measured as ONE box (a known edge as the scale). */
  fit?: "frames" | "joint";
  /** 2 or more photos of one part, measured as ONE box (a known edge as the scale; no cloud). */
  views?: ViewSpec[];
  tolerance?: number;
  method?: "default" | "paper";
  /** One photo: the face P4, P5 and P7 mark besides the front; "auto" reads it from them. */
  side_face?: "auto" | "right" | "left" | "top";
  cloud?: "surface" | "volume";
  scale?: Scale;
  focal_px?: number;
  /** The part's nominal width, height and depth (mm), and the tolerance on them. */
  nominal?: [number, number, number];
  tolerance_mm?: number | [number, number, number];
  formats?: string[];
  /** A stored station's id: the part on its support measured with no points and no scale. */
  station?: string;
}
