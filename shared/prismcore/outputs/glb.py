"""The fitted box as a textured binary glTF 2.0 model (``.glb``): opens in browser viewers and Blender.

The box is the report's measured width x height x depth; each face seen in the photo(s) (the
front and the second face) is textured with the photo rectified onto it (``cv2.warpPerspective``
with the homography of the face's fitted corners, ``report.faces.<name>.corners``); the four
hidden faces are plain grey. Textures are JPEG (quality :data:`JPEG_QUALITY`), each face's at
the photo's own resolution across it, at most :data:`TEXTURE_MAX_PX` on its longer side.

Units and axes: glTF is metres, Y up, right-handed, the viewer looking along -Z. The box frame
(mm; X along P1 -> P2, Y down the front face, Z into the object) maps to

    gx = x / 1000,   gy = (height - y) / 1000,   gz = -z / 1000

(a rotation of 180 degrees about X, then a lift): the box stands on the ground plane gy = 0 with
its front face at gz = 0 facing +Z, toward a default glTF camera; P1 is at (0, height, 0) m. The
model's bounds are therefore exactly [0, W] x [0, H] x [-D, 0] m.

Written with pygltflib; one mesh, one primitive per textured face plus one for the grey faces,
outward normals, counter-clockwise front faces.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from prismcore.errors import InputError
from prismcore.report import ScanReport

__all__ = ["GREY", "JPEG_QUALITY", "TEXTURE_MAX_PX", "box_corners", "box_glb", "box_to_gltf"]

TEXTURE_MAX_PX = 1024
"""Longest side of a face's texture, px."""

JPEG_QUALITY = 85

GREY = (0.6, 0.6, 0.6, 1.0)
"""Base colour of the hidden faces (linear RGBA)."""

# Each face's corners in texture order (top-left, top-right, bottom-right, bottom-left), as the
# engine scans it (see cloud.assemble): the indices are into box_corners()'s 8 corners.
_CORNER_OF = {(x, y, z): i for i, (x, y, z) in enumerate(
    (x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1))}


def _c(x: int, y: int, z: int) -> int:
    return _CORNER_OF[(x, y, z)]


_FACES = {  # (x, y, z) in units of (W, H, D)
    "front": (_c(0, 0, 0), _c(1, 0, 0), _c(1, 1, 0), _c(0, 1, 0)),
    "back": (_c(1, 0, 1), _c(0, 0, 1), _c(0, 1, 1), _c(1, 1, 1)),
    "right": (_c(1, 0, 0), _c(1, 0, 1), _c(1, 1, 1), _c(1, 1, 0)),  # u along Z from the front
    "left": (_c(0, 0, 1), _c(0, 0, 0), _c(0, 1, 0), _c(0, 1, 1)),  # u toward the front
    "top": (_c(0, 0, 1), _c(1, 0, 1), _c(1, 0, 0), _c(0, 0, 0)),  # v toward the front
    "bottom": (_c(0, 1, 0), _c(1, 1, 0), _c(1, 1, 1), _c(0, 1, 1)),
}


def box_corners(width: float, height: float, depth: float) -> np.ndarray:
    """The box's 8 corners (8, 3) float64 in the box frame, mm; corner i is (x, y, z) with
    x = W * (i >> 2 & 1), y = H * (i >> 1 & 1), z = D * (i & 1)."""
    i = np.arange(8)
    return np.stack([width * (i >> 2 & 1), height * (i >> 1 & 1), depth * (i & 1)], axis=1).astype(float)


def box_to_gltf(points: np.ndarray, height: float) -> np.ndarray:
    """Box-frame points (N, 3) mm -> glTF (N, 3) float64 metres (see the module's mapping)."""
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[:, 0], height - p[:, 1], -p[:, 2]], axis=1) / 1000.0


def _rgb8(image: np.ndarray) -> np.ndarray:
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"a photo must be (H, W, 3) RGB, got shape {image.shape}")
    if image.dtype == np.uint8:
        return image
    rgb: np.ndarray = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return rgb


