"""Local coordinate systems (LCS) per joint, joint-angle limits and random valid poses.

This is the paper's supplementary section "Mesh Movement via Local Coordinate Systems", exactly:
for every non-root joint ``j_i`` of a kinematic chain (rest pose),

* ``z_i`` = direction from the joint to its next point along the chain, ``j_{i+1} - j_i``;
* ``x_i`` = direction ``v_i - j_i`` to a mesh vertex ``v_i`` that follows the joint's flexion
  direction, projected onto the plane perpendicular to ``z_i``;
* ``y_i = z_i × x_i``;

all normalised, so ``F_i = [x_i | y_i | z_i]`` is a rotation matrix (right-handed, det +1).

**Angles.** A joint's articulation is three angles ``(a_x, a_y, a_z)`` in radians, one per LCS
axis, composed like the joint coordinate system of Grood & Suntay: flexion about the
proximal-fixed ``y``, then abduction about the floating ``x``, then twist about the bone's own
``z``: ``R(a) = R_y(a_y) · R_x(a_x) · R_z(a_z)`` (scipy ``from_euler("YXZ", (a_y, a_x, a_z))``).
Because a positive rotation about ``y`` turns ``z`` towards ``x`` (``R_y(θ) e_z = sin θ e_x +
cos θ e_z``) and ``x`` points to the flexion side (palmar for fingers), **positive ``a_y`` is
flexion**: the distal bone swings towards the palm. ``a_x`` swings it sideways (towards ``-y``
for positive angles), ``a_z`` spins it about itself. Only ``a_x`` may reach ±90° before the
decomposition becomes ambiguous, so flexion ranges beyond 90° (PIP 110°) round-trip exactly.

**Into the hand model.** MANO's pose of joint ``k`` is its rotation relative to the parent,
expressed in rest-pose axes. A rotation about the rest LCS axes is therefore
``R_k = F_k R(a) F_k^T``, and its axis-angle is simply ``F_k @ rotvec(R(a))``; that is what
[`Articulation.to_pose`][handmesh_tutorial.lcs.Articulation.to_pose] returns, ready for
``HandModel(pose=...)`` (and for [`ManoModel`][handmesh_tutorial.mano.model.ManoModel]).

**Which vertex (hand).** [`hand_lcs`][handmesh_tutorial.lcs.hand_lcs] picks ``v_i`` with a
deterministic rule on the rest mesh: (1) a target direction ``d_i`` = the palmar normal of the hand
for the four fingers, and for the thumb the palmar normal turned by ``thumb_flexion_angle`` (default
45°) towards the little finger (the thumb's pad faces obliquely across the palm); the palmar normal
is ``(index MCP - pinky MCP) × (middle MCP - wrist)`` for a right hand and its negative for a left
hand. (2) Candidates are vertices whose strongest skinning weight belongs to the joint or its parent
and which lie within ``slab`` (default 0.25) of the bone length from the joint's cross-section
plane. (3) The chosen vertex maximises the cosine between ``d_i`` and its offset from the joint
projected off ``z_i``. The ids are stored in ``Articulation.flexion_vertex_ids``.

**Limits** (degrees, per axis ``(x: abduction, y: flexion, z: twist)``), see
[`ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG] and
[`PAPER_LIMIT_DEG`][handmesh_tutorial.lcs.PAPER_LIMIT_DEG]. The paper's generator uses ±60° on every
axis (``limits="paper"``); ``limits="anatomical"`` uses one-sided flexion, small abduction and
(except at the thumb's CMC) almost no twist, rounded from commonly cited ranges of motion (finger
MCP 0–90° flexion and ±15° abduction, PIP 0–110°, DIP 0–90° as in Lin, Wu & Huang 2000, "Modeling
the constraints of human hand motion"; MCP hyperextension and thumb ranges rounded from clinical
range-of-motion tables such as the AAOS values). They are plausible defaults for sampling, not
measurements.

**Left hands.** If the left mesh is the mirror image of the right by a reflection ``M`` (the
library's hand negates z, [`mirror_points`][handmesh_tutorial.hand.skinning.mirror_points]),
the rule gives ``F_left = M F_right diag(1, -1, 1)``: ``z`` and ``x`` mirror, ``y`` flips to
stay right-handed (``(Mz) × (Mx) = -M (z × x)``). Then equal flexion angles give mirrored
poses, while ``a_x`` and ``a_z`` change sign
([`mirror_angles`][handmesh_tutorial.lcs.mirror_angles]). All limits on ``x`` and ``z`` are
symmetric, so the same table serves both sides.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "ANATOMICAL_LIMITS_DEG",
    "HAND_JOINT_KINDS",
    "PAPER_LIMIT_DEG",
    "Articulation",
    "clip_angles",
    "forward_kinematics",
    "hand_joint_limits",
    "hand_lcs",
    "lcs_angles_to_pose",
    "local_frames",
    "mirror_angles",
    "palm_normal",
    "pose_to_lcs_angles",
    "random_pose",
    "rotation_from_lcs_angles",
    "select_flexion_vertices",
    "within_limits",
]

PAPER_LIMIT_DEG = 60.0
"""The paper's limit: ±60° about every LCS axis (supplementary, step 4 of the generator)."""

