"""The generator's parameters and its failure: `InteractionConfig`, `InteractionError`,
`STOP_REASONS`.

Lengths are in metres, angles in degrees. Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..data import SampleRejected
from ..lcs import THUMB_ZERO_ELEVATION_DEG

__all__ = ["STOP_REASONS", "InteractionConfig", "InteractionError"]


STOP_REASONS: tuple[str, ...] = ("no valid move", "max rounds")
"""Why the joint-move loop (steps 4-5) stopped."""


class InteractionError(RuntimeError, SampleRejected):
    """A scene could not be generated (bounded retries exhausted or an impossible config).

    A [`SampleRejected`][handmesh_tutorial.data.SampleRejected]:
    [`generate_interactions`][handmesh_tutorial.scenes.generate.generate_interactions] and
    [`generate_dataset`][handmesh_tutorial.data.generate_dataset] replace the seed with the next
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
        flexion_bias: probability that a hand joint's direction flexes (rather than extends);
            only with ``poses="uniform"``.
        poses: ``"natural"`` (the default with anatomical limits): every hand draws a target
            pose from the synergy prior
            ([`lcs.natural_hand_angles`][handmesh_tutorial.lcs.synergy.natural_hand_angles]:
            fingers flex together, MCP with PIP, neighbours alike); the centre hand starts part of
            the way there, the second hand flat, and in step 4 each joint moves straight towards
            its target until it gets there or touches the other body. ``"uniform"``: the paper's
            rule: random initial angles (``init_pose_scale``) and a random direction per joint,
            moved until contact or a joint limit (the default with ``limits="paper"``, so that
            the paper's generator stays one setting away). ``None`` picks by ``limits``.
        natural_closure: ``(lo, hi)`` range of the closure (0 open, 1 fist) of the natural
            target poses of hand-hand scenes.
        grasp_closure: the same for the hand of hand-object and hand-chain scenes (it closes
            around the body until contact).
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
            [`objects.OBJECT_KINDS`][handmesh_tutorial.objects.static.OBJECT_KINDS]).
        thumb_zero_elevation: degrees out of the palm plane that the thumb's zero angles mean
            (default 5°,
            [`THUMB_ZERO_ELEVATION_DEG`][handmesh_tutorial.lcs.hands.THUMB_ZERO_ELEVATION_DEG]:
            the joint limits and the pose prior count from a thumb near the palm plane, as
            anatomical ranges do); ``None`` counts from the MakeHuman template's rest thumb,
            35° out of the palm, which turns every thumb about 30° further across the palm. See
            [`lcs.hand_lcs`][handmesh_tutorial.lcs.hands.hand_lcs].
    """

    limits: str = "anatomical"
    approach_step: float = 0.002
    joint_step_deg: float = 2.0
    sweep_deg: float = 30.0
    max_rounds: int = 12
    init_pose_scale: float = 0.5
    axis_weights: tuple[float, float, float] = (0.3, 1.0, 0.15)
    flexion_bias: float = 0.9
    poses: str | None = None
    natural_closure: tuple[float, float] = (0.0, 0.9)
    grasp_closure: tuple[float, float] = (0.4, 1.0)
    shape_scale: float = 1.0
    lateral_offset: float = 0.025
    contact_tol: float = 0.0015
    penetration_tol: float = 0.0015
    settle: bool = True
    reapproach: bool = True
    max_attempts: int = 20
    chain_links: tuple[int, int] = (3, 5)
    object_kinds: tuple[str, ...] | None = None
    thumb_zero_elevation: float | None = THUMB_ZERO_ELEVATION_DEG

    def __post_init__(self):
        if self.limits not in ("paper", "anatomical"):
            raise ValueError(f"limits must be 'paper' or 'anatomical', got {self.limits!r}")
        if self.poses is None:  # frozen dataclass: resolve the default once, here
            object.__setattr__(self, "poses",
                               "natural" if self.limits == "anatomical" else "uniform")
        if self.poses not in ("natural", "uniform"):
            raise ValueError(f"poses must be 'natural' or 'uniform', got {self.poses!r}")
        for name in ("natural_closure", "grasp_closure"):
            lo, hi = getattr(self, name)
            if not 0.0 <= lo <= hi <= 1.0:
                raise ValueError(f"{name} must be (lo, hi) with 0 <= lo <= hi <= 1, got "
                                 f"{getattr(self, name)}")
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
        t = self.thumb_zero_elevation
        if t is not None and (isinstance(t, bool) or not isinstance(t, int | float)
                              or not -30.0 <= t <= 60.0):
            raise ValueError(f"thumb_zero_elevation must be None or degrees in [-30, 60], got "
                             f"{t!r}")
        lo, hi = self.chain_links
        if not 2 <= lo <= hi:
            raise ValueError(f"chain_links must be (lo, hi) with 2 <= lo <= hi, got "
                             f"{self.chain_links}")
