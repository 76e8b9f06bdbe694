"""A `Scene` path traced by Mitsuba 3 (variant scalar_rgb: the llvm variants crash on these
machines), then developed as a camera does: auto exposure, white balance, shot and read noise,
a tone curve, JPEG. Renders are cached outside the repository (PRISM_PBR_CACHE, default
~/.cache/prismcloud/pbr): a scene's key is its description, so a changed generator renders anew.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from .layout import Clutter, Light, Part, Scene
from .meshes import rounded_box, write_ply
from .textures import fabric, glossy_print, kraft, laminate, linear, printed_page, printed_table, wood

__all__ = ["GENERATOR_VERSION", "cache_dir", "develop", "render_scene"]

GENERATOR_VERSION = "pbr-1"
_PAGE_PX_PER_MM = 5.0


def cache_dir() -> Path:
    """Where renders are kept between runs (never inside the repository)."""
    return Path(os.environ.get("PRISM_PBR_CACHE", Path.home() / ".cache" / "prismcloud" / "pbr"))


def _mi() -> Any:
    import mitsuba as mi

    if mi.variant() != "scalar_rgb":
        mi.set_variant("scalar_rgb")
        # A cylinder's frame from p0, p1 carries rounding-level shear, which Mitsuba warns of
        # once per segment of every cable.
        mi.set_log_level(mi.LogLevel.Error)
    return mi


def _t4(M: np.ndarray) -> Any:
    return _mi().ScalarTransform4f(np.asarray(M, np.float64).tolist())


def _bitmap(img: np.ndarray) -> dict[str, Any]:
    return {
        "type": "bitmap",
        "bitmap": _mi().Bitmap(np.ascontiguousarray(img, np.float32)),
        "raw": True,
        "filter_type": "bilinear",
    }


def _trs(
    t: tuple[float, float, float], yaw_deg: float = 0.0, s: tuple[float, float, float] = (1, 1, 1)
) -> np.ndarray:
    c, si = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    M = np.eye(4)
    M[:3, :3] = np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]]) @ np.diag(s)
    M[:3, 3] = t
    return M


def _facing_down(centre: tuple[float, float, float], half: tuple[float, float]) -> np.ndarray:
    """A rectangle (local [-1, 1]^2, normal +z) turned to face -z (up, towards the camera), its
    texture's rows running along +y."""
    M = np.eye(4)
    M[:3, :3] = np.diag([half[0], half[1], -1.0])  # mirror z: the normal points up
    M[:3, 3] = centre
    return M


def _rgb(v: tuple[float, ...] | np.ndarray) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(x) for x in v]}


def _part_bsdf(part: Part, rng: np.random.Generator) -> dict[str, Any]:
    tex = (256, 384)
    m = part.material
    if m == "kraft":
        return {"type": "diffuse", "reflectance": _bitmap(kraft(rng, tex))}
    if m == "glossy":
        return _varnished(float(rng.uniform(0.03, 0.12)), _bitmap(glossy_print(rng, tex)), ior=1.5)
    if m == "aluminium":
        return {
            "type": "roughconductor",
            "material": "Al",
            "distribution": "ggx",
            "alpha_u": float(rng.uniform(0.05, 0.25)),
            "alpha_v": float(rng.uniform(0.02, 0.1)),
        }
    if m == "steel":
        return {
            "type": "roughconductor",
            "material": "Cr",
            "distribution": "ggx",
            "alpha": float(rng.uniform(0.03, 0.15)),
        }
    if m == "black":
        return _varnished(float(rng.uniform(0.1, 0.35)), _rgb(linear(np.full(3, rng.uniform(0.06, 0.16)))))
    return _varnished(float(rng.uniform(0.1, 0.35)), _rgb(linear(rng.uniform(0.86, 0.95, 3))))


def _varnished(alpha: float, reflectance: dict[str, Any], ior: float = 1.49) -> dict[str, Any]:
    """A diffuse surface under a clear coat of roughness `alpha` and index `ior` (a varnished or
    laminated top, printed packaging, plastic; 1.49 is Mitsuba's own default)."""
    return {"type": "roughplastic", "alpha": alpha, "distribution": "ggx", "diffuse_reflectance": reflectance,
            "int_ior": ior}