def _texture(photo: np.ndarray, quad: np.ndarray, aspect: float) -> bytes:
    """JPEG of the photo rectified onto a face whose corners (TL, TR, BR, BL) are `quad` px and
    whose real width / height is `aspect`."""
    import cv2

    edges = np.linalg.norm(quad - np.roll(quad, -1, axis=0), axis=1)
    longest = min(TEXTURE_MAX_PX, max(8, round(float(edges.max()))))
    if aspect >= 1:
        w, h = longest, max(1, round(longest / aspect))
    else:
        w, h = max(1, round(longest * aspect)), longest
    # Corner points are pixel centres; the texture's outer pixel edges are the face's edges.
    target = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]], np.float32)
    H = cv2.getPerspectiveTransform(quad.astype(np.float32), target)
    flat = cv2.warpPerspective(_rgb8(photo), H, (w, h), flags=cv2.INTER_AREA,
                               borderMode=cv2.BORDER_REPLICATE)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(flat, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise InputError(f"could not encode a {w}x{h} face texture as JPEG")
    return data.tobytes()


def _undistorted(report: ScanReport, photos: list[np.ndarray]) -> list[np.ndarray]:
    """The photos as the fit saw them: undistorted with the report's camera when it was."""
    if report.camera is None or not report.camera.undistorted:
        return photos
    from prismcore.camera import CameraModel, undistort_image

    model = (report.inputs or {}).get("camera")
    if model is None:
        raise InputError("the report says the photos were undistorted but has no inputs.camera")
    out = []
    for photo in photos:
        camera = CameraModel.model_validate(model).for_size(photo.shape[1], photo.shape[0])
        out.append(undistort_image(_rgb8(photo), camera))
    return out


def box_glb(report: ScanReport, front: np.ndarray, side: np.ndarray | None = None) -> bytes:
    """The bytes of a ``.glb`` of the fitted box, textured from the photo(s).

    Parameters
    ----------
    report : ScanReport
        The scan's report: reads ``dimensions`` (mm), ``side_face``, ``faces.front.corners``
        and ``faces.side.corners`` (px, TL TR BR BL), ``inputs.side_image``, ``camera.undistorted``
        and ``inputs.camera``.
    front : ndarray, shape (H, W, 3)
        The front photo as decoded (uint8, or 0-255 floats), RGB.
    side : ndarray, shape (H, W, 3), optional
        The side photo, in two-photo mode.

    Raises
    ------
    InputError
        Dimensions not in mm (no scale), missing corners, or a missing side photo.
    """
    import pygltflib as g

    dims = report.dimensions
    if dims.unit != "mm":
        raise InputError(f"a glTF model is in metres: the dimensions are in {dims.unit!r}; "
                         "give a scale")
    W, H, D = float(dims.width), float(dims.height), float(dims.depth)
    second = report.side_face or "right"
    two_photo = bool((report.inputs or {}).get("side_image"))
    if two_photo and side is None:
        raise InputError("two-photo report: the side photo is needed for its face's texture")
    photos = _undistorted(report, [front] + ([side] if two_photo and side is not None else []))
    faces = {name: face.corners for name, face in (report.faces or {}).items()}
    seen = {"front": ("front", photos[0], (W, H)),
            second: ("side", photos[-1], (W, D) if second == "top" else (D, H))}
    corners = box_corners(W, H, D)
    centre = corners.mean(axis=0)

    blob = bytearray()
    # pygltflib is untyped: its objects are Any here
    views: list[Any] = []
    accessors: list[Any] = []

    def add_view(data: bytes, target: int | None = None) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data)
        return len(views) - 1

    def add_accessor(array: np.ndarray, kind: str, component: int, target: int,
                     bounds: bool = False) -> int:
        view = add_view(array.tobytes(), target)
        accessors.append(g.Accessor(
            bufferView=view, componentType=component, count=len(array), type=kind,
            min=array.min(axis=0).tolist() if bounds else None,
            max=array.max(axis=0).tolist() if bounds else None))
        return len(accessors) - 1

    def geometry(names: list[str], uv: bool) -> dict[str, int]:
        pos: list[np.ndarray] = []
        nrm: list[np.ndarray] = []
        tex: list[np.ndarray] = []
        idx: list[int] = []
        for name in names:
            quad = box_to_gltf(corners[list(_FACES[name])], H)
            d = corners[list(_FACES[name])].mean(axis=0) - centre  # outward, box frame
            normal = np.array([d[0], -d[1], -d[2]]) / np.linalg.norm(d)  # as box_to_gltf turns it
            base = len(pos) * 4
            tri = [(0, 1, 2), (0, 2, 3)]
            if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), normal) < 0:
                tri = [(0, 2, 1), (0, 3, 2)]
            pos.append(quad)
            nrm.append(np.tile(normal, (4, 1)))
            tex.append(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
            idx += [base + i for t in tri for i in t]
        attrs = {"POSITION": add_accessor(np.concatenate(pos).astype(np.float32), "VEC3", g.FLOAT,
                                          g.ARRAY_BUFFER, bounds=True),
                 "NORMAL": add_accessor(np.concatenate(nrm).astype(np.float32), "VEC3", g.FLOAT,
                                        g.ARRAY_BUFFER)}
        if uv:
            attrs["TEXCOORD_0"] = add_accessor(np.concatenate(tex).astype(np.float32), "VEC2", g.FLOAT,
                                               g.ARRAY_BUFFER)
        attrs["indices"] = add_accessor(np.array(idx, np.uint16), "SCALAR", g.UNSIGNED_SHORT,
                                        g.ELEMENT_ARRAY_BUFFER)
        return attrs

    images: list[Any] = []
    materials: list[Any] = []
    primitives: list[Any] = []
    for name, (key, photo, (fw, fh)) in seen.items():
        fitted = faces.get(key)
        if fitted is None:
            raise InputError(f"report has no corners for the {key} face")
        quad = np.asarray(fitted, dtype=np.float64)
        if quad.shape != (4, 2) or not np.isfinite(quad).all():
            raise InputError(f"face {key}: corners {fitted!r} are not a finite (4, 2) array")
        images.append(g.Image(bufferView=add_view(_texture(photo, quad, fw / fh)), mimeType="image/jpeg",
                              name=f"{name}.jpg"))
        materials.append(g.Material(
            name=f"{name} (photo)", pbrMetallicRoughness=g.PbrMetallicRoughness(
                baseColorTexture=g.TextureInfo(index=len(images) - 1), metallicFactor=0.0,
                roughnessFactor=1.0)))
        attrs = geometry([name], uv=True)
        indices = attrs.pop("indices")
        primitives.append(g.Primitive(attributes=g.Attributes(**attrs), indices=indices,
                                      material=len(materials) - 1))
    hidden = [n for n in _FACES if n not in seen]
    materials.append(g.Material(name="hidden faces", pbrMetallicRoughness=g.PbrMetallicRoughness(
        baseColorFactor=list(GREY), metallicFactor=0.0, roughnessFactor=1.0)))
    attrs = geometry(hidden, uv=False)
    indices = attrs.pop("indices")
    primitives.append(g.Primitive(attributes=g.Attributes(**attrs), indices=indices,
                                  material=len(materials) - 1))
    while len(blob) % 4:
        blob.append(0)
    model = g.GLTF2(
        asset=g.Asset(version="2.0", generator="PrismCloud"),
        scene=0, scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0, name="box")],
        meshes=[g.Mesh(name=f"box {W:g} x {H:g} x {D:g} mm", primitives=primitives)],
        materials=materials, images=images,
        samplers=[g.Sampler(magFilter=g.LINEAR, minFilter=g.LINEAR_MIPMAP_LINEAR,
                            wrapS=g.CLAMP_TO_EDGE, wrapT=g.CLAMP_TO_EDGE)],
        textures=[g.Texture(sampler=0, source=i) for i in range(len(images))],
        accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))],
    )
    model.set_binary_blob(bytes(blob))
    return b"".join(model.save_to_bytes())
