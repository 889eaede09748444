"""3D views for the browser: meshes you can turn with the mouse, in Jupyter and on the docs site.

A [`View3D`][handmesh_tutorial.viz.web3d.View3D] is a small payload, meshcat scene commands
(three.js JSON in msgpack, the meshes as typed arrays: about 20 kB per hand), drawn by meshcat's
viewer (three.js, MIT) when it scrolls into view. In Jupyter its HTML carries the payload inline
and, in the first view of a kernel, the viewer itself (gzip, base64, about 290 kB); on the docs
site the viewer is served once by the site (the build copies it from the installed ``meshcat``)
and a page's view fetches its payload from a file next to the page
([`View3D.save`][handmesh_tutorial.viz.web3d.View3D.save]). Nothing is loaded from another host.
The camera is the one of the matplotlib figures,
[`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] for hands in the template frame. Every view
carries a static picture of the same meshes from the same camera (a JPEG drawn by matplotlib,
[`View3D.picture`][handmesh_tutorial.viz.web3d.View3D.picture]): it is what a reader sees where
JavaScript or WebGL is missing (GitHub's notebook view, a browser without WebGL), and the live
view replaces it when it starts. Page weights and the design: docs page "3D views"
(``docs/concepts/3d_views.md``); taught in notebooks 01, 02 and 05.
"""

from __future__ import annotations

import base64
import gzip
import html
import importlib.util
import io
import os
import struct
import uuid
from functools import lru_cache
from pathlib import Path

import numpy as np

from .._io import atomic_write_bytes
from .._optional import require
from ._common import _to_numpy
from .mesh3d import FINGER_COLORS, HAND_VIEW, set_axes_equal, shade_faces, view_direction

__all__ = ["View3D", "view_meshes", "view_hand", "view_prediction", "viewer_js_path"]

_ASSET = Path(__file__).resolve().parent / "hmt_views.js"
_FOV = 30.0           # degrees, vertical: little perspective, close to matplotlib's figures
_UP_TO_Y = {          # rotation taking the view's vertical axis to +y (three.js's up)
    "x": np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]).T,
    "y": np.eye(3),
    "z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
}
_ROTATED = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])   # meshcat's camera node: +90 deg about x
_state = {"viewer_sent": False}
# numpy dtype -> three.js typed array and msgpack-lite's extension code for it
_TYPED = {np.dtype(np.uint8): ("Uint8Array", 0x12), np.dtype(np.uint16): ("Uint16Array", 0x14),
          np.dtype(np.uint32): ("Uint32Array", 0x16), np.dtype(np.float32): ("Float32Array", 0x17)}
_PICTURE_ASPECT = 4 / 3   # width / height of the static picture (the view is as wide as its page)
_PICTURE_QUALITY = 80     # JPEG quality: a 380 px hand picture is about 15-25 kB
# the note over a view: its picture until the live view starts (hmt_views.js rewrites it on failure)
_NOTE = ("Static picture: the 3D view (drag to turn, scroll to zoom) replaces it when it starts; "
         "it needs JavaScript and WebGL.")


def viewer_js_path() -> Path:
    """Path of meshcat's viewer bundle (``main.min.js``) in the installed ``meshcat`` package.

    Raises:
        ModuleNotFoundError: ``meshcat`` is not installed (the ``notebooks`` extra).
    """
    spec = importlib.util.find_spec("meshcat")    # not imported: its server side needs zmq
    if spec is None or spec.origin is None:
        require("meshcat", "hmt.viz 3D views")      # raises, naming the extra
    return Path(spec.origin).parent / "viewer" / "dist" / "main.min.js"


@lru_cache(maxsize=1)
def _viewer_gz_b64() -> str:
    return base64.b64encode(gzip.compress(viewer_js_path().read_bytes(), 9, mtime=0)).decode()


def _rgb(color) -> np.ndarray:
    """One colour (a matplotlib name, ``#rrggbb``, or RGB in [0, 1] or 0-255) as (3,) in [0, 1]."""
    if isinstance(color, str):
        to_rgb = require("matplotlib.colors", "hmt.viz 3D views").to_rgb
        return np.asarray(to_rgb(color), dtype=float)
    c = np.asarray(color, dtype=float).reshape(-1)[:3]
    return c / 255.0 if c.max() > 1.0 else c


