"""Headless rendering of INTER-SH scenes with pyrender: image, label mask, depth, bodies alone.

Everything public here is in the **OpenCV camera frame** (x right, y down, z forward, metres) with a
pinhole intrinsic matrix ``K`` in the OpenCV convention::

    K = [[fx, 0, cx],
         [0, fy, cy],
         [0,  0,  1]]      u = fx * X / Z + cx,   v = fy * Y / Z + cy   (pixels)

where pixel ``(row v, column u)`` has its *centre* at integer coordinates (the top-left pixel's
centre is ``(0, 0)``, so the centre of a ``W``-wide image is ``cx = (W - 1) / 2``). OpenGL's frame
(y up, z backward, pixel centres at half-integers) appears only inside this module: the scene's
world frame *is* the OpenCV camera frame, and the pyrender camera node gets the pose
`CV_TO_GL` = ``diag(1, -1, -1, 1)`` plus a half-pixel shift of the principal point.

pyrender is imported lazily, only here, through `import_pyrender`, which first selects the
EGL platform when no display exists and applies the NumPy 2 fix `patch_pyrender_numpy2`
(see ``docs/concepts/rendering.md``).

Typical use::

    with Renderer(224) as r:
        out = r.render([(verts, faces, colors, 1), (v2, f2, c2, 2)], K,
                       lights=random_lights(rng), background=scene_background(rng, 224, 224),
                       alone=True)
    out.image, out.labels, out.depth, out.alone_masks

Backgrounds are procedural (`random_background`) or cut from natural photographs
(`photo_background`): CC0 / public-domain images that scikit-image bundles in its wheel
(`BACKGROUND_PHOTOS`, read from the installed package at run time; licences and credits in
``docs/concepts/scenes.md``).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import io
import os
import types
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "BACKGROUND_PHOTOS",
    "CV_TO_GL",
    "BackgroundPhoto",
    "Light",
    "RenderMesh",
    "RenderResult",
    "Renderer",
    "color_temperature",
    "crop_camera",
    "default_lights",
    "ensure_egl",
    "framing",
    "import_pyrender",
    "intrinsics",
    "patch_pyrender_numpy2",
    "photo_background",
    "photo_pixels",
    "project",
    "random_background",
    "random_lights",
    "scene_background",
    "skimage_data_dir",
]

CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
"""Pose of the pyrender (OpenGL) camera in the OpenCV camera frame, and its own inverse: it flips
y (down -> up) and z (forward -> backward). Points are never transformed; only the camera is.
"""

_MAX_LABEL = 2**24 - 1  # labels are encoded in the 24 bits of the RGB segmentation colour


# --------------------------------------------------------------------------------------------
# pyrender import, EGL platform and the NumPy 2 fix
# --------------------------------------------------------------------------------------------

def ensure_egl() -> str | None:
    """Select EGL (headless OpenGL) for PyOpenGL when there is no display.

    Sets ``PYOPENGL_PLATFORM=egl`` with ``os.environ.setdefault`` when ``DISPLAY`` and
    ``WAYLAND_DISPLAY`` are unset, so a user's explicit choice (e.g. ``osmesa``) wins. It must run
    before PyOpenGL is first imported, which `import_pyrender` guarantees.

    Returns:
        The value of ``PYOPENGL_PLATFORM`` afterwards (``None`` if unset: a display exists).
    """
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    return os.environ.get("PYOPENGL_PLATFORM")


class _NumpyWithInfty(types.ModuleType):
    """A stand-in for ``numpy`` that forwards every attribute and adds ``infty = inf``."""

    infty = np.inf

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)


def patch_pyrender_numpy2(mesh_module: types.ModuleType) -> bool:
    """Make pyrender 0.1.45's ``Mesh.bounds`` work under NumPy 2, without touching NumPy.

    ``pyrender/mesh.py`` computes ``Mesh.bounds`` starting from ``np.infty``, an alias NumPy 2
    removed. Every code path that needs bounds then raises ``AttributeError``: ``Mesh.bounds``,
    ``Mesh.centroid``/``extents``/``scale``, ``Scene.bounds``/``centroid``/``scale``, directional
    shadows (the shadow camera is sized from the scene bounds) and the interactive viewer.

    The fix rebinds the *module-local* name ``np`` inside ``pyrender.mesh`` to a proxy module that
    forwards everything to NumPy and adds ``infty = numpy.inf``. NumPy itself is left alone (no
    removed alias resurrected for the whole process), nothing is forked or pinned, and the function
    is a no-op on NumPy 1.x or when already applied.

    Args:
        mesh_module: the ``pyrender.mesh`` module.

    Returns:
        ``True`` when the patch was applied by this call, ``False`` when not needed.
    """
    current = getattr(mesh_module, "np", None)
    if isinstance(current, _NumpyWithInfty):
        return False
    if current is not None and hasattr(current, "infty"):  # NumPy 1.x: nothing to fix
        return False
    mesh_module.np = _NumpyWithInfty("numpy")
    return True


_PYRENDER = None


def import_pyrender() -> types.ModuleType:
    """Import pyrender once: EGL when headless (`ensure_egl`), then the NumPy 2 fix.

    This is the only place in the library that imports pyrender.

    Returns:
        The ``pyrender`` module.
    """
    global _PYRENDER
    if _PYRENDER is None:
        ensure_egl()
        import pyrender
        import pyrender.mesh

        patch_pyrender_numpy2(pyrender.mesh)
        _PYRENDER = pyrender
    return _PYRENDER


# --------------------------------------------------------------------------------------------
# Cameras
# --------------------------------------------------------------------------------------------

def intrinsics(fx: float, fy: float | None = None, cx: float = 0.0, cy: float = 0.0) -> np.ndarray:
    """Build an OpenCV pinhole matrix.

    Args:
        fx: focal length along x, pixels.
        fy: focal length along y, pixels (default ``fx``).
        cx: principal point column, pixels (pixel centres at integers).
        cy: principal point row, pixels.

    Returns:
        ``K`` (3, 3) float64.
    """
    fy = fx if fy is None else fy
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _check_K(K: Any) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {K.shape}")
    if not (K[0, 0] > 0 and K[1, 1] > 0) or abs(K[0, 1]) > 1e-12 or np.any(K[2] != (0, 0, 1)):
        raise ValueError("K must be [[fx,0,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0, "
                         f"got {K.tolist()}")
    return K


def project(points: Any, K: Any) -> np.ndarray:
    """Project camera-frame points to pixels: ``(u, v) = (K @ X)[:2] / Z``.

    Args:
        points: (N, 3) points in the OpenCV camera frame, metres, ``Z > 0``.
        K: (3, 3) intrinsics.

    Returns:
        (N, 2) float64 pixel coordinates ``(u = column, v = row)``, pixel centres at integers.

    Raises:
        ValueError: bad shapes or a point with ``Z <= 0``.
    """
    K = _check_K(K)
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {P.shape}")
    if np.any(P[:, 2] <= 0):
        raise ValueError("points must lie in front of the camera (Z > 0)")
    uvw = P @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def crop_camera(points3d: Any, image_size: int, margin: float = 0.1, focal: float | None = None,
                center: Any = None) -> np.ndarray:
    """A pinhole ``K`` for a square image that frames given 3D points (a "crop camera").

    The camera stays at the origin of the OpenCV camera frame (the points do not move); only the
    focal length and the principal point are chosen, exactly like cropping and rescaling a larger
    photo. The framing point ``center`` (default: the centre of the points' projected bounding box)
    lands on the image centre ``((S-1)/2, (S-1)/2)`` and every point lands at least
    ``margin * S`` pixels inside the image border (which lies at ``-0.5`` and ``S - 0.5`` in
    pixel coordinates, since pixel centres are integers).

    Args:
        points3d: (N, 3) points in the camera frame, metres, ``Z > 0`` (e.g. the target hand's
            vertices).
        image_size: side ``S`` of the square image, pixels (e.g. 224).
        margin: free border on each side as a fraction of ``S``, in ``[0, 0.5)``.
        focal: fixed focal length in pixels; ``None`` picks the largest focal that fits.
        center: optional (3,) point to centre on (e.g. the interaction centre), camera frame.

    Returns:
        ``K`` (3, 3) float64 with ``fx = fy``.

    Raises:
        ValueError: bad shapes, ``Z <= 0``, a margin outside ``[0, 0.5)``, or a fixed ``focal``
            too long to keep all points inside (the message gives the largest focal that fits).
    """
    P = np.asarray(points3d, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        raise ValueError(f"points3d must have shape (N, 3) with N >= 1, got {P.shape}")
    if np.any(P[:, 2] <= 0):
        raise ValueError("points3d must lie in front of the camera (Z > 0)")
    if not 0.0 <= margin < 0.5:
        raise ValueError(f"margin must be in [0, 0.5), got {margin}")
    S = int(image_size)
    if S < 1:
        raise ValueError(f"image_size must be a positive integer, got {image_size}")
    n = P[:, :2] / P[:, 2:3]  # normalised image coordinates
    if center is None:
        c = 0.5 * (n.min(0) + n.max(0))
    else:
        C = np.asarray(center, dtype=np.float64).reshape(-1)
        if C.shape != (3,) or C[2] <= 0:
            raise ValueError(f"center must be a (3,) point with Z > 0, got {np.asarray(center)}")
        c = C[:2] / C[2]
    half = (0.5 - margin) * S  # pixels available between centre and the margin
    reach = float(np.abs(n - c).max())
    f_fit = half / reach if reach > 0 else float(S)
    if focal is None:
        f = f_fit
    else:
        f = float(focal)
        if f <= 0:
            raise ValueError(f"focal must be > 0, got {focal}")
        if f > f_fit * (1 + 1e-9):
            raise ValueError(f"focal {f:.1f} px puts points outside the {margin:.2f} margin; "
                             f"the largest focal that fits is {f_fit:.1f} px")
    mid = (S - 1) / 2.0
    return intrinsics(f, f, mid - f * c[0], mid - f * c[1])


def framing(points3d: Any, K: Any, image_size: int, margin: float = 0.08) -> dict:
    """How a body is framed in a square image: its share of the image and what lies inside.

    Args:
        points3d: (N, 3) points in the camera frame, metres, ``Z > 0`` (a hand's vertices or
            its 21 joints).
        K: (3, 3) intrinsics.
        image_size: side ``S`` of the square image, pixels.
        margin: border, as a fraction of ``S``, that counts as outside for ``inside``.

    Returns:
        dict with ``share`` (the longer side of the points' projected bounding box over ``S``),
        ``inside`` (fraction of the points at least ``margin * S`` pixels inside the image
        border, which lies at ``-0.5`` and ``S - 0.5``) and ``center`` ((2,) bounding-box centre,
        pixels).
    """
    uv = project(points3d, K)
    S = int(image_size)
    lo, hi = uv.min(0), uv.max(0)
    m = margin * S
    ok = ((uv >= -0.5 + m) & (uv <= S - 0.5 - m)).all(1)
    return {"share": float((hi - lo).max() / S), "inside": float(ok.mean()),
            "center": 0.5 * (lo + hi)}


# --------------------------------------------------------------------------------------------
# Lights and backgrounds
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Light:
    """A light in the OpenCV camera frame.

    Attributes:
        kind: ``"directional"`` or ``"point"``.
        color: (3,) RGB in [0, 1].
        intensity: lux for directional lights, candela for point lights (pyrender units).
        direction: (3,) unit direction the light *travels* (directional lights), camera frame.
        position: (3,) position, metres, camera frame (point lights).
    """

    kind: str
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 3.0
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)


def default_lights() -> list[Light]:
    """Deterministic lighting: a head light along the view axis and a key light from top left.

    Returns:
        A list of `Light`.
    """
    key = np.array([0.4, 0.6, 1.0])
    key /= np.linalg.norm(key)
    return [Light("directional", intensity=1.0, direction=(0.0, 0.0, 1.0)),
            Light("directional", intensity=0.8, direction=tuple(key))]


def random_lights(rng: np.random.Generator | int | None, num: tuple[int, int] = (2, 4),
                  target_depth: float = 0.5) -> list[Light]:
    """Random lighting: a few directional and point lights with random intensity and direction.

    Intensities are chosen so that a surface at ``target_depth`` facing the camera receives an
    irradiance of roughly 0.5-3 (pyrender units; 1 is a well exposed single light).
    Directions come from the camera's hemisphere (lights travel roughly along +z, never from
    behind the objects towards the camera), point lights sit around the camera at
    ``0.2-0.6 * target_depth`` from the optical axis, colours are slightly warm or cool whites.

    Args:
        rng: a ``numpy.random.Generator`` or a seed.
        num: inclusive range of the number of lights.
        target_depth: typical depth of the scene, metres (sizes the point-light positions).

    Returns:
        A list of `Light` (first one always directional so the scene is never dark).
    """
    rng = np.random.default_rng(rng)
    n = int(rng.integers(num[0], num[1] + 1))
    lights = []
    for i in range(n):
        tint = np.clip(1.0 + rng.normal(0.0, 0.08, 3), 0.75, 1.0)
        kind = "directional" if i == 0 or rng.random() < 0.6 else "point"
        if kind == "directional":
            d = rng.normal(size=3)
            d[2] = abs(d[2]) + 0.8  # travel into the scene
            d /= np.linalg.norm(d)
            lights.append(Light("directional", tuple(tint), float(rng.uniform(0.4, 1.2)),
                                direction=tuple(d)))
        else:
            ang = rng.uniform(0, 2 * np.pi)
            r = rng.uniform(0.2, 0.6) * target_depth
            pos = (r * np.cos(ang), r * np.sin(ang), rng.uniform(-0.2, 0.2) * target_depth)
            lights.append(Light("point", tuple(tint),
                                float(rng.uniform(0.3, 1.0) * target_depth**2),
                                position=tuple(float(p) for p in pos)))
    return lights


def color_temperature(kelvin: float) -> tuple[float, float, float]:
    """The colour of a black-body light source, as linear RGB with its largest channel 1.

    Tanner Helland's fit of the Planckian locus in sRGB (valid 1000-40000 K), converted to linear
    RGB for pyrender: about ``(1, 0.42, 0.13)`` at 2700 K (a tungsten bulb), ``(1, 0.86, 0.76)``
    at 5000 K, white at 6600 K, and blue above (``(0.71, 0.79, 1)`` at 10000 K, shade).

    Args:
        kelvin: colour temperature, kelvin.

    Returns:
        ``(r, g, b)`` in [0, 1].
    """
    t = float(np.clip(kelvin, 1000.0, 40000.0)) / 100.0
    if t <= 66:
        r = 255.0
        g = 99.4708025861 * np.log(t) - 161.1195681661
        b = 0.0 if t <= 19 else 138.5177312231 * np.log(t - 10) - 305.0447927307
    else:
        r = 329.698727446 * (t - 60) ** -0.1332047592
        g = 288.1221695283 * (t - 60) ** -0.0755148492
        b = 255.0
    rgb = srgb_to_linear(np.clip(np.array([r, g, b]) / 255.0, 0.0, 1.0))
    rgb = rgb / rgb.max()
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


def _value_noise(rng: np.random.Generator, H: int, W: int, octaves: int = 4) -> np.ndarray:
    """Multi-octave smooth value noise (a Perlin-like texture) in [0, 1], shape (H, W)."""
    out = np.zeros((H, W))
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cells = 2 ** (o + 1) + 1
        grid = rng.random((cells + 1, cells + 1))
        y = np.linspace(0, cells - 1e-9, H)
        x = np.linspace(0, cells - 1e-9, W)
        y0, x0 = np.floor(y).astype(int), np.floor(x).astype(int)
        ty, tx = y - y0, x - x0
        ty, tx = ty * ty * (3 - 2 * ty), tx * tx * (3 - 2 * tx)  # smoothstep
        g00 = grid[y0][:, x0]
        g01 = grid[y0][:, x0 + 1]
        g10 = grid[y0 + 1][:, x0]
        g11 = grid[y0 + 1][:, x0 + 1]
        top = g00 + (g01 - g00) * tx[None]
        bot = g10 + (g11 - g10) * tx[None]
        out += amp * (top + (bot - top) * ty[:, None])
        total += amp
        amp *= 0.5
    return out / total


def random_background(rng: np.random.Generator | int | None, H: int, W: int | None = None,
                      kind: str | None = None) -> np.ndarray:
    """A procedural background image (no downloads).

    Kinds: ``"gradient"`` (linear, random direction, two colours), ``"noise"`` (multi-octave value
    noise mapping between two colours), ``"stripes"`` (sinusoidal stripes, random angle/period),
    ``"checker"`` (rotated checkerboard). Colours are random with jitter, plus a little pixel noise.

    Args:
        rng: a ``numpy.random.Generator`` or a seed.
        H: height, pixels.
        W: width, pixels (default ``H``).
        kind: one of the kinds above, or ``None`` to draw one at random.

    Returns:
        (H, W, 3) uint8 RGB image.

    Raises:
        ValueError: unknown ``kind``.
    """
    rng = np.random.default_rng(rng)
    W = H if W is None else W
    kinds = ("gradient", "noise", "stripes", "checker")
    if kind is None:
        kind = kinds[int(rng.integers(len(kinds)))]
    if kind not in kinds:
        raise ValueError(f"unknown background kind {kind!r}; expected one of {kinds}")
    c0, c1 = rng.random(3), rng.random(3)
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    ang = rng.uniform(0, np.pi)
    s = np.cos(ang) * xx + np.sin(ang) * yy
    if kind == "gradient":
        t = (s - s.min()) / max(s.max() - s.min(), 1e-9)
    elif kind == "noise":
        t = _value_noise(rng, H, W)
    elif kind == "stripes":
        period = rng.uniform(0.05, 0.25)
        t = 0.5 + 0.5 * np.sin(2 * np.pi * s / period)
    else:
        period = rng.uniform(0.08, 0.3)
        s2 = -np.sin(ang) * xx + np.cos(ang) * yy
        t = ((np.floor(s / period) + np.floor(s2 / period)) % 2).astype(float)
    img = c0 + t[..., None] * (c1 - c0)
    img = img + rng.normal(0.0, 0.02, img.shape)
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


@dataclass(frozen=True)
class BackgroundPhoto:
    """A photograph shipped in scikit-image's wheel (``skimage/data/<file>``), used as a
    background by `photo_background`.

    Attributes:
        name: short name (the ``skimage.data`` function of the same image).
        file: file name in ``skimage/data``.
        texture: ``True`` for a grey close-up texture (tinted at random), ``False`` for a colour
            photograph.
        licence: the licence stated in the image's ``skimage.data`` docstring (scikit-image 0.26).
        credit: author or source.
        description: what it shows.
        tints: for textures, plausible sRGB surface colours (one is drawn and jittered).
        sha256: hash of the file in scikit-image 0.22-0.26 (the same bytes in all of them).
    """

    name: str
    file: str
    texture: bool
    licence: str
    credit: str
    description: str
    tints: tuple[tuple[float, float, float], ...] = ()
    sha256: str = ""


BACKGROUND_PHOTOS: tuple[BackgroundPhoto, ...] = (
    BackgroundPhoto("coffee", "coffee.png", False, "CC0",
                    "Rachel Michetti (photographer), courtesy of Pikolo Espresso Bar",
                    "a cup of espresso on a wooden table",
                    sha256="cc02f8ca188b167c775a7101b5d767d1e71792cf762c33d6fa15a4599b5a8de7"),
    BackgroundPhoto("chelsea", "chelsea.png", False, "CC0",
                    "Stefan van der Walt (photographer)", "Chelsea the cat",
                    sha256="596aa1e7cb875eb79f437e310381d26b338a81c2da23439704a73c4651e8c4bb"),
    BackgroundPhoto("rocket", "rocket.jpg", False, "public domain", "SpaceX",
                    "a Falcon 9 on its launch pad at dusk",
                    sha256="c2dd0de7c538df8d111e479619b129464d0269d0ae5fd18ca91d33a7fdfea95c"),
    BackgroundPhoto("brick", "brick.png", True, "CC0", "CC0Textures (Bricks25)",
                    "a brick wall, grey",
                    ((0.55, 0.28, 0.2), (0.62, 0.45, 0.35), (0.5, 0.5, 0.5), (0.85, 0.82, 0.75)),
                    "7966caf324f6ba843118d98f7a07746d22f6a343430add0233eca5f6eaaa8fcf"),
    BackgroundPhoto("grass", "grass.png", True, "CC0", "linolafett on DeviantArt (Grass 01)",
                    "grass, grey", ((0.3, 0.42, 0.18), (0.42, 0.5, 0.22), (0.6, 0.55, 0.32)),
                    "b6b6022426b38936c43a4ac09635cd78af074e90f42ffa8227ac8b7452d39f89"),
    BackgroundPhoto("gravel", "gravel.png", True, "CC0", "CC0Textures (Gravel04)",
                    "gravel, grey", ((0.5, 0.48, 0.45), (0.62, 0.56, 0.46), (0.4, 0.4, 0.42)),
                    "c48615b451bf1e606fbd72c0aa9f8cc0f068ab7111ef7d93bb9b0f2586440c12"),
)
"""The photographs `photo_background` draws from: only images that scikit-image *bundles in its
wheel* (not the ones ``skimage.data`` downloads with pooch) and whose ``skimage.data`` docstring
states CC0 or the public domain. Left out: the astronaut and camera portraits (faces), the Hubble
deep field (black sky), microscopy and retina images, and the Middlebury motorcycle pair (no licence
stated). Nothing is copied into this library: the files are read from the installed scikit-image at
run time.
"""


def _photo(name: str) -> BackgroundPhoto:
    for ph in BACKGROUND_PHOTOS:
        if ph.name == name:
            return ph
    raise ValueError(f"unknown background photo {name!r}; expected one of "
                     f"{[ph.name for ph in BACKGROUND_PHOTOS]}")


def skimage_data_dir() -> Path:
    """The ``data`` folder of the installed scikit-image (found without importing it).

    Raises:
        ImportError: scikit-image is not installed (``pip install scikit-image``).
    """
    spec = importlib.util.find_spec("skimage")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("photo backgrounds read the photographs bundled in scikit-image's "
                          "wheel: pip install scikit-image (random_background needs nothing)")
    return Path(list(spec.submodule_search_locations)[0]) / "data"


@functools.cache
def photo_pixels(name: str) -> np.ndarray:
    """The pixels of one of `BACKGROUND_PHOTOS`, read once per process (read-only array).

    Args:
        name: a `BackgroundPhoto` name (``"coffee"``, ``"brick"``, ...).

    Returns:
        (H, W, 3) uint8 RGB for photographs, (H, W) uint8 grey for textures.

    Raises:
        ValueError: unknown name.
        ImportError: scikit-image is not installed.
        FileNotFoundError: the installed scikit-image lacks the file.
    """
    from PIL import Image

    ph = _photo(name)
    path = skimage_data_dir() / ph.file
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: the installed scikit-image does not bundle "
                                f"{ph.file} (scikit-image 0.26's wheel does)")
    data = path.read_bytes()
    if ph.sha256 and hashlib.sha256(data).hexdigest() != ph.sha256:
        warnings.warn(f"{path} differs from the {ph.file} of scikit-image 0.22-0.26: scenes made "
                      "with the same seed will differ from other installations", stacklevel=2)
    with Image.open(io.BytesIO(data)) as im:
        a = np.array(im.convert("L" if ph.texture else "RGB"))
    a.setflags(write=False)
    return a


def photo_background(rng: np.random.Generator | int | None, H: int, W: int | None = None,
                     photo: str | None = None) -> np.ndarray:
    """A background cut from a natural photograph (`BACKGROUND_PHOTOS`), randomly varied.

    One photograph (a colour photograph with probability 0.6, else a texture, uniform within
    each group; or ``photo``) is cropped at a random place
    and scale (35-100 % of the largest window of the image's aspect for photographs, 25-90 % for
    textures, which are also turned by a multiple of 90 degrees and flipped vertically), resized
    to ``(H, W)``, flipped left-right with probability 0.5, and defocused with probability 0.6
    (Gaussian blur, sigma up to 2 px at 224 px: the shallow depth of field of a close-up).
    Grey textures get one of their plausible surface colours (`BackgroundPhoto.tints`), jittered.
    Then colour jitter (brightness x0.55-1.2, contrast x0.7-1.15,
    saturation x0.5-1.15, per-channel white balance), an illumination gradient of up to ±25 % in
    a random direction, and a little pixel noise.

    Args:
        rng: a ``numpy.random.Generator`` or a seed.
        H: height, pixels.
        W: width, pixels (default ``H``).
        photo: a `BackgroundPhoto` name, or ``None`` to draw one.

    Returns:
        (H, W, 3) uint8 RGB image.

    Raises:
        ValueError: unknown ``photo``.
        ImportError: scikit-image is not installed.
    """
    from PIL import Image, ImageFilter

    rng = np.random.default_rng(rng)
    W = H if W is None else W
    if photo is None:
        texture = bool(rng.random() >= 0.6)
        group = [ph for ph in BACKGROUND_PHOTOS if ph.texture == texture]
        photo = group[int(rng.integers(len(group)))].name
    ph = _photo(photo)
    im = Image.fromarray(photo_pixels(photo))
    if ph.texture:
        k = int(rng.integers(4))
        if k:
            im = im.transpose((Image.Transpose.ROTATE_90, Image.Transpose.ROTATE_180,
                               Image.Transpose.ROTATE_270)[k - 1])
        scale = rng.uniform(0.25, 0.9)
    else:
        scale = rng.uniform(0.35, 1.0)
    pw, phh = im.size
    aspect = W / H
    cw = min(pw, phh * aspect) * scale
    ch = cw / aspect
    x0, y0 = rng.uniform(0, pw - cw), rng.uniform(0, phh - ch)
    im = im.resize((W, H), Image.Resampling.BILINEAR, box=(x0, y0, x0 + cw, y0 + ch))
    if rng.random() < 0.5:
        im = im.transpose(Image.Transpose.FLIP_LEFT_RIGHT)
    if ph.texture and rng.random() < 0.5:
        im = im.transpose(Image.Transpose.FLIP_TOP_BOTTOM)
    sigma = rng.uniform(0.3, 2.0) * max(H, W) / 224
    if rng.random() < 0.6:
        im = im.filter(ImageFilter.GaussianBlur(float(sigma)))
    img = np.asarray(im, dtype=np.float64) / 255.0
    if ph.texture:  # grey -> a surface colour (the mean of the texture becomes the colour)
        base = np.asarray(ph.tints[int(rng.integers(len(ph.tints)))])
        base = np.clip(base * np.exp(rng.normal(0.0, 0.08, 3)) * rng.uniform(0.7, 1.2), 0, 1)
        img = img[..., None] / max(float(img.mean()), 1e-3) * base
    mean = img.mean((0, 1))
    img = (img - mean) * rng.uniform(0.7, 1.15) + mean  # contrast
    grey = img @ np.array([0.299, 0.587, 0.114])
    img = grey[..., None] + rng.uniform(0.5, 1.15) * (img - grey[..., None])  # saturation
    img = img * rng.uniform(0.55, 1.2) * np.exp(rng.normal(0.0, 0.06, 3))  # exposure, white bal.
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    ang = rng.uniform(0, 2 * np.pi)
    ramp = np.cos(ang) * (xx - xx.mean()) + np.sin(ang) * (yy - yy.mean())
    img = img * (1 + rng.uniform(-0.5, 0.5) * ramp)[..., None]
    img = img + rng.normal(0.0, 0.01, img.shape)
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


def scene_background(rng: np.random.Generator | int | None, H: int, W: int | None = None,
                     photo_prob: float = 0.75) -> np.ndarray:
    """The generator's background: a `photo_background` with probability ``photo_prob``, else a
    procedural `random_background` with its colours muted (saturation x0.3-0.8: the random
    colours of the procedural textures are far more vivid than real surroundings).

    Args:
        rng: a ``numpy.random.Generator`` or a seed.
        H: height, pixels.
        W: width, pixels (default ``H``).
        photo_prob: probability of a photograph, in [0, 1].

    Returns:
        (H, W, 3) uint8 RGB image.
    """
    if not 0.0 <= photo_prob <= 1.0:
        raise ValueError(f"photo_prob must be in [0, 1], got {photo_prob}")
    rng = np.random.default_rng(rng)
    if rng.random() < photo_prob:
        return photo_background(rng, H, W)
    img = random_background(rng, H, W).astype(np.float64)
    grey = (img @ np.array([0.299, 0.587, 0.114]))[..., None]
    img = grey + rng.uniform(0.3, 0.8) * (img - grey)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------------------------
# Renderer
# --------------------------------------------------------------------------------------------

class RenderMesh(NamedTuple):
    """One body to render (a plain 4-tuple works too).

    Attributes:
        vertices: (V, 3) float, metres, OpenCV camera frame.
        faces: (F, 3) int vertex indices, counter-clockwise seen from outside.
        colors: (V, 3) or (V, 4) sRGB vertex colours, float in [0, 1] or uint8 in [0, 255]
            (linearised for pyrender by `srgb_to_linear`).
        label: int >= 1, unique in the scene; its value in the label mask.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    label: int


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
        if len(m) != 4:
            raise ValueError(f"meshes[{i}] must be (vertices, faces, colors, label), "
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
        out.append(RenderMesh(v, f.astype(np.int64), np.clip(c, 0.0, 1.0), label))
    return out


def srgb_to_linear(colors) -> np.ndarray:
    """sRGB colours in [0, 1] -> linear RGB (the IEC 61966-2-1 transfer function), same shape.

    pyrender multiplies the lit colour by the vertex colour and gamma-encodes the result
    (``shaders/mesh.frag``), so it expects *linear* vertex colours; the library's colours (skin
    tones, object palettes) are sRGB, and `Renderer.render` converts them with this function.
    """
    c = np.clip(np.asarray(colors, float), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


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


def _keep_egl_display(platform: Any) -> None:
    """Make a pyrender EGL platform's ``delete_context`` destroy its context only, without
    ``eglTerminate`` on the display that the process's other renderers still use."""
    if platform is None or not hasattr(platform, "_egl_display"):
        return

    def delete_context() -> None:
        from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglDestroyContext, eglMakeCurrent

        if platform._egl_display is not None:
            if platform._egl_context is not None:
                eglMakeCurrent(platform._egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE,
                               EGL_NO_CONTEXT)
                eglDestroyContext(platform._egl_display, platform._egl_context)
                platform._egl_context = None
            platform._egl_display = None

    platform.delete_context = delete_context


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
        self._r = self._pr.OffscreenRenderer(self.width, self.height)
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
        scene = pr.Scene(bg_color=np.zeros(4), ambient_light=amb)
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
        prim = pr.Primitive(positions=m.vertices.astype(np.float32),
                            normals=_vertex_normals(m.vertices, m.faces).astype(np.float32),
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
                colors (V, 3) float [0, 1] or uint8, label int >= 1 (unique).
            K: (3, 3) OpenCV intrinsics (pixel centres at integer coordinates).
            lights: lights in the camera frame; ``None`` means `default_lights`.
            background: (H, W, 3) uint8 (or float [0, 1]) image, or an RGB (3,) colour, behind
                the bodies; ``None`` is black. Use `random_background` for variety.
            ambient: ambient light level in [0, 1], or a (3,) linear RGB ambient colour (e.g.
                tinted by the background, as light bouncing off the surroundings is).
            color: run the colour pass (``False``: masks and depth only, faster).
            alone: also render each body alone and return its mask (the VR denominators).
            alone_images: also return each body alone over the background (implies ``alone``).
            occluders: scenery ``(vertices, faces, colors, owner)`` tuples (e.g. a hand's
                forearm): drawn in the image and hiding what is behind them, but label 0 in the
                masks; an occluder also hides parts of its owner (a body label, or 0 for none)
                in the owner's *alone* mask, so VR counts only what other bodies hide.

        Returns:
            A `RenderResult`.

        Raises:
            ValueError: bad mesh arrays, labels, ``K`` or background shape.
        """
        if self._r is None:
            raise ValueError("this Renderer is closed")
        ms = _as_meshes(meshes)
        K = _check_K(K)
        bg = self._background(background)
        lights = default_lights() if lights is None else list(lights)
        scene, nodes = self._scene(ms, K, lights, ambient)
        scenery = []
        for i, occ in enumerate(occluders):
            if len(occ) != 4:
                raise ValueError(f"occluders[{i}] must be (vertices, faces, colors, owner), got "
                                 f"{len(occ)} items")
            mesh = _as_meshes([(occ[0], occ[1], occ[2], 1)])[0]     # validated, colours in [0,1]
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
