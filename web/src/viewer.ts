// The 3D view of a cloud: three.js points with orbit controls. The cloud comes as a binary PLY
// (the worker's decimated preview), is thinned further here if it is still large, and is shown
// in the box frame turned so that the part stands upright (the engine's Y points down). Over it:
// the fitted box as a wireframe, its dimension lines with labels, the box frame's axes and a
// scale bar (labels are DOM elements: readable, and testable). The worker's glTF box model
// (box.glb) can be shown instead of the cloud.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { PLYLoader } from "three/addons/loaders/PLYLoader.js";
import { CSS2DObject, CSS2DRenderer } from "three/addons/renderers/CSS2DRenderer.js";

import { colours, type ColourMode } from "./colours";
import { gapScales } from "./coverage";
import type { Dimension, Verdict } from "./types";
import { verdictText } from "./verdicts";

export const MAX_DISPLAY_POINTS = 200_000;
const FOV = 45;

/** The fitted box (in the cloud's unit, from the box frame's origin P1) and its labels. */
export interface BoxAnnotation {
  size: [number, number, number];
  unit: string;
  labels: Record<Dimension, { text: string; verdict?: Verdict; warned?: boolean }>;
}

export class Viewer {
  private renderer: THREE.WebGLRenderer;
  private labels = new CSS2DRenderer();
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(FOV, 1, 0.1, 1e7);
  private controls: OrbitControls;
  // The box frame (Y down, Z into the part) turned to Y up, Z to the viewer.
  private frame = new THREE.Group();
  private points: THREE.Points | null = null;
  private model: THREE.Object3D | null = null;
  private overlay = new THREE.Group(); // box wireframe, dimension lines, axes
  private scaleBar: HTMLElement;
  private unit = "";
  private spacing = 1; // typical distance between neighbouring points, cloud units
  private sizeStep = 3;
  // World-sized points (size attenuation): each covers its share of the surface at any zoom, so
  // a thinned cloud shows no regular gaps (fixed-pixel points left stripes on grazing faces).
  // Each point is further enlarged by its own factor (the attribute `gapScale`, coverage.ts) where
  // the preview's thinning left its face with slits wider than a point.
  private material = pointsMaterial();