ANATOMICAL_LIMITS_DEG: dict[str, tuple[tuple[float, float], ...]] = {
    "mcp": ((-15.0, 15.0), (-20.0, 90.0), (-5.0, 5.0)),
    "pip": ((0.0, 0.0), (0.0, 110.0), (0.0, 0.0)),
    "dip": ((0.0, 0.0), (0.0, 80.0), (0.0, 0.0)),
    "thumb_cmc": ((-30.0, 30.0), (-15.0, 45.0), (-30.0, 30.0)),
    "thumb_mcp": ((-10.0, 10.0), (-10.0, 60.0), (-5.0, 5.0)),
    "thumb_ip": ((0.0, 0.0), (-15.0, 80.0), (0.0, 0.0)),
}
"""Anatomical limits in degrees, ``(lower, upper)`` per axis ``x`` (abduction), ``y`` (flexion,
positive towards the palm), ``z`` (twist about the bone).
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

_EULER = "YXZ"  # intrinsic: flexion (y), then abduction (x), then twist (z)


# ---------------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------------
def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        bad = np.flatnonzero(n.reshape(-1) < 1e-12).tolist()
        raise ValueError(f"{what} has zero length for joint(s) {bad}")
    return v / n


def local_frames(joints, children, flexion_points) -> np.ndarray:
    """The paper's LCS of each joint, for any articulated mesh.

    Args:
        joints: (J,3) joint positions in the rest pose (metres).
        children: either (J,) int indices into ``joints`` of each joint's next joint along the
            chain, or (J,3) positions of that next point (e.g. a fingertip).
        flexion_points: (J,3) points (usually mesh vertices ``v_i``) whose direction from the
            joint follows the joint's flexion direction.

    Returns:
        (J,3,3) float64 rotation matrices whose *columns* are ``x``, ``y``, ``z``.

    Raises:
        ValueError: shapes disagree, a child coincides with its joint, or a flexion point lies
            on the joint's ``z`` axis.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 2 or joints.shape[1] != 3:
        raise ValueError(f"joints must have shape (J,3), got {joints.shape}")
    children = np.asarray(children)
    if children.ndim == 1 and np.issubdtype(children.dtype, np.integer):
        if children.shape[0] != len(joints) or children.min() < 0 or \
                children.max() >= len(joints):
            raise ValueError(f"children must be {len(joints)} indices in 0..{len(joints) - 1}, "
                             f"got {children.tolist()}")
        child_pts = joints[children]
    else:
        child_pts = np.asarray(children, dtype=np.float64)
    flex = np.asarray(flexion_points, dtype=np.float64)
    for name, arr in (("children", child_pts), ("flexion_points", flex)):
        if arr.shape != joints.shape:
            raise ValueError(f"{name} must have shape {joints.shape}, got {arr.shape}")
    z = _unit(child_pts - joints, "z (child - joint)")
    x_hat = flex - joints
    x = x_hat - np.sum(x_hat * z, -1, keepdims=True) * z  # projection onto the plane ⟂ z
    x = _unit(x, "x (flexion point projected off z)")
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def select_flexion_vertices(vertices, joints, child_points, directions, *, weights=None,
                            joint_ids=None, parents=None, slab: float = 0.25) -> np.ndarray:
    """Pick, per joint, the mesh vertex that best follows a flexion direction.

    The rule: among candidate vertices (dominant skinning joint is the joint or its parent, when
    ``weights`` are given; within ``slab`` x bone length of the joint's cross-section plane),
    take the one whose offset from the joint, projected off the bone axis, has the largest
    cosine with ``directions``. The constraints are dropped (weights first, then the slab) if
    they leave no candidate.

    Args:
        vertices: (V,3) rest-pose mesh vertices.
        joints: (J,3) joint positions.
        child_points: (J,3) next point along the chain of each joint (defines ``z``).
        directions: (J,3) desired flexion directions (need not be unit or ⟂ ``z``).
        weights: optional (V,K) skinning weights over the model's K joints.
        joint_ids: (J,) index of each joint among the K skinning joints (with ``weights``).
        parents: (K,) parent of each skinning joint (with ``weights``).
        slab: half-thickness of the candidate slab as a fraction of the bone length.

    Returns:
        (J,) int64 vertex ids.
    """
    verts = np.asarray(vertices, dtype=np.float64)
    joints = np.asarray(joints, dtype=np.float64)
    z = _unit(np.asarray(child_points, dtype=np.float64) - joints, "bone")
    bone = np.linalg.norm(np.asarray(child_points, dtype=np.float64) - joints, axis=-1)
    d = np.asarray(directions, dtype=np.float64)
    d = _unit(d - np.sum(d * z, -1, keepdims=True) * z, "flexion direction off z")
    if weights is not None and (joint_ids is None or parents is None):
        raise ValueError("select_flexion_vertices: weights need joint_ids and parents too")
    owner = None if weights is None else np.argmax(np.asarray(weights), axis=1)
    ids = np.empty(len(joints), dtype=np.int64)
    for i in range(len(joints)):
        off = verts - joints[i]
        along = off @ z[i]
        perp = off - along[:, None] * z[i]
        cos = (perp @ d[i]) / (np.linalg.norm(perp, axis=1) + 1e-12)
        in_slab = np.abs(along) <= slab * bone[i]
        masks = []
        if owner is not None:
            k = int(joint_ids[i])
            mine = (owner == k) | (owner == int(parents[k])) if parents[k] >= 0 else owner == k
            masks.append(mine & in_slab)
        masks += [in_slab, np.ones(len(verts), bool)]
        mask = next(m for m in masks if m.any())
        ids[i] = np.flatnonzero(mask)[np.argmax(cos[mask])]
    return ids


