"""Backgrounds behind the rendered bodies: procedural textures and natural photographs.

Backgrounds are procedural (`random_background`) or cut from natural photographs
(`photo_background`): CC0 / public-domain images that scikit-image bundles in its wheel
(`BACKGROUND_PHOTOS`, read from the installed package at run time; licences and credits in
``docs/concepts/scenes.md``). `scene_background` is the generator's mix of both. Every
background is an (H, W, 3) uint8 sRGB image; same seed -> same bytes.

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._optional import missing_extra_message

__all__ = [
    "BACKGROUND_PHOTOS",
    "BackgroundPhoto",
    "PHOTO_PROB",
    "photo_background",
    "photo_pixels",
    "random_background",
    "scene_background",
]


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


def _skimage_data_dir() -> Path:
    """The ``data`` folder of the installed scikit-image (found without importing it).

    Raises:
        ImportError: scikit-image is not installed (``pip install "handmesh_tutorial[scenes]"``).
    """
    spec = importlib.util.find_spec("skimage")
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError(missing_extra_message(
            "skimage", "photo backgrounds (the photographs bundled in scikit-image's wheel; "
            "random_background needs nothing)"), name="skimage")
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
    path = _skimage_data_dir() / ph.file
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


PHOTO_PROB: float = 0.75
"""The generator's share of photograph backgrounds (`scene_background`); the rest are muted
procedural textures."""


def scene_background(rng: np.random.Generator | int | None, H: int, W: int | None = None,
                     photo_prob: float = PHOTO_PROB) -> np.ndarray:
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
