"""The outputs people open elsewhere, on a rendered box of known size: a cloud at a metric spacing,
LAS/LAZ read back with laspy, the textured box glb loaded with pygltflib and with trimesh."""

from __future__ import annotations

import io
import json

import cv2
import laspy
import numpy as np
import pygltflib
import pytest
import trimesh
from scipy.spatial import cKDTree

from prismcore import Cloud, InputError, ScanSpec, run_scan
from prismcore.camera import CameraModel
from prismcore.outputs.glb import box_glb, box_to_gltf
from prismcore.outputs.las import SCALE_M, box_to_las, write_las
from prismcore.outputs.writers import write_format
from prismcore.report import report_dict
from prismcore.scan.spacing import thin_to_count, thin_to_spacing
from prismsynth import Box, Realism, distort_points, render_oblique_view

BOX = Box(120.0, 80.0, 60.0)
NAMES = ("p1", "p2", "p3", "p4", "p5", "p6", "p7")


def _spec(**extra) -> ScanSpec:
    return ScanSpec.model_validate({"image": "box.png", "points": [SCENE_POINTS[n] for n in NAMES],
                                    "focal_px": 1400.0, "nominal": [120, 80, 60], "tolerance_mm": 0.5,
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0},
                                    **extra})


SCENE = render_oblique_view(BOX, seed=5)
SCENE_POINTS = {n: SCENE.points[n] for n in NAMES}


@pytest.fixture(scope="module")
def scan():
    spec = _spec()
    return spec, run_scan(spec, SCENE.image)


@pytest.fixture(scope="module")
def thinned():
    spec = _spec(spacing_mm=1.0)
    return spec, run_scan(spec, SCENE.image)


# ------------------------------------------------------------------------------------ spacing


def _front(cloud: Cloud) -> np.ndarray:
    return cloud.points[cloud.points[:, 2] == 0.0][:, :2].astype(np.float64)


def test_the_report_has_the_quality_block(scan):
    quality = report_dict(scan[1].report)["quality"]
    assert set(quality["dimensions"]) == {"width", "height", "depth"}
    assert quality["dimensions"]["width"]["nominal_mm"] == 120.0
    assert sum(quality["counts"].values()) == 3
    json.dumps(quality)  # JSON-ready


def test_spacing_gives_neighbours_about_that_far_apart_and_no_holes(scan, thinned):
    full, thin = scan[1].cloud, thinned[1].cloud
    assert len(thin.points) < len(full.points) / 4
    assert thinned[1].report.points == len(thin.points)
    assert thinned[1].report.dimensions == scan[1].report.dimensions  # thinning measures nothing
    front = _front(thin)
    d, _ = cKDTree(front).query(front, k=2)
    assert np.median(d[:, 1]) == pytest.approx(1.0, rel=0.15)
    # No hole wider than ~2 spacings anywhere inside the face: every spot of the face has a
    # kept point within one spacing.
    w, h = thinned[1].report.dimensions.width, thinned[1].report.dimensions.height
    gx, gy = np.meshgrid(np.linspace(1, w - 1, 400), np.linspace(1, h - 1, 300))
    gap, _ = cKDTree(front).query(np.stack([gx.ravel(), gy.ravel()], axis=1))
    assert gap.max() <= 1.0
    # every kept point is a real point of the full cloud, with its own colour
    full_index = {tuple(p): i for i, p in enumerate(map(tuple, full.points))}
    rows = [full_index[tuple(p)] for p in thin.points[:500]]
    assert np.array_equal(full.colors[rows], thin.colors[:500])


def test_thinning_a_regular_grid_keeps_one_point_per_voxel():
    u, v = np.meshgrid(np.arange(0, 10, 0.25), np.arange(0, 5, 0.25))  # pitch 0.25 mm
    pts = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1).astype(np.float32)
    cloud = Cloud(pts, np.zeros((len(pts), 3), np.uint8))
    thin = thin_to_spacing(cloud, 1.0)
    assert len(thin.points) == 10 * 5
    assert np.array_equal(thin_to_spacing(cloud, 1.0).points, thin.points)  # deterministic
    assert len(thin_to_spacing(cloud, 0.01).points) == len(pts)  # never densified, nothing lost
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError):
            thin_to_spacing(cloud, bad)