# ---------------------------------------------------------------------------------------------
# Angles <-> rotations <-> pose vectors
# ---------------------------------------------------------------------------------------------
def _check_angles(frames: np.ndarray, angles) -> np.ndarray:
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape[-2:] != (frames.shape[0], 3):
        raise ValueError(f"angles must have shape (..., {frames.shape[0]}, 3), "
                         f"got {angles.shape}")
    return angles


def _euler_rotation(angles: np.ndarray) -> Rotation:
    """scipy Rotation of R_y(a_y) R_x(a_x) R_z(a_z) for angles (N,3) ordered (a_x, a_y, a_z)."""
    return Rotation.from_euler(_EULER, angles[:, [1, 0, 2]])


def rotation_from_lcs_angles(frames, angles) -> np.ndarray:
    """Rotation matrices of joints turned by LCS angles, in rest-pose (parent) axes.

    Args:
        frames: (J,3,3) rest LCS, columns ``x, y, z``.
        angles: (..., J, 3) radians about ``(x, y, z)``, composed ``R_y R_x R_z``.

    Returns:
        (..., J, 3, 3) ``F_k R(a) F_k^T``.
    """
    frames = np.asarray(frames, dtype=np.float64)
    angles = _check_angles(frames, angles)
    local = _euler_rotation(angles.reshape(-1, 3)).as_matrix().reshape(*angles.shape, 3)
    return frames @ local @ np.swapaxes(frames, -1, -2)


def lcs_angles_to_pose(frames, angles) -> np.ndarray:
    """Axis-angle pose vectors (MANO convention) of LCS angles.

    Args:
        frames: (J,3,3) rest LCS.
        angles: (..., J, 3) radians.

    Returns:
        (..., J, 3) float64 axis-angle of ``F_k R(a) F_k^T`` (= ``F_k @ rotvec(R(a))``).
    """
    frames = np.asarray(frames, dtype=np.float64)
    angles = _check_angles(frames, angles)
    rotvec = _euler_rotation(angles.reshape(-1, 3)).as_rotvec().reshape(angles.shape)
    return np.einsum("jab,...jb->...ja", frames, rotvec)


