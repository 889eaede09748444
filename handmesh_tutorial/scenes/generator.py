"""Steps 1-5 of the paper's algorithm (centre body, second hand, approach, joint moves, repeat)
plus the mesh-level settle: `build_scene`.

World frame, metres; joint angles in radians (the config's steps in degrees). Taught in
notebook 04 ("Generating interactions").
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
from scipy.spatial.transform import Rotation

from ..collision import cylinders_intersect
from ..data import KINDS
from ..lcs import natural_hand_angles
from ._common import _random_direction, _random_rotation, _unit
from .bodies import FOREARM_LENGTH, _ChainBody, _Hand, _hand_assets, _Static
from .config import InteractionConfig, InteractionError
from .contact import _MeshSDF, mesh_contact
from .rig import _Rig
from .scene import Scene, SceneBody

__all__ = ["build_scene"]

_MAX_SETTLE = 0.05


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
        from ..hand import SKIN_TONES

        return int(self.rng.integers(len(SKIN_TONES)))

    def _hand(self, side, label, tone):
        from ..hand import random_shape

        shape = random_shape(self.rng, 1, self.cfg.shape_scale)[0]
        model, _ = _hand_assets(side)
        colors = model.vertex_colors(tone, rng=int(self.rng.integers(2**31)))
        return _Hand(side, shape, self.cfg.limits, label, colors, tone=tone,
                     thumb_zero_elevation=self.cfg.thumb_zero_elevation)

    def _natural_target(self, hand, closure) -> None:
        """Draw the hand's natural target pose (``poses="natural"``): the synergy prior's angles
        inside the hand's own limits."""
        hand.target = hand.art.clip(natural_hand_angles(self.rng, closure, side=hand.side))

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
            natural = cfg.poses == "natural"
            for _ in range(cfg.max_attempts):
                if natural:  # part of the way to its target pose; step 4 goes on from there
                    self._natural_target(centre, cfg.natural_closure)
                    angles = centre.target * rng.uniform(0.4, 1.0)
                else:
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
                from ..objects import OBJECT_KINDS, make_object

                kinds = cfg.object_kinds or OBJECT_KINDS
                kind = kinds[int(rng.integers(len(kinds)))]
                centre = _Static(make_object(kind, int(rng.integers(2**31))), 2)
            else:
                from ..objects import make_chain

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
        if cfg.poses == "natural":  # the second hand starts flat and closes towards its target
            self._natural_target(mover, cfg.natural_closure if self.kind == "hand-hand"
                                 else cfg.grasp_closure)
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
            if mover.rig.collides(centre.rig):
                mover.rig.translate(step * u)  # back to the last valid place
                return travelled
            travelled += step
        mover.rig.translate(travelled * u)
        return None

    # -- steps 4 and 5 -------------------------------------------------------------------------
    def _direction(self, body, j) -> tuple[np.ndarray, float] | None:
        """A joint's move of step 4: ``(unit direction (3,), largest travel in radians)``, or
        ``None`` when the joint does not move. The paper's rule: a random direction (flexion with
        probability ``flexion_bias``), travel up to the limits. Natural poses: straight towards
        the hand's target pose, travel up to it."""
        if j in body.rig.followers:   # driven by its leader (a DIP by its PIP)
            return None
        target = getattr(body, "target", None)
        if target is not None:
            d = target[j - 1] - body.rig.angles[j - 1]
            n = float(np.linalg.norm(d))
            return None if n < 1e-9 else (d / n, n)
        span = body.rig.upper[j - 1] - body.rig.lower[j - 1]
        w = np.asarray(self.cfg.axis_weights, float) if body.kind == "hand" else np.ones(3)
        d = self.rng.normal(size=3) * w * (span > 0)
        if body.kind == "hand":
            flex = self.rng.random() < self.cfg.flexion_bias
            d[1] = abs(d[1]) if flex else -abs(d[1])
        n = np.linalg.norm(d)
        return None if n < 1e-12 else (d / n, np.inf)

    def _blocked(self, body, others, node, cand, limit=None) -> np.ndarray:
        """(K,) bool: candidate angles of ``node`` that collide (other bodies or itself).

        Every (moved cylinder, fixed cylinder) pair of every candidate goes through one call of
        [`collision.cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect];
        candidates after ``limit`` (the first one out of the joint limits) are not tested (False).
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
        hit = cylinders_intersect(a0, a1, ra, b0, b1, rb)
        out = np.zeros(len(cand), bool)
        out[:K] = hit.reshape(K, P).any(1)
        return out

    def joint_moves(self, bodies, centre, mover, u):
        cfg, rng = self.cfg, self.rng
        step = np.deg2rad(cfg.joint_step_deg)
        per_round = max(1, int(round(cfg.sweep_deg / cfg.joint_step_deg)))
        dynamic = [b for b in bodies if b.dynamic]
        # each joint gets one direction (random, or towards its natural target); it moves along
        # it until blocked (contact, a limit, or the target reached)
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
                j, (d, travel) = key[1], active[key]
                others = [o for o in bodies if o is not body]
                a0 = body.rig.angles[j - 1]
                k = np.arange(1, per_round + 1)
                cand = a0 + step * k[:, None] * d
                ok_lim = ((cand >= body.rig.lower[j - 1] - 1e-12)
                          & (cand <= body.rig.upper[j - 1] + 1e-12)).all(1)
                if np.isfinite(travel):   # natural poses: the last step lands on the target
                    cand[k * step >= travel] = a0 + travel * d
                    ok_lim &= (k - 1) * step < travel
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
                    if np.isfinite(travel):
                        active[key] = (d, max(travel - n * step, 0.0))
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
            forearm = normals = None
            if is_hand:
                from ..hand import forearm_colors, forearm_mesh, wrist_seam_normals

                loop = b.model.wrist_loop
                fv, ff = forearm_mesh(v[loop], b.rig.G[0] @ np.array([-1.0, 0.0, 0.0]),
                                      length=FOREARM_LENGTH)
                # the forearm continues the wrist's colours and shading: no ring at the seam
                normals, fn = wrist_seam_normals(v, f, b.model.template.cap_faces, loop, fv, ff)
                fc = forearm_colors(np.asarray(b.colors, float)[loop])
                forearm = (fv, ff, fc, fn)
            out.append(SceneBody(
                label=b.label, name=b.name, kind=b.kind, side=b.side if is_hand else None,
                vertices=v, faces=np.asarray(f, np.int64), colors=np.asarray(b.colors, float),
                cylinders=b.rig.cylinders(), joints=joints[b.label],
                pose=b.art.to_pose(b.rig.angles) if is_hand else None,
                angles=b.rig.angles.copy() if b.rig.num_joints else None,
                shape=b.shape.copy() if is_hand else None, dynamic=b.dynamic, forearm=forearm,
                tone=b.tone if is_hand else None, normals=normals))
        return Scene(self.kind, self.seed, out, target, u, stats, self.history)


def build_scene(kind: str, seed: int | np.random.Generator, config: InteractionConfig | None = None,
                *, record: bool = False, **overrides) -> Scene:
    """Generate one interaction (steps 1-5 of the paper's algorithm, plus the mesh settle).

    Args:
        kind: ``"hand-hand"``, ``"hand-object"`` or ``"hand-chain"``.
        seed: an integer seed or a ``numpy.random.Generator``; same seed -> same scene.
        config: an [`InteractionConfig`][handmesh_tutorial.scenes.config.InteractionConfig]
            (defaults when ``None``).
        record: keep a snapshot of every step in ``Scene.history`` (for figures).
        **overrides: fields of
            [`InteractionConfig`][handmesh_tutorial.scenes.config.InteractionConfig] to change,
            e.g. ``limits="paper"`` (which also selects that limit set's poses, the paper's
            uniform rule, unless ``poses`` is given too).

    Returns:
        A [`Scene`][handmesh_tutorial.scenes.scene.Scene] in the world frame (centre body near the
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
        if "limits" in overrides and "poses" not in overrides:
            overrides = {**overrides, "poses": None}   # the limits' own poses (see the config)
        cfg = InteractionConfig(**{**asdict(cfg), **overrides})
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    s = None if isinstance(seed, np.random.Generator) else seed
    return _Generator(kind, rng, s, cfg, record).run()