# ------------------------------------------------------------------------------------ LAS / LAZ


@pytest.mark.parametrize("kind", ["laz", "las"])
def test_las_reads_back_with_laspy(scan, kind):
    spec, result = scan
    buf = io.BytesIO()
    write_format(kind, buf, result.cloud, spec)
    las = laspy.read(io.BytesIO(buf.getvalue()))
    assert (las.header.point_format.id, str(las.header.version)) == (2, "1.2")
    assert np.allclose(las.header.scales, SCALE_M)
    assert las.header.point_count == len(result.cloud.points)
    # metres, Z up: (x, z, -y) / 1000, to within the 0.1 mm grid
    xyz = np.stack([las.x, las.y, las.z], axis=1)
    expected = box_to_las(result.cloud.points)
    assert np.abs(xyz - expected).max() <= SCALE_M / 2 + 1e-12
    assert np.allclose(xyz[:, 0] * 1000, result.cloud.points[:, 0], atol=0.051)
    assert np.allclose(xyz[:, 2] * 1000, -result.cloud.points[:, 1], atol=0.051)
    rgb = np.stack([las.red, las.green, las.blue], axis=1)
    assert np.array_equal(rgb // 257, result.cloud.colors) and np.array_equal(rgb % 257, 0 * rgb)
    assert np.allclose(las.header.mins, xyz.min(axis=0)) and np.allclose(las.header.maxs, xyz.max(axis=0))


def test_laz_is_compressed_and_refuses_bad_destinations(scan, tmp_path):
    cloud = scan[1].cloud
    laz = write_las(tmp_path / "c.laz", cloud.points, cloud.colors)
    las = write_las(tmp_path / "c.las", cloud.points, cloud.colors, compressed=False)
    assert laz == (tmp_path / "c.laz").stat().st_size and las == (tmp_path / "c.las").stat().st_size
    assert laz < las / 4

    class Pipe:
        def write(self, b):
            return len(b)

        def seekable(self):
            return False

    with pytest.raises(InputError, match="seekable"):
        write_las(Pipe(), cloud.points, cloud.colors)  # type: ignore[arg-type]
    with pytest.raises(InputError):
        write_las(io.BytesIO(), cloud.points[:, :2], None)


# ------------------------------------------------------------------------------------ glb


@pytest.fixture(scope="module")
def glb(scan):
    spec, result = scan
    buf = io.BytesIO()
    write_format("glb", buf, result.cloud, spec, report=result.report, images=[SCENE.image])
    return buf.getvalue()


def test_glb_loads_with_pygltflib_and_is_well_formed(glb, scan):
    model = pygltflib.GLTF2.load_from_bytes(glb)
    assert model.asset.version == "2.0"
    blob = model.binary_blob()
    assert model.buffers[0].byteLength == len(blob)
    for view in model.bufferViews:
        assert view.byteOffset % 4 == 0 and view.byteOffset + view.byteLength <= len(blob)
    textured = [p for p in model.meshes[0].primitives if p.attributes.TEXCOORD_0 is not None]
    assert len(textured) == 2  # the front and the second face: the photo's two faces
    assert len(model.images) == 2 and all(i.mimeType == "image/jpeg" for i in model.images)
    for image in model.images:
        view = model.bufferViews[image.bufferView]
        data = np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength], np.uint8)
        picture = cv2.imdecode(data, cv2.IMREAD_COLOR)
        assert picture is not None and min(picture.shape[:2]) > 100
    # POSITION accessors carry min/max (required by the spec) matching their data
    for prim in model.meshes[0].primitives:
        acc = model.accessors[prim.attributes.POSITION]
        view = model.bufferViews[acc.bufferView]
        raw = blob[view.byteOffset:view.byteOffset + view.byteLength]
        pos = np.frombuffer(raw, np.float32).reshape(-1, 3)
        assert np.allclose(acc.min, pos.min(axis=0)) and np.allclose(acc.max, pos.max(axis=0))