def _table(scene: Scene, rng: np.random.Generator) -> dict[str, Any]:
    x0, y0, x1, y1 = scene.table_extent_mm
    px = 0.5  # texture px per mm
    size = (int((y1 - y0) * px), int((x1 - x0) * px))
    kind = scene.table
    if kind == "wood":
        bsdf = _varnished(float(rng.uniform(0.1, 0.4)), _bitmap(wood(rng, size)))
    elif kind == "laminate":
        bsdf = _varnished(float(rng.uniform(0.08, 0.3)), _bitmap(laminate(rng, size)))
    elif kind == "metal":
        bsdf = {
            "type": "roughconductor",
            "material": str(rng.choice(["Al", "Cr"])),
            "distribution": "ggx",
            "alpha": float(rng.uniform(0.15, 0.4)),
        }
    elif kind == "fabric":
        bsdf = {"type": "diffuse", "reflectance": _bitmap(fabric(rng, size))}
    else:
        bsdf = {"type": "diffuse", "reflectance": _bitmap(printed_table(rng, size))}
    centre = ((x0 + x1) / 2, (y0 + y1) / 2, 0.0)
    return {
        "table": {
            "type": "rectangle",
            "to_world": _t4(_facing_down(centre, ((x1 - x0) / 2, (y1 - y0) / 2))),
            "bsdf": bsdf,
        },
        "table_body": {
            "type": "cube",
            "to_world": _t4(_trs((centre[0], centre[1], 16.0), 0, ((x1 - x0) / 2, (y1 - y0) / 2, 15.0))),
            "bsdf": {"type": "diffuse", "reflectance": _rgb(linear(rng.uniform(0.1, 0.5, 3)))},
        },
        "floor": {
            "type": "rectangle",
            "to_world": _t4(_facing_down((centre[0], centre[1], 760.0), (4000, 4000))),
            "bsdf": {"type": "diffuse", "reflectance": _rgb(linear(rng.uniform(0.15, 0.6, 3)))},
        },
    }


def _light(i: int, light: Light) -> dict[str, Any]:
    if light.kind == "ambient":
        return {f"light{i}": {"type": "constant", "radiance": _rgb(light.rgb)}}
    emitter = {"type": "area", "radiance": _rgb(light.rgb)}
    half = (light.size[0] / 2, light.size[1] / 2)
    if light.kind == "area":
        M = np.eye(4)
        M[:3, :3] = np.diag([half[0], half[1], 1.0])  # normal +z: down onto the table
        M[:3, 3] = light.centre
    else:
        n = np.array(light.facing)
        up = np.array([0.0, 0.0, -1.0])
        side = np.cross(up, n)
        M = np.eye(4)
        M[:3, :3] = np.column_stack([side * half[0], up * half[1], n])
        M[:3, 3] = light.centre
    return {f"light{i}": {"type": "rectangle", "to_world": _t4(M), "emitter": emitter}}


def _plastic(rgb: tuple[float, ...], metal: bool) -> dict[str, Any]:
    if metal:
        return {"type": "roughconductor", "material": "Al", "alpha": 0.15}
    return {"type": "roughplastic", "alpha": 0.25, "diffuse_reflectance": _rgb(linear(np.array(rgb)))}


def _clutter(i: int, c: Clutter, work: Path) -> dict[str, Any]:
    key = f"clutter{i}"
    bsdf = _plastic(c.rgb, c.metal)
    if c.kind in ("box", "ruler"):
        if c.kind == "ruler":  # a pale plastic rule, whatever the clutter's colour
            pale = _rgb(linear(np.array([0.9, 0.88, 0.8])))
            bsdf = {"type": "roughplastic", "alpha": 0.3, "diffuse_reflectance": pale}
        half = (c.size[0] / 2, c.size[1] / 2, c.size[2] / 2)
        return {key: {"type": "cube", "to_world": _t4(_trs((c.x_mm, c.y_mm, -half[2]), c.yaw_deg, half)),
                      "bsdf": bsdf}}
    if c.kind == "ball":
        r = c.size[0]
        return {key: {"type": "sphere", "center": [c.x_mm, c.y_mm, -r], "radius": r, "bsdf": bsdf}}
    if c.kind == "mug":
        r, h = c.size[0], c.size[2]
        return {
            key: {
                "type": "cylinder",
                "p0": [c.x_mm, c.y_mm, 0.0],
                "p1": [c.x_mm, c.y_mm, -h],
                "radius": r,
                "bsdf": {"type": "twosided", "bsdf": bsdf},
            },
            key + "_cap": {
                "type": "disk",
                "to_world": _t4(_facing_down((c.x_mm, c.y_mm, -h), (r, r))),
                "bsdf": bsdf,
            },
        }
    if c.kind == "hand":
        # An occluder well above the board: a hand's soft shadow, not the hand.
        return {
            key: {
                "type": "sphere",
                "to_world": _t4(_trs((c.x_mm, c.y_mm, -450.0), c.yaw_deg, c.size)),
                "bsdf": {"type": "diffuse", "reflectance": _rgb(linear(np.array(c.rgb)))},
            }
        }
    out: dict[str, Any] = {}
    r = c.size[0]
    for k, (a, b) in enumerate(zip(c.path[:-1], c.path[1:], strict=True)):
        out[f"{key}_{k}"] = {
            "type": "cylinder",
            "p0": [a[0], a[1], -r],
            "p1": [b[0], b[1], -r],
            "radius": r,
            "bsdf": bsdf,
        }
        out[f"{key}_j{k}"] = {"type": "sphere", "center": [b[0], b[1], -r], "radius": r, "bsdf": bsdf}
    return out


