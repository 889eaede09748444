"""The INTER-SH interaction generator: the paper's six-step algorithm (supplementary,
"Generating Mesh Interactions"), for hand-hand, hand-object and hand-chain scenes.

1. **Centre body.** A hand at a random valid pose (LCS angles inside the limits, no self-collision)
   and random rotation, a static object
   ([`objects.make_object`][handmesh_tutorial.objects.make_object]) or an articulated chain of rings
   ([`objects.make_chain`][handmesh_tutorial.objects.make_chain]), at the scene centre.
2. **Second hand.** A hand in the neutral (flat) pose whose palm faces the centre body, far
   enough along a random approach direction ``u`` that the two cannot collide.
3. **Approach.** The second hand moves towards the centre in steps of ``approach_step``
   (2 mm) until its cylinders first collide; it backs off to the last valid position.
4. **Joint moves.** Every joint of every dynamic body (both hands, the chain links) gets a random
   direction in its LCS-angle space and turns along it in increments of ``joint_step_deg`` (2
   degrees) until a collision with another body, a self-collision, or its limit stops it, backing
   off to the last valid angle. The default limits are anatomical (``limits="anatomical"``,
   [`handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG]:
   one-sided flexion, little abduction and twist), which give natural poses; the paper's ±60 degrees
   about every axis (fingers bent backwards and twisted) is ``limits="paper"``
   (``handmesh generate --limits paper``).
5. **Repeat.** Joints move in turn, at most ``sweep_deg`` per round, until no joint can make a
   valid move (stop reason ``"no valid move"``) or ``max_rounds`` rounds have run
   (``"max rounds"``).
6. **Render** ([`make_sample`][handmesh_tutorial.interact.make_sample]): a camera framed on the
   target hand like a FreiHAND crop ([`frame_camera`][handmesh_tutorial.interact.frame_camera]: the
   hand wholly inside, 45-75 % of the image side), random lights of random colour temperature
   ([`scene_lights`][handmesh_tutorial.interact.scene_lights]), a natural photograph or a procedural
   texture behind
   ([`handmesh_tutorial.render.scene_background`][handmesh_tutorial.render.scene_background]); scene
   image, label mask, every body alone, visibility ratios.

Validity is decided on the collision cylinders
([`handmesh_tutorial.collision`][handmesh_tutorial.collision]), as in the paper; each body is a rig
of rigid cylinders attached to the nodes of its kinematic tree, and all candidate angles of one
joint are tested in one vectorised call (bounding spheres, then capsules, then the exact
Ketchel-Larochelle test on the survivors).

**Deviations from the paper.** (a) *Settle (step 5b)*: cylinders approximate the meshes only to a
few millimetres (radii are the 95th percentile of the vertex distances, see
[`collision.hand_cylinders`][handmesh_tutorial.collision.hand_cylinders]; round palm cylinders stick
out of the flat palm), so after step 5 the generator measures the *meshes*
([`mesh_contact`][handmesh_tutorial.interact.mesh_contact]: vertex-to-surface distances with exact
inside/outside signs) and translates the second body along ``u`` until the meshes touch (gap <=
``contact_tol``) without interpenetrating by more than ``penetration_tol``. Both numbers end up in
the scene ``stats`` (mm). (b) *Re-approach* (``reapproach``): after every round of joint moves the
second hand is pushed towards the centre again until its cylinders touch (step 3 repeated), so
contacts lost by joint moves are restored.

Further choices the paper leaves open, all in
[`InteractionConfig`][handmesh_tutorial.interact.InteractionConfig]: a joint's random direction has
per-axis weights ``axis_weights`` (abduction, flexion, twist) and flexes rather than extends with
probability ``flexion_bias``; the centre hand's random pose uses ``init_pose_scale`` of the range; a
joint stops for good once it is blocked (by contact or limit), which is what makes "no valid move"
reachable.

Everything is seeded: the same seed gives the same scene, to the byte.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from .collision import Cylinders, cylinders_intersect, self_collisions
from .dataset import KINDS, SampleRejected

__all__ = [
    "FRAME_FOCAL",
    "FRAME_MARGIN",
    "FRAME_SHARE",
    "KINDS",
    "MAX_IMAGE_SIZE",
    "MIN_IMAGE_SIZE",
    "STOP_REASONS",
    "InteractionConfig",
    "InteractionError",
    "Scene",
    "SceneBody",
    "build_scene",
    "camera_pose",
    "frame_camera",
    "closest_points_on_triangles",
    "generate_interactions",
    "get_renderer",
    "init_worker",
    "make_sample",
    "mesh_contact",
    "render_scene",
    "scene_lights",
    "signed_distance",
]


STOP_REASONS: tuple[str, ...] = ("no valid move", "max rounds")
"""Why the joint-move loop (steps 4-5) stopped."""


class InteractionError(RuntimeError, SampleRejected):
    """A scene could not be generated (bounded retries exhausted or an impossible config).

    A [`SampleRejected`][handmesh_tutorial.dataset.SampleRejected]:
    [`generate_interactions`][handmesh_tutorial.interact.generate_interactions] and
    [`generate_dataset`][handmesh_tutorial.dataset.generate_dataset] replace the seed with the next
    attempt's.

    Attributes:
        kind: the scene kind.
        seed: the seed of the scene.
        reason: what failed.
    """

    def __init__(self, kind: str, seed: Any, reason: str):
        self.kind, self.seed, self.reason = kind, seed, reason
        super().__init__(f"cannot generate a {kind!r} scene for seed {seed}: {reason}")

    def __reduce__(self):
        # Rebuild from the three fields: a worker process raising it must reach the parent intact.
        return (type(self), (self.kind, self.seed, self.reason))


@dataclass(frozen=True)
class InteractionConfig:
    """Parameters of the generator (lengths in metres, angles in degrees).

    Attributes:
        limits: joint limits of the hands: ``"anatomical"`` (default,
            [`lcs.ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG]: natural
            poses) or ``"paper"`` (±60° about every LCS axis, the paper's generator).
        approach_step: step of the approach (step 3), metres.
        joint_step_deg: angular increment of a joint move (step 4), degrees.
        sweep_deg: largest rotation of one joint per round, degrees (joints take turns).
        max_rounds: bound on the rounds of step 5.
        init_pose_scale: the centre hand's random pose uses this fraction of each joint range.
        axis_weights: scale of a joint's random direction about its LCS ``(x, y, z)`` axes
            (abduction, flexion, twist).
        flexion_bias: probability that a hand joint's direction flexes (rather than extends).
        shape_scale: scales the adult shape ranges of
            [`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.SHAPE_SAMPLE_RANGES] (0 = every hand
            average).
        lateral_offset: spread of the aim point on the second hand (palm plane), metres.
        contact_tol: the settle step closes mesh gaps larger than this, metres.
        penetration_tol: the settle step backs off mesh penetrations deeper than this, metres.
        settle: run the mesh-level settle step (deviation from the paper, see the module text).
        reapproach: after every round of joint moves, move the second hand towards the centre
            again until its cylinders touch (step 3 repeated; deviation, see the module text).
        max_attempts: scene candidates (approach directions, initial poses) before giving up.
        chain_links: inclusive range of the number of chain links.
        object_kinds: static object kinds to draw from (``None``: all of
            [`handmesh_tutorial.objects.OBJECT_KINDS`][handmesh_tutorial.objects.OBJECT_KINDS]).
    """

    limits: str = "anatomical"
    approach_step: float = 0.002
    joint_step_deg: float = 2.0
    sweep_deg: float = 30.0
    max_rounds: int = 12
    init_pose_scale: float = 0.5
    axis_weights: tuple[float, float, float] = (0.3, 1.0, 0.15)
    flexion_bias: float = 0.9
    shape_scale: float = 1.0
    lateral_offset: float = 0.025
    contact_tol: float = 0.0015
    penetration_tol: float = 0.0015
    settle: bool = True
    reapproach: bool = True
    max_attempts: int = 20
    chain_links: tuple[int, int] = (3, 5)
    object_kinds: tuple[str, ...] | None = None

    def __post_init__(self):
        if self.limits not in ("paper", "anatomical"):
            raise ValueError(f"limits must be 'paper' or 'anatomical', got {self.limits!r}")
        for name in ("approach_step", "joint_step_deg", "sweep_deg", "contact_tol",
                     "penetration_tol"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.max_rounds < 1 or self.max_attempts < 1:
            raise ValueError("max_rounds and max_attempts must be >= 1")
        if not 0 <= self.init_pose_scale <= 1 or not 0 <= self.flexion_bias <= 1:
            raise ValueError("init_pose_scale and flexion_bias must be in [0, 1]")
        if len(self.axis_weights) != 3 or min(self.axis_weights) < 0:
            raise ValueError(f"axis_weights must be 3 non-negative numbers, got "
                             f"{self.axis_weights}")
        lo, hi = self.chain_links
        if not 2 <= lo <= hi:
            raise ValueError(f"chain_links must be (lo, hi) with 2 <= lo <= hi, got "
                             f"{self.chain_links}")


# ---------------------------------------------------------------------------------------------
# Articulated rigs: rigid cylinders attached to the nodes of a kinematic tree
# ---------------------------------------------------------------------------------------------
def _segment_closest(p0, p1, q0, q1):
    """Squared distances and closest parameters ``(d2, s, t)`` of segments ``p0p1``, ``q0q1``
    (N,3), none degenerate (Ericson, *Real-Time Collision Detection*, 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = (d1 * d1).sum(1), (d2 * d2).sum(1)
    b, c, f = (d1 * d2).sum(1), (d1 * r).sum(1), (d2 * r).sum(1)
    denom = a * e - b * b
    s = np.where(denom > 1e-12 * a * e, np.clip((b * f - c * e) / np.maximum(denom, 1e-300), 0, 1),
                 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    w = r + d1 * s[:, None] - d2 * t[:, None]
    return (w * w).sum(1), s, t


def _pair_stages(a0, a1, ra, b0, b1, rb):
    """Cheap stages of the cylinder test for aligned pairs (N,3),(N,3),(N,).

    1. bounding spheres; 2. capsules (a capsule contains its cylinder: a capsule miss is a
    cylinder miss); 3. a *certain hit*: when the closest points of the two axes are interior to
    both segments and closer than ``ra + rb``, the point of the common normal at ``ra`` from axis
    A lies inside both solids.

    Returns:
        ``(sure, maybe)``: (N,) bool certain hits, and the indices of the capsule hits that
        still need the exact test.
    """
    sure = np.zeros(len(a0), bool)
    da, db = a1 - a0, b1 - b0
    reach = 0.5 * (np.sqrt((da * da).sum(1)) + np.sqrt((db * db).sum(1))) + ra + rb
    dc = 0.5 * (a0 + a1 - b0 - b1)
    idx = np.flatnonzero((dc * dc).sum(1) <= reach * reach)
    if idx.size == 0:
        return sure, idx
    d2, s, t = _segment_closest(a0[idx], a1[idx], b0[idx], b1[idx])
    rs = ra[idx] + rb[idx]
    cap = d2 <= (rs + 1e-9) ** 2
    ok = cap & (s > 0) & (s < 1) & (t > 0) & (t < 1) & (d2 <= rs * rs)
    sure[idx[ok]] = True
    return sure, idx[cap & ~ok]


def _pair_hits(a0, a1, ra, b0, b1, rb) -> np.ndarray:
    """(N,) exact cylinder test of aligned pairs: `_pair_stages`, then
    [`collision.cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect]
    (Ketchel-Larochelle) on the undecided pairs."""
    hit, maybe = _pair_stages(a0, a1, ra, b0, b1, rb)
    if maybe.size:
        hit[maybe] = cylinders_intersect(a0[maybe], a1[maybe], ra[maybe], b0[maybe], b1[maybe],
                                         rb[maybe])
    return hit


class _Rig:
    """A body as a kinematic tree of nodes carrying rigid cylinders (numpy, fast).

    Node 0 is the root, placed by ``(root_R, root_P)`` (its world rotation and position).
    Articulated node ``k >= 1`` turns by ``F R(a) F^T`` about its rest position relative to its
    parent (the convention of [`handmesh_tutorial.lcs`][handmesh_tutorial.lcs]), so for node ``k``:
    ``G_k = G_parent L_k`` and ``P_k = P_parent + G_parent (rest_k - rest_parent)``; a rest point
    ``x`` attached to node ``k`` is at ``G_k (x - rest_k) + P_k``.
    """

    def __init__(self, rest, parents, frames, lower, upper, cylinders: Cylinders, attach,
                 root_R=None, root_P=None, followers: dict | None = None):
        # followers {node: (leader node, ratio)}: the node's flexion (y) angle is ``ratio`` times
        # its leader's and it has no freedom of its own (a finger's DIP following its PIP)
        self.followers = dict(followers or {})
        self.leads = {lead: (node, ratio) for node, (lead, ratio) in self.followers.items()}
        self.rest = np.asarray(rest, float)
        self.parents = np.asarray(parents, int)
        n = len(self.rest)
        self.frames = np.asarray(frames, float).reshape(n - 1, 3, 3)
        self.lower = np.asarray(lower, float).reshape(n - 1, 3)
        self.upper = np.asarray(upper, float).reshape(n - 1, 3)
        self.angles = np.zeros((n - 1, 3))
        self.local = np.tile(np.eye(3), (n, 1, 1))
        self.rest_cyl = cylinders
        self.attach = np.asarray(attach, int)
        self.radius = cylinders.radius.copy()
        self.off0 = cylinders.p0 - self.rest[self.attach]
        self.off1 = cylinders.p1 - self.rest[self.attach]
        children = [[] for _ in range(n)]
        for k in range(1, n):
            children[self.parents[k]].append(k)
        self.subtree = []
        for k in range(n):
            order, stack = [], [k]
            while stack:
                m = stack.pop(0)
                order.append(m)
                stack.extend(children[m])
            self.subtree.append(np.array(order))
        # per node: the cylinders that move with it, and the non-adjacent (moved, static) pairs
        # whose intersection is a self-collision
        adj = {(int(i), int(j)) for i, j in cylinders.adjacent}
        self.moved = []
        self.self_pairs = []
        for k in range(n):
            mv = np.flatnonzero(np.isin(self.attach, self.subtree[k]))
            st = np.setdiff1d(np.arange(len(self.attach)), mv)
            pairs = [(a, b) for a in mv for b in st if (min(a, b), max(a, b)) not in adj]
            p = np.array(pairs, int).reshape(-1, 2)
            pos = {int(c): i for i, c in enumerate(mv)}
            self.moved.append(mv)
            self.self_pairs.append((np.array([pos[a] for a in p[:, 0]], int), p[:, 1]))
        self.root_R = np.eye(3) if root_R is None else np.asarray(root_R, float)
        self.root_P = self.rest[0].copy() if root_P is None else np.asarray(root_P, float)
        self.update()

    @property
    def num_joints(self) -> int:
        return len(self.rest) - 1

    def place(self, R, P) -> None:
        self.root_R, self.root_P = np.asarray(R, float), np.asarray(P, float)
        self.update()

    def set_angles(self, angles) -> None:
        from .lcs import rotation_from_lcs_angles

        self.angles = np.array(angles, float).reshape(self.num_joints, 3)
        for node, (lead, ratio) in self.followers.items():
            self.angles[node - 1] = [0.0, ratio * self.angles[lead - 1, 1], 0.0]
        if self.num_joints:
            self.local[1:] = rotation_from_lcs_angles(self.frames, self.angles)
        self.update()

    def set_joint(self, node: int, angles) -> None:
        """Set the LCS angles (3,) of one articulated node (1..J) and update the pose."""
        from .lcs import rotation_from_lcs_angles

        a = np.asarray(angles, float).reshape(1, 3)
        self.angles[node - 1] = a[0]
        self.local[node] = rotation_from_lcs_angles(self.frames[node - 1:node], a)[0]
        if node in self.leads:
            f, ratio = self.leads[node]
            fa = np.array([[0.0, ratio * a[0, 1], 0.0]])
            self.angles[f - 1] = fa[0]
            self.local[f] = rotation_from_lcs_angles(self.frames[f - 1:f], fa)[0]
        self.update()

    def update(self) -> None:
        n = len(self.rest)
        G = np.empty((n, 3, 3))
        P = np.empty((n, 3))
        G[0], P[0] = self.root_R @ self.local[0], self.root_P
        for k in range(1, n):
            p = self.parents[k]
            G[k] = G[p] @ self.local[k]
            P[k] = P[p] + G[p] @ (self.rest[k] - self.rest[p])
        self.G, self.P = G, P
        Ga = G[self.attach]
        self.p0 = np.einsum("cab,cb->ca", Ga, self.off0) + P[self.attach]
        self.p1 = np.einsum("cab,cb->ca", Ga, self.off1) + P[self.attach]

    def translate(self, d) -> None:
        d = np.asarray(d, float)
        self.root_P = self.root_P + d
        self.P = self.P + d
        self.p0 = self.p0 + d
        self.p1 = self.p1 + d

    def cylinders(self) -> Cylinders:
        c = self.rest_cyl
        return Cylinders(self.p0.copy(), self.p1.copy(), self.radius.copy(), c.names, c.parts,
                         c.adjacent)

    def to_world(self, points, node: int = 0) -> np.ndarray:
        """Rest points attached to ``node`` -> world."""
        return (np.asarray(points) - self.rest[node]) @ self.G[node].T + self.P[node]

    def candidates(self, node: int, angles) -> tuple[np.ndarray, np.ndarray]:
        """World end points (K, Cm, 3) of the cylinders moving with ``node`` for K angle sets."""
        from .lcs import rotation_from_lcs_angles

        A = np.asarray(angles, float).reshape(-1, 1, 3)
        K = len(A)
        Lk = rotation_from_lcs_angles(self.frames[node - 1:node], A)[:, 0]  # (K,3,3)
        follower = self.leads.get(node)
        if follower is not None:
            f, ratio = follower
            Af = np.zeros_like(A)
            Af[..., 1] = ratio * A[..., 1]
            Lf = rotation_from_lcs_angles(self.frames[f - 1:f], Af)[:, 0]
        G = {}
        P = {}
        for m in self.subtree[node]:
            p = self.parents[m]
            if m == node:
                G[m] = self.G[p] @ Lk
                P[m] = np.broadcast_to(self.P[m], (K, 3))
            elif follower is not None and m == follower[0]:
                G[m] = G[p] @ Lf
                P[m] = P[p] + G[p] @ (self.rest[m] - self.rest[p])
            else:
                G[m] = G[p] @ self.local[m]
                P[m] = P[p] + G[p] @ (self.rest[m] - self.rest[p])
        mv = self.moved[node]
        Gs = np.stack([G[a] for a in self.attach[mv]], 1)  # (K,Cm,3,3)
        Ps = np.stack([P[a] for a in self.attach[mv]], 1)  # (K,Cm,3)
        q0 = np.einsum("kcab,cb->kca", Gs, self.off0[mv]) + Ps
        q1 = np.einsum("kcab,cb->kca", Gs, self.off1[mv]) + Ps
        return q0, q1

    def self_collides(self) -> bool:
        return len(self_collisions(self.cylinders())[0]) > 0


def _collides(a: _Rig, b: _Rig) -> bool:
    """Does any cylinder of rig ``a`` meet any cylinder of rig ``b``?"""
    lo_a = np.minimum(a.p0, a.p1) - a.radius[:, None]
    hi_a = np.maximum(a.p0, a.p1) + a.radius[:, None]
    lo_b = np.minimum(b.p0, b.p1) - b.radius[:, None]
    hi_b = np.maximum(b.p0, b.p1) + b.radius[:, None]
    if (lo_a.min(0) > hi_b.max(0)).any() or (lo_b.min(0) > hi_a.max(0)).any():
        return False
    i, j = np.divmod(np.arange(len(a.radius) * len(b.radius)), len(b.radius))
    return bool(_pair_hits(a.p0[i], a.p1[i], a.radius[i], b.p0[j], b.p1[j], b.radius[j]).any())


# ---------------------------------------------------------------------------------------------
# Bodies
# ---------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=2)
def _hand_assets(side: str):
    """(HandModel, Articulation) of one side, built once per process."""
    from .hand import HandModel
    from .lcs import hand_lcs

    model = HandModel(side)
    return model, hand_lcs(model, "anatomical")


# rest node of each of the 20 hand cylinders (collision.HAND_CYLINDER_NAMES): phalanx s of finger
# f leaves FreiHAND keypoint 1 + 4 f + s, i.e. MANO joint MANO_TO_FREIHAND[...]; palm -> wrist
def _hand_attach() -> np.ndarray:
    from .hand import MANO_TO_FREIHAND

    att = [MANO_TO_FREIHAND[1 + 4 * f + s] for f in range(5) for s in range(3)]
    return np.array(att + [0] * 5, int)


_MAX_SETTLE = 0.05

FOREARM_LENGTH: float = 0.25
"""Length of the forearm drawn behind each hand, metres (scenery: not a collision body)."""


@dataclass
class SceneBody:
    """One body of a generated scene, in the scene (world) frame.

    Attributes:
        label: the body's label in masks (1 = the target hand).
        name: ``"left_hand"``, ``"right_hand"``, an object kind, or ``"chain"``.
        kind: ``"hand"``, ``"object"`` or ``"chain"``.
        side: ``"left"``/``"right"`` for hands, ``None`` otherwise.
        vertices: (V, 3) float64 world coordinates, metres.
        faces: (F, 3) int64.
        colors: (V, 3) float RGB in [0, 1].
        cylinders: the collision cylinders in their final place (world, metres).
        joints: (21, 3) FreiHAND keypoints of a hand (world, metres), else ``None``.
        pose: (15, 3) float32 axis-angle finger pose of a hand (MANO order), else ``None``.
        angles: (J, 3) LCS angles (radians) of a hand's joints or the chain's links, else None.
        shape: (6,) hand shape parameters
            ([`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.SHAPE_PARAM_NAMES]), else ``None``.
        dynamic: whether step 4 moved its joints.
        forearm: a hand's forearm for rendering,
            ``(vertices (N,3) world, faces (M,3), colours (N,3))``
            ([`forearm_mesh`][handmesh_tutorial.hand.forearm_mesh]: scenery, not a body: it occludes
            but has no label, no annotation and no collision), else ``None``.
    """

    label: int
    name: str
    kind: str
    side: str | None
    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    cylinders: Cylinders
    joints: np.ndarray | None = None
    pose: np.ndarray | None = None
    angles: np.ndarray | None = None
    shape: np.ndarray | None = None
    dynamic: bool = True
    forearm: tuple | None = None


@dataclass
class Scene:
    """A generated interaction (world frame, metres), before rendering.

    Attributes:
        kind: ``"hand-hand"``, ``"hand-object"`` or ``"hand-chain"``.
        seed: the seed (or ``None`` when a Generator was passed).
        bodies: the bodies, in label order.
        target: label of the target hand (the left hand in hand-hand scenes).
        approach: (3,) unit direction from the centre body towards the second hand (step 2).
        stats: ``contact_mm`` (mesh-to-mesh distance, 0 when touching), ``penetration_mm`` (deepest
            vertex of one mesh inside the other), ``rounds``, ``stop`` (one of
            [`STOP_REASONS`][handmesh_tutorial.interact.STOP_REASONS]), ``moves`` (accepted joint
            moves), ``blocked_contact`` / ``blocked_limit`` (joints stopped by a collision / a
            limit), ``approach_mm`` (distance travelled in step 3), ``settle_mm`` (signed shift of
            the settle step, positive towards the centre), ``attempts`` (candidates tried).
        history: with ``record=True``, a list of snapshots ``{"step", "text", "bodies"}`` where
            ``bodies`` maps label -> ``{"cylinders", "vertices", "faces", "colors"}``.
    """

    kind: str
    seed: Any
    bodies: list[SceneBody]
    target: int
    approach: np.ndarray
    stats: dict
    history: list | None = None

    def body(self, label: int) -> SceneBody:
        """The body with this label."""
        for b in self.bodies:
            if b.label == label:
                return b
        raise ValueError(f"no body with label {label}; labels are "
                         f"{[b.label for b in self.bodies]}")

    def render_meshes(self, R=None, t=None) -> list[tuple]:
        """``(vertices, faces, sRGB colors, label)`` per body, optionally moved ``x -> R x + t``.

        Args:
            R: (3, 3) rotation (default identity).
            t: (3,) translation, metres (default zero).
        """
        R = np.eye(3) if R is None else np.asarray(R, float)
        t = np.zeros(3) if t is None else np.asarray(t, float)
        return [(b.vertices @ R.T + t, b.faces, b.colors, b.label) for b in self.bodies]

    def scenery_meshes(self, R=None, t=None) -> list[tuple]:
        """``(vertices, faces, sRGB colors, owner label)`` of the scenery (the hands' forearms),
        optionally moved ``x -> R x + t``; see
        [`handmesh_tutorial.render.Renderer.render`][handmesh_tutorial.render.Renderer.render]'s
        ``occluders``."""
        R = np.eye(3) if R is None else np.asarray(R, float)
        t = np.zeros(3) if t is None else np.asarray(t, float)
        return [(b.forearm[0] @ R.T + t, b.forearm[1], b.forearm[2], b.label)
                for b in self.bodies if b.forearm is not None]


class _Hand:
    """A hand during generation: its rig plus what is needed to produce the mesh."""

    def __init__(self, side: str, shape: np.ndarray, limits: str, label: int, colors):
        from .collision import hand_cylinders

        self.side, self.label, self.kind, self.colors = side, label, "hand", colors
        self.name = f"{side}_hand"
        self.model, art = _hand_assets(side)
        self.art = art.with_limits(limits)
        self.shape = np.asarray(shape, np.float32)
        import torch

        with torch.no_grad():
            rest = self.model(shape=torch.as_tensor(self.shape[None]))
        self.rest_joints21 = rest.joints[0].numpy().astype(float)
        rest16 = rest.joints_mano[0].numpy().astype(float)
        cyl = hand_cylinders(rest, model=self.model)
        from .lcs import DIP_FOLLOWS_PIP, DIP_PIP_RATIO

        # natural hands: each finger's DIP follows its PIP (the paper's +-60 deg: independent)
        followers = ({dip: (pip, DIP_PIP_RATIO) for dip, pip in DIP_FOLLOWS_PIP.items()}
                     if limits == "anatomical" else None)
        self.rig = _Rig(rest16, self.model.parents, self.art.frames, self.art.lower,
                        self.art.upper, cyl, _hand_attach(), followers=followers)
        self.dynamic = True

    def mesh(self):
        """(vertices (V,3), joints (21,3)) world, via the hand model (LBS), float64."""
        import torch

        pose = self.art.to_pose(self.rig.angles)
        go = Rotation.from_matrix(self.rig.root_R).as_rotvec()
        transl = self.rig.root_P - self.rig.rest[0]
        with torch.no_grad():
            out = self.model(pose=torch.as_tensor(pose[None]),
                             shape=torch.as_tensor(self.shape[None]),
                             global_orient=torch.as_tensor(go[None], dtype=torch.float32),
                             transl=torch.as_tensor(transl[None], dtype=torch.float32))
        return out.vertices[0].numpy().astype(float), out.joints[0].numpy().astype(float)

    @property
    def faces(self):
        return self.model.faces

    def palm(self):
        """Rest palm centre (3,), palm normal (3,) and distal direction (3,), hand frame."""
        from .lcs import palm_normal

        j = self.rest_joints21
        centre = j[[0, 5, 9, 13, 17]].mean(0)
        distal = j[9] - j[0]
        return centre, palm_normal(j, self.side), distal / np.linalg.norm(distal)


class _Static:
    """A static object during generation (rig with a root only)."""

    def __init__(self, body, label: int):
        self.body, self.label, self.kind, self.name = body, label, "object", body.name
        self.side, self.colors, self.dynamic = None, body.colors, False
        c = body.cylinders
        self.rig = _Rig(np.zeros((1, 3)), [-1], np.zeros((0, 3, 3)), np.zeros((0, 3)),
                        np.zeros((0, 3)), c, np.zeros(len(c), int))

    def mesh(self):
        return self.rig.to_world(self.body.vertices), None

    @property
    def faces(self):
        return self.body.faces


class _ChainBody:
    """The articulated chain during generation: node 0 a fixed root at link 0's pivot."""

    def __init__(self, chain, label: int):
        self.chain, self.label, self.kind, self.name = chain, label, "chain", "chain"
        self.side, self.dynamic = None, True
        L = chain.num_links
        art = chain.articulation
        rest = np.vstack([chain.pivots[:1], chain.pivots])
        parents = np.r_[-1, np.arange(L)]
        cyl = Cylinders.concat([b.cylinders for b in chain.links])
        self.rig = _Rig(rest, parents, art.frames, art.lower, art.upper, cyl, cyl.parts + 1)
        self.colors = np.concatenate([b.colors for b in chain.links])
        off = np.cumsum([0] + [len(b.vertices) for b in chain.links[:-1]])
        self._faces = np.concatenate([b.faces + o for b, o in zip(chain.links, off, strict=True)])

    def mesh(self):
        v = [self.rig.to_world(b.vertices, k + 1) for k, b in enumerate(self.chain.links)]
        return np.concatenate(v), None

    @property
    def faces(self):
        return self._faces


# ---------------------------------------------------------------------------------------------
# Mesh-level contact: distances with exact inside/outside signs
# ---------------------------------------------------------------------------------------------
def closest_points_on_triangles(p, a, b, c):
    """Closest points on triangles ``abc`` to points ``p`` (Ericson, *Real-Time Collision
    Detection*, 5.1.5), vectorised over broadcast batches.

    Args:
        p: (..., 3) query points, metres.
        a: (..., 3) first triangle corners.
        b: (..., 3) second triangle corners.
        c: (..., 3) third triangle corners.

    Returns:
        ``(q, region)``: (..., 3) closest points and (...,) int feature codes: 0 the face
        interior, 1/2/3 the edges opposite ``a``/``b``/``c`` (bc, ca, ab), 4/5/6 the corners
        ``a``/``b``/``c``.
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    tiny = 1e-300
    # face interior (default)
    denom = va + vb + vc
    denom = np.where(np.abs(denom) < tiny, tiny, denom)
    v, w = vb / denom, vc / denom
    q = a + ab * v[..., None] + ac * w[..., None]
    region = np.zeros(p.shape[:-1], int)

    def put(mask, point, code):
        nonlocal q, region
        q = np.where(mask[..., None], point, q)
        region = np.where(mask, code, region)

    # edge bc (region 1)
    e_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    t = (d4 - d3) / np.where(e_bc, (d4 - d3) + (d5 - d6), 1.0).clip(tiny)
    put(e_bc, b + (c - b) * t[..., None], 1)
    # edge ac (region 2)
    e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    t = d2 / np.where(e_ac, d2 - d6, 1.0).clip(tiny)
    put(e_ac, a + ac * t[..., None], 2)
    # edge ab (region 3)
    e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    t = d1 / np.where(e_ab, d1 - d3, 1.0).clip(tiny)
    put(e_ab, a + ab * t[..., None], 3)
    # corners (regions 4, 5, 6) take precedence over edges
    put((d6 >= 0) & (d5 <= d6), np.broadcast_to(c, q.shape), 6)
    put((d3 >= 0) & (d4 <= d3), np.broadcast_to(b, q.shape), 5)
    put((d1 <= 0) & (d2 <= 0), np.broadcast_to(a, q.shape), 4)
    return q, region


class _MeshSDF:
    """Signed distance to a closed triangle mesh with angle-weighted pseudo-normals.

    The sign of ``p - c`` (``c`` the closest surface point) against the pseudo-normal of the
    feature holding ``c`` (face, edge or vertex) is exact for closed, consistently oriented
    meshes (Baerentzen & Aanaes 2005), so no ray casting is needed. Closest points are exact:
    for a query at distance ``r`` from its nearest mesh vertex, every face whose bounding sphere
    (centroid, radius ``rho``) comes within ``r`` is tested (k-d trees of vertices and of face
    centroids).
    """

    def __init__(self, vertices, faces):
        v = np.asarray(vertices, float)
        f = np.asarray(faces, np.int64)
        self.v, self.f = v, f
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        fn /= np.linalg.norm(fn, axis=1, keepdims=True) + 1e-30
        self.fn = fn
        vn = np.zeros_like(v)  # angle-weighted vertex normals
        for i in range(3):
            e1 = v[f[:, (i + 1) % 3]] - v[f[:, i]]
            e2 = v[f[:, (i + 2) % 3]] - v[f[:, i]]
            cosang = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                                         + 1e-30)
            np.add.at(vn, f[:, i], np.arccos(np.clip(cosang, -1, 1))[:, None] * fn)
        self.vn = vn
        # edge pseudo-normals (sum of the two adjacent face normals); edge i of a face is
        # opposite its corner i
        e = np.sort(np.stack([f[:, [1, 2]], f[:, [2, 0]], f[:, [0, 1]]], 1), axis=2)
        _, inv = np.unique(e[..., 0] * len(v) + e[..., 1], return_inverse=True)
        inv = inv.reshape(-1)
        en = np.zeros((inv.max() + 1, 3))
        np.add.at(en, inv, np.repeat(fn, 3, axis=0))
        self.edge_of = inv.reshape(-1, 3)
        self.en = en
        from scipy.spatial import cKDTree

        self.tree = cKDTree(v)
        self.centroid = v[f].mean(1)
        self.rho = np.linalg.norm(v[f] - self.centroid[:, None], axis=2).max(1)
        self.rho_max = float(self.rho.max())
        self.ctree = cKDTree(self.centroid)

    def __call__(self, points) -> np.ndarray:
        """(N,) signed distances of points (N,3), metres: negative inside the mesh."""
        p = np.asarray(points, float).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0)
        f = self.f
        dmin, _ = self.tree.query(p)  # the nearest vertex bounds the distance to the surface
        near = self.ctree.query_ball_point(p, dmin + self.rho_max * (1 + 1e-9) + 1e-12)
        counts = np.array([len(x) for x in near])
        face = np.concatenate([np.asarray(x, np.int64) for x in near])
        pid = np.repeat(np.arange(len(p)), counts)
        # a face can hold the closest point only if its bounding sphere reaches within dmin
        keep = (np.linalg.norm(p[pid] - self.centroid[face], axis=1)
                <= dmin[pid] + self.rho[face] * (1 + 1e-9) + 1e-12)
        pid, face = pid[keep], face[keep]
        tri = self.v[f[face]]
        q, reg = closest_points_on_triangles(p[pid], tri[:, 0], tri[:, 1], tri[:, 2])
        d2 = ((q - p[pid]) ** 2).sum(-1)
        order = np.lexsort((d2, pid))
        first = order[np.r_[True, pid[order][1:] != pid[order][:-1]]]  # per point: its minimum
        qc, reg, face, d = q[first], reg[first], face[first], np.sqrt(d2[first])
        n = self.fn[face].copy()
        on_edge = (reg >= 1) & (reg <= 3)
        n[on_edge] = self.en[self.edge_of[face[on_edge], reg[on_edge] - 1]]
        on_vert = reg >= 4
        n[on_vert] = self.vn[f[face[on_vert], reg[on_vert] - 4]]
        return np.where(((p - qc) * n).sum(1) < 0, -d, d)


def signed_distance(points, vertices, faces) -> np.ndarray:
    """Signed distance of points to a closed triangle mesh (negative inside).

    Args:
        points: (N, 3) metres.
        vertices: (V, 3) mesh vertices, metres.
        faces: (F, 3) int, consistently oriented, closed (watertight) mesh.

    Returns:
        (N,) float64 metres: ``> 0`` outside, ``< 0`` inside (the opposite sign of
        ``trimesh.proximity.signed_distance``).
    """
    return _MeshSDF(vertices, faces)(points)


def _near(points, cyl_p0, cyl_p1, radius, dist: float) -> np.ndarray:
    """(N,) bool: points within ``dist`` of some capsule (a superset of "of some cylinder")."""
    d = cyl_p1 - cyl_p0                                     # (C,3)
    w = points[:, None] - cyl_p0[None]                      # (N,C,3)
    t = np.clip((w * d).sum(-1) / (d * d).sum(1), 0, 1)
    e = w - t[..., None] * d
    r = radius + dist
    return ((e * e).sum(-1) <= r * r).any(1)


def mesh_contact(a_vertices, a_faces, b_vertices, b_faces, *, a_cylinders: Cylinders | None = None,
                 b_cylinders: Cylinders | None = None, near: float = 0.01, a_shift=None,
                 sdf_a=None, sdf_b=None) -> dict:
    """Contact and penetration between two closed meshes, measured on their vertices.

    Each mesh's vertices are tested against the other mesh's surface (signed distance with an exact
    sign, see [`signed_distance`][handmesh_tutorial.interact.signed_distance]). With cylinders
    given, only vertices within ``near`` of the other body's cylinders are tested (a prefilter: the
    cylinders cover their mesh to within a few millimetres, so farther vertices cannot set the
    contact); when no vertex passes it, every vertex is tested.

    Args:
        a_vertices: (V, 3) vertices of the first mesh (closed), metres.
        a_faces: (F, 3) its triangles.
        b_vertices: (V', 3) vertices of the second mesh (closed), metres.
        b_faces: (F', 3) its triangles.
        a_cylinders: optional collision cylinders of the first mesh, for the prefilter.
        b_cylinders: optional collision cylinders of the second mesh.
        near: prefilter distance, metres.
        a_shift: optional (3,) translation applied to mesh A (and its cylinders), metres.
        sdf_a: optional prebuilt signed-distance object of the (unshifted) first mesh.
        sdf_b: optional prebuilt signed-distance object of the second mesh.

    Returns:
        dict with ``contact_mm`` (smallest vertex-to-surface distance, 0 when some vertex is
        inside the other mesh), ``gap_mm`` (that distance over the outside vertices only),
        ``penetration_mm`` (depth of the deepest vertex inside the other mesh, 0 when none),
        ``inside`` (count of such vertices), ``tested`` (vertices tested).
    """
    av, bv = np.asarray(a_vertices, float), np.asarray(b_vertices, float)
    sh = np.zeros(3) if a_shift is None else np.asarray(a_shift, float).reshape(3)
    sa = sdf_a if sdf_a is not None else _MeshSDF(av, a_faces)
    sb = sdf_b if sdf_b is not None else _MeshSDF(bv, b_faces)
    pa, pb = av + sh, bv
    if b_cylinders is not None:
        pa = pa[_near(pa, b_cylinders.p0, b_cylinders.p1, b_cylinders.radius, near)]
    if a_cylinders is not None:
        pb = pb[_near(pb, a_cylinders.p0 + sh, a_cylinders.p1 + sh, a_cylinders.radius, near)]
    if len(pa) == 0 or len(pb) == 0:  # nothing near the other body: test every vertex
        pa, pb = av + sh, bv
    d = np.concatenate([sb(pa), sa(pb - sh)])
    inside = d < 0
    gap = float(d[~inside].min()) if (~inside).any() else float("inf")
    pen = float(-d[inside].min()) if inside.any() else 0.0
    return {"contact_mm": 0.0 if inside.any() else 1e3 * gap, "gap_mm": 1e3 * gap,
            "penetration_mm": 1e3 * pen, "inside": int(inside.sum()), "tested": int(d.size)}


# ---------------------------------------------------------------------------------------------
# The algorithm
# ---------------------------------------------------------------------------------------------
def _unit(v):
    return v / np.linalg.norm(v)


def _random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


def _random_direction(rng) -> np.ndarray:
    return _unit(rng.normal(size=3))


def _aim_point(rig: _Rig, rng) -> np.ndarray:
    """A random point on the axis of a random cylinder of a body."""
    k = int(rng.integers(len(rig.radius)))
    return rig.p0[k] + rng.uniform(0.2, 0.8) * (rig.p1[k] - rig.p0[k])


def _bound(rig: _Rig, centre) -> float:
    d = np.maximum(np.linalg.norm(rig.p0 - centre, axis=1), np.linalg.norm(rig.p1 - centre,
                                                                          axis=1))
    return float((d + rig.radius).max())


class _Generator:
    def __init__(self, kind: str, rng: np.random.Generator, seed, cfg: InteractionConfig,
                 record: bool):
        self.kind, self.rng, self.seed, self.cfg, self.record = kind, rng, seed, cfg, record
        self.history: list | None = [] if record else None

    # -- bodies ------------------------------------------------------------------------------
    def _tone(self):
        from .hand import SKIN_TONES

        return int(self.rng.integers(len(SKIN_TONES)))

    def _hand(self, side, label, tone):
        from .hand import random_shape

        shape = random_shape(self.rng, 1, self.cfg.shape_scale)[0]
        model, _ = _hand_assets(side)
        colors = model.vertex_colors(tone, rng=int(self.rng.integers(2**31)))
        return _Hand(side, shape, self.cfg.limits, label, colors)

    def snapshot(self, step: str, text: str, bodies) -> None:
        if self.history is None:
            return
        snap = {}
        for b in bodies:
            v, _ = b.mesh()
            snap[b.label] = {"cylinders": b.rig.cylinders(), "vertices": v, "faces": b.faces,
                             "colors": b.colors, "name": b.name}
        self.history.append({"step": step, "text": text, "bodies": snap})

    def _random_hand_angles(self, art) -> np.ndarray:
        """Random LCS angles inside the limits, scaled per axis like the joint directions."""
        cfg, rng = self.cfg, self.rng
        a = art.random_angles(rng, scale=cfg.init_pose_scale)
        w = np.asarray(cfg.axis_weights, float) / max(cfg.axis_weights)
        a = a * w
        flex = rng.random(len(a)) < cfg.flexion_bias
        a[:, 1] = np.where(flex, np.abs(a[:, 1]), -np.abs(a[:, 1]))
        return art.clip(a)

    # -- step 1 ------------------------------------------------------------------------------
    def centre_body(self):
        rng, cfg = self.rng, self.cfg
        if self.kind == "hand-hand":
            tone = self._tone()
            centre_side = "left" if rng.random() < 0.5 else "right"
            other_side = "right" if centre_side == "left" else "left"
            same_person = rng.random() < 0.7
            labels = {"left": 1, "right": 2}
            centre = self._hand(centre_side, labels[centre_side], tone)
            mover = self._hand(other_side, labels[other_side],
                               tone if same_person else self._tone())
            for _ in range(cfg.max_attempts):
                angles = self._random_hand_angles(centre.art)
                centre.rig.set_angles(angles)
                if not centre.rig.self_collides():
                    break
            else:
                raise InteractionError(self.kind, self.seed, "no self-collision-free random "
                                       f"pose for the centre hand in {cfg.max_attempts} draws")
            R = _random_rotation(rng)
            centre.rig.place(R, np.zeros(3))
            # put the palm centre at the scene centre
            c = centre.rig.to_world(centre.palm()[0])
            centre.rig.translate(-c)
            target = 1
        else:
            side = "left" if rng.random() < 0.5 else "right"
            mover = self._hand(side, 1, self._tone())
            target = 1
            if self.kind == "hand-object":
                from .objects import OBJECT_KINDS, make_object

                kinds = cfg.object_kinds or OBJECT_KINDS
                kind = kinds[int(rng.integers(len(kinds)))]
                centre = _Static(make_object(kind, int(rng.integers(2**31))), 2)
            else:
                from .objects import make_chain

                n = int(rng.integers(cfg.chain_links[0], cfg.chain_links[1] + 1))
                chain = make_chain(n, int(rng.integers(2**31)), limit_deg=60.0)
                centre = _ChainBody(chain, 2)
                # a loosely hanging chain: small random link angles, no link collisions
                for _ in range(cfg.max_attempts):
                    a = chain.articulation.random_angles(rng, scale=0.4)
                    centre.rig.set_angles(a)
                    if not centre.rig.self_collides():
                        break
                else:
                    centre.rig.set_angles(np.zeros((n, 3)))
            R = _random_rotation(rng)
            centre.rig.place(R, np.zeros(3))
            lo = np.minimum(centre.rig.p0, centre.rig.p1).min(0)
            hi = np.maximum(centre.rig.p0, centre.rig.p1).max(0)
            centre.rig.translate(-0.5 * (lo + hi))
        return centre, mover, target

    # -- steps 2 and 3 -------------------------------------------------------------------------
    def approach(self, centre, mover):
        rng, cfg = self.rng, self.cfg
        pc, normal, distal = mover.palm()
        lateral = _unit(np.cross(normal, distal))
        for attempt in range(cfg.max_attempts):
            u = _random_direction(rng)
            # palm normal -> -u, then a random roll about u
            Ra = Rotation.align_vectors([-u], [normal])[0]
            R = Rotation.from_rotvec(rng.uniform(0, 2 * np.pi) * u) * Ra
            R = R.as_matrix()
            off = (rng.uniform(-1, 1) * cfg.lateral_offset * lateral
                   + rng.uniform(-0.5, 1.5) * cfg.lateral_offset * distal)
            ref = pc + off  # rest point of the mover that is aimed at the centre body
            aim = _aim_point(centre.rig, rng)
            mover.rig.place(R, np.zeros(3))
            ref_w = mover.rig.to_world(ref)
            s0 = _bound(centre.rig, aim) + _bound(mover.rig, ref_w) + 0.005
            mover.rig.translate(aim + s0 * u - ref_w)
            self.snapshot("2", "second hand: neutral pose, palm facing the centre body",
                          [centre, mover])
            travelled = self.push(centre, mover, u, 2 * s0)
            if travelled is not None:
                self.snapshot("3", "approach: last position before the first collision",
                              [centre, mover])
                return u, travelled, attempt + 1
            if self.history:
                self.history.pop()  # the approach missed: forget its snapshot
        raise InteractionError(self.kind, self.seed, f"the second hand missed the centre body "
                               f"on {cfg.max_attempts} approach directions")

    def push(self, centre, mover, u, max_travel: float) -> float | None:
        """Move ``mover`` by ``-approach_step * u`` until its next step would collide.

        Returns the distance travelled (metres), or ``None`` (mover back where it started) when
        nothing was hit within ``max_travel``.
        """
        step = self.cfg.approach_step
        travelled = 0.0
        while travelled < max_travel:
            mover.rig.translate(-step * u)
            if _collides(mover.rig, centre.rig):
                mover.rig.translate(step * u)  # back to the last valid place
                return travelled
            travelled += step
        mover.rig.translate(travelled * u)
        return None

    # -- steps 4 and 5 -------------------------------------------------------------------------
    def _direction(self, body, j) -> np.ndarray | None:
        if j in body.rig.followers:   # driven by its leader (a DIP by its PIP)
            return None
        span = body.rig.upper[j - 1] - body.rig.lower[j - 1]
        w = np.asarray(self.cfg.axis_weights, float) if body.kind == "hand" else np.ones(3)
        d = self.rng.normal(size=3) * w * (span > 0)
        if body.kind == "hand":
            flex = self.rng.random() < self.cfg.flexion_bias
            d[1] = abs(d[1]) if flex else -abs(d[1])
        n = np.linalg.norm(d)
        return None if n < 1e-12 else d / n

    def _blocked(self, body, others, node, cand, limit=None) -> np.ndarray:
        """(K,) bool: candidate angles of ``node`` that collide (other bodies or itself).

        Only candidates before the first colliding one are decided exactly (and none after
        ``limit``, the first candidate out of the joint limits); the rest may be False.
        """
        rig = body.rig
        q0, q1 = rig.candidates(node, cand)  # (K,Cm,3)
        K, Cm = q0.shape[:2]
        r = rig.radius[rig.moved[node]]
        # one list of (moved cylinder, fixed cylinder) pairs: all pairs with the other bodies
        # (when their boxes meet the swept cylinders), the non-adjacent pairs with the own body
        im, st = rig.self_pairs[node]
        I, B0, B1, RB = [im], [rig.p0[st]], [rig.p1[st]], [rig.radius[st]]
        lo = np.minimum(q0, q1).min((0, 1)) - r.max()
        hi = np.maximum(q0, q1).max((0, 1)) + r.max()
        for o in others:
            orig = o.rig
            olo = np.minimum(orig.p0, orig.p1).min(0) - orig.radius.max()
            ohi = np.maximum(orig.p0, orig.p1).max(0) + orig.radius.max()
            if (olo > hi).any() or (lo > ohi).any():
                continue
            n = len(orig.radius)
            I.append(np.repeat(np.arange(Cm), n))
            B0.append(np.tile(orig.p0, (Cm, 1)))
            B1.append(np.tile(orig.p1, (Cm, 1)))
            RB.append(np.tile(orig.radius, Cm))
        i = np.concatenate(I)
        if i.size == 0:
            return np.zeros(K, bool)
        b0, b1, rb = np.concatenate(B0), np.concatenate(B1), np.concatenate(RB)
        P = len(i)
        if limit is not None:  # candidates from the first one out of limits on do not matter
            K = min(K, limit + 1)
            q0, q1 = q0[:K], q1[:K]
        a0, a1, ra = q0[:, i].reshape(-1, 3), q1[:, i].reshape(-1, 3), np.tile(r[i], K)
        b0, b1, rb = np.tile(b0, (K, 1)), np.tile(b1, (K, 1)), np.tile(rb, K)
        # certain hits first; exact tests only for candidates before the first certain hit
        hit, maybe = _pair_stages(a0, a1, ra, b0, b1, rb)
        sure_k = hit.reshape(K, P).any(1)
        first = int(np.argmax(sure_k)) if sure_k.any() else K
        maybe = maybe[maybe // P < first]
        if maybe.size:
            hit[maybe] = cylinders_intersect(a0[maybe], a1[maybe], ra[maybe], b0[maybe],
                                             b1[maybe], rb[maybe])
        out = np.zeros(len(cand), bool)
        out[:K] = hit.reshape(K, P).any(1)
        return out

    def joint_moves(self, bodies, centre, mover, u):
        cfg, rng = self.cfg, self.rng
        step = np.deg2rad(cfg.joint_step_deg)
        per_round = max(1, int(round(cfg.sweep_deg / cfg.joint_step_deg)))
        dynamic = [b for b in bodies if b.dynamic]
        # each joint gets one random direction; it moves along it until blocked
        active = {}
        for b in dynamic:
            for j in range(1, b.rig.num_joints + 1):
                d = self._direction(b, j)
                if d is not None:
                    active[(b.label, j)] = d
        by_label = {b.label: b for b in bodies}
        moves = rounds = blocked_contact = blocked_limit = 0
        reapproach = 0.0
        stop = "max rounds"
        for rounds in range(1, cfg.max_rounds + 1):  # noqa: B007 - rounds is reported
            moved = False
            keys = sorted(active)
            for i in rng.permutation(len(keys)):
                key = keys[i]
                if key not in active:
                    continue
                body = by_label[key[0]]
                j, d = key[1], active[key]
                others = [o for o in bodies if o is not body]
                a0 = body.rig.angles[j - 1]
                cand = a0 + step * np.arange(1, per_round + 1)[:, None] * d
                ok_lim = ((cand >= body.rig.lower[j - 1] - 1e-12)
                          & (cand <= body.rig.upper[j - 1] + 1e-12)).all(1)
                # candidates in chunks of 8: most sweeps end early (contact or limit)
                n = per_round
                for c0 in range(0, per_round, 8):
                    ch = slice(c0, min(c0 + 8, per_round))
                    lim_ch = ok_lim[ch]
                    lim = int(np.argmin(lim_ch)) if not lim_ch.all() else None
                    bad = self._blocked(body, others, j, cand[ch], lim) | ~lim_ch
                    if bad.any():
                        n = c0 + int(np.argmax(bad))
                        break
                if n > 0:
                    body.rig.set_joint(j, cand[n - 1])
                    moves += 1
                    moved = True
                if n < per_round:  # blocked: by a limit or by a collision
                    del active[key]
                    if ok_lim[n]:
                        blocked_contact += 1
                    else:
                        blocked_limit += 1
            if cfg.reapproach:  # deviation: keep the hands pressed together
                pushed = self.push(centre, mover, u, 0.05)
                if pushed:
                    reapproach += pushed
                    moved = True
            self.snapshot("4", f"joint moves, round {rounds}", bodies)
            if not moved or not active:
                stop = "no valid move"
                break
        return {"rounds": rounds, "stop": stop, "moves": moves,
                "blocked_contact": blocked_contact, "blocked_limit": blocked_limit,
                "reapproach_mm": 1e3 * reapproach}

    # -- step 5b: mesh-level settle (deviation, see the module text) ---------------------------
    # (the cylinders already touch, so the meshes are millimetres apart: a settle that wants to
    # move a body by more than this has diverged, and the scene is rejected)
    def settle(self, centre, mover, u, meshes):
        cfg = self.cfg
        (cv, cf), (mv, mf) = meshes[centre.label], meshes[mover.label]
        sdf_c, sdf_m = _MeshSDF(cv, cf), _MeshSDF(mv, mf)
        ccyl, mcyl = centre.rig.cylinders(), mover.rig.cylinders()

        def measure(shift_):  # the mover moved by shift_ towards the centre (along -u)
            return mesh_contact(mv, mf, cv, cf, a_cylinders=mcyl, b_cylinders=ccyl,
                                a_shift=-shift_ * u, sdf_a=sdf_m, sdf_b=sdf_c)

        shift = 0.0
        m = measure(shift)
        if cfg.settle:
            rate = 1.0  # gap closed per metre moved along u (1 when u points at the gap)
            last_ok = None
            for _ in range(16):
                pen, gap = m["penetration_mm"] * 1e-3, m["gap_mm"] * 1e-3
                if pen > cfg.penetration_tol:  # too deep: back off
                    if last_ok is not None:  # halfway back to the last state without it
                        shift = 0.5 * (shift + last_ok)
                    else:
                        shift -= pen - 0.5 * cfg.penetration_tol
                elif m["inside"] == 0 and gap > cfg.contact_tol:  # a gap: close it
                    last_ok = shift
                    # moving by less than the gap cannot intersect (distance is 1-Lipschitz);
                    # an oblique gap closes slower: divide by the observed closing rate
                    step = (gap - 0.5 * cfg.contact_tol) / rate
                    if abs(shift + step) > _MAX_SETTLE:   # the gap does not close this way
                        raise InteractionError(self.kind, self.seed, "the settle step would move "
                                               f"the second body by more than {_MAX_SETTLE} m")
                    shift += step
                    m_new = measure(shift)
                    closed = gap - m_new["gap_mm"] * 1e-3 if m_new["inside"] == 0 else step
                    rate = float(np.clip(closed / step, 0.2, 1.0))
                    m = m_new
                    continue
                else:
                    break
                m = measure(shift)
            mover.rig.translate(-shift * u)
            meshes[mover.label] = (mv - shift * u, mf)
        return m, shift

    # -- all steps ----------------------------------------------------------------------------
    def run(self) -> Scene:
        centre, mover, target = self.centre_body()
        self.snapshot("1", "centre body at the scene centre", [centre])
        u, travelled, attempts = self.approach(centre, mover)
        bodies = sorted([centre, mover], key=lambda b: b.label)
        loop = self.joint_moves(bodies, centre, mover, u)
        meshes, joints = {}, {}
        for b in bodies:
            v, j = b.mesh()
            meshes[b.label], joints[b.label] = (v, b.faces), j
        m, shift = self.settle(centre, mover, u, meshes)
        if joints.get(mover.label) is not None:
            joints[mover.label] = joints[mover.label] - shift * u
        if self.cfg.settle:
            self.snapshot("5b", "mesh-level settle", bodies)
        stats = {"contact_mm": m["contact_mm"], "gap_mm": m["gap_mm"],
                 "penetration_mm": m["penetration_mm"], "inside_vertices": m["inside"],
                 **loop, "approach_mm": 1e3 * travelled, "settle_mm": 1e3 * shift,
                 "attempts": attempts}
        out = []
        for b in bodies:
            v, f = meshes[b.label]
            is_hand = b.kind == "hand"
            forearm = None
            if is_hand:
                from .hand import forearm_mesh

                loop = b.model.wrist_loop
                fv, ff = forearm_mesh(v[loop], b.rig.G[0] @ np.array([-1.0, 0.0, 0.0]),
                                      length=FOREARM_LENGTH)
                skin = np.asarray(b.colors, float)[loop].mean(0)
                forearm = (fv, ff, np.tile(skin, (len(fv), 1)))
            out.append(SceneBody(
                label=b.label, name=b.name, kind=b.kind, side=b.side if is_hand else None,
                vertices=v, faces=np.asarray(f, np.int64), colors=np.asarray(b.colors, float),
                cylinders=b.rig.cylinders(), joints=joints[b.label],
                pose=b.art.to_pose(b.rig.angles) if is_hand else None,
                angles=b.rig.angles.copy() if b.rig.num_joints else None,
                shape=b.shape.copy() if is_hand else None, dynamic=b.dynamic, forearm=forearm))
        return Scene(self.kind, self.seed, out, target, u, stats, self.history)


def build_scene(kind: str, seed: int | np.random.Generator, config: InteractionConfig | None = None,
                *, record: bool = False, **overrides) -> Scene:
    """Generate one interaction (steps 1-5 of the paper's algorithm, plus the mesh settle).

    Args:
        kind: ``"hand-hand"``, ``"hand-object"`` or ``"hand-chain"``.
        seed: an integer seed or a ``numpy.random.Generator``; same seed -> same scene.
        config: an [`InteractionConfig`][handmesh_tutorial.interact.InteractionConfig] (defaults
            when ``None``).
        record: keep a snapshot of every step in ``Scene.history`` (for figures).
        **overrides: fields of [`InteractionConfig`][handmesh_tutorial.interact.InteractionConfig]
            to change, e.g. ``limits="anatomical"``.

    Returns:
        A [`Scene`][handmesh_tutorial.interact.Scene] in the world frame (centre body near the
        origin).

    Raises:
        ValueError: unknown kind or config field.
        InteractionError: no valid scene within ``config.max_attempts`` candidates.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    cfg = config or InteractionConfig()
    if overrides:
        bad = sorted(set(overrides) - set(asdict(cfg)))
        if bad:
            raise ValueError(f"unknown InteractionConfig fields {bad}")
        cfg = InteractionConfig(**{**asdict(cfg), **overrides})
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    s = None if isinstance(seed, np.random.Generator) else seed
    return _Generator(kind, rng, s, cfg, record).run()


# ---------------------------------------------------------------------------------------------
# Step 6: camera, rendering, the dataset sample
# ---------------------------------------------------------------------------------------------
_RENDERERS: dict = {}


def get_renderer(image_size: int = 224):
    """The per-process [`Renderer`][handmesh_tutorial.render.Renderer] of this image size (created
    on first use and then reused: one OpenGL context per process)."""
    key = int(image_size)
    if key not in _RENDERERS:
        from .render import Renderer

        _RENDERERS[key] = Renderer(key)
    return _RENDERERS[key]


def init_worker(image_size: int = 224, threads: int = 1) -> None:
    """``worker_init`` for
    [`handmesh_tutorial.dataset.generate_dataset`][handmesh_tutorial.dataset.generate_dataset]: one
    renderer and the hand models per process, torch limited to ``threads`` threads.

    Use ``functools.partial(init_worker, image_size)``.
    """
    import torch

    torch.set_num_threads(int(threads))
    get_renderer(image_size)
    for side in ("left", "right"):
        _hand_assets(side)


def camera_pose(centre, rng, distance=(0.35, 0.7), toward=None,
                spread: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """A random camera looking at ``centre``, at a random distance and with a random roll.

    Args:
        centre: (3,) world point the optical axis goes through, metres.
        rng: ``numpy.random.Generator``.
        distance: (min, max) camera distance, metres.
        toward: optional (3,) direction from ``centre`` in which to put the camera (e.g. towards
            an occluding body); ``None`` draws the direction uniformly on the sphere.
        spread: with ``toward``, the camera direction is ``toward`` plus Gaussian noise of this
            standard deviation (unit vectors), normalised.

    Returns:
        ``(R, t)``: world -> OpenCV camera frame, ``X_cam = R @ X + t``.
    """
    c = np.asarray(centre, float)
    if toward is None:
        z = -_random_direction(rng)  # optical axis (camera -> centre)
    else:
        z = -_unit(_unit(np.asarray(toward, float)) + spread * rng.normal(size=3))
    cam = c - rng.uniform(*distance) * z
    a = _random_direction(rng)
    while abs(a @ z) > 0.95:
        a = _random_direction(rng)
    x = _unit(np.cross(z, a))
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ cam


FRAME_SHARE: tuple[float, float] = (0.45, 0.75)
"""Share of the image side covered by the target hand's bounding box (FreiHAND's 224-px crops:
roughly 40-80 %), see [`frame_camera`][handmesh_tutorial.interact.frame_camera].
"""
FRAME_FOCAL: tuple[float, float] = (1.8, 3.6)
"""Focal length as a multiple of the image side (403-806 px at 224 px, fields of view of
31-16 degrees: a crop of a hand from an ordinary camera), see
[`frame_camera`][handmesh_tutorial.interact.frame_camera].
"""
FRAME_MARGIN: float = 0.08
"""Free border, as a fraction of the image side, that the target hand never enters."""


def frame_camera(target_vertices, rng, image_size: int = 224, *, toward=None,
                 spread: float = 0.6, share: tuple[float, float] = FRAME_SHARE,
                 focal: tuple[float, float] = FRAME_FOCAL,
                 margin: float = FRAME_MARGIN,
                 avoid=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera framed on the target hand like a FreiHAND 224-px crop.

    1. The view direction is uniform on the sphere (or ``toward`` plus Gaussian noise of
       ``spread``), with a random roll, aimed at the centre of the hand's bounding box.
    2. A share ``s`` of the image side is drawn from ``share`` and a focal length ``f0`` from
       ``focal`` (log-uniform, times the image side); the camera distance is the one at which the
       hand's extent across the view, seen with ``f0``, covers ``s`` of the image:
       ``d = f0 * extent / (s * S)``.
    3. The camera turns (a small rotation, so the hand stays near the optical axis) to put the
       hand's box centre at a random place that keeps the whole hand at least ``margin * S``
       pixels inside the border, and the focal length is set so that the longer side of the
       hand's projected bounding box is exactly ``s * S`` (``f`` stays close to ``f0``; the
       principal point is the image centre within ±1 %).

    Every vertex of the hand (so all 21 joints) ends up inside the image with the margin; the
    second body may leave the frame. Deterministic in ``rng``.

    Args:
        target_vertices: (V, 3) world vertices of the target hand, metres.
        rng: ``numpy.random.Generator`` or seed.
        image_size: side ``S`` of the square image, pixels.
        toward: optional (3,) world direction from the hand in which to put the camera.
        spread: noise of the ``toward`` direction (unit vectors).
        share: (min, max) share of the image side covered by the hand's bounding box, with
            ``max <= 1 - 2 * margin``.
        focal: (min, max) focal length as a multiple of ``S``.
        margin: free border, as a fraction of ``S``.
        avoid: optional ``(axis (3,), max_cos)``: view directions (hand -> camera) closer than
            ``arccos(max_cos)`` to ``axis`` are drawn again (up to 20 times), e.g. views along
            the forearm from the elbow, where the forearm would hide the hand.

    Returns:
        ``(R, t, K)``: world -> OpenCV camera frame ``X_cam = R @ X + t``, and (3, 3) intrinsics.

    Raises:
        ValueError: a share, focal or margin range that cannot be met.
    """
    from .render import intrinsics

    V = np.asarray(target_vertices, float)
    S = int(image_size)
    rng = np.random.default_rng(rng)
    lo_s, hi_s = (float(x) for x in share)
    if not 0 <= margin < 0.5 or not 0 < lo_s <= hi_s <= 1 - 2 * margin:
        raise ValueError(f"need 0 <= margin < 0.5 and 0 < share[0] <= share[1] <= 1 - 2 * margin, "
                         f"got share {share}, margin {margin}")
    if not 0 < focal[0] <= focal[1]:
        raise ValueError(f"focal must be (min, max) with 0 < min <= max, got {focal}")
    centre = 0.5 * (V.min(0) + V.max(0))
    for _ in range(20):
        if toward is None:
            z = -_random_direction(rng)  # optical axis (camera -> hand)
        else:
            z = -_unit(_unit(np.asarray(toward, float)) + spread * rng.normal(size=3))
        if avoid is None or -z @ _unit(np.asarray(avoid[0], float)) <= avoid[1]:
            break
    a = _random_direction(rng)
    while abs(a @ z) > 0.95:
        a = _random_direction(rng)
    x = _unit(np.cross(z, a))
    R = np.stack([x, np.cross(z, x), z])
    s = rng.uniform(lo_s, hi_s)
    f0 = S * np.exp(rng.uniform(np.log(focal[0]), np.log(focal[1])))
    P = (V - centre) @ R.T
    extent = float(max(np.ptp(P[:, 0]), np.ptp(P[:, 1])))
    d = max(f0 * extent / (s * S), 0.5 * float(np.ptp(P[:, 2])) + 0.1)
    cam = centre - d * z
    mid = (S - 1) / 2.0
    pp = mid + rng.uniform(-0.01, 0.01, 2) * S
    where = rng.uniform(-0.9, 0.9, 2)  # box centre: this fraction of the room left to move
    for _ in range(3):  # turn the camera so the box centre lands where wanted
        Xc = (V - cam) @ R.T
        n = Xc[:, :2] / Xc[:, 2:3]
        nlo, nhi = n.min(0), n.max(0)
        f = s * S / float((nhi - nlo).max())
        room = np.maximum(S * (0.5 - margin) - 0.5 * f * (nhi - nlo) - np.abs(pp - mid), 0.0)
        want = (mid + where * room - pp) / f
        cur = 0.5 * (nlo + nhi)
        Q = Rotation.align_vectors([np.r_[want, 1.0]], [np.r_[cur, 1.0]])[0].as_matrix()
        R = Q @ R
    Xc = (V - cam) @ R.T
    n = Xc[:, :2] / Xc[:, 2:3]
    f = s * S / float((n.max(0) - n.min(0)).max())
    # guarantee: shrink about the principal point if a vertex is within the margin
    lo_ok, hi_ok = -0.5 + margin * S, S - 0.5 - margin * S
    k = 1.0
    for ax in range(2):
        umin, umax = pp[ax] + f * n[:, ax].min(), pp[ax] + f * n[:, ax].max()
        if umax > hi_ok:
            k = min(k, (hi_ok - pp[ax]) / (umax - pp[ax]))
        if umin < lo_ok:
            k = min(k, (pp[ax] - lo_ok) / (pp[ax] - umin))
    f *= k * (1 - 1e-9) if k < 1 else 1.0
    return R, -R @ cam, intrinsics(f, f, float(pp[0]), float(pp[1]))


def scene_lights(rng, depth: float = 0.5):
    """Random lighting of varied intensity, colour temperature and direction (camera frame).

    * a **key light** 20-75 degrees off the optical axis from a random side;
    * a weaker **fill light** from the opposite side;
    * with probability 0.3 a **rim light** from behind the bodies (it lights their silhouettes);
    * with probability 0.3 a point light near the camera.

    The key light's colour temperature is drawn log-uniformly in 2700-8000 K; the fill shares it
    half of the time, else it differs by about 60 mired (mixed light: a lamp and a window). The
    camera is white-balanced for a temperature near the key's (15 mired off), so colour casts
    stay as mild as in real photos. All intensities share an exposure factor (x0.6-1.6). A side
    key light gives the shading cues (folds, finger outlines) that real photos have;
    ``render.random_lights`` lights mostly along the optical axis.

    Args:
        rng: ``numpy.random.Generator`` or seed.
        depth: typical scene depth, metres (places the point light).

    Returns:
        A list of [`handmesh_tutorial.render.Light`][handmesh_tutorial.render.Light] (camera frame).
    """
    from .render import Light, color_temperature

    rng = np.random.default_rng(rng)

    def direction(lo, hi, phi):
        th = np.deg2rad(rng.uniform(lo, hi))
        return (float(np.sin(th) * np.cos(phi)), float(np.sin(th) * np.sin(phi)),
                float(np.cos(th)))

    def shifted(kelvin, mired):  # colour temperatures differ evenly in mired (1e6 / K)
        return float(np.clip(1e6 / (1e6 / kelvin + mired), 2500.0, 9000.0))

    t_key = float(np.exp(rng.uniform(np.log(2700.0), np.log(8000.0))))
    t_wb = shifted(t_key, rng.normal(0.0, 15.0))  # the camera's (imperfect) white balance
    ref = np.asarray(color_temperature(t_wb))

    def colour(kelvin):
        c = np.asarray(color_temperature(kelvin)) / ref
        return tuple(float(v) for v in c / c.max())

    exposure = float(np.exp(rng.uniform(np.log(0.6), np.log(1.6))))
    phi = rng.uniform(0, 2 * np.pi)
    t_fill = t_key if rng.random() < 0.5 else shifted(t_key, rng.normal(0.0, 60.0))
    lights = [Light("directional", colour(t_key), float(rng.uniform(1.5, 3.0)) * exposure,
                    direction=direction(20, 75, phi)),
              Light("directional", colour(t_fill), float(rng.uniform(0.3, 1.0)) * exposure,
                    direction=direction(10, 50, phi + np.pi + rng.uniform(-0.8, 0.8)))]
    if rng.random() < 0.3:
        lights.append(Light("directional", colour(t_key), float(rng.uniform(1.0, 3.0)) * exposure,
                            direction=direction(110, 160, rng.uniform(0, 2 * np.pi))))
    if rng.random() < 0.3:
        ang = rng.uniform(0, 2 * np.pi)
        lights.append(Light("point", colour(t_wb), float(rng.uniform(0.2, 0.6) * depth**2)
                            * exposure, position=(float(0.3 * depth * np.cos(ang)),
                                                  float(0.3 * depth * np.sin(ang)), 0.0)))
    return lights


def _choose_kind(seed: int) -> str:
    g = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(3)[2])
    return KINDS[int(g.integers(len(KINDS)))]


def make_sample(sample_seed: int, kind: str = "hand-hand", image_size: int = 224,
                renderer=None, config: InteractionConfig | None = None, *,
                limits: str | None = None) -> dict:
    """One INTER-SH sample: [`build_scene`][handmesh_tutorial.interact.build_scene] then
    [`render_scene`][handmesh_tutorial.interact.render_scene].

    The scene and the view draw from independent streams of ``sample_seed``
    (``numpy.random.SeedSequence(sample_seed).spawn(3)``: scene, view, kind), so the same seed
    always gives the same bytes.

    Args:
        sample_seed: the sample's seed (from
            [`handmesh_tutorial.dataset.sample_seed`][handmesh_tutorial.dataset.sample_seed]).
        kind: ``"hand-hand"``, ``"hand-object"``, ``"hand-chain"`` or ``"mixed"`` (one of the
            three drawn from the seed).
        image_size: square image side, pixels.
        renderer: a [`Renderer`][handmesh_tutorial.render.Renderer] of that size; ``None`` uses the
            per-process one ([`get_renderer`][handmesh_tutorial.interact.get_renderer]).
        config: generator parameters
            ([`InteractionConfig`][handmesh_tutorial.interact.InteractionConfig]).
        limits: shortcut for ``config.limits``: ``"anatomical"`` (the default config's) or
            ``"paper"`` (±60° on every axis).

    Returns:
        The sample dict of [`render_scene`][handmesh_tutorial.interact.render_scene].

    Raises:
        ValueError: unknown kind or limits.
        InteractionError: the scene could not be generated.
    """
    if kind == "mixed":
        kind = _choose_kind(sample_seed)
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS} or 'mixed', got {kind!r}")
    cfg = config or InteractionConfig()
    if limits is not None and limits != cfg.limits:
        cfg = InteractionConfig(**{**asdict(cfg), "limits": limits})
    scene_ss, view_ss, _ = np.random.SeedSequence(int(sample_seed)).spawn(3)
    try:
        scene = build_scene(kind, np.random.default_rng(scene_ss), cfg)
    except InteractionError as e:
        raise InteractionError(kind, int(sample_seed), e.reason) from None
    scene.seed = int(sample_seed)
    return render_scene(scene, np.random.default_rng(view_ss), image_size, renderer)


def render_scene(scene: Scene, rng, image_size: int = 224, renderer=None,
                 occluder_view: float = 0.4, *, share: tuple[float, float] = FRAME_SHARE,
                 focal: tuple[float, float] = FRAME_FOCAL, margin: float = FRAME_MARGIN,
                 photo_prob: float = 0.75) -> dict:
    """Step 6: place a camera, render a scene and measure visibility; the dataset sample dict.

    **Camera** ([`frame_camera`][handmesh_tutorial.interact.frame_camera]): it looks at the target
    hand from a uniformly random direction (or, with probability ``occluder_view``, from around the
    other body's side), with a random roll, at the distance where the hand covers a random share
    (``share``, 45-75 %) of the image side with a focal length of 1.8-3.6 times the side; the whole
    target hand stays at least ``margin`` (8 %) of the side inside the border, like a FreiHAND
    224-px crop. The other body may leave the frame.
    **Light** ([`scene_lights`][handmesh_tutorial.interact.scene_lights]): key, fill, sometimes rim
    and point lights of random colour temperature and exposure, plus an ambient term tinted by the
    background. **Background**
    ([`handmesh_tutorial.render.scene_background`][handmesh_tutorial.render.scene_background]): a
    natural photograph (random crop, flip, defocus, colour jitter; ``photo_prob``) or a procedural
    texture. The renderer draws the scene (image, label mask) and each body alone (the VR
    denominators);
    the image gets a little sensor noise (0-2 grey levels).

    Args:
        scene: a [`Scene`][handmesh_tutorial.interact.Scene].
        rng: ``numpy.random.Generator`` or seed of the view.
        image_size: square image side, pixels.
        renderer: a [`Renderer`][handmesh_tutorial.render.Renderer] of that size, or ``None`` for
            the per-process one.
        occluder_view: probability of a view from the side of the other body (camera direction
            around ``other centre - target centre``), which makes low VRs (occlusion) common.
        share: (min, max) share of the image side covered by the target hand's bounding box.
        focal: (min, max) focal length as a multiple of the image side.
        margin: free border around the target hand, as a fraction of the image side.
        photo_prob: probability of a photograph (else a procedural texture) as background.

    Returns:
        A sample for
        [`handmesh_tutorial.dataset.write_sample`][handmesh_tutorial.dataset.write_sample]:
        ``image`` (S,S,3) uint8, ``scene_mask`` (S,S) int32, ``alone_masks`` {label: (S,S) bool},
        ``meshes`` {label: (vertices (V,3) float32 camera frame metres, faces (F,3) int32)},
        ``joints`` {hand label: (21,3) float32 camera frame}, ``pose`` {hand label: (15,3)}, ``K``
        (3,3), ``vr`` {label: float}, ``kind``, ``target`` (label 1; the left hand in hand-hand
        scenes), ``sides``, ``names``, ``stats`` (`Scene.stats` plus ``camera_distance_m`` (camera
        to scene centre), ``target_distance_m`` (camera to the target hand's box centre),
        ``focal_px`` and ``target_share`` (the hand's box over the image side)).

    Raises:
        InteractionError: a body is not in view.
    """
    from .render import framing, scene_background, srgb_to_linear
    from .visibility import visibility_ratios

    rng = np.random.default_rng(rng)
    r = renderer if renderer is not None else get_renderer(image_size)
    if (r.width, r.height) != (image_size, image_size):
        raise ValueError(f"renderer is {r.width}x{r.height}, image_size is {image_size}")
    tb = scene.body(scene.target)
    centre = 0.5 * (tb.vertices.min(0) + tb.vertices.max(0))
    # a uniformly random view hides the target rarely; with probability occluder_view look from
    # behind the other body, so all VR bins of the paper get filled
    toward = None
    if rng.random() < occluder_view:
        other = [b for b in scene.bodies if b.label != scene.target][0]
        toward = other.vertices.mean(0) - centre
    # never look along the target's forearm from the elbow: the forearm would hide the hand
    avoid = None
    if tb.forearm is not None:
        fv = tb.forearm[0]   # every ring's centroid and the far end (last vertex) are on the axis
        avoid = (fv[-1] - fv.mean(0), np.cos(np.deg2rad(50)))
    # Up to 10 views: a view fails when a body sits behind the camera or ends up entirely out of
    # view (or behind its own forearm); the first good view is used (same bytes as long as it
    # is the first one).
    missing = None
    for _ in range(10):
        R, t, K = frame_camera(tb.vertices, rng, image_size, toward=toward, share=share,
                               focal=focal, margin=margin, avoid=avoid)
        meshes = scene.render_meshes(R, t)
        if min(m[0][:, 2].min() for m in meshes) <= 0.05:  # something behind the camera
            continue
        target_v = tb.vertices @ R.T + t
        depth = float(np.linalg.norm(centre @ R.T + t))
        lights = scene_lights(rng, depth)
        bg = scene_background(rng, image_size, image_size, photo_prob=photo_prob)
        # ambient light: bounced off the surroundings, so tinted by the background's mean colour
        tint = srgb_to_linear(bg.reshape(-1, 3).mean(0) / 255.0)
        tint = 0.6 + 0.4 * tint / max(float(tint.mean()), 1e-3)
        ambient = float(rng.uniform(0.06, 0.2)) * tint
        out = r.render(meshes, K, lights=lights, background=bg, ambient=ambient, alone=True,
                       occluders=scene.scenery_meshes(R, t))
        alone = dict(out.alone_masks)
        missing = [lab for lab, m in alone.items() if not m.any()]
        if not missing:
            break
    else:
        what = f"body {missing[0]} is not in view" if missing else "no view in front of all bodies"
        raise InteractionError(scene.kind, scene.seed, f"{what} (10 camera draws)")
    noise = rng.uniform(0.0, 2.0)
    image = np.clip(out.image + rng.normal(0.0, noise, out.image.shape) + 0.5, 0, 255)
    image = image.astype(np.uint8)
    vr = visibility_ratios(out.labels, alone)
    hands = [b for b in scene.bodies if b.kind == "hand"]
    return {
        "image": image,
        "scene_mask": out.labels.astype(np.int32),
        "alone_masks": alone,
        "meshes": {b.label: ((b.vertices @ R.T + t).astype(np.float32), b.faces.astype(np.int32))
                   for b in scene.bodies},
        "joints": {b.label: (b.joints @ R.T + t).astype(np.float32) for b in hands},
        "pose": {b.label: b.pose.astype(np.float32) for b in hands},
        "K": K,
        "vr": vr,
        "kind": scene.kind,
        "target": scene.target,
        "sides": {b.label: b.side for b in hands},
        "names": {b.label: b.name for b in scene.bodies},
        "stats": {**scene.stats, "camera_distance_m": float(np.linalg.norm(t)),
                  "target_distance_m": depth, "focal_px": float(K[0, 0]),
                  "target_share": framing(target_v, K, image_size, margin)["share"]},
    }


MIN_IMAGE_SIZE, MAX_IMAGE_SIZE = 32, 4096
"""Range of ``image_size`` that
[`generate_interactions`][handmesh_tutorial.interact.generate_interactions] accepts, pixels: below
32 a hand is a few pixels; above 4096 one image needs gigabytes of render buffers.
"""


def generate_interactions(root, kind: str, num: int, seed: int, *, image_size: int = 224,
                          workers: int = 1, balance_vr: bool = False,
                          shard: tuple[int, int] | None = None, limits: str = "anatomical",
                          durable: bool = True, progress: bool = True, max_attempts: int = 100,
                          vr_probe: int = 64):
    """Generate (or resume) an INTER-SH dataset of rendered interactions on disk.

    A thin wrapper of
    [`handmesh_tutorial.dataset.generate_dataset`][handmesh_tutorial.dataset.generate_dataset] with
    ``make_sample = functools.partial(make_sample, kind=..., image_size=..., limits=...)`` and one
    renderer per worker process ([`init_worker`][handmesh_tutorial.interact.init_worker]). Rerunning
    the same call skips the samples already written (resume).

    Args:
        root: output folder.
        kind: ``"hand-hand"``, ``"hand-object"``, ``"hand-chain"`` or ``"mixed"``.
        num: samples of the whole dataset (all shards).
        seed: base seed.
        image_size: square image side, pixels.
        workers: processes.
        balance_vr: spread the target VRs evenly over the paper's VR bins: bins that a probe of
            candidates never reaches (e.g. [0.4, 0.6) for hand-chain scenes) are reported up front
            and left out (see
            [`handmesh_tutorial.dataset.generate_dataset`][handmesh_tutorial.dataset.generate_dataset]).
        shard: ``(k, n)``: only the k-th of n equal index ranges.
        limits: ``"anatomical"`` joint limits (default: natural poses) or ``"paper"`` (±60°
            about every LCS axis, as in the paper).
        durable: fsync every file (slower, safe against power cuts).
        progress: tqdm progress bar.
        max_attempts: candidates per sample (VR balancing rejects some).
        vr_probe: candidates of the VR probe that finds the reachable bins (``balance_vr``).

    Returns:
        The
        [`handmesh_tutorial.dataset.GenerationSummary`][handmesh_tutorial.dataset.GenerationSummary].
    """
    from .dataset import generate_dataset

    # every argument is checked before anything is written (a bad one never leaves a
    # meta.json behind that blocks the corrected rerun); generate_dataset checks the rest
    if kind not in KINDS + ("mixed",):
        raise ValueError(f"kind must be one of {KINDS + ('mixed',)}, got {kind!r}")
    if isinstance(image_size, bool) or not isinstance(image_size, int | np.integer) \
            or not MIN_IMAGE_SIZE <= image_size <= MAX_IMAGE_SIZE:
        raise ValueError(f"image_size must be an integer in [{MIN_IMAGE_SIZE}, "
                         f"{MAX_IMAGE_SIZE}] pixels, got {image_size!r}")
    InteractionConfig(limits=limits)  # validates
    fn = functools.partial(make_sample, kind=kind, image_size=int(image_size), limits=limits)
    kinds = list(KINDS) if kind == "mixed" else kind
    params = {"generator": "handmesh_tutorial.interact", "kind": kind, "limits": limits,
              "config": {k: (list(v) if isinstance(v, tuple) else v)
                         for k, v in asdict(InteractionConfig(limits=limits)).items()}}
    return generate_dataset(root, fn, int(num), int(seed), kinds, shard=shard, workers=workers,
                            progress=progress, params=params, image_size=int(image_size),
                            balance_vr=balance_vr, max_attempts=max_attempts,
                            vr_probe=vr_probe,
                            worker_init=functools.partial(init_worker, int(image_size)),
                            durable=durable)