def test_glb_bounds_are_the_measured_box_in_metres_y_up(glb, scan):
    dims = report_dict(scan[1].report)["dimensions"]
    W, H, D = (dims[k] / 1000 for k in ("width", "height", "depth"))
    scene = trimesh.load(io.BytesIO(glb), file_type="glb", force="scene")
    assert np.allclose(scene.bounds, [[0, 0, -D], [W, H, 0]], atol=1e-6)
    area = sum(g.area for g in scene.geometry.values())  # all six faces, once each
    assert area == pytest.approx(2 * (W * H + W * D + H * D), rel=1e-6)
    # every face's normal points out of the box
    centre = np.array([W / 2, H / 2, -D / 2])
    for geom in scene.geometry.values():
        outward = np.einsum("ij,ij->i", geom.face_normals, geom.triangles_center - centre)
        assert (outward > 0).all()
    textures = [g.visual.material.baseColorTexture for g in scene.geometry.values()
                if g.visual.kind == "texture" and getattr(g.visual.material, "baseColorTexture", None)]
    assert len(textures) == 2


def test_front_texture_is_the_rectified_photo(glb, scan):
    """The front texture's middle has the photo's colour at the front face's middle."""
    model = pygltflib.GLTF2.load_from_bytes(glb)
    blob = model.binary_blob()
    front = model.images[0]
    view = model.bufferViews[front.bufferView]
    tex = cv2.cvtColor(cv2.imdecode(np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength],
                                                  np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    h, w = tex.shape[:2]
    assert w / h == pytest.approx(120 / 80, rel=0.02)
    corners = np.asarray(scan[1].report.faces["front"].corners, np.float64)
    middle = cv2.perspectiveTransform(np.array([[[w / 2 - 0.5, h / 2 - 0.5]]]), cv2.getPerspectiveTransform(
        np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]], np.float32),
        corners.astype(np.float32)))[0, 0]
    x, y = np.rint(middle).astype(int)
    photo = SCENE.image[y - 2:y + 3, x - 2:x + 3].reshape(-1, 3).mean(axis=0)
    texel = tex[h // 2 - 2:h // 2 + 3, w // 2 - 2:w // 2 + 3].reshape(-1, 3).mean(axis=0)
    assert np.abs(photo - texel).max() < 12


def test_glb_needs_its_inputs(scan):
    spec, result = scan
    with pytest.raises(InputError, match="report"):
        write_format("glb", io.BytesIO(), result.cloud, spec)
    report = json.loads(json.dumps(report_dict(result.report)))
    report["dimensions"]["unit"] = "px"
    with pytest.raises(InputError, match="metres"):
        write_format("glb", io.BytesIO(), result.cloud, spec, report=report, images=[SCENE.image])


def test_gltf_axes_are_a_proper_rotation():
    # x right stays right, "down" becomes -up, "into the object" becomes -Z: det +1
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    g = box_to_gltf(p, height=0.0) * 1000
    axes = g[1:] - g[0]
    assert np.linalg.det(axes) == pytest.approx(1.0)
    las = box_to_las(p) * 1000
    assert np.linalg.det(las[1:] - las[0]) == pytest.approx(1.0)


def _texture_middle_matches_photo(model, index: int, corners, photo: np.ndarray) -> None:
    blob = model.binary_blob()
    view = model.bufferViews[model.images[index].bufferView]
    data = np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength], np.uint8)
    tex = cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    h, w = tex.shape[:2]
    quad = np.asarray(corners, np.float32)
    # the texture's middle is where the face's diagonals cross in the photo
    H = cv2.getPerspectiveTransform(
        np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]], np.float32), quad)
    x, y = np.rint(cv2.perspectiveTransform(np.array([[[w / 2 - 0.5, h / 2 - 0.5]]]), H)[0, 0]).astype(int)
    seen = photo[y - 2:y + 3, x - 2:x + 3].reshape(-1, 3).mean(axis=0)
    texel = tex[h // 2 - 2:h // 2 + 3, w // 2 - 2:w // 2 + 3].reshape(-1, 3).mean(axis=0)
    assert np.abs(seen - texel).max() < 12


@pytest.mark.parametrize(("face", "yaw", "pitch", "axis", "where"), [
    ("left", -30.0, 15.0, 0, "low"),  # the left side at gx = 0
    ("top", 15.0, 35.0, 1, "high"),  # the top at gy = H
    ("right", 30.0, 15.0, 0, "high"),  # the right side at gx = W
])
def test_glb_textures_the_second_face_where_it_was_photographed(face, yaw, pitch, axis, where):
    scene = render_oblique_view(BOX, yaw_deg=yaw, pitch_deg=pitch, seed=3, side_face=face)
    spec = ScanSpec.model_validate({"image": "b.png", "points": [scene.points[n] for n in NAMES],
                                    "focal_px": scene.focal_px, "side_face": face,
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0}})
    result = run_scan(spec, scene.image)
    buf = io.BytesIO()
    write_format("glb", buf, result.cloud, spec, report=result.report, images=[scene.image])
    model = pygltflib.GLTF2.load_from_bytes(buf.getvalue())
    second = model.meshes[0].primitives[1]  # front, second face, then the grey ones
    assert second.attributes.TEXCOORD_0 is not None
    pos = model.accessors[second.attributes.POSITION]
    dims = report_dict(result.report)["dimensions"]
    plane = {("low", 0): 0.0, ("high", 0): dims["width"] / 1000, ("high", 1): dims["height"] / 1000}
    assert pos.min[axis] == pytest.approx(plane[where, axis], abs=1e-6)
    assert pos.max[axis] == pytest.approx(plane[where, axis], abs=1e-6)
    _texture_middle_matches_photo(model, 1, result.report.faces["side"].corners, scene.image)
    _texture_middle_matches_photo(model, 0, result.report.faces["front"].corners, scene.image)