def _scene_dict(scene: Scene, spp: int, work: Path) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    cam = scene.camera
    cw, ch, fov, map_x, map_y = cam.render_plan()
    rng = np.random.default_rng([scene.table_seed, 1])
    d: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": {
            "type": "perspective",
            "fov": fov,
            "fov_axis": "x",
            "near_clip": 5.0,
            "far_clip": 20000.0,
            "to_world": _t4(cam.mitsuba_to_world()),
            "film": {
                "type": "hdrfilm",
                "width": cw,
                "height": ch,
                "pixel_format": "rgb",
                "rfilter": {"type": "gaussian"},
            },
            "sampler": {"type": "independent", "sample_count": spp},
        },
    }
    d.update(_table(scene, rng))
    page = printed_page(
        scene.board,
        scene.paper_mm,
        _PAGE_PX_PER_MM,
        scene.page_board_offset_mm,
        scene.ink,
        scene.paper_white,
    )
    sx, sy = scene.sheet_origin_mm
    pw, ph = scene.paper_mm
    d["sheet"] = {
        "type": "rectangle",
        "to_world": _t4(_facing_down((sx + pw / 2, sy + ph / 2, -0.15), (pw / 2, ph / 2))),
        "bsdf": {
            "type": "roughplastic",
            "alpha": 0.4,
            "distribution": "ggx",
            "diffuse_reflectance": _bitmap(page),
        },
    }
    for i, light in enumerate(scene.lights):
        d.update(_light(i, light))
    for i, c in enumerate(scene.clutter):
        d.update(_clutter(i, c, work))
    if scene.part is not None:
        p = scene.part
        prng = np.random.default_rng([p.seed, 2])
        v, n, uv, tris = rounded_box((p.length_mm, p.width_mm, p.height_mm), p.radius_mm)
        path = work / "part.ply"
        write_ply(path, v, n, uv, tris)
        d["part"] = {
            "type": "ply",
            "filename": str(path),
            "face_normals": False,
            "to_world": _t4(_trs((p.x_mm, p.y_mm, -p.height_mm / 2), p.yaw_deg)),
            "bsdf": _part_bsdf(p, prng),
        }
    return d, map_x, map_y


def develop(linear_rgb: np.ndarray, scene: Scene, rng: np.random.Generator) -> np.ndarray:
    """A camera's processing of the sensor's linear light into an 8-bit sRGB photo: white balance
    (grey world, with the camera's own error), auto exposure (the 97th percentile of luminance
    near white, biased as meters are), shot noise and read noise, the sRGB curve with a gentle
    shoulder, then JPEG at the photo's quality."""
    img = np.clip(linear_rgb.astype(np.float64), 0, None)
    means = img.reshape(-1, 3).mean(0) + 1e-9
    wb = means.mean() / means * np.array(scene.exposure.white_balance_error)
    img = img * wb
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    img = img * (0.85 / max(float(np.percentile(lum, 97)), 1e-9)) * 2.0**scene.exposure.bias_ev
    full = scene.exposure.full_well
    img = rng.poisson(np.clip(img, 0, 4) * full) / full + rng.normal(0, 3.0 / full, img.shape)
    img = np.clip(img, 0, None)
    img = img / (1 + 0.15 * img)  # a shoulder: highlights roll off instead of clipping hard
    img = img * 1.15
    srgb = np.where(img <= 0.0031308, 12.92 * img, 1.055 * np.power(img, 1 / 2.4) - 0.055)
    out = np.clip(np.round(srgb * 255), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(
        ".jpg", cv2.cvtColor(out, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, scene.exposure.jpeg_quality]
    )
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    assert ok and decoded is not None
    return np.asarray(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB), np.uint8)


def _key(scene: Scene, spp: int) -> str:
    text = repr(
        (
            GENERATOR_VERSION,
            scene,
            spp,
            scene.camera.K.tolist(),
            scene.camera.R.tolist(),
            scene.camera.t.tolist(),
            scene.camera.dist.tolist(),
        )
    )
    return hashlib.sha1(text.encode()).hexdigest()[:20]


def render_scene(scene: Scene, spp: int | None = None, *, cache: bool = True) -> np.ndarray:
    """The photo of `scene`: (H, W, 3) uint8 RGB, as a camera would have written it."""
    spp = scene.settings.spp if spp is None else spp
    path = cache_dir() / f"{scene.settings.name}-{_key(scene, spp)}.png"
    cached = cv2.imread(str(path), cv2.IMREAD_COLOR) if cache and path.is_file() else None
    if cached is not None:
        return np.asarray(cv2.cvtColor(cached, cv2.COLOR_BGR2RGB), np.uint8)
    mi = _mi()
    with tempfile.TemporaryDirectory() as tmp:
        d, map_x, map_y = _scene_dict(scene, spp, Path(tmp))
        loaded = mi.load_dict(d)
        seed = int(hashlib.sha1(path.name.encode()).hexdigest()[:7], 16)
        raw = np.asarray(mi.render(loaded, seed=seed), np.float32)
    ideal = cv2.remap(raw, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    photo = develop(ideal, scene, np.random.default_rng(seed))
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(path), cv2.cvtColor(photo, cv2.COLOR_RGB2BGR))
    return photo
