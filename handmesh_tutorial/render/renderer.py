"""The offscreen renderer: scene image, label mask, depth and each body alone, with pyrender.

Everything public here is in the **OpenCV camera frame** (x right, y down, z forward, metres) with
a pinhole intrinsic matrix ``K`` (see
[`handmesh_tutorial.render.camera`][handmesh_tutorial.render.camera]). OpenGL's frame (y up, z
backward, pixel centres at half-integers) appears only inside this module:
the scene's world frame *is* the OpenCV camera frame, and the pyrender camera node gets the pose
`CV_TO_GL` = ``diag(1, -1, -1, 1)`` plus a half-pixel shift of the principal point.

Typical use::

    with Renderer(224) as r:
        out = r.render([(verts, faces, colors, 1), (v2, f2, c2, 2)], K,
                       lights=random_lights(rng), background=scene_background(rng, 224, 224),
                       alone=True)
    out.image, out.labels, out.depth, out.alone_masks

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from . import backend as _backend
from .backend import _keep_egl_display, import_pyrender
from .camera import check_intrinsics
from .color import srgb_to_linear
from .lights import Light, default_lights

__all__ = ["CV_TO_GL", "RenderMesh", "RenderResult", "Renderer"]

CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
"""Pose of the pyrender (OpenGL) camera in the OpenCV camera frame, and its own inverse: it flips
y (down -> up) and z (forward -> backward). Points are never transformed; only the camera is.
"""

_MAX_LABEL = 2**24 - 1  # labels are encoded in the 24 bits of the RGB segmentation colour


class RenderMesh(NamedTuple):
    """One body to render (a plain 4- or 5-tuple works too).

    Attributes:
        vertices: (V, 3) float, metres, OpenCV camera frame.
        faces: (F, 3) int vertex indices, counter-clockwise seen from outside.
        colors: (V, 3) or (V, 4) sRGB vertex colours, float in [0, 1] or uint8 in [0, 255]
            (linearised for pyrender by `srgb_to_linear`).
        label: int >= 1, unique in the scene; its value in the label mask.
        normals: (V, 3) vertex normals for shading (normalised here), or ``None``: the
            area-weighted normals of ``faces``. Given, they let two meshes that meet (a hand and
            its forearm) shade as one surface
            ([`wrist_seam_normals`][handmesh_tutorial.hand.mesh.wrist_seam_normals]).
    """

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    label: int
    normals: np.ndarray | None = None


@dataclass
class RenderResult:
    """Output of `Renderer.render`.

    Attributes:
        image: (H, W, 3) uint8 RGB, bodies composited over the background (``None`` if
            ``color=False``).
        labels: (H, W) int32 label mask from the segmentation pass: 0 background, else the label of
            the body that is visible at that pixel centre.
        depth: (H, W) float32 Z (metres, OpenCV frame) of the visible surface, 0 where background;
            ``depth > 0`` exactly where ``labels > 0``.
        alone_masks: {label: (H, W) bool} each body rendered alone (``alone=True``), else ``None``.
        alone_images: {label: (H, W, 3) uint8} each body alone over the background
            (``alone_images=True``), else ``None``.
    """

    image: np.ndarray | None
    labels: np.ndarray
    depth: np.ndarray
    alone_masks: dict[int, np.ndarray] | None = None
    alone_images: dict[int, np.ndarray] | None = field(default=None, repr=False)


def _label_color(label: int) -> np.ndarray:
    return np.array([label & 255, (label >> 8) & 255, (label >> 16) & 255], dtype=np.float64)


def _decode_labels(seg: np.ndarray) -> np.ndarray:
    s = seg.astype(np.int32)
    return s[..., 0] | (s[..., 1] << 8) | (s[..., 2] << 16)


def _as_meshes(meshes: Sequence[Any]) -> list[RenderMesh]:
    out: list[RenderMesh] = []
    seen: set[int] = set()
    for i, m in enumerate(meshes):
        if len(m) not in (4, 5):
            raise ValueError(f"meshes[{i}] must be (vertices, faces, colors, label[, normals]), "
                             f"got {len(m)} items")
        v = np.asarray(m[0], dtype=np.float64)
        f = np.asarray(m[1])
        c = np.asarray(m[2])
        label = int(m[3])
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"meshes[{i}] vertices must have shape (V, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"meshes[{i}] faces must be an integer (F, 3) array, got "
                             f"{f.dtype} {f.shape}")
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"meshes[{i}] faces index outside [0, {len(v)})")
        if c.ndim != 2 or c.shape[0] != len(v) or c.shape[1] not in (3, 4):
            raise ValueError(f"meshes[{i}] colors must have shape ({len(v)}, 3) or "
                             f"({len(v)}, 4), got {c.shape}")
        if not 1 <= label <= _MAX_LABEL:
            raise ValueError(f"meshes[{i}] label must be in [1, {_MAX_LABEL}], got {label}")
        if label in seen:
            raise ValueError(f"duplicate label {label} in meshes")
        seen.add(label)
        c = c[:, :3].astype(np.float64) / 255.0 if c.dtype == np.uint8 else c[:, :3].astype(float)
        n = None if len(m) == 4 or m[4] is None else np.asarray(m[4], dtype=np.float64)
        if n is not None:
            if n.shape != v.shape:
                raise ValueError(f"meshes[{i}] normals must have shape {v.shape} like its "
                                 f"vertices, got {n.shape}")
            length = np.linalg.norm(n, axis=1, keepdims=True)
            if not (np.isfinite(n).all() and (length > 0).all()):
                raise ValueError(f"meshes[{i}] normals must be finite and non-zero")
            n = n / length
        out.append(RenderMesh(v, f.astype(np.int64), np.clip(c, 0.0, 1.0), label, n))
    return out



def _vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (V, 3); zero-area regions fall back to +z."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    vn = np.where(norm > 1e-20, vn / np.maximum(norm, 1e-20), np.array([0.0, 0.0, 1.0]))
    return vn


_LIVE_RENDERERS = 0  # open Renderers of this process (they share the EGL display)


@functools.cache
def _ordered_scene_class(pr):
    """pyrender's ``Scene`` with its mesh and light nodes in insertion order (a subclass).

    pyrender keeps nodes in sets, so they come out in the order of their object ids, which changes
    from run to run. Two things depended on it: the drawing order of meshes (pyrender sorts them
    by the distance of their node's origin to the camera, and every node here sits at the origin),
    which decides a pixel where two surfaces have the same depth (a hand's wrist rim and its
    forearm share vertices), and the order in which the shader sums the lights, which moves a
    pixel by one grey level now and then. Both made the same seed give slightly different images.
    In insertion order, bodies are drawn before scenery and win such ties.
    """

    class OrderedScene(pr.Scene):
        def add_node(self, node, parent_node=None):
            super().add_node(node, parent_node)
            order = self.__dict__.setdefault("_insertion", {})
            order.setdefault(node, len(order))

        def _in_order(self, nodes) -> list:
            order = self.__dict__.get("_insertion", {})
            return sorted(nodes, key=lambda n: order.get(n, len(order)))

        @property
        def mesh_nodes(self):
            return self._in_order(self._mesh_nodes)

        @property
        def point_light_nodes(self):
            return self._in_order(self._point_light_nodes)

        @property
        def spot_light_nodes(self):
            return self._in_order(self._spot_light_nodes)

        @property
        def directional_light_nodes(self):
            return self._in_order(self._directional_light_nodes)

        @property
        def light_nodes(self):
            return self._in_order(self._point_light_nodes | self._spot_light_nodes
                                  | self._directional_light_nodes)

    return OrderedScene


class Renderer:
    """An offscreen pyrender renderer of a fixed image size, reused for many scenes.

    It owns one ``pyrender.OffscreenRenderer`` (one OpenGL context): create one per process and
    reuse it; use it as a context manager or call `close`. Each `render` builds a
    fresh pyrender scene whose world frame is the OpenCV camera frame.

    Passes per `render` call: one colour pass (lit, 4x MSAA, RGBA so the background shows
    through anti-aliased edges), one segmentation pass (``RenderFlags.SEG``, flat colours, no
    MSAA: each pixel is owned by exactly one body, the one whose surface is nearest at the pixel
    centre) that gives the label mask and the depth, and with ``alone=True`` one segmentation pass
    per body with only that body drawn (and a colour pass per body with ``alone_images=True``).
    Scene and alone masks use the same rasterisation, so a body's visible pixels are always a
    subset of its alone mask.

    Args:
        width: image width, pixels.
        height: image height, pixels (default ``width``).
        znear: near clipping plane, metres.
        zfar: far clipping plane, metres.
    """

    def __init__(self, width: int = 224, height: int | None = None, znear: float = 0.01,
                 zfar: float = 10.0):
        self.width = int(width)
        self.height = int(width if height is None else height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        self.znear, self.zfar = float(znear), float(zfar)
        self._pr = import_pyrender()
        _backend._GL_OPENED = True  # before the attempt: a failed one may leave driver state
        self._r = self._pr.OffscreenRenderer(self.width, self.height)
        self._scene_class = _ordered_scene_class(self._pr)
        global _LIVE_RENDERERS
        _LIVE_RENDERERS += 1

    # context management ------------------------------------------------------------------
    def close(self) -> None:
        """Free the OpenGL context (idempotent).

        Under EGL all renderers of a process share one display, and pyrender's
        ``delete_context`` calls ``eglTerminate`` on it, which breaks every other live renderer
        (``eglMakeCurrent`` then fails with error 12296). While other renderers live, only this
        renderer's context is destroyed (`_keep_egl_display`); the last one terminates.
        """
        global _LIVE_RENDERERS
        if self._r is not None:
            _LIVE_RENDERERS -= 1
            if _LIVE_RENDERERS > 0:
                _keep_egl_display(getattr(self._r, "_platform", None))
            self._r.delete()
            self._r = None

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # best effort; explicit close() is preferred
        try:
            self.close()
        except Exception:
            pass

    # scene construction ------------------------------------------------------------------
    def _scene(self, meshes: list[RenderMesh], K: np.ndarray, lights: Sequence[Light],
               ambient: Any):
        pr = self._pr
        amb = np.broadcast_to(np.asarray(ambient, dtype=float), (3,)).copy()
        scene = self._scene_class(bg_color=np.zeros(4), ambient_light=amb)
        # pyrender's IntrinsicsCamera puts u = fx X/Z + cx at a pixel's left edge (OpenGL window
        # coordinates); +0.5 moves it to the pixel centre (OpenCV convention).
        cam = pr.IntrinsicsCamera(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2] + 0.5, cy=K[1, 2] + 0.5,
                                  znear=self.znear, zfar=self.zfar)
        scene.add(cam, pose=CV_TO_GL)
        material = pr.MetallicRoughnessMaterial(metallicFactor=0.0, roughnessFactor=0.7,
                                                baseColorFactor=(1.0, 1.0, 1.0, 1.0))
        self._material = material
        nodes = {}
        for m in meshes:
            nodes[m.label] = self._add_mesh(scene, m, name=f"body{m.label}")
        for light in lights:
            if light.kind == "directional":
                pl = pr.DirectionalLight(color=np.asarray(light.color), intensity=light.intensity)
                scene.add(pl, pose=_frame_with_z(-np.asarray(light.direction, dtype=float)))
            elif light.kind == "point":
                pl = pr.PointLight(color=np.asarray(light.color), intensity=light.intensity)
                pose = np.eye(4)
                pose[:3, 3] = light.position
                scene.add(pl, pose=pose)
            else:
                raise ValueError(f"unknown light kind {light.kind!r}; expected directional|point")
        return scene, nodes

    def _add_mesh(self, scene, m: RenderMesh, name: str):
        pr = self._pr
        normals = _vertex_normals(m.vertices, m.faces) if m.normals is None else m.normals
        prim = pr.Primitive(positions=m.vertices.astype(np.float32),
                            normals=normals.astype(np.float32),
                            indices=m.faces.astype(np.uint32),
                            color_0=np.concatenate([srgb_to_linear(m.colors),
                                                    np.ones((len(m.colors), 1))],
                                                   1).astype(np.float32),
                            material=self._material)
        return scene.add(pr.Mesh([prim]), name=name)

    def _color(self, scene, background: np.ndarray) -> np.ndarray:
        rgba, _ = self._r.render(scene, flags=self._pr.RenderFlags.RGBA)
        a = rgba[..., 3:4].astype(np.float32) / 255.0
        img = rgba[..., :3].astype(np.float32) * a + background.astype(np.float32) * (1 - a)
        # pyrender outputs premultiplied-free colour where a < 1 only on MSAA edges
        return np.clip(img + 0.5, 0, 255).astype(np.uint8)

    def _seg(self, scene, seg_map: dict) -> tuple[np.ndarray, np.ndarray]:
        seg, depth = self._r.render(scene, flags=self._pr.RenderFlags.SEG, seg_node_map=seg_map)
        return _decode_labels(seg), depth

    def _background(self, background: Any) -> np.ndarray:
        H, W = self.height, self.width
        if background is None:
            return np.zeros((H, W, 3), np.uint8)
        bg = np.asarray(background)
        if bg.ndim == 1 and bg.shape == (3,):
            bg = np.broadcast_to(bg, (H, W, 3))
        if bg.shape != (H, W, 3):
            raise ValueError(f"background must have shape ({H}, {W}, 3) or (3,), got {bg.shape}")
        if bg.dtype != np.uint8:
            bg = np.clip(np.asarray(bg, float) * 255 + 0.5, 0, 255).astype(np.uint8)
        return bg

    # public API -----------------------------------------------------------------------------
    def render(self, meshes: Sequence[Any], K: Any, *, lights: Sequence[Light] | None = None,
               background: Any = None, ambient: Any = 0.25, color: bool = True,
               alone: bool = False, alone_images: bool = False,
               occluders: Sequence[Any] = ()) -> RenderResult:
        """Render a scene: RGB image, label mask, depth and optionally each body alone.

        Args:
            meshes: list of `RenderMesh` or plain ``(vertices, faces, colors, label)``
                tuples; vertices (V, 3) metres in the OpenCV camera frame, faces (F, 3) int,
                colors (V, 3) float [0, 1] or uint8, label int >= 1 (unique); an optional fifth
                item gives (V, 3) shading normals (``RenderMesh.normals``).
            K: (3, 3) OpenCV intrinsics (pixel centres at integer coordinates).
            lights: lights in the camera frame; ``None`` means `default_lights`.
            background: (H, W, 3) uint8 (or float [0, 1]) image, or an RGB (3,) colour, behind
                the bodies; ``None`` is black. Use `random_background` for variety.
            ambient: ambient light level in [0, 1], or a (3,) linear RGB ambient colour (e.g.
                tinted by the background, as light bouncing off the surroundings is).
            color: run the colour pass (``False``: masks and depth only, faster).
            alone: also render each body alone and return its mask (the VR denominators).
            alone_images: also return each body alone over the background (implies ``alone``).
            occluders: scenery ``(vertices, faces, colors, owner[, normals])`` tuples (e.g. a
                hand's forearm): drawn in the image and hiding what is behind them, but label 0
                in the masks; an occluder also hides parts of its owner (a body label, or 0 for
                none) in the owner's *alone* mask, so VR counts only what other bodies hide.

        Returns:
            A `RenderResult`.

        Raises:
            ValueError: bad mesh arrays, labels, ``K`` or background shape.
        """
        if self._r is None:
            raise ValueError("this Renderer is closed")
        ms = _as_meshes(meshes)
        K = check_intrinsics(K)
        bg = self._background(background)
        lights = default_lights() if lights is None else list(lights)
        scene, nodes = self._scene(ms, K, lights, ambient)
        scenery = []
        for i, occ in enumerate(occluders):
            if len(occ) not in (4, 5):
                raise ValueError(f"occluders[{i}] must be (vertices, faces, colors, owner"
                                 f"[, normals]), got {len(occ)} items")
            normals = occ[4] if len(occ) == 5 else None
            # validated, colours in [0,1]
            mesh = _as_meshes([(occ[0], occ[1], occ[2], 1, normals)])[0]
            scenery.append((self._add_mesh(scene, mesh, name="scenery"), int(occ[3])))
        image = self._color(scene, bg) if color else None
        background_code = _label_color(0)
        seg_map = {n: _label_color(lab) for lab, n in nodes.items()}
        seg_map.update({node: background_code for node, _ in scenery})
        labels, depth = self._seg(scene, seg_map)
        out = RenderResult(image, labels, depth.astype(np.float32))
        if alone or alone_images:
            out.alone_masks = {}
            out.alone_images = {} if alone_images else None
            for lab, node in nodes.items():
                own = {n: background_code for n, owner in scenery if owner == lab}
                lab_img, _ = self._seg(scene, {node: _label_color(lab), **own})
                out.alone_masks[lab] = lab_img == lab
                if alone_images:
                    for other in nodes.values():  # hide the others; no re-upload of buffers
                        other.mesh.is_visible = other is node
                    out.alone_images[lab] = self._color(scene, bg)
                    for other in nodes.values():
                        other.mesh.is_visible = True
        return out

    def render_alone(self, meshes: Sequence[Any], K: Any, *, images: bool = False,
                     lights: Sequence[Light] | None = None, background: Any = None,
                     ambient: float = 0.25) -> dict[int, np.ndarray]:
        """Render each body alone: its mask (the denominator of the visibility ratio).

        Args:
            meshes: as in `render`.
            K: (3, 3) OpenCV intrinsics.
            images: when ``True`` return ``{label: (mask, image)}`` instead of ``{label: mask}``.
            lights: as in `render` (only used for ``images=True``).
            background: as in `render` (only used for ``images=True``).
            ambient: as in `render`.

        Returns:
            ``{label: (H, W) bool mask}``, or ``{label: ((H, W) bool, (H, W, 3) uint8)}``.
        """
        out = self.render(meshes, K, lights=lights, background=background, ambient=ambient,
                          color=False, alone=True, alone_images=images)
        if images:
            return {lab: (m, out.alone_images[lab]) for lab, m in out.alone_masks.items()}
        return out.alone_masks


def _frame_with_z(z: np.ndarray) -> np.ndarray:
    """A 4x4 pose whose z axis is ``z`` (normalised); pyrender lights shine along -z."""
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = x, y, z
    return pose