def pose_to_lcs_angles(frames, pose) -> np.ndarray:
    """Inverse of [`lcs_angles_to_pose`][handmesh_tutorial.lcs.lcs_angles_to_pose] (exact while
    ``|a_x| < 90°``).

    Args:
        frames: (J,3,3) rest LCS.
        pose: (..., J, 3) axis-angle in rest-pose (parent) axes.

    Returns:
        (..., J, 3) radians ``(a_x, a_y, a_z)``; ``a_y`` and ``a_z`` in (-π, π].
    """
    frames = np.asarray(frames, dtype=np.float64)
    pose = _check_angles(frames, pose)
    local = np.einsum("jba,...jb->...ja", frames, pose)  # F^T rotvec
    eul = Rotation.from_rotvec(local.reshape(-1, 3)).as_euler(_EULER)
    return eul[:, [1, 0, 2]].reshape(pose.shape)


def mirror_angles(angles) -> np.ndarray:
    """Angles of the mirrored joint motion: ``(a_x, a_y, a_z) -> (-a_x, a_y, -a_z)``.

    With left frames built as mirror images of right ones (see the module text), right-hand
    angles ``a`` and left-hand angles ``mirror_angles(a)`` give mirror-image poses.
    """
    out = np.array(angles, dtype=np.float64, copy=True)
    out[..., 0] *= -1
    out[..., 2] *= -1
    return out


def clip_angles(angles, lower, upper) -> np.ndarray:
    """Clip angles (..., J, 3) to per-joint, per-axis limits ``lower``/``upper`` (J,3), radians."""
    return np.clip(np.asarray(angles, dtype=np.float64), lower, upper)


def within_limits(angles, lower, upper, atol: float = 1e-9) -> np.ndarray:
    """True where all 3J angles of a pose are inside the limits.

    Args:
        angles: (..., J, 3) radians.
        lower: (J,3) radians.
        upper: (J,3) radians.
        atol: tolerance in radians.

    Returns:
        bool array of shape ``angles.shape[:-2]``.
    """
    a = np.asarray(angles, dtype=np.float64)
    ok = (a >= np.asarray(lower) - atol) & (a <= np.asarray(upper) + atol)
    return ok.all(axis=(-2, -1))


def forward_kinematics(rest_joints, parents, rotations, root_rotation=None) -> np.ndarray:
    """Posed joint positions of a kinematic tree with MANO-convention local rotations.

    ``G_k = G_parent(k) · [R_k | j_k - j_parent(k)]``; the root keeps its position and turns by
    ``root_rotation``. Use it to predict where a child joint goes for given LCS angles.

    Args:
        rest_joints: (K,3) rest positions, parents before children.
        parents: (K,) parent indices, -1 for the root.
        rotations: (..., K, 3, 3) local rotations in rest axes (the root's entry is ignored when
            ``root_rotation`` is given).
        root_rotation: optional (..., 3, 3).

    Returns:
        (..., K, 3) posed positions.
    """
    rest = np.asarray(rest_joints, dtype=np.float64)
    rots = np.asarray(rotations, dtype=np.float64)
    if root_rotation is not None:
        rots = rots.copy()
        rots[..., 0, :, :] = root_rotation
    glob_r = [None] * len(rest)
    glob_t = [None] * len(rest)
    for k, p in enumerate(parents):
        if p < 0:
            glob_r[k] = rots[..., k, :, :]
            glob_t[k] = np.broadcast_to(rest[k], rots.shape[:-3] + (3,))
        else:
            glob_r[k] = glob_r[p] @ rots[..., k, :, :]
            glob_t[k] = glob_t[p] + np.einsum("...ab,b->...a", glob_r[p], rest[k] - rest[p])
    return np.stack(glob_t, axis=-2)