def _primitive_arrays(model, prim) -> tuple[np.ndarray, np.ndarray]:
    blob = model.binary_blob()

    def read(index: int, width: int) -> np.ndarray:
        acc = model.accessors[index]
        view = model.bufferViews[acc.bufferView]
        raw = blob[view.byteOffset:view.byteOffset + view.byteLength]
        return np.frombuffer(raw, np.float32).reshape(-1, width)

    return read(prim.attributes.POSITION, 3), read(prim.attributes.TEXCOORD_0, 2)


def _texel_misses(scene, result, lens: np.ndarray | None = None) -> np.ndarray:
    """How far (px) each sampled texel's source pixel, read from a position-coded picture (red =
    column, green = row) textured onto the model, is from where the rendering camera (with its
    lens distortion `lens`) sees the same spot of the true box."""
    h_img, w_img = scene.image.shape[:2]
    cols, rows = np.meshgrid(np.arange(w_img), np.arange(h_img))
    coded = np.zeros_like(scene.image)
    coded[..., 0] = np.rint(cols * 255 / (w_img - 1))
    coded[..., 1] = np.rint(rows * 255 / (h_img - 1))
    model = pygltflib.GLTF2.load_from_bytes(box_glb(result.report, coded))
    dims = report_dict(result.report)["dimensions"]
    to_true = np.array([BOX.width_mm, BOX.height_mm, BOX.depth_mm]) / np.array(
        [dims["width"], dims["height"], dims["depth"]])
    blob = model.binary_blob()
    misses = []
    for index, prim in enumerate(model.meshes[0].primitives[:2]):
        pos, uv = _primitive_arrays(model, prim)
        view = model.bufferViews[model.images[index].bufferView]
        tex = cv2.cvtColor(cv2.imdecode(np.frombuffer(
            blob[view.byteOffset:view.byteOffset + view.byteLength], np.uint8), cv2.IMREAD_COLOR),
            cv2.COLOR_BGR2RGB).astype(float)
        h, w = tex.shape[:2]
        assert np.allclose(uv, [[0, 0], [1, 0], [1, 1], [0, 1]])
        for s, t in np.random.default_rng(index).uniform(0.1, 0.9, (40, 2)):
            g = (pos[0] * (1 - s) * (1 - t) + pos[1] * s * (1 - t) + pos[2] * s * t
                 + pos[3] * (1 - s) * t) * 1000.0
            box_point = np.array([g[0], dims["height"] - g[1], -g[2]]) * to_true
            cam = scene.rotation @ box_point + scene.translation
            projected = (scene.camera_matrix @ cam)[:2] / cam[2]
            if lens is not None:
                projected = distort_points(projected[None], scene.camera_matrix, lens)[0]
            red, green = tex[int(t * h), int(s * w), :2]
            decoded = np.array([red * (w_img - 1) / 255, green * (h_img - 1) / 255])
            misses.append(np.linalg.norm(projected - decoded))
    return np.array(misses)


