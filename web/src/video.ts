// Videos: told from photos by their first bytes (mirrors prismcore.io.containers), and read through
// the API, which has a worker decode them: the frame shown here is the very PNG the worker's
// decoder makes, so it is the frame measured, whatever the codec (MJPEG AVI plays in no browser).

import { whenReady as ready } from "./api";
import type { VideoInfo } from "./types";

const HEAD_BYTES = 16;
// ISO media brands that are still images or audio (prismcore.io.containers._NOT_VIDEO_BRANDS).
const NOT_VIDEO_BRANDS = new Set(["heic", "heix", "heim", "heis", "hevc", "hevx", "hevm", "hevs", "mif1",
  "msf1", "avif", "avis", "avio", "jxl ", "crx ", "jp2 ", "jpx ", "jpm ", "M4A ", "M4B ", "M4P ", "F4A ", "F4B "]);
const QUICKTIME_ATOMS = new Set(["moov", "mdat", "wide", "free", "skip", "pnot"]);
const CACHED_FRAMES = 24;

/** Is this file a video (AVI, MP4, MOV, MKV/WebM)? The content decides, as on the service. */
export async function isVideo(file: File): Promise<boolean> {
  const head = new Uint8Array(await file.slice(0, HEAD_BYTES).arrayBuffer());
  const text = (a: number, b: number) => String.fromCharCode(...head.slice(a, b));
  if (text(0, 4) === "RIFF" && text(8, 12) === "AVI ") return true;
  if (head[0] === 0x1a && head[1] === 0x45 && head[2] === 0xdf && head[3] === 0xa3) return true; // EBML
  const box = text(4, 8);
  if (box === "ftyp" && head.length >= 12) return !NOT_VIDEO_BRANDS.has(text(8, 12));
  const size = new DataView(head.buffer).getUint32(0);
  if (QUICKTIME_ATOMS.has(box) && (size === 1 || (size >= 8 && size < 1 << 24) || box === "mdat")) return true;
  return false;
}

/** GET `path`, asking again while the worker is still decoding. */
function whenReady(path: string): Promise<Response> {
  return ready(path, "The service has not decoded the video yet; try again in a while.");
}

export async function videoInfo(uploadId: string): Promise<VideoInfo> {
  return (await whenReady(`/v1/uploads/${uploadId}/video`)).json() as Promise<VideoInfo>;
}

const frames = new Map<string, Promise<ImageBitmap>>(); // most recent last

/** Frame `index` of an uploaded video, as the worker decodes it (kept for a few frames). */
export function videoFrame(uploadId: string, index: number): Promise<ImageBitmap> {
  const key = `${uploadId}/${index}`;
  let bitmap = frames.get(key);
  if (bitmap) {
    frames.delete(key);
  } else {
    bitmap = whenReady(`/v1/uploads/${uploadId}/frames/${index}.png`)
      .then((r) => r.blob())
      .then((blob) => createImageBitmap(blob));
    bitmap.catch(() => frames.delete(key)); // a failure is not kept: asking again retries
  }
  frames.set(key, bitmap);
  while (frames.size > CACHED_FRAMES) frames.delete(frames.keys().next().value!);
  return bitmap;
}

/** "8 frames at 25 fps (0.32 s), 640 × 512, codec MJPG". */
export function describeVideo(v: VideoInfo): string {
  const rate = v.fps ? ` at ${v.fps.toLocaleString("en", { maximumFractionDigits: 3 })} fps` +
    ` (${v.duration_s.toFixed(2)} s)` : " (no frame rate stated)";
  return `${v.frame_count} frames${rate}, ${v.width} × ${v.height}, codec ${v.codec}`;
}