  constructor(private host: HTMLElement) {
    // preserveDrawingBuffer: the picture stays readable after a frame (screenshots, tests).
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.domElement.setAttribute("aria-hidden", "true");
    host.append(this.renderer.domElement);
    const labels = this.labels.domElement;
    labels.className = "label2d";
    Object.assign(labels.style, { position: "absolute", top: "0", left: "0", pointerEvents: "none" });
    host.append(labels);
    this.scaleBar = document.createElement("div");
    this.scaleBar.className = "scale-bar";
    this.scaleBar.hidden = true;
    host.append(this.scaleBar);
    this.scene.background = new THREE.Color(0x1d2025);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 2.2), this.frame);
    this.frame.rotation.x = Math.PI;
    this.frame.add(this.overlay);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener("change", () => this.render());
    new ResizeObserver(() => this.resize()).observe(host);
  }

  /** Show the cloud in `ply`; returns how many points are shown out of how many came. */
  show(ply: ArrayBuffer, mode: ColourMode, box?: BoxAnnotation): { shown: number; total: number } {
    const full = new PLYLoader().parse(ply);
    const geometry = thin(full, MAX_DISPLAY_POINTS);
    this.clear();
    this.points = new THREE.Points(geometry, this.material);
    this.frame.add(this.points);
    const shown = geometry.getAttribute("position").count;
    geometry.computeBoundingBox();
    this.spacing = spacing(geometry.boundingBox!, shown);
    const position = geometry.getAttribute("position");
    geometry.setAttribute("gapScale", new THREE.BufferAttribute(
      gapScales(position, geometry.boundingBox!, this.worldSize(3)), 1));
    this.pointSize(this.sizeStep);
    this.annotate(box ?? null, geometry.boundingBox!);
    this.colour(mode);
    this.reset();
    return { shown, total: full.getAttribute("position").count };
  }

  /** Show the glTF box model (metres, Y up, origin at the box's bottom-front-left corner). */
  async showModel(glb: ArrayBuffer, box?: BoxAnnotation): Promise<void> {
    const gltf = await new GLTFLoader().parseAsync(glb, "");
    this.clear();
    const model = gltf.scene;
    const bounds = new THREE.Box3().setFromObject(model);
    const height = box ? box.size[1] : (bounds.max.y - bounds.min.y) * 1000;
    // glb (x, H - y, -z) / 1000 -> this view's (x, -y, -z): the same place as the cloud.
    model.scale.setScalar(1000);
    model.position.y = -height;
    this.model = model;
    this.scene.add(model);
    const frameBox = new THREE.Box3(new THREE.Vector3(0, 0, 0),
      new THREE.Vector3(...(box?.size ?? [bounds.max.x * 1000, height, (bounds.max.z - bounds.min.z) * 1000])));
    this.annotate(box ?? null, frameBox);
    this.reset();
  }

  colour(mode: ColourMode): void {
    if (!this.points) return;
    const geometry = this.points.geometry;
    geometry.setAttribute("color", colours(geometry, mode));
    this.render();
  }

  /** The point size slider's step (1-8; 3 by default covers the surface without gaps). */
  pointSize(step: number): void {
    this.sizeStep = step;
    // PointsMaterial's attenuated size is drawn (viewport height / 2) / depth pixels per unit,
    // without the field of view; a world length L covers L (height / 2) / (depth tan(fov / 2)).
    this.material.size = this.worldSize(step) / Math.tan(THREE.MathUtils.degToRad(FOV / 2));
    this.render();
  }

  /** The side of a point, in cloud units, at slider step `step`. */
  private worldSize(step: number): number {
    return this.spacing * 0.55 * step;
  }

  /** Show or hide the box, its dimension lines and the axes. */
  annotations(on: boolean): void {
    this.overlay.visible = on;
    for (const el of this.labels.domElement.querySelectorAll<HTMLElement>(".dim-label, .axis-label")) {
      el.hidden = !on;
    }
    this.render();
  }

  /** Look at the whole cloud from the front, a little from the right and above. */
  reset(): void {
    const shown = this.points ?? this.model;
    if (!shown) return this.render();
    const sphere = new THREE.Box3().setFromObject(shown).getBoundingSphere(new THREE.Sphere());
    const centre = sphere.center;
    const r = Math.max(sphere.radius, 1e-6);
    this.camera.position.copy(centre).add(new THREE.Vector3(0.9 * r, 0.8 * r, 2.6 * r));
    this.camera.near = r / 100;
    this.camera.far = r * 100;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
    this.render();
  }

  clear(): void {
    if (this.points) {
      this.frame.remove(this.points);
      this.points.geometry.dispose();
      this.points = null;
    }
    if (this.model) {
      this.scene.remove(this.model);
      this.model = null;
    }
    this.annotate(null, null);
    this.render();
  }

  /** The fitted box's wireframe, dimension lines and labels, and the axes at P1. */
  private annotate(box: BoxAnnotation | null, bounds: THREE.Box3 | null): void {
    for (const child of [...this.overlay.children]) {
      this.overlay.remove(child);
      child.traverse((o) => {
        if (o instanceof CSS2DObject) o.element.remove();
        if (o instanceof THREE.LineSegments) o.geometry.dispose();
      });
    }
    this.unit = box?.unit ?? "";
    this.scaleBar.hidden = !bounds;
    if (!bounds) return;
    const [w, h, d] = box ? box.size : bounds.getSize(new THREE.Vector3()).toArray();
    const big = Math.max(w, h, d);
    const o = 0.12 * big; // dimension lines stand this far off the box
    const line = (points: number[], colour: number, opacity = 1): THREE.LineSegments => {
      const geometry = new THREE.BufferGeometry().setAttribute("position", new THREE.Float32BufferAttribute(points, 3));
      // Drawn over the cloud (no depth test): the fit stays visible against dense points.
      const material = new THREE.LineBasicMaterial({ color: colour, depthTest: false, transparent: true, opacity });
      const segments = new THREE.LineSegments(geometry, material);
      segments.renderOrder = 2;
      return segments;
    };
    if (box) {
      const edges = new THREE.EdgesGeometry(new THREE.BoxGeometry(w, h, d));
      const wire = line(Array.from(edges.getAttribute("position").array as Float32Array), 0xffffff, 0.75);
      wire.position.set(w / 2, h / 2, d / 2);
      wire.name = "box";
      this.overlay.add(wire);
      // (start, end, offset direction) per dimension, in the box frame (Y down, Z into the part).
      const dims: [Dimension, THREE.Vector3, THREE.Vector3, THREE.Vector3][] = [
        ["width", new THREE.Vector3(0, 0, 0), new THREE.Vector3(w, 0, 0), new THREE.Vector3(0, -1, 0)],
        ["height", new THREE.Vector3(0, 0, 0), new THREE.Vector3(0, h, 0), new THREE.Vector3(-1, 0, 0)],
        ["depth", new THREE.Vector3(w, h, 0), new THREE.Vector3(w, h, d), new THREE.Vector3(1, 0, 0)],
      ];
      for (const [name, a, b, dir] of dims) {
        const [a2, b2] = [a.clone().addScaledVector(dir, o), b.clone().addScaledVector(dir, o)];
        const [a3, b3] = [a.clone().addScaledVector(dir, o * 1.25), b.clone().addScaledVector(dir, o * 1.25)];
        const tick = (p: THREE.Vector3, q: THREE.Vector3) => [p.x, p.y, p.z, q.x, q.y, q.z];
        const dimLine = line([...tick(a2, b2), ...tick(a, a3), ...tick(b, b3)], 0x7cc4ff);
        dimLine.name = `dim-${name}`;
        const { text, verdict, warned } = box.labels[name];
        const label = labelDiv(text, warned ? "dim-label warned" : "dim-label", verdict);
        label.dataset.dim = name;
        const object = new CSS2DObject(label);
        object.position.copy(a2).add(b2).multiplyScalar(0.5);
        dimLine.add(object);
        this.overlay.add(dimLine);
      }
    }
    // The box frame's axes at P1: X along P1->P2 (red), Y down the front (green), Z into the part (blue).
    const axes = new THREE.AxesHelper(0.3 * big);
    (axes.material as THREE.LineBasicMaterial).depthTest = false;
    axes.renderOrder = 3;
    const colour = ["#ff6b6b", "#6bff8a", "#6bb6ff"];
    ["X", "Y", "Z"].forEach((name, i) => {
      const label = labelDiv(name, "axis-label");
      label.style.color = colour[i];
      const object = new CSS2DObject(label);
      object.position.setComponent(i, 0.34 * big);
      axes.add(object);
    });
    this.overlay.add(axes);
  }

  private resize(): void {
    const { clientWidth: w, clientHeight: h } = this.host;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.labels.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  /** A bar of a round length (1, 2 or 5 times a power of ten) about 100 px long at the target. */
  private updateScaleBar(): void {
    const h = this.host.clientHeight;
    if (this.scaleBar.hidden || !h) return;
    const distance = this.camera.position.distanceTo(this.controls.target);
    const perPx = (2 * distance * Math.tan(THREE.MathUtils.degToRad(FOV / 2))) / h; // units per pixel
    const raw = 110 * perPx;
    const power = 10 ** Math.floor(Math.log10(raw));
    const nice = [5, 2, 1].map((m) => m * power).find((v) => v <= raw) ?? power;
    const bar = document.createElement("div");
    bar.className = "bar";
    bar.style.width = `${Math.round(nice / perPx)}px`;
    const text = `${nice.toLocaleString("en", { maximumSignificantDigits: 3 })} ${this.unit}`.trim();
    this.scaleBar.replaceChildren(bar, text);
    this.scaleBar.dataset.length = String(nice);
    this.scaleBar.setAttribute("aria-label", `Scale bar: ${text} at the centre of the view`);
  }

  private render(): void {
    this.renderer.render(this.scene, this.camera);
    this.labels.render(this.scene, this.camera);
    this.updateScaleBar();
  }
}

