"""Example and random poses of the hand (axis-angle, MANO order, radians).

[`flexion_axes`][handmesh_tutorial.hand.poses.flexion_axes] gives, per articulated joint, the axis
that curls it towards the palm; [`example_pose`][handmesh_tutorial.hand.poses.example_pose] builds
named poses (flat, fist, point, pinch, spread) from them and
[`random_pose`][handmesh_tutorial.hand.poses.random_pose] draws loosely plausible random ones. A
pose is (15,3) axis-angle in MANO joint order (index1..thumb3), ready for ``HandModel(pose=...)``;
anatomically limited random poses come from [`handmesh_tutorial.lcs`][handmesh_tutorial.lcs].

Taught in notebook 01 (the hand model); random poses are used in notebooks 03 and 07.
"""

from __future__ import annotations

import numpy as np

from ._common import _check_side, _unit
from .joints import _FINGER_MANO, FINGER_NAMES
from .skinning import mirror_axis_angle
from .template import load_template

__all__ = ["flexion_axes", "example_pose", "random_pose"]


def flexion_axes(side: str = "right") -> np.ndarray:
    """Unit rotation axes that curl each articulated joint towards the palm (rest frame).

    For the four fingers the axis is ``finger direction x palm normal (-y)``; for the thumb the
    thumb direction crossed with a direction towards the palm centre, so a positive angle about
    the axis flexes the joint.

    Args:
        side: ``"right"`` or ``"left"`` (the left axes are the mirrored right axes).

    Returns:
        (15,3) float64, MANO order of the articulated joints (index1..thumb3).

    Raises:
        ValueError: ``side`` is not ``"right"`` or ``"left"``.
    """
    _check_side(side)
    kp = np.asarray(load_template().keypoints, float)
    axes = np.zeros((15, 3))
    palm_normal = np.array([0.0, -1.0, 0.0])
    for f_i, finger in enumerate(FINGER_NAMES):
        base = 1 + 4 * f_i
        for k, j in enumerate(_FINGER_MANO[finger]):
            d = _unit(kp[base + k + 1] - kp[base + k])
            if finger == "thumb":
                axes[j - 1] = _unit(np.cross(d, _unit([0.0, -0.5, 1.0])))
            else:
                axes[j - 1] = _unit(np.cross(d, palm_normal))
    return axes if side == "right" else mirror_axis_angle(axes)


# The thumb of the fist and point poses (CMC, MCP, IP flexion, degrees from the template's rest
# thumb, which already stands ~26 degrees flexed in the LCS sense): inside the anatomical limits.
_THUMB_CLOSED = (30, 25, 40)


def example_pose(name: str, side: str = "right") -> np.ndarray:
    """A few named poses for figures and tests.

    Args:
        name: ``"flat"`` (the rest pose), ``"fist"``, ``"point"`` (index extended),
            ``"pinch"`` (thumb and index tips close) or ``"spread"`` (fingers fanned out).
        side: ``"right"`` or ``"left"``.

    Returns:
        (15,3) float32 axis-angle pose, MANO order; its LCS angles lie inside the anatomical
        limits ([`lcs.ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG]).

    Raises:
        ValueError: unknown name or side.
    """
    _check_side(side)
    axes = flexion_axes("right")
    flex = np.zeros(15)
    pose = np.zeros((15, 3))
    fing = {f: [j - 1 for j in _FINGER_MANO[f]] for f in FINGER_NAMES}
    if name == "flat":
        pass
    elif name == "fist":
        for f in ("index", "middle", "ring", "pinky"):
            flex[fing[f]] = np.deg2rad([80, 95, 60])
        flex[fing["thumb"]] = np.deg2rad(_THUMB_CLOSED)
    elif name == "point":
        for f in ("middle", "ring", "pinky"):
            flex[fing[f]] = np.deg2rad([80, 95, 60])
        flex[fing["index"]] = np.deg2rad([5, 5, 5])
        flex[fing["thumb"]] = np.deg2rad(_THUMB_CLOSED)
    elif name == "pinch":
        flex[fing["index"]] = np.deg2rad([35, 40, 20])
        for f in ("middle", "ring", "pinky"):
            flex[fing[f]] = np.deg2rad([20, 25, 15])
        flex[fing["thumb"]] = np.deg2rad([25, 20, 15])
    elif name == "spread":
        for f, ang in zip(("index", "middle", "ring", "pinky"), (-12, -3, 8, 14), strict=True):
            pose[fing[f][0]] = np.deg2rad(ang) * np.array([0.0, -1.0, 0.0])  # +: towards pinky
        pose[fing["thumb"][0]] = np.deg2rad(-15) * _unit([0.0, -1.0, 1.2])
    else:
        raise ValueError(f"unknown pose name {name!r}; expected flat, fist, point, pinch, spread")
    pose = pose + flex[:, None] * axes
    pose = pose if side == "right" else mirror_axis_angle(pose)
    return pose.astype(np.float32)


def random_pose(rng: np.random.Generator | int | None = None, batch: int = 1,
                side: str = "right", max_flexion_deg: float = 90.0,
                max_spread_deg: float = 10.0) -> np.ndarray:
    """Random, loosely plausible poses: flexion in [0, max] per joint, small MCP sideways spread.

    Not anatomically limited; meant for figures, tests and the fitting demos. This is a different
    distribution from [`lcs.random_pose`][handmesh_tutorial.lcs.hands.random_pose], which draws the
    three LCS angles of every joint uniformly inside per-axis joint limits (the generator's step 4):
    here each joint only curls about its fixed flexion axis
    ([`flexion_axes`][handmesh_tutorial.hand.poses.flexion_axes]) by a uniform angle in
    [0, ``max_flexion_deg``], the MCPs also turn sideways by at most ``max_spread_deg``, and no
    hand model or LCS is needed. With ``max_flexion_deg <= 30`` and ``max_spread_deg <= 10``
    every pose lies inside the anatomical limits
    ([`lcs.ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG], tested);
    larger flexions can leave them (the thumb's CMC first).

    Args:
        rng: generator or seed.
        batch: number of poses B, an integer >= 0.
        side: ``"right"`` or ``"left"``.
        max_flexion_deg: largest flexion per joint, degrees in [0, 180].
        max_spread_deg: largest sideways rotation of the MCP joints, degrees in [0, 180].

    Returns:
        (B,15,3) float32 axis-angle poses, MANO order.

    Raises:
        ValueError: an argument outside its range (a NaN angle gave NaN poses, another side
            a left hand).
    """
    _check_side(side)
    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 0:
        raise ValueError(f"batch must be an integer >= 0 (poses), got {batch!r}")
    for name, deg in (("max_flexion_deg", max_flexion_deg), ("max_spread_deg", max_spread_deg)):
        if isinstance(deg, bool) or not isinstance(deg, (int, float, np.number)) \
                or not 0 <= deg <= 180:
            raise ValueError(f"{name} must be a number of degrees in [0, 180], got {deg!r}")
    gen = np.random.default_rng(rng)
    axes = flexion_axes("right")
    flex = gen.uniform(0.0, np.deg2rad(max_flexion_deg), size=(batch, 15))
    pose = flex[..., None] * axes
    spread = gen.uniform(-1, 1, size=(batch, 5)) * np.deg2rad(max_spread_deg)
    for f_i, finger in enumerate(FINGER_NAMES):
        pose[:, _FINGER_MANO[finger][0] - 1, 1] += spread[:, f_i]
    pose = pose if side == "right" else mirror_axis_angle(pose)
    return pose.astype(np.float32)