def _array(a: np.ndarray, normalized: bool = False) -> dict:
    umsgpack = require("umsgpack", "hmt.viz 3D views")
    name, code = _TYPED[a.dtype]
    return {"itemSize": int(a.shape[1]) if a.ndim == 2 else 1, "type": name,
            "array": umsgpack.Ext(code, np.ascontiguousarray(a).tobytes()),
            "normalized": normalized}


def _object(key: str, kind: str, vertices: np.ndarray, faces: np.ndarray | None,
            colors: np.ndarray | None, color: np.ndarray, opacity: float) -> dict:
    """A three.js JSON object (version 4.5) holding one mesh or line set."""
    # uuids from the name: the same view gives the same bytes
    gid, mid, oid = (str(uuid.uuid5(uuid.NAMESPACE_URL, f"hmt-view/{key}/{p}")) for p in "gmo")
    attrs = {"position": _array(vertices.astype(np.float32))}
    if colors is not None:
        attrs["color"] = _array(np.clip(np.round(colors * 255), 0, 255).astype(np.uint8), True)
    data = {"attributes": attrs}
    if faces is not None:
        dtype = np.uint16 if len(vertices) < 65536 else np.uint32
        data["index"] = _array(faces.reshape(-1).astype(dtype))
    hexcolor = int("".join(f"{int(round(255 * c)):02x}" for c in color), 16)
    material = {"uuid": mid,
                "type": "MeshLambertMaterial" if kind == "Mesh" else "LineBasicMaterial",
                "color": 0xFFFFFF if colors is not None else hexcolor,
                "vertexColors": colors is not None, "side": 2, "opacity": float(opacity),
                "transparent": bool(opacity < 1.0), "depthWrite": bool(opacity >= 1.0),
                # lines (skeletons) drawn over the meshes, as the matplotlib figures do
                "depthTest": kind == "Mesh"}
    return {"metadata": {"version": 4.5, "type": "Object"},
            "geometries": [{"uuid": gid, "type": "BufferGeometry", "data": data}],
            "materials": [material],
            "object": {"uuid": oid, "type": kind, "geometry": gid, "material": mid,
                       "matrix": np.eye(4).reshape(-1).tolist()}}