/** three's PointsMaterial, its size multiplied per point by the attribute `gapScale`. */
function pointsMaterial(): THREE.PointsMaterial {
  const material = new THREE.PointsMaterial({ size: 1, sizeAttenuation: true, vertexColors: true });
  material.onBeforeCompile = (shader) => {
    shader.vertexShader = shader.vertexShader
      .replace("uniform float size;", "uniform float size;\nattribute float gapScale;")
      .replace("gl_PointSize = size;", "gl_PointSize = size * gapScale;");
  };
  return material;
}

function labelDiv(text: string, cls: string, verdict?: Verdict): HTMLElement {
  const div = document.createElement("div");
  div.className = cls + (verdict ? ` verdict-${verdict}` : "");
  div.textContent = verdict ? `${text} · ${verdictText(verdict)}` : text;
  return div;
}

/** The typical distance between neighbouring points: the cloud's bounding box surface shared
 * out among its points (a box's surface cloud covers its six faces). */
function spacing(bounds: THREE.Box3, count: number): number {
  const [a, b, c] = bounds.getSize(new THREE.Vector3()).toArray();
  const area = 2 * (a * b + b * c + c * a);
  return count > 0 && area > 0 ? Math.sqrt(area / count) : 1;
}

/** Every k-th point, so that at most `max` remain (an even spread over the cloud's rows). */
export function thin(geometry: THREE.BufferGeometry, max: number): THREE.BufferGeometry {
  const count = geometry.getAttribute("position").count;
  if (count <= max) return geometry;
  const step = Math.ceil(count / max);
  const out = new THREE.BufferGeometry();
  for (const [name, attr] of Object.entries(geometry.attributes)) {
    const a = attr as THREE.BufferAttribute;
    const Ctor = a.array.constructor as new (n: number) => THREE.TypedArray;
    const kept = new Ctor(Math.ceil(count / step) * a.itemSize);
    for (let i = 0, j = 0; i < count; i += step, j++) {
      for (let c = 0; c < a.itemSize; c++) kept[j * a.itemSize + c] = a.array[i * a.itemSize + c];
    }
    out.setAttribute(name, new THREE.BufferAttribute(kept, a.itemSize, a.normalized));
  }
  return out;
}
