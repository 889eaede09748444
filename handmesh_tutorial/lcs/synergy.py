"""Natural hand poses from a flexion-synergy prior: `natural_hand_angles`.

Drawing each joint's angle independently inside its limits gives poses real hands rarely make:
a finger with a straight (or hyperextended) knuckle and a fully bent middle joint (a "claw"),
neighbouring fingers bent in opposite ways. Real hands move in *synergies*: the first principal
component of recorded grasps closes all fingers together, MCP and PIP joints of a finger flex
together, neighbouring fingers follow each other, and a relaxed hand cascades (the little finger
more flexed than the index) (Santello, Flanders & Soechting 1998, "Postural hand synergies for tool
use"). The prior here is a hand-written version of that structure, not a fit to recorded data:

1. a **closure** ``g`` in [0, 1] for the whole hand (0 open, 1 a fist);
2. per finger (index, middle, ring, little) ``c_f = clip(g + cascade_f + sigma * e_f, 0, 1)`` with
   ``cascade = (-0.06, 0, +0.05, +0.10)`` and noise ``e`` correlated between neighbouring fingers
   (correlation 0.6); with probability ``point_prob`` the index stays open (pointing);
3. each finger's joints flex *together* with ``c_f``: MCP ``-5 + 85 c_f`` degrees, PIP
   ``3 + 97 c_f``, each with 6° of independent noise; the DIP follows the PIP
   ([`DIP_PIP_RATIO`][handmesh_tutorial.lcs.limits.DIP_PIP_RATIO]); the spread (MCP abduction)
   shrinks as the hand closes;
4. the thumb opposes with the closure: CMC flexion ``-10 + 45 o``, MCP ``5 + 40 o``, IP
   ``5 + 55 o`` degrees for ``o = clip(0.85 g + 0.15 e, 0, 1)``, small CMC abduction and twist.

Angles are LCS angles ``(15, 3)`` in radians (axis order ``x`` abduction, ``y`` flexion, ``z``
twist; MANO joint order 1..15), clipped to the anatomical limits; feed them to
[`Articulation.to_pose`][handmesh_tutorial.lcs.articulation.Articulation.to_pose]. The generator
(notebook 04, ``InteractionConfig(poses="natural")``) draws one such pose per hand as the target
its joints move towards.
"""

from __future__ import annotations

import numpy as np

from .angles import mirror_angles
from .limits import DIP_FOLLOWS_PIP, DIP_PIP_RATIO, hand_joint_limits

__all__ = ["FINGER_JOINTS", "THUMB_JOINTS", "natural_hand_angles"]

FINGER_JOINTS: tuple[tuple[int, int, int], ...] = ((1, 2, 3), (4, 5, 6), (10, 11, 12), (7, 8, 9))
"""MANO joint numbers (1..15) of the MCP, PIP and DIP of the index, middle, ring and little
finger, in that anatomical order (MANO stores the little finger before the ring finger)."""

THUMB_JOINTS: tuple[int, int, int] = (13, 14, 15)
"""MANO joint numbers of the thumb's CMC, MCP and IP."""

_CASCADE = np.array([-0.06, 0.0, 0.05, 0.10])
_NEIGHBOUR_CORRELATION = 0.6


def _finger_noise(rng: np.random.Generator) -> np.ndarray:
    """(4,) unit-variance noise, correlation 0.6 between anatomical neighbours (AR(1) chain)."""
    r = _NEIGHBOUR_CORRELATION
    e = np.empty(4)
    e[0] = rng.standard_normal()
    for i in range(1, 4):
        e[i] = r * e[i - 1] + np.sqrt(1 - r * r) * rng.standard_normal()
    return e


def natural_hand_angles(rng=None, closure: float | tuple[float, float] = (0.0, 0.9),
                        side: str = "right", sigma: float = 0.12, point_prob: float = 0.1,
                        joint_noise_deg: float = 6.0) -> np.ndarray:
    """One natural hand pose from the synergy prior (see the module text).

    Args:
        rng: ``numpy.random.Generator`` or seed.
        closure: the hand's closure ``g`` (0 open, 1 fist), or a ``(lo, hi)`` range to draw it
            from uniformly.
        side: ``"right"`` or ``"left"``. A left hand's LCS frames are mirror images of the
            right's, so the same motion has mirrored angles
            ([`mirror_angles`][handmesh_tutorial.lcs.angles.mirror_angles]: abduction and twist
            negated); the same seed gives mirror-image hands.
        sigma: spread of the per-finger closures around ``g``.
        point_prob: probability that the index finger stays open (a pointing hand).
        joint_noise_deg: independent noise on each flexion angle, degrees.

    Returns:
        (15, 3) LCS angles in radians inside the anatomical limits
        ([`hand_joint_limits`][handmesh_tutorial.lcs.limits.hand_joint_limits]), MANO joint
        order 1..15.

    Raises:
        ValueError: closure outside [0, 1], an unknown side, or a negative ``sigma`` /
            ``joint_noise_deg``.
    """
    rng = np.random.default_rng(rng)
    lo, hi = (closure, closure) if np.isscalar(closure) else closure
    if not 0.0 <= lo <= hi <= 1.0:
        raise ValueError(f"closure must be in [0, 1] (or a range lo <= hi inside it), got "
                         f"{closure!r}")
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    if sigma < 0 or joint_noise_deg < 0 or not 0 <= point_prob <= 1:
        raise ValueError("sigma and joint_noise_deg must be >= 0 and point_prob in [0, 1]")
    g = float(rng.uniform(lo, hi))
    c = np.clip(g + _CASCADE + sigma * _finger_noise(rng), 0.0, 1.0)
    if rng.random() < point_prob:
        c[0] = 0.0
    deg = np.zeros((15, 3))
    noise = joint_noise_deg * rng.standard_normal((4, 2))
    spread = (1.0 - g) * rng.uniform(0.0, 1.0)           # fingers fan out when the hand opens
    # right hand: +x swings a finger towards the little finger, so the index spreads with -x
    fan = np.array([-1.0, -0.3, 0.4, 1.0]) * 12.0 * spread
    for f, (mcp, pip, _dip) in enumerate(FINGER_JOINTS):   # the DIP follows below
        deg[mcp - 1, 1] = -5.0 + 85.0 * c[f] + noise[f, 0]
        deg[mcp - 1, 0] = fan[f] + 3.0 * rng.standard_normal()
        deg[pip - 1, 1] = 3.0 + 97.0 * c[f] + noise[f, 1]
    o = float(np.clip(0.85 * g + 0.15 * rng.standard_normal(), 0.0, 1.0))
    cmc, tmcp, tip = THUMB_JOINTS
    deg[cmc - 1] = (8.0 * rng.standard_normal(), -10.0 + 45.0 * o, 8.0 * rng.standard_normal())
    deg[tmcp - 1, 1] = 5.0 + 40.0 * o + joint_noise_deg * rng.standard_normal()
    deg[tip - 1, 1] = 5.0 + 55.0 * o + joint_noise_deg * rng.standard_normal()
    lower, upper = hand_joint_limits("anatomical")
    angles = np.clip(np.deg2rad(deg), lower, upper)
    for dip, pip in DIP_FOLLOWS_PIP.items():                # the DIP follows its PIP
        angles[dip - 1, 1] = DIP_PIP_RATIO * angles[pip - 1, 1]
    if side == "left":  # (the anatomical limits are symmetric in x and z: still inside them)
        angles = mirror_angles(angles)
    return np.clip(angles, lower, upper)
