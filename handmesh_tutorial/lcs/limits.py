"""Joint-angle limits of the hand: the paper's ±60° and anatomical ranges, DIP-PIP coupling.

Limits are ``(lower, upper)`` per joint and per LCS axis ``x`` (abduction), ``y`` (flexion,
positive towards the palm), ``z`` (twist), in degrees in the tables and radians in the arrays
(15,3) that [`hand_joint_limits`][handmesh_tutorial.lcs.limits.hand_joint_limits] returns.

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .articulation import Articulation

__all__ = [
    "PAPER_LIMIT_DEG", "ANATOMICAL_LIMITS_DEG", "DIP_PIP_RATIO", "DIP_FOLLOWS_PIP",
    "hand_joint_limits",
]

PAPER_LIMIT_DEG = 60.0
"""The paper's limit: ±60° about every LCS axis (supplementary, step 4 of the generator)."""

# Sideways and twist range (±, degrees) of the hinge joints (PIP, DIP, thumb IP) in
# ANATOMICAL_LIMITS_DEG: the few degrees by which a flexion about the joint's true axis reads as
# abduction and twist in its LCS (up to 10° at full flexion for the hand's own poses).
_HINGE_PLAY_DEG: float = 10.0

ANATOMICAL_LIMITS_DEG: dict[str, tuple[tuple[float, float], ...]] = {
    "mcp": ((-15.0, 15.0), (-20.0, 90.0), (-10.0, 10.0)),
    "pip": ((-_HINGE_PLAY_DEG, _HINGE_PLAY_DEG), (0.0, 110.0), (-_HINGE_PLAY_DEG, _HINGE_PLAY_DEG)),
    "dip": ((-_HINGE_PLAY_DEG, _HINGE_PLAY_DEG), (0.0, 80.0), (-_HINGE_PLAY_DEG, _HINGE_PLAY_DEG)),
    "thumb_cmc": ((-30.0, 30.0), (-15.0, 60.0), (-30.0, 30.0)),
    "thumb_mcp": ((-15.0, 15.0), (-10.0, 60.0), (-5.0, 5.0)),
    "thumb_ip": ((-_HINGE_PLAY_DEG, _HINGE_PLAY_DEG), (-15.0, 80.0),
                 (-_HINGE_PLAY_DEG, _HINGE_PLAY_DEG)),
}
"""Anatomical limits in degrees, ``(lower, upper)`` per axis ``x`` (abduction), ``y`` (flexion,
positive towards the palm), ``z`` (twist about the bone).

The hinges (PIP, DIP, thumb IP) flex about one axis, but their sideways and twist ranges are
±10°, not 0: the LCS ``x`` axis comes from one mesh vertex that only
"approximately follows the flexion direction" (the paper's words), so a hinge's true axis is
a few degrees off ``y`` and any pose not made from these angles (the hand's own
[`example_pose`][handmesh_tutorial.hand.poses.example_pose] and
[`random_pose`][handmesh_tutorial.hand.poses.random_pose], a MANO fit) reads as a little
abduction and twist there; a zero-width range refused every such pose. For the same reason the
finger MCPs twist ±10° (a fist's 80° of flexion reads as up to 8°) and the thumb's MCP moves
±15° sideways (radial/ulnar deviation, 10-20° in clinical tables). The thumb's CMC flexes
up to 60°: its LCS flexion direction is the opposition direction (the palmar normal turned 45°
towards the little finger), which combines CMC flexion and palmar abduction (70° in clinical
tables). Neither change moves a hand of the default generator (natural poses never reach
these bounds); ``poses="uniform"`` under anatomical limits draws from the wider ranges.
"""

DIP_PIP_RATIO: float = 2.0 / 3.0
"""DIP flexion = this fraction of the PIP flexion under anatomical limits: the distal joint of a
finger is driven by the same tendons as the middle one and follows it (about 2/3, Rijpkema & Girard
1991; the constraint common in hand animation and tracking).
"""

DIP_FOLLOWS_PIP: dict[int, int] = {3: 2, 6: 5, 9: 8, 12: 11}
"""Coupled joints of the hand under anatomical limits: ``{DIP node: PIP node}`` (MANO nodes
1..15; the thumb's IP stays independent).
"""

HAND_JOINT_KINDS: tuple[str, ...] = (
    ("mcp", "pip", "dip") * 4 + ("thumb_cmc", "thumb_mcp", "thumb_ip"))
"""Kind of each of the 15 articulated MANO joints (MANO order 1..15: index, middle, pinky, ring,
thumb; three joints each).
"""

def hand_joint_limits(limits: str = "anatomical") -> tuple[np.ndarray, np.ndarray]:
    """Per-axis limits of the 15 articulated hand joints (MANO order), radians.

    Args:
        limits: ``"paper"`` (±60° everywhere) or ``"anatomical"``
            ([`ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.limits.ANATOMICAL_LIMITS_DEG]).

    Returns:
        ``(lower, upper)``, each (15,3) radians, axis order ``x, y, z``.
    """
    if limits == "paper":
        lim = np.full((15, 3), np.deg2rad(PAPER_LIMIT_DEG))
        return -lim, lim.copy()
    if limits == "anatomical":
        table = np.array([ANATOMICAL_LIMITS_DEG[k] for k in HAND_JOINT_KINDS])  # (15,3,2)
        return np.deg2rad(table[..., 0]), np.deg2rad(table[..., 1])
    raise ValueError(f"limits must be 'paper' or 'anatomical', got {limits!r}")


def _resolve_limits(limits, art: Articulation | None):
    if isinstance(limits, str):
        if art is not None and art.num_joints != 15:
            if limits == "paper":
                lim = np.full((art.num_joints, 3), np.deg2rad(PAPER_LIMIT_DEG))
                return -lim, lim.copy(), "paper"
            raise ValueError(f"named limits {limits!r} are defined for the 15 hand joints; "
                             f"give (lower, upper) arrays for {art.num_joints} joints")
        lower, upper = hand_joint_limits(limits)
        return lower, upper, limits
    lower, upper = (np.asarray(a, dtype=np.float64) for a in limits)
    n = 15 if art is None else art.num_joints
    if lower.shape != (n, 3) or upper.shape != (n, 3) or np.any(lower > upper):
        raise ValueError(f"custom limits must be two ({n},3) arrays with lower <= upper, got "
                         f"{lower.shape} and {upper.shape}")
    return lower, upper, "custom"