# ---------------------------------------------------------------------------------------------
# The articulation object
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Articulation:
    """Rest LCS and per-axis limits of J articulated joints.

    Attributes:
        names: (J,) joint names.
        joints: (J,3) rest positions, metres.
        frames: (J,3,3) rest LCS, columns ``x`` (flexion side), ``y = z × x``, ``z`` (to child).
        lower: (J,3) lower limits, radians, axis order ``x, y, z``.
        upper: (J,3) upper limits, radians.
        child_points: (J,3) the next point along the chain of each joint.
        flexion_points: (J,3) the points that defined ``x`` (mesh vertices for a hand).
        flexion_vertex_ids: (J,) ids of those vertices, or ``None``.
        joint_ids: (J,) index of each joint in its model's kinematic tree (1..15 for a hand).
        side: ``"right"``, ``"left"`` or ``None`` (objects).
        limits_name: ``"paper"``, ``"anatomical"`` or ``"custom"``.
    """

    names: tuple
    joints: np.ndarray
    frames: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    child_points: np.ndarray
    flexion_points: np.ndarray
    flexion_vertex_ids: np.ndarray | None = None
    joint_ids: np.ndarray | None = None
    side: str | None = None
    limits_name: str = "custom"

    @property
    def num_joints(self) -> int:
        """Number of articulated joints J."""
        return len(self.names)

    def rotations(self, angles) -> np.ndarray:
        """(..., J, 3, 3) local rotations (rest axes) of LCS angles (..., J, 3) radians."""
        return rotation_from_lcs_angles(self.frames, angles)

    def to_pose(self, angles) -> np.ndarray:
        """(..., J, 3) float32 axis-angle pose (MANO convention) of LCS angles, radians."""
        return lcs_angles_to_pose(self.frames, angles).astype(np.float32)

    def from_pose(self, pose) -> np.ndarray:
        """(..., J, 3) LCS angles (radians) of an axis-angle pose."""
        return pose_to_lcs_angles(self.frames, pose)

    def clip(self, angles) -> np.ndarray:
        """Angles clipped to this articulation's limits."""
        return clip_angles(angles, self.lower, self.upper)

    def within_limits(self, angles, atol: float = 1e-9) -> np.ndarray:
        """Bool (...) whether every angle lies within the limits."""
        return within_limits(angles, self.lower, self.upper, atol)

    def with_limits(self, limits) -> Articulation:
        """A copy with other limits: ``"paper"``, ``"anatomical"`` (hands) or ``(lower, upper)``
        arrays (J,3) in radians."""
        lower, upper, name = _resolve_limits(limits, self)
        return replace(self, lower=lower, upper=upper, limits_name=name)

    def random_angles(self, rng=None, n: int | None = None, scale: float = 1.0) -> np.ndarray:
        """Uniform angles inside the limits scaled by ``scale`` about zero.

        Args:
            rng: ``numpy.random.Generator`` or seed.
            n: number of poses; ``None`` returns a single (J,3) array.
            scale: in [0,1]; each range shrinks towards its neutral angle (0, or the nearest
                limit when 0 is outside), so the result always respects the limits.

        Returns:
            (J,3) or (n,J,3) radians.
        """
        if not 0.0 <= scale <= 1.0:
            raise ValueError(f"scale must be in [0, 1], got {scale}")
        rng = np.random.default_rng(rng)
        shape = (self.num_joints, 3) if n is None else (n, self.num_joints, 3)
        # Shrink each range towards its neutral angle (0, or the nearest limit if 0 is outside).
        neutral = np.clip(0.0, self.lower, self.upper)
        lo = neutral + scale * (self.lower - neutral)
        hi = neutral + scale * (self.upper - neutral)
        return rng.uniform(lo, hi, size=shape)

    def random_pose(self, rng=None, n: int | None = None, scale: float = 1.0) -> np.ndarray:
        """Random valid pose vectors:
        [`random_angles`][handmesh_tutorial.lcs.Articulation.random_angles] through
        [`to_pose`][handmesh_tutorial.lcs.Articulation.to_pose].

        Returns:
            (J,3) or (n,J,3) float32 axis-angle, ready for ``HandModel(pose=...)``.
        """
        return self.to_pose(self.random_angles(rng, n, scale))


