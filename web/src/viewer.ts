// The 3D view of a cloud: three.js points with orbit controls. The cloud comes as a binary PLY
// (the worker's decimated preview), is thinned further here if it is still large, and is shown
// in the box frame turned so that the part stands upright (the engine's Y points down).

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { PLYLoader } from "three/addons/loaders/PLYLoader.js";

import { colours, type ColourMode } from "./colours";

export const MAX_DISPLAY_POINTS = 200_000;

export class Viewer {
  private renderer: THREE.WebGLRenderer;
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(45, 1, 0.1, 1e7);
  private controls: OrbitControls;
  private points: THREE.Points | null = null;
  private material = new THREE.PointsMaterial({ size: 3, sizeAttenuation: false, vertexColors: true });

  constructor(private host: HTMLElement) {
    // preserveDrawingBuffer: the picture stays readable after a frame (screenshots, tests).
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.domElement.setAttribute("aria-hidden", "true");
    host.append(this.renderer.domElement);
    this.scene.background = new THREE.Color(0x1d2025);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener("change", () => this.render());
    new ResizeObserver(() => this.resize()).observe(host);
  }

  /** Show the cloud in `ply`; returns how many points are shown out of how many came. */
  show(ply: ArrayBuffer, mode: ColourMode): { shown: number; total: number } {
    const full = new PLYLoader().parse(ply);
    const geometry = thin(full, MAX_DISPLAY_POINTS);
    this.clear();
    this.points = new THREE.Points(geometry, this.material);
    this.points.rotation.x = Math.PI; // box frame (Y down, Z into the part) -> Y up, Z to the viewer
    this.scene.add(this.points);
    this.colour(mode);
    this.reset();
    return { shown: geometry.getAttribute("position").count, total: full.getAttribute("position").count };
  }

  colour(mode: ColourMode): void {
    if (!this.points) return;
    const geometry = this.points.geometry;
    geometry.setAttribute("color", colours(geometry, mode));
    this.render();
  }

  pointSize(px: number): void {
    this.material.size = px;
    this.render();
  }

  /** Look at the whole cloud from the front, a little from the right and above. */
  reset(): void {
    if (!this.points) return this.render();
    this.points.updateMatrixWorld();
    this.points.geometry.computeBoundingSphere();
    const sphere = this.points.geometry.boundingSphere!.clone().applyMatrix4(this.points.matrixWorld);
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
      this.scene.remove(this.points);
      this.points.geometry.dispose();
      this.points = null;
    }
    this.render();
  }

  private resize(): void {
    const { clientWidth: w, clientHeight: h } = this.host;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  private render(): void {
    this.renderer.render(this.scene, this.camera);
  }
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