class View3D:
    """A 3D view: meshcat commands that build a scene, shown by meshcat's viewer in a browser.

    Build one with [`view_meshes`][handmesh_tutorial.viz.web3d.view_meshes],
    [`view_hand`][handmesh_tutorial.viz.web3d.view_hand] or
    [`view_prediction`][handmesh_tutorial.viz.web3d.view_prediction]; a notebook displays it
    (``_repr_mimebundle_``: the HTML, and the static picture as ``image/jpeg`` for viewers that
    run no HTML), a docs page shows a saved one (``save`` and ``save_picture``, then
    ``html(src=..., picture_src=...)``).

    Attributes:
        commands: the msgpack-encoded meshcat commands, in order.
        height: height of the view in pixels.
        camera: ``(3,)`` position of the camera in meshcat's camera frame (metres), for tests.
    """

    def __init__(self, commands: list[bytes], height: int, camera: np.ndarray,
                 scene: dict | None = None):
        self.commands = list(commands)
        self.height = int(height)
        self.camera = np.asarray(camera, dtype=float)
        # what the static picture draws: {"meshes": {name: parts}, "lines": {...}, "view": {...}}
        self._scene = scene
        self._picture: bytes | None = None

    @property
    def payload(self) -> bytes:
        """The commands as one file: each prefixed by its length (uint32, little-endian)."""
        return b"".join(struct.pack("<I", len(c)) + c for c in self.commands)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the payload atomically (e.g. ``docs/concepts/views/hand.bin``); returns the path.

        A docs page then shows it with the HTML of ``html(src=...)``, ``src`` relative to the
        page's URL.
        """
        return atomic_write_bytes(path, self.payload)

    def picture(self) -> bytes | None:
        """The static picture: a JPEG of the same meshes and lines from the same camera.

        Drawn once with matplotlib (Agg, no window; per-face Lambert shading lit from the
        camera, as [`shade_faces`][handmesh_tutorial.viz.mesh3d.shade_faces] computes), ``height``
        pixels high and 4/3 as wide. It is what a reader sees where the live view cannot start.

        Returns:
            The JPEG's bytes, or ``None`` for a view made from commands alone (no meshes known).

        Raises:
            ModuleNotFoundError: matplotlib missing (the ``notebooks`` extra).
        """
        if self._picture is None and self._scene is not None:
            self._picture = _draw_picture(self._scene, self.height)
        return self._picture

    def save_picture(self, path: str | os.PathLike) -> Path:
        """Write [`picture`][handmesh_tutorial.viz.web3d.View3D.picture] atomically (a ``.jpg``).

        Raises:
            ValueError: the view has no picture (made from commands alone).
        """
        data = self.picture()
        if data is None:
            raise ValueError("this View3D was made from commands alone and has no picture; build "
                             "it with view_meshes, view_hand or view_prediction")
        return atomic_write_bytes(path, data)

    def html(self, src: str | None = None, viewer: bool = False,
             picture_src: str | None = None) -> str:
        """The view's HTML: a ``div.hmt-view`` with its static picture, and the script that
        replaces the picture by the live view when it scrolls into view.

        Args:
            src: URL of a saved payload, relative to the page (docs pages); ``None`` puts the
                payload inline (base64).
            viewer: also inline meshcat's viewer (gzip, base64; needed once per Jupyter page).
            picture_src: URL of a saved picture (``save_picture``), relative to the page;
                ``None`` puts the picture inline (a base64 ``data:`` URL).

        Returns:
            An HTML fragment that loads nothing from another host. Without JavaScript or WebGL
            it shows the picture and a note saying so.
        """
        where = (f'data-src="{html.escape(src)}"' if src is not None else
                 f'data-payload="{base64.b64encode(self.payload).decode()}"')
        parts = []
        if viewer:
            parts.append('<script type="application/octet-stream" class="hmt-viewer-js">'
                         f"{_viewer_gz_b64()}</script>")
        if picture_src is not None:
            img = html.escape(picture_src)
        else:
            data = self.picture()
            img = None if data is None else ("data:image/jpeg;base64,"
                                              + base64.b64encode(data).decode())
        picture = ("" if img is None else
                   f'<img class="hmt-view-picture" src="{img}" alt="static picture of the 3D view"'
                   ' style="display:block;width:100%;height:100%;object-fit:contain">')
        parts.append(
            f'<div class="hmt-view" {where} style="position:relative;width:100%;'
            f'height:{self.height}px;border:1px solid #ddd;overflow:hidden;'
            f'background:linear-gradient(#fff,#e2e7f0)">{picture}'
            '<p class="hmt-view-note" style="position:absolute;left:0;bottom:0;margin:0;'
            'padding:0.2em 0.6em;font-size:12px;color:#555;background:rgba(255,255,255,0.8)">'
            f"{_NOTE}</p></div>")
        if src is None:
            parts.append(f"<script>{_ASSET.read_text()}</script>")
        return "\n".join(parts)

    def _repr_html_(self) -> str:
        first = not _state["viewer_sent"]
        _state["viewer_sent"] = True
        return self.html(viewer=first)

    def _repr_mimebundle_(self, include=None, exclude=None) -> dict:
        """Jupyter's outputs: the HTML (Jupyter, the docs site), the picture as ``image/jpeg``
        (viewers that show no HTML or run no script, e.g. GitHub's notebook view), the text."""
        bundle = {"text/html": self._repr_html_(), "text/plain": repr(self)}
        data = self.picture()
        if data is not None:
            bundle["image/jpeg"] = base64.b64encode(data).decode()
        return bundle

    def __repr__(self) -> str:
        return (f"View3D({len(self.commands)} commands, {len(self.payload) / 1e3:.0f} kB, "
                f"height={self.height})")


def _draw_picture(scene: dict, height: int) -> bytes:
    """JPEG bytes of a view's meshes and lines, drawn by matplotlib from the view's camera.

    Drawn at twice the size, cropped to what was drawn (plus a margin) and scaled into a
    ``4/3 * height`` by ``height`` picture: the meshes fill it whatever their shape.
    """
    require("matplotlib", "hmt.viz 3D views' static pictures")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from PIL import Image  # a matplotlib dependency

    view, background = scene["view"], (244, 246, 250)
    width = int(round(_PICTURE_ASPECT * height))
    dpi = 100
    fig = Figure(figsize=(2 * width / dpi, 2 * height / dpi), dpi=dpi,
                 facecolor=np.array(background) / 255)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1), projection="3d")
    ax.set_facecolor(fig.get_facecolor())
    ax.computed_zorder = False                   # skeletons over the meshes, as in the browser
    light = view_direction(view)                 # lit from the camera, as a headlamp
    points = []
    # opaque meshes first (matplotlib sorts whole artists): a translucent one reads over them
    meshes = sorted(scene["meshes"].values(), key=lambda p: p["opacity"] < 1.0)
    for z, p in enumerate(meshes):
        v, f = p["vertices"], p["faces"]
        colors = p["colors"] if p["colors"] is not None else np.tile(p["color"], (len(v), 1))
        points.append(v)
        if len(f):
            rgba = shade_faces(v, f, colors, light=light)
            rgba[:, 3] = p["opacity"]
            opaque = p["opacity"] >= 1.0               # edges in the faces' colour: no seams
            ax.add_collection3d(Poly3DCollection(
                v[f], facecolors=rgba, edgecolors=rgba if opaque else "none",
                linewidths=0.4 if opaque else 0.0, zorder=z))
    for segments, colours in scene["lines"].values():
        for seg, c in zip(segments.reshape(-1, 2, 3), colours, strict=False):
            ax.plot(*seg.T, color=tuple(c), linewidth=2.5, zorder=len(meshes) + 1)
    set_axes_equal(ax, np.concatenate(points), pad=0.0)
    ax.view_init(**view)
    ax.set_axis_off()
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3]
    drawn = np.argwhere(np.abs(rgb.astype(int) - background).sum(-1) > 12)
    image = Image.fromarray(np.ascontiguousarray(rgb))
    if len(drawn):
        (y0, x0), (y1, x1) = drawn.min(0), drawn.max(0) + 1
        m = int(0.06 * max(y1 - y0, x1 - x0))
        image = image.crop((max(x0 - m, 0), max(y0 - m, 0), min(x1 + m, rgb.shape[1]),
                            min(y1 + m, rgb.shape[0])))
    scale = min(width / image.width, height / image.height)
    image = image.resize((max(1, round(image.width * scale)), max(1, round(image.height * scale))),
                         Image.LANCZOS)
    out = Image.new("RGB", (width, height), background)
    out.paste(image, ((width - image.width) // 2, (height - image.height) // 2))
    buf = io.BytesIO()
    out.save(buf, format="JPEG", quality=_PICTURE_QUALITY, optimize=True)
    return buf.getvalue()


def _mesh_parts(name: str, item) -> dict:
    if isinstance(item, dict):
        d = dict(item)
    else:
        keys = ("vertices", "faces", "color", "opacity")
        d = dict(zip(keys, item, strict=False))
    if "vertices" not in d or "faces" not in d:
        raise ValueError(f"mesh {name!r}: give (vertices, faces[, color[, opacity]]) or a dict "
                         "with 'vertices' and 'faces'")
    v = np.asarray(_to_numpy(d["vertices"]), dtype=float)
    f = np.asarray(_to_numpy(d["faces"]), dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"mesh {name!r}: vertices must be (V, 3) and faces (F, 3), got "
                         f"{v.shape} and {f.shape}")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"mesh {name!r}: face indices must lie in [0, {len(v)}), got "
                         f"[{f.min()}, {f.max()}]")
    color = d.get("color")
    colors = None
    if color is not None and np.ndim(color) == 2:
        colors = np.asarray(_to_numpy(color), dtype=float)[:, :3]
        if len(colors) != len(v):
            raise ValueError(f"mesh {name!r}: per-vertex colours must be ({len(v)}, 3), got "
                             f"{colors.shape}")
        colors = colors / 255.0 if colors.max() > 1.0 else colors
        color = None
    return {"vertices": v, "faces": f, "colors": colors,
            "color": _rgb("#d9ad94" if color is None else color),
            "opacity": float(d.get("opacity", 1.0))}


def view_meshes(meshes: dict, *, lines: dict | None = None, view: dict | None = None,
                height: int = 380) -> View3D:
    """A browser 3D view of named meshes, seen from a matplotlib-style camera.

    Args:
        meshes: ``{name: (vertices, faces[, color[, opacity]])}`` or ``{name: {"vertices": ...,
            "faces": ..., "color": ..., "opacity": ...}}``; vertices ``(V, 3)`` metres (numpy or
            torch), faces ``(F, 3)``, colour one colour (a matplotlib name, ``#rrggbb``, RGB) or
            ``(V, 3)`` per-vertex RGB in [0, 1] or 0-255. The names label the viewer's controls
            (each can be hidden there).
        lines: optional ``{name: (segments (S, 2, 3), colors (S, 3) or one colour)}``.
        view: the camera as ``ax.view_init`` keywords (``elev``, ``azim``, ``vertical_axis``);
            [`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] when ``None``. The camera looks
            at the centre of the meshes' bounding box along
            [`view_direction`][handmesh_tutorial.viz.mesh3d.view_direction], the vertical axis up,
            from where the whole box fits.
        height: view height, pixels, at least 50 (the static picture is as high, 4/3 as wide).

    Returns:
        The [`View3D`][handmesh_tutorial.viz.web3d.View3D]; its static picture is drawn when
        first needed (its HTML, ``picture()``).

    Raises:
        ValueError: no mesh, a mesh that is not ``(V, 3)`` / ``(F, 3)``, face indices out of
            range, per-vertex colours of the wrong length, an unknown ``vertical_axis``, a
            ``height`` under 50.
        ModuleNotFoundError: ``meshcat`` (and its ``umsgpack``) missing: the ``notebooks`` extra.
    """
    umsgpack = require("umsgpack", "hmt.viz 3D views")
    if not height >= 50:
        raise ValueError(f"height must be at least 50 pixels, got {height!r}")
    view = HAND_VIEW if view is None else view
    d = view_direction(view)                      # also checks vertical_axis
    if not meshes:
        raise ValueError("view_meshes needs at least one mesh")
    parts = {name: _mesh_parts(name, item) for name, item in meshes.items()}
    pts = np.concatenate([p["vertices"] for p in parts.values()])
    lo, hi = pts.min(0), pts.max(0)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
    distance = 1.1 * radius / np.sin(np.deg2rad(_FOV / 2))
    q = _UP_TO_Y[view.get("vertical_axis", "z")]
    world = np.eye(4)                             # data frame -> meshcat world
    world[:3, :3] = _ROTATED @ q
    world[:3, 3] = -(_ROTATED @ q @ centre)
    camera = q @ (-d * distance)                  # in the camera node's (rotated, y-up) frame

    def cmd(c: dict) -> bytes:
        return umsgpack.packb(c)

    cmds = [cmd({"type": "set_property", "path": "/Grid", "property": "visible", "value": False}),
            cmd({"type": "set_property", "path": "/Axes", "property": "visible", "value": False}),
            # the page's background shows through (meshcat's gradient texture is 3-byte RGB,
            # which some WebGL implementations read misaligned)
            cmd({"type": "set_property", "path": "/Background", "property": "visible",
                 "value": False}),
            cmd({"type": "set_transform", "path": "/hmt",
                 "matrix": world.T.reshape(-1).tolist()})]
    for name, p in parts.items():
        obj = _object(name, "Mesh", p["vertices"], p["faces"], p["colors"], p["color"],
                      p["opacity"])
        cmds.append(cmd({"type": "set_object", "path": f"/hmt/{name}", "object": obj}))
    line_parts = {}
    for name, (segments, col) in (lines or {}).items():
        seg = np.asarray(_to_numpy(segments), dtype=float).reshape(-1, 3)
        one = isinstance(col, str) or (np.ndim(col) == 1 and not isinstance(col[0], str))
        col = np.asarray([_rgb(col)] * (len(seg) // 2) if one else [_rgb(c) for c in col])
        obj = _object(name, "LineSegments", seg, None, np.repeat(col, 2, axis=0), col[0], 1.0)
        cmds.append(cmd({"type": "set_object", "path": f"/hmt/{name}", "object": obj}))
        line_parts[name] = (seg, col)
    cam = "/Cameras/default/rotated/<object>"
    cmds += [cmd({"type": "set_property", "path": cam, "property": "fov", "value": _FOV}),
             cmd({"type": "set_property", "path": cam, "property": "near",
                  "value": distance / 100}),
             cmd({"type": "set_property", "path": cam, "property": "far",
                  "value": distance * 100}),
             cmd({"type": "set_property", "path": cam, "property": "position",
                  "value": camera.tolist()})]
    return View3D(cmds, height, camera,
                  scene={"meshes": parts, "lines": line_parts, "view": dict(view)})


def _skeleton(joints) -> tuple[np.ndarray, list]:
    j = np.asarray(_to_numpy(joints), dtype=float).reshape(-1, 3)
    parents = [-1] + [0 if k % 4 == 1 else k - 1 for k in range(1, 21)]
    segs = np.stack([np.stack([j[p], j[k]]) for k, p in enumerate(parents) if p >= 0])
    return segs, [FINGER_COLORS[(k - 1) // 4] for k in range(1, 21)]


def view_hand(vertices, faces, colors=None, joints=None, *, view: dict | None = None,
              height: int = 380) -> View3D:
    """A browser 3D view of one hand, from the shared hand camera.

    Args:
        vertices: ``(V, 3)`` metres, in the hand template's frame for the default camera.
        faces: ``(F, 3)``.
        colors: ``(V, 3)`` RGB in [0, 1] (e.g. ``HandModel.vertex_colors()``) or one colour;
            skin when ``None``.
        joints: optional ``(21, 3)`` keypoints (FreiHAND order), drawn as a skeleton coloured by
            finger (the mesh then half transparent).
        view: the camera; [`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] when ``None``.
        height: view height, pixels.

    Returns:
        The [`View3D`][handmesh_tutorial.viz.web3d.View3D].
    """
    mesh = {"vertices": vertices, "faces": faces, "color": colors,
            "opacity": 0.6 if joints is not None else 1.0}
    lines = {"skeleton": _skeleton(joints)} if joints is not None else None
    return view_meshes({"hand": mesh}, lines=lines, view=view, height=height)


def view_prediction(pred_vertices, gt_vertices, faces, *, pred_joints=None, gt_joints=None,
                    view: dict | None = None, height: int = 380) -> View3D:
    """A browser 3D view of a predicted hand (orange) over its ground truth (blue, translucent).

    Both in the same frame (e.g. the camera frame, the prediction placed at the true root as the
    metrics do); the viewer's controls hide either.

    Args:
        pred_vertices: ``(V, 3)`` metres.
        gt_vertices: ``(V, 3)`` metres.
        faces: ``(F, 3)``.
        pred_joints: optional ``(21, 3)``: the predicted skeleton.
        gt_joints: optional ``(21, 3)``: the true skeleton (black).
        view: the camera; [`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] when ``None``
            (camera-frame data: turn OpenCV's y-down, z-forward into y-up first, ``v * (1, -1,
            -1)``; then ``{"elev": 15, "azim": 25, "vertical_axis": "y"}`` looks from near the
            image's camera).
        height: view height, pixels.

    Returns:
        The [`View3D`][handmesh_tutorial.viz.web3d.View3D].
    """
    meshes = {"prediction": (pred_vertices, faces, "#ff7f0e", 1.0),
              "ground truth": (gt_vertices, faces, "#1f77b4", 0.45)}
    lines = {}
    if pred_joints is not None:
        lines["predicted joints"] = _skeleton(pred_joints)
    if gt_joints is not None:
        segs, _ = _skeleton(gt_joints)
        lines["true joints"] = (segs, "#000000")
    return view_meshes(meshes, lines=lines or None, view=view, height=height)