@pytest.mark.parametrize("face", ["right", "left", "top"])
def test_glb_texels_come_from_where_the_camera_saw_that_spot(face):
    """Independent oracle: the rendering camera (a flipped or turned texture lands hundreds of
    pixels away)."""
    yaw, pitch = {"right": (30.0, 15.0), "left": (-30.0, 15.0), "top": (15.0, 35.0)}[face]
    scene = render_oblique_view(BOX, yaw_deg=yaw, pitch_deg=pitch, seed=11, side_face=face)
    spec = ScanSpec.model_validate({"image": "b.png", "points": [scene.points[n] for n in NAMES],
                                    "focal_px": scene.focal_px, "side_face": face,
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0}})
    misses = _texel_misses(scene, run_scan(spec, scene.image))
    assert np.median(misses) < 12 and np.max(misses) < 30


def test_glb_of_an_undistorted_scan_is_textured_from_the_undistorted_photo():
    realism = Realism(k1=-0.3)  # strong barrel distortion: a few px where the box is
    scene = render_oblique_view(BOX, realism=realism, seed=3)
    h, w = scene.image.shape[:2]
    camera = CameraModel(fx=scene.focal_px, fy=scene.focal_px, cx=(w - 1) / 2, cy=(h - 1) / 2,
                         dist=list(realism.distortion()), image_width=w, image_height=h)
    spec = ScanSpec.model_validate({"image": "b.png", "points": [scene.points[n] for n in NAMES],
                                    "camera": camera.model_dump(),
                                    "scale": {"kind": "edge", "edge": "width", "length_mm": 120.0}})
    result = run_scan(spec, scene.image)
    assert result.report.camera.undistorted is True
    misses = _texel_misses(scene, result, lens=realism.distortion())
    assert np.median(misses) < 12 and np.max(misses) < 30
    # the texture agrees with the real lens better than with a lens-free camera
    assert np.median(misses) < np.median(_texel_misses(scene, result)) - 0.5


def test_glb_two_photos_textures_the_side_from_the_side_photo():
    from prismsynth import render_front_view, render_side_view

    front = render_front_view(BOX, seed=2)
    side = render_side_view(BOX, seed=102)
    spec = ScanSpec(image="front", side_image="side",
                    points=[front.points[n] for n in ("p1", "p2", "p3")]
                    + [side.points[n] for n in ("p4", "p5")],
                    scale={"kind": "mm_per_px", "front": front.mm_per_px, "side": side.mm_per_px})
    result = run_scan(spec, front.image, side.image)
    with pytest.raises(InputError, match="side photo"):
        box_glb(result.report, front.image)
    model = pygltflib.GLTF2.load_from_bytes(box_glb(result.report, front.image, side.image))
    _texture_middle_matches_photo(model, 0, result.report.faces["front"].corners, front.image)
    _texture_middle_matches_photo(model, 1, result.report.faces["side"].corners, side.image)
    scene = trimesh.load(io.BytesIO(b"".join(model.save_to_bytes())), file_type="glb", force="scene")
    dims = report_dict(result.report)["dimensions"]
    assert np.allclose(scene.extents, [dims[k] / 1000 for k in ("width", "height", "depth")], atol=1e-6)


def test_thin_to_count_fits_and_leaves_no_stripes(scan):
    cloud = scan[1].cloud
    preview = thin_to_count(cloud, 100_000)
    assert 50_000 <= len(preview.points) <= 100_000
    assert thin_to_count(preview, 100_000) is preview
    front = _front(preview)
    w, h = scan[1].report.dimensions.width, scan[1].report.dimensions.height
    spacing = np.median(cKDTree(front).query(front, k=2)[0][:, 1])
    gx, gy = np.meshgrid(np.linspace(1, w - 1, 300), np.linspace(1, h - 1, 200))
    gap, _ = cKDTree(front).query(np.stack([gx.ravel(), gy.ravel()], axis=1))
    assert gap.max() <= 1.1 * spacing  # no hole wider than about two spacings
    with pytest.raises(InputError):
        thin_to_count(cloud, 0)