def hand_joint_limits(limits: str = "anatomical") -> tuple[np.ndarray, np.ndarray]:
    """Per-axis limits of the 15 articulated hand joints (MANO order), radians.

    Args:
        limits: ``"paper"`` (±60° everywhere) or ``"anatomical"``
            ([`ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG]).

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


# ---------------------------------------------------------------------------------------------
# Hands
# ---------------------------------------------------------------------------------------------
def _np(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def palm_normal(joints21, side: str) -> np.ndarray:
    """Unit palmar normal of a hand from its 21 FreiHAND-order keypoints (rest pose).

    ``(index MCP - pinky MCP) × (middle MCP - wrist)`` points out of the palm of a right hand
    (radial × distal); a left hand uses the negative.
    """
    j = _np(joints21)
    n = np.cross(j[5] - j[17], j[9] - j[0])
    n = n / np.linalg.norm(n)
    return n if side == "right" else -n


def hand_lcs(model, limits="anatomical", *, thumb_flexion_angle: float = 45.0,
             slab: float = 0.25) -> Articulation:
    """The LCS of the 15 articulated joints of a hand model, in MANO joint order 1..15.

    Works for [`HandModel`][handmesh_tutorial.hand.model.HandModel] and
    [`ManoModel`][handmesh_tutorial.mano.model.ManoModel]
    (anything with ``side``, ``template_vertices``, ``skinning_weights``, ``parents`` and a
    zero-pose call returning ``joints`` (FreiHAND order) and ``joints_mano``).

    Args:
        model: the hand model (its rest pose, zero shape, is used).
        limits: ``"anatomical"`` (default), ``"paper"`` or ``(lower, upper)`` (15,3) radians.
        thumb_flexion_angle: degrees the thumb's flexion direction is turned from the palmar
            normal towards the little finger.
        slab: candidate slab of the vertex rule (fraction of the bone length).

    Returns:
        An [`Articulation`][handmesh_tutorial.lcs.Articulation] whose ``to_pose`` output is the
        model's ``pose`` (15,3).
    """
    from . import hand as _hand

    side = getattr(model, "side", "right")
    out = model()
    j21 = _np(out.joints)[0]
    j16 = _np(out.joints_mano)[0]
    m2f = _mano_to_freihand_16(_hand)
    fparents = np.asarray(_hand.FREIHAND_PARENTS)
    child_kp = np.array([int(np.flatnonzero(fparents == m2f[k])[0]) for k in range(1, 16)])
    joints = j16[1:]
    child_points = j21[child_kp]

    n = palm_normal(j21, side)
    radial = j21[5] - j21[17]
    ulnar = -radial / np.linalg.norm(radial)
    t = np.deg2rad(thumb_flexion_angle)
    thumb_dir = np.cos(t) * n + np.sin(t) * ulnar
    directions = np.array([thumb_dir if k.startswith("thumb") else n for k in HAND_JOINT_KINDS])
    verts = _np(model.template_vertices)
    ids = select_flexion_vertices(verts, joints, child_points, directions,
                                  weights=_np(model.skinning_weights),
                                  joint_ids=np.arange(1, 16), parents=np.asarray(model.parents),
                                  slab=slab)
    frames = local_frames(joints, child_points, verts[ids])
    lower, upper, name = _resolve_limits(limits, None)
    names = tuple(_hand.MANO_JOINT_NAMES[1:16])
    return Articulation(names=names, joints=joints, frames=frames, lower=lower, upper=upper,
                        child_points=child_points, flexion_points=verts[ids],
                        flexion_vertex_ids=ids, joint_ids=np.arange(1, 16), side=side,
                        limits_name=name)


def _mano_to_freihand_16(hand_module) -> np.ndarray:
    """(16,) FreiHAND keypoint index of each MANO joint."""
    m2f = np.asarray(hand_module.MANO_TO_FREIHAND)
    if m2f.shape == (16,):
        return m2f.astype(np.int64)
    if m2f.shape == (21,):  # FreiHAND i <- row m2f[i] of [16 joints, 5 tips]
        out = np.empty(16, dtype=np.int64)
        for i, r in enumerate(m2f):
            if r < 16:
                out[r] = i
        return out
    raise ValueError(f"hand.MANO_TO_FREIHAND has unexpected shape {m2f.shape}")


def random_pose(model_or_lcs, rng=None, n: int | None = None, limits=None,
                scale: float = 1.0) -> np.ndarray:
    """Random pose vectors whose LCS angles respect the limits.

    Args:
        model_or_lcs: an [`Articulation`][handmesh_tutorial.lcs.Articulation] or a hand model (then
            [`hand_lcs`][handmesh_tutorial.lcs.hand_lcs] is built).
        rng: ``numpy.random.Generator`` or seed (same seed -> same bytes).
        n: number of poses; ``None`` returns one (15,3) pose.
        limits: ``None`` (keep the articulation's; ``"anatomical"`` for a model), ``"paper"``,
            ``"anatomical"`` or ``(lower, upper)`` arrays.
        scale: shrink every range towards 0 (1 = full range).

    Returns:
        (J,3) or (n,J,3) float32 axis-angle poses (MANO convention).
    """
    art = model_or_lcs if isinstance(model_or_lcs, Articulation) else \
        hand_lcs(model_or_lcs, limits or "anatomical")
    if limits is not None:
        art = art.with_limits(limits)
    return art.random_pose(rng, n, scale)
