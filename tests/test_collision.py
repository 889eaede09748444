"""Tests of handmesh_tutorial.collision against independent references.

The main reference is an oracle that shares no code with the tested algorithm
(:func:`~handmesh_tutorial.collision.distance_bounds`): alternating projections give points x in
A, y in B (upper bound |x - y| on the distance), support functions give separating slabs (lower
bound); where those bounds stay apart, per-pair SLSQP searches look for a deeper common point or a
wider slab. Every certificate is re-checked with exact closed forms.

Agreement rule (``atol`` = 1e-9 m): a pair whose distance is certified <= 0.5e-9 m must test
True; a pair whose distance is certified > 1.5e-9 m (> sqrt(2) atol) must test False. Pairs in
between, or that the oracle cannot certify, form the tolerance band and are only counted.
"""

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import handmesh_tutorial as hmt
from handmesh_tutorial import collision as C

try:
    import numba  # noqa: F401
    BACKENDS = ("numpy", "numba")
except ImportError:  # the numpy reference alone
    BACKENDS = ("numpy",)

MUST_TRUE = 0.5e-9   # certified distance at most this -> must intersect
MUST_FALSE = 1.5e-9  # certified distance above this -> must not intersect


# ------------------------------------------------------------------------------------------------
# Oracle helpers
# ------------------------------------------------------------------------------------------------

def random_pairs(n, rng, box=0.03):
    """n random finger-sized cylinder pairs: radius 5-12 mm, length 15-50 mm, centres in a box."""
    def one():
        c = rng.uniform(-box, box, (n, 3))
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        length = rng.uniform(0.015, 0.05, n)
        r = rng.uniform(0.005, 0.012, n)
        return c - 0.5 * length[:, None] * d, c + 0.5 * length[:, None] * d, r
    return (*one(), *one())


def near_contact_pairs(n, seed):
    """Random pairs moved to a signed gap +-10^U(-9, -2.5) m along their closest-point direction.

    Separated pairs whose distance the oracle pins down are translated along ``y - x`` so that the
    gap becomes the target (negative: pushed into each other), so both answers occur and many pairs
    lie within micrometres of contact.
    """
    rng = np.random.default_rng(seed)
    a0, a1, ra, b0, b1, rb = random_pairs(3 * n, rng)
    lo, hi, x, y = C.distance_bounds(a0, a1, ra, b0, b1, rb, iters=300, return_points=True)
    ok = np.flatnonzero((lo > 1e-6) & (hi - lo < 1e-12))[:n]
    gap = 10 ** rng.uniform(-9, -2.5, ok.size) * rng.choice([-1.0, 1.0], ok.size)
    nrm = (y[ok] - x[ok]) / hi[ok, None]
    shift = -(hi[ok] - gap)[:, None] * nrm
    return (a0[ok], a1[ok], ra[ok], b0[ok] + shift, b1[ok] + shift, rb[ok]), gap


def certified(a0, a1, ra, b0, b1, rb):
    """Oracle bounds (lower, upper) on the distance, refined per pair where they stay apart."""
    return C.distance_bounds(a0, a1, ra, b0, b1, rb, iters=1000, refine_at=1e-9)


def agreement(result, lo, hi):
    must_t, must_f = hi <= MUST_TRUE, lo > MUST_FALSE
    return {"true": int(must_t.sum()), "false": int(must_f.sum()),
            "band": int((~must_t & ~must_f).sum()),
            "missed": int((must_t & ~result).sum()), "false_hits": int((must_f & result).sum())}


# ------------------------------------------------------------------------------------------------
# Random pairs against the oracle
# ------------------------------------------------------------------------------------------------

def test_oracle_bounds_are_consistent():
    rng = np.random.default_rng(1)
    pairs = random_pairs(500, rng)
    lo, hi = C.distance_bounds(*pairs)
    assert (lo <= hi + 1e-15).all() and (lo >= 0).all()
    # the upper bound is a real distance between points of the two solids; spot-check its pair
    lo2, hi2, x, y = C.distance_bounds(*pairs, return_points=True)
    np.testing.assert_allclose(np.linalg.norm(y - x, axis=1), hi2, atol=1e-15)
    assert np.allclose(C.point_cylinder_distance(x, pairs[0], pairs[1], pairs[2]), 0, atol=1e-12)
    assert np.allclose(C.point_cylinder_distance(y, pairs[3], pairs[4], pairs[5]), 0, atol=1e-12)


def test_random_pairs_agree_with_oracle():
    n = min(hmt.budget().test_pairs, 2000)
    pairs = random_pairs(n, np.random.default_rng(2))
    bounds = certified(*pairs)
    for backend in BACKENDS:
        counts = agreement(C.cylinders_intersect(*pairs, backend=backend), *bounds)
        print("uniform pairs:", backend, counts)
        assert counts["missed"] == 0 and counts["false_hits"] == 0
        assert counts["band"] <= 0.01 * n


def test_near_contact_pairs_agree_with_oracle():
    n = min(hmt.budget().test_pairs, 2000)
    pairs, _ = near_contact_pairs(min(n, 800), seed=3)
    bounds = certified(*pairs)
    for backend in BACKENDS:
        res = C.cylinders_intersect(*pairs, backend=backend)
        counts = agreement(res, *bounds)
        print("near-contact pairs:", backend, counts)
        assert counts["missed"] == 0 and counts["false_hits"] == 0
        # both answers occur often; the band holds the pairs placed within ~1e-9 m of contact
        assert counts["true"] > 0.3 * len(res) and counts["false"] > 0.3 * len(res)
        assert counts["band"] <= 0.1 * len(res)


def test_near_parallel_pairs_agree_with_oracle():
    # the numerically delicate family: axes (anti)parallel up to 1e-12..1e-3 rad, side by side or
    # end to end, touching or nearly so
    rng = np.random.default_rng(6)
    n = 400
    a0, a1, ra, _, _, rb = random_pairs(n, rng)
    d = (a1 - a0) / np.linalg.norm(a1 - a0, axis=1)[:, None]
    la = np.linalg.norm(a1 - a0, axis=1)
    axis = rng.normal(size=(n, 3))
    tilt = Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=1)[:, None]
                                * 10 ** rng.uniform(-12, -3, n)[:, None]).as_matrix()
    db = np.einsum("nij,nj->ni", tilt, d) * rng.choice([-1.0, 1.0], n)[:, None]
    side = rng.normal(size=(n, 3))
    side -= np.sum(side * d, axis=1)[:, None] * d
    side /= np.linalg.norm(side, axis=1)[:, None]
    lb = rng.uniform(0.015, 0.05, n)
    end_to_end = rng.random(n) < 0.5
    gap = 10 ** rng.uniform(-9, -3, n) * rng.choice([-1.0, 1.0], n)
    along = d * (0.5 * (la + lb) + gap)[:, None]
    across = side * (ra + rb + gap)[:, None] + d * rng.uniform(-0.02, 0.02, n)[:, None]
    offset = np.where(end_to_end[:, None], along, across)
    cb = 0.5 * (a0 + a1) + offset
    pairs = (a0, a1, ra, cb - 0.5 * lb[:, None] * db, cb + 0.5 * lb[:, None] * db, rb)
    bounds = certified(*pairs)
    for backend in BACKENDS:
        counts = agreement(C.cylinders_intersect(*pairs, backend=backend), *bounds)
        print("near-parallel pairs:", backend, counts)
        assert counts["missed"] == 0 and counts["false_hits"] == 0
        assert counts["band"] <= 0.05 * n and min(counts["true"], counts["false"]) > 0.2 * n


def test_cylinder_implies_capsule_and_capsule_is_segment_distance():
    pairs, _ = near_contact_pairs(1000, seed=4)
    cyl = C.cylinders_intersect(*pairs)
    cap = C.capsules_intersect(*pairs)
    assert not (cyl & ~cap).any()
    assert (cap & ~cyl).any()  # capsules stick out past the end caps
    d = C.segment_segment_distance(pairs[0], pairs[1], pairs[3], pairs[4])
    np.testing.assert_array_equal(cap, d <= pairs[2] + pairs[5] + C.ATOL)


def test_against_fcl_away_from_contact():
    fcl = pytest.importorskip("fcl")
    pairs, gap = near_contact_pairs(300, seed=5)
    res = C.cylinders_intersect(*pairs)
    # fcl's GJK/EPA has its own tolerance near contact: compare 0.1 mm or more from it (a pair
    # pushed 0.1 mm along its former closest-point direction overlaps by about that much)
    clear = np.abs(gap) > 1e-4

    def obj(p0, p1, r):
        d = p1 - p0
        length = np.linalg.norm(d)
        rot = Rotation.align_vectors([d / length], [[0.0, 0.0, 1.0]])[0].as_matrix()
        return fcl.CollisionObject(fcl.Cylinder(r, length), fcl.Transform(rot, 0.5 * (p0 + p1)))

    for k in np.flatnonzero(clear):
        a = obj(pairs[0][k], pairs[1][k], pairs[2][k])
        b = obj(pairs[3][k], pairs[4][k], pairs[5][k])
        got = fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0
        assert got == res[k], (k, gap[k])


# ------------------------------------------------------------------------------------------------
# Hand-made special cases: A is the z axis from 0 to L; B is placed at signed gap g
# ------------------------------------------------------------------------------------------------

L, RA, RB, LB = 0.03, 0.008, 0.006, 0.025


def _rot(axis, angle):
    return Rotation.from_rotvec(np.asarray(axis, float) / np.linalg.norm(axis) * angle).as_matrix()


def _about(points, pivot, R):
    return (np.asarray(points) - pivot) @ R.T + pivot


def _case(name, g):
    """(b0, b1, rb) of special case ``name`` at gap g (B's distance to A is g for g >= 0)."""
    s2 = np.sqrt(0.5)
    if name == "parallel side-side":
        d = RA + RB + g
        return [d, 0, 0.005], [d, 0, 0.005 + LB], RB
    if name == "anti-parallel side-side":
        d = RA + RB + g
        return [d, 0, 0.005 + LB], [d, 0, 0.005], RB
    if name == "coaxial end-to-end (cap face on cap face)":
        return [0, 0, L + g], [0, 0, L + g + LB], RB
    if name == "coaxial anti-parallel end-to-end":
        return [0, 0, L + g + LB], [0, 0, L + g], RB
    if name == "cap face on cap face, offset axes":
        return [0.004, 0, L + g], [0.004, 0, L + g + LB], RB
    if name in ("rim on rim, parallel", "rim on rim, tilted"):
        p = np.array([RA, 0, L]) + 0.5 * g * np.array([s2, 0, s2])   # B = A mirrored through p
        b0, b1 = 2 * p - np.array([0, 0, 0]), 2 * p - np.array([0, 0, L])
        if name == "rim on rim, tilted":  # turn B about the contact normal through its rim point
            pivot = 2 * p - np.array([RA, 0, L])
            b0, b1 = _about([b0, b1], pivot, _rot([1, 0, 1], np.deg2rad(40)))
        return b0, b1, RA
    if name == "rim on side, coplanar axes":
        phi = np.deg2rad(30)
        c = np.array([RA + g + RB * np.sin(phi), 0, L / 2])
        return c, c + LB * np.array([np.cos(phi), 0, np.sin(phi)]), RB
    if name == "rim on cap face, coplanar axes":
        phi = np.deg2rad(35)
        c = np.array([0.002 - RB * np.cos(phi), 0, L + RB * np.sin(phi) + g])
        return c, c + LB * np.array([np.sin(phi), 0, np.cos(phi)]), RB
    if name == "T: side on cap face (intersecting axis lines)":
        return [-LB / 2, 0, L + RB + g], [LB / 2, 0, L + RB + g], RB
    if name == "T: cap face on side (intersecting axis lines)":
        return [RA + g, 0, L / 2], [RA + g + LB, 0, L / 2], RB
    if name == "crossing at 90 deg, side-side":
        d = RA + RB + g
        return [d, -LB / 2, L / 2], [d, LB / 2, L / 2], RB
    if name == "skew at 20 deg, side-side":
        d, w = RA + RB + g, np.array([0, np.cos(0.35), np.sin(0.35)])
        c = np.array([d, 0, L / 2])
        return c - 0.5 * LB * w, c + 0.5 * LB * w, RB
    if name == "near-parallel (1e-7 rad), side-side":
        d = RA + RB + g
        b = np.array([[d, 0, 0.005], [d, 0, 0.005 + LB]])
        b0, b1 = _about(b, np.array([d, 0, 0.015]), _rot([1, 0, 0], 1e-7))
        return b0, b1, RB
    if name == "near-coaxial (1e-9 rad), cap on cap":
        b = np.array([[0, 0, L + g], [0, 0, L + g + LB]])
        b0, b1 = _about(b, np.array([RB, 0, L + g]), _rot([0, 1, 0], 1e-9))
        return b0, b1, RB
    raise KeyError(name)


GAP_CASES = ("parallel side-side", "anti-parallel side-side",
             "coaxial end-to-end (cap face on cap face)", "coaxial anti-parallel end-to-end",
             "cap face on cap face, offset axes", "rim on rim, parallel", "rim on rim, tilted",
             "rim on side, coplanar axes", "rim on cap face, coplanar axes",
             "T: side on cap face (intersecting axis lines)",
             "T: cap face on side (intersecting axis lines)", "crossing at 90 deg, side-side",
             "skew at 20 deg, side-side", "near-parallel (1e-7 rad), side-side",
             "near-coaxial (1e-9 rad), cap on cap")
GAPS = (-1e-3, -1e-6, 0.0, 1e-6, 1e-3)


def _moved(points, seed):
    """A fixed random rigid motion (so nothing is axis-aligned)."""
    R = Rotation.random(random_state=seed).as_matrix()
    return np.asarray(points, float) @ R.T + np.array([0.1, -0.2, 0.35])


@pytest.mark.parametrize("name", GAP_CASES)
def test_special_cases(name):
    a0, a1 = np.array([0.0, 0, 0]), np.array([0.0, 0, L])
    for g in GAPS:
        b0, b1, rb = _case(name, g)
        expected = g <= 0
        for seed in (None, 7):
            pa0, pa1, pb0, pb1 = (np.asarray(p, float) for p in (a0, a1, b0, b1))
            if seed is not None:
                pa0, pa1, pb0, pb1 = _moved([pa0, pa1, pb0, pb1], seed)
            for backend in BACKENDS:
                got = [bool(C.cylinders_intersect(pa0, pa1, RA, pb0, pb1, rb, backend=backend)),
                       bool(C.cylinders_intersect(pb0, pb1, rb, pa0, pa1, RA,   # swapped bodies
                                                  backend=backend)),
                       bool(C.cylinders_intersect(pa1, pa0, RA, pb1, pb0, rb,   # swapped ends
                                                  backend=backend))]
                assert got == [expected] * 3, (name, g, seed, backend, got)
            assert not expected or C.capsules_intersect(pa0, pa1, RA, pb0, pb1, rb)
        if abs(g) == 1e-3:  # the independent oracle agrees with the construction
            lo, hi = certified(*(np.atleast_2d(x) for x in (a0, a1, RA, b0, b1, rb)))
            assert (hi[0] <= MUST_TRUE) if expected else (lo[0] > 0.9e-3), (name, lo, hi)


def _axis_aligned_layouts():
    """B (radius RB, length LB) along x, y (both perpendicular to A) or z (parallel / coaxial),
    its centre on grids within a few mm of contact with A (the z axis from 0 to L, radius RA):
    over and beside A's top cap, beside A's side, stacked cap on cap. Exact axis alignment, so
    a line parallel to a cap plane meets the trust-region step with kappa == 0 exactly."""
    layouts = []
    ys = np.arange(0.0, 0.0201, 0.001)
    for axis in ((1.0, 0, 0), (0, 1.0, 0)):   # perpendicular: over / beside the top cap
        for cx in (0.0, 0.012):
            for cy in ys:
                for cz in L + np.arange(-0.004, 0.0101, 0.0005):
                    layouts.append((axis, (cx, cy, cz)))
    for cy in ys:                              # perpendicular, crossing beside the side
        layouts.append(((1.0, 0, 0), (0.0, RA + RB + 0.0005, L / 2)))
        layouts.append(((1.0, 0, 0), (0.0, cy, -RB - 0.0003)))   # under the bottom cap
    for cy in ys:                              # parallel, coaxial (cy = 0), cap on cap
        for cz in L + LB / 2 + np.arange(-0.003, 0.0031, 0.0005):
            layouts.append(((0, 0, 1.0), (0.0, cy, cz)))
        layouts.append(((0, 0, 1.0), (0.0, cy, L / 2)))          # side by side
    out = []
    for axis, c in layouts:
        c, w = np.asarray(c, float), np.asarray(axis)
        out.append((c - 0.5 * LB * w, c + 0.5 * LB * w))
    b0, b1 = (np.array(x) for x in zip(*out, strict=True))
    return b0, b1


def test_axis_aligned_layouts_agree_with_fcl():
    """Perpendicular, parallel and coaxial axis-aligned pairs against python-fcl (an independent
    GJK implementation). Only layouts whose fcl answer is the same with both cylinders grown and
    shrunk by 0.05 mm (radius and each end) are compared, so the separation or overlap is clear
    of fcl's own contact tolerance. Both backends must give fcl's answer (and each other's)."""
    fcl = pytest.importorskip("fcl")
    b0, b1 = _axis_aligned_layouts()
    n = len(b0)
    a0, a1 = np.zeros((n, 3)), np.tile([0.0, 0.0, L], (n, 1))

    def obj(p0, p1, r, grow):
        d = p1 - p0
        length = np.linalg.norm(d)
        rot = Rotation.align_vectors([d / length], [[0.0, 0.0, 1.0]])[0].as_matrix()
        return fcl.CollisionObject(fcl.Cylinder(r + grow, length + 2 * grow),
                                   fcl.Transform(rot, 0.5 * (p0 + p1)))

    def collide(k, grow):
        return fcl.collide(obj(a0[k], a1[k], RA, grow), obj(b0[k], b1[k], RB, grow),
                           fcl.CollisionRequest(), fcl.CollisionResult()) > 0

    expected = np.array([collide(k, 0.0) for k in range(n)])
    clear = np.array([collide(k, 5e-5) == expected[k] == collide(k, -5e-5) for k in range(n)])
    assert clear.sum() > 0.9 * n and 0.2 < expected[clear].mean() < 0.8  # both answers, many
    for backend in BACKENDS:
        got = C.cylinders_intersect(a0, a1, RA, b0, b1, RB, backend=backend)
        swapped = C.cylinders_intersect(b0, b1, RB, a0, a1, RA, backend=backend)
        for res in (got, swapped):
            bad = np.flatnonzero(clear & (res != expected))
            assert bad.size == 0, (backend, [(b0[k], b1[k], expected[k]) for k in bad[:5]])
    if len(BACKENDS) == 2:
        np.testing.assert_array_equal(
            C.cylinders_intersect(a0, a1, RA, b0, b1, RB, backend="numpy"),
            C.cylinders_intersect(a0, a1, RA, b0, b1, RB, backend="numba"))


def test_line_parallel_to_a_cap_passing_beside_it_is_not_inside_the_disk():
    """B perpendicular to A, 0.6 mm from A's top rim: its axis runs 7 mm above the cap plane
    (less than RB) but 15 mm from A's axis (more than RA), so B's foot on the cap plane lies
    outside A's cap disk. The distance is known in closed form."""
    ra, rb, off, h = 0.01, 0.008, 0.015, 0.007
    a0, a1 = [0.0, 0, 0], [0.0, 0, 0.04]
    b0, b1 = [-0.03, off, 0.04 + h], [0.03, off, 0.04 + h]
    gap = np.hypot(off - ra, h) - rb   # from A's rim point (0, ra, 0.04) to B's surface
    assert 5e-4 < gap < 7e-4
    lo, hi = C.distance_bounds(*(np.atleast_2d(x) for x in (a0, a1, ra, b0, b1, rb)))
    np.testing.assert_allclose([lo[0], hi[0]], gap, atol=1e-9)
    for backend in BACKENDS:
        assert not C.cylinders_intersect(a0, a1, ra, b0, b1, rb, backend=backend), backend
        assert not C.cylinders_intersect(b0, b1, rb, a0, a1, ra, backend=backend), backend
        # moved by gap + 0.1 mm towards A's rim: the rim now pokes 0.1 mm into B
        shift = -(gap + 1e-4) * np.array([0.0, off - ra, h]) / np.hypot(off - ra, h)
        assert C.cylinders_intersect(a0, a1, ra, np.add(b0, shift), np.add(b1, shift), rb,
                                     backend=backend), backend


@pytest.mark.parametrize("b0, b1, rb", [
    ([-LB / 2, 0, L / 2], [LB / 2, 0, L / 2], RB),             # axes intersect inside both
    ([0, 0, L], [LB, 0, L], RB),                                # zero separation: axis end on axis
    ([0, 0, L], [LB * 0.5, 0, L + LB * 0.866], RB),             # V: the axes share an end point
    ([0, 0, 0], [0, 0, L], RA),                                 # identical
    ([0, 0, 0.01], [0, 0, 0.02], 0.002),                        # B inside A
    ([0, 0, -0.01], [0, 0, L + 0.01], 0.002),                   # coaxial, B pierces A
    ([0, 0, 0.02], [0, 0, 0.05], RB),                           # coaxial, overlapping
    ([0, 0, 0.02], [0, 0.0, -0.01], 0.02),                      # coaxial anti-parallel, wider
])
def test_always_intersecting_cases(b0, b1, rb):
    a0, a1 = [0.0, 0, 0], [0.0, 0, L]
    for backend in BACKENDS:
        assert C.cylinders_intersect(a0, a1, RA, b0, b1, rb, backend=backend)
        assert C.cylinders_intersect(*_moved([b0, b1], 3), rb, *_moved([a0, a1], 3), RA,
                                     backend=backend)


def test_capsule_differs_near_end_caps():
    # coaxial, 1 mm apart: the cylinders miss, their capsules (round ends) overlap
    args = ([0, 0, 0], [0, 0, L], RA, [0, 0, L + 1e-3], [0, 0, L + 0.02], RB)
    assert not C.cylinders_intersect(*args) and C.capsules_intersect(*args)


def test_atol_semantics():
    for g in (0.3e-9, 0.9e-9):   # within atol: touching
        assert C.cylinders_intersect(*_case_args("parallel side-side", g))
    assert not C.cylinders_intersect(*_case_args("parallel side-side", 1.6e-9))
    assert not C.cylinders_intersect(*_case_args("parallel side-side", 1e-12), atol=0.0)
    assert C.cylinders_intersect(*_case_args("parallel side-side", 4e-7), atol=1e-6)


def _case_args(name, g):
    b0, b1, rb = _case(name, g)
    return [0.0, 0, 0], [0.0, 0, L], RA, b0, b1, rb


# ------------------------------------------------------------------------------------------------
# Properties (hypothesis)
# ------------------------------------------------------------------------------------------------

coord = st.floats(-0.03, 0.03)
direction = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
    lambda d: np.linalg.norm(d) > 0.1)
cylinder = st.tuples(st.tuples(coord, coord, coord), direction, st.floats(0.015, 0.05),
                     st.floats(0.005, 0.012))


def _ends(cyl):
    c, d, length, r = cyl
    d = np.asarray(d) / np.linalg.norm(d)
    return np.asarray(c) - 0.5 * length * d, np.asarray(c) + 0.5 * length * d, r


def _in_band(a0, a1, ra, b0, b1, rb):
    lo, hi = certified(*(np.atleast_2d(x) for x in (a0, a1, ra, b0, b1, rb)))
    return not (hi[0] <= MUST_TRUE or lo[0] > MUST_FALSE)


@settings(max_examples=150, deadline=None)
@given(cylinder, cylinder, st.integers(0, 2 ** 31))
def test_properties(ca, cb, seed):
    a0, a1, ra = _ends(ca)
    b0, b1, rb = _ends(cb)
    ref = bool(C.cylinders_intersect(a0, a1, ra, b0, b1, rb))
    R = Rotation.random(random_state=seed).as_matrix()
    t = np.random.default_rng(seed).uniform(-1, 1, 3)
    variants = {
        "symmetry": C.cylinders_intersect(b0, b1, rb, a0, a1, ra),
        "swap ends": C.cylinders_intersect(a1, a0, ra, b1, b0, rb),
        "rigid motion": C.cylinders_intersect(a0 @ R.T + t, a1 @ R.T + t, ra,
                                              b0 @ R.T + t, b1 @ R.T + t, rb),
    }
    for name, got in variants.items():
        if bool(got) != ref:
            assert _in_band(a0, a1, ra, b0, b1, rb), name
    if ref:
        assert C.capsules_intersect(a0, a1, ra, b0, b1, rb)


# ------------------------------------------------------------------------------------------------
# Batching, validation, helpers
# ------------------------------------------------------------------------------------------------

def test_broadcasting_matches_loop():
    rng = np.random.default_rng(8)
    a0, a1, ra, b0, b1, rb = random_pairs(7, rng)
    grid = C.cylinders_intersect(a0[:, None], a1[:, None], ra[:, None],
                                 b0[None], b1[None], rb[None])
    assert grid.shape == (7, 7)
    for i in range(7):
        for j in range(7):
            assert grid[i, j] == C.cylinders_intersect(a0[i], a1[i], ra[i], b0[j], b1[j], rb[j])
    assert C.cylinders_intersect(a0, a1, 0.01, b0[0], b1[0], 0.01).shape == (7,)
    assert C.capsules_intersect(a0[:, None], a1[:, None], ra[:, None], b0, b1, rb).shape == (7, 7)


@pytest.mark.parametrize("args, match", [
    (([0, 0], [0, 0, 1], 0.1, [1, 0, 0], [1, 0, 1], 0.1), "a0 must have shape"),
    (([0, 0, 0], [0, 0, 1], 0.1, [1, 0, np.nan], [1, 0, 1], 0.1), "b0 contains NaN"),
    (([0, 0, 0], [0, 0, 0], 0.1, [1, 0, 0], [1, 0, 1], 0.1), "axis a0->a1 has zero length"),
    (([0, 0, 0], [0, 0, 1], 0.1, [1, 0, 0], [1, 0, 0], 0.1), "axis b0->b1 has zero length"),
    (([0, 0, 0], [0, 0, 1], -0.1, [1, 0, 0], [1, 0, 1], 0.1), "ra must be non-negative"),
    (([0, 0, 0], [0, 0, 1], 0.1, [1, 0, 0], [1, 0, 1], np.inf), "rb contains NaN or inf"),
    ((np.zeros((3, 3)), np.ones((3, 3)), 0.1, np.zeros((2, 3)), np.ones((2, 3)), 0.1),
     "do not broadcast"),
])
def test_validation(args, match):
    for fn in (C.cylinders_intersect, C.capsules_intersect):
        with pytest.raises(ValueError, match=match):
            fn(*args)
    for backend in BACKENDS:
        with pytest.raises(ValueError, match=match):
            C.cylinders_intersect(*args, backend=backend)


def test_zero_radius_is_a_segment():
    # a radius-0 cylinder is its axis segment: it meets A exactly when the segment does
    assert C.cylinders_intersect([0, 0, 0], [0, 0, L], RA, [RA - 1e-4, -1, L / 2],
                                 [RA - 1e-4, 1, L / 2], 0.0)
    assert not C.cylinders_intersect([0, 0, 0], [0, 0, L], RA, [RA + 1e-4, -1, L / 2],
                                     [RA + 1e-4, 1, L / 2], 0.0)


def test_segment_distance_against_dense_sampling():
    rng = np.random.default_rng(9)
    p0, p1, _, q0, q1, _ = random_pairs(50, rng)
    d, s, t = C.segment_segment_distance(p0, p1, q0, q1, return_params=True)
    grid = np.linspace(0, 1, 401)
    for k in range(50):
        pa = p0[k] + grid[:, None] * (p1[k] - p0[k])
        pb = q0[k] + grid[:, None] * (q1[k] - q0[k])
        dense = np.linalg.norm(pa[:, None] - pb[None], axis=2).min()
        assert d[k] <= dense + 1e-15 and dense - d[k] < 2e-4
        np.testing.assert_allclose(
            np.linalg.norm(p0[k] + s[k] * (p1[k] - p0[k]) - q0[k] - t[k] * (q1[k] - q0[k])), d[k])


def test_point_distance_projection_support():
    rng = np.random.default_rng(10)
    a0, a1, ra, *_ = random_pairs(200, rng)
    x = rng.uniform(-0.06, 0.06, (200, 3))
    proj = C.project_to_cylinder(x, a0, a1, ra)
    np.testing.assert_allclose(C.point_cylinder_distance(x, a0, a1, ra),
                               np.linalg.norm(x - proj, axis=1), atol=1e-15)
    assert np.allclose(C.point_cylinder_distance(proj, a0, a1, ra), 0, atol=1e-15)
    # the support value is reached by a rim point and bounds every point of the cylinder
    n = rng.normal(size=(200, 3))
    h = C.cylinder_support(n, a0, a1, ra)
    assert (np.sum(n * proj, axis=1) <= h + 1e-15).all()
    assert C.sphere_cylinder_intersect(proj[0] + [0, 0, 0.002], 0.002, a0[0], a1[0], ra[0])


# ------------------------------------------------------------------------------------------------
# Bodies
# ------------------------------------------------------------------------------------------------

def test_cylinders_dataclass():
    a = C.Cylinders(np.zeros((2, 3)), np.ones((2, 3)), [0.01, 0.02], ("a", "b"), adjacent=[[1, 0]])
    b = C.ring_cylinders([0, 0, 1], [0, 0, 1], 0.05, 0.01, n=6)
    ab = C.Cylinders.concat([a, b])
    assert len(ab) == 8 and ab.names[:2] == ("a", "b") and ab.names[2] == "ring_0"
    assert [0, 1] in ab.adjacent.tolist() and [2, 3] in ab.adjacent.tolist()
    assert [2, 7] in ab.adjacent.tolist()  # the ring closes
    R, t = Rotation.random(random_state=0).as_matrix(), np.array([1.0, 2, 3])
    moved = ab.transform(R, t)
    np.testing.assert_allclose(moved.p1, ab.p1 @ R.T + t)
    np.testing.assert_allclose(moved.length, ab.length)
    sub = ab.subset([0, 1, 2])
    assert len(sub) == 3 and sub.adjacent.tolist() == [[0, 1]]
    with pytest.raises(ValueError, match="radius must be finite and non-negative"):
        C.Cylinders(np.zeros((1, 3)), np.ones((1, 3)), [-1.0])
    with pytest.raises(ValueError, match="p1 must have shape"):
        C.Cylinders(np.zeros((2, 3)), np.ones((1, 3)), [1.0, 1.0])
    with pytest.raises(ValueError, match="names must have 2 entries"):
        C.Cylinders(np.zeros((2, 3)), np.ones((2, 3)), [1.0, 1.0], ("x",))


def test_ring_and_box_primitives():
    ring = C.ring_cylinders([0, 0, 0], [0, 0, 2], 0.02, 0.004, n=12)
    assert np.allclose(np.linalg.norm(ring.p0, axis=1), 0.02)
    assert np.allclose(ring.p0[:, 2], 0) and np.allclose(ring.radius, 0.004)
    # a rod through the hole misses the ring, one through the tube hits it
    rod = C.Cylinders([[0, 0, -0.05]], [[0, 0, 0.05]], [0.01])
    assert not C.bodies_collide(ring, rod)
    assert C.bodies_collide(ring, rod.transform(np.eye(3), [0.02, 0, 0]))
    # the box cylinders contain the box
    R = Rotation.random(random_state=1).as_matrix()
    box = C.box_cylinders([0.1, 0, 0], R, [0.03, 0.01, 0.02], cells=2)
    u = np.random.default_rng(0).uniform(-1, 1, (2000, 3)) * [0.03, 0.01, 0.02]
    pts = u @ R.T + [0.1, 0, 0]
    d = C.point_cylinder_distance(pts[:, None], box.p0[None], box.p1[None], box.radius[None])
    assert (d.min(1) <= 1e-12).all()


def test_fit_cylinders_recovers_a_cylinder():
    rng = np.random.default_rng(11)
    ang, z = rng.uniform(0, 2 * np.pi, 500), rng.uniform(0, 0.04, 500)
    v = np.c_[0.01 * np.cos(ang), 0.01 * np.sin(ang), z]
    body = C.fit_cylinders(v, [[[0, 0, 0], [0, 0, 0.04]]], np.zeros(500, int), percentile=100)
    np.testing.assert_allclose(body.radius, [0.01])
    assert C.coverage(v, body)["fraction_outside"] == 0.0
    with pytest.raises(ValueError, match="assignment must have shape"):
        C.fit_cylinders(v, [[[0, 0, 0], [0, 0, 0.04]]], np.zeros(3, int))


# ------------------------------------------------------------------------------------------------
# The hand
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def hands():
    import torch
    torch.set_num_threads(1)
    return {side: hmt.hand.HandModel(side) for side in ("right", "left")}


def _posed(model, name):
    import torch
    pose = torch.as_tensor(hmt.hand.example_pose(name, model.side))[None]
    return model(pose=pose)


@pytest.mark.parametrize("side", ["right", "left"])
def test_hand_cylinders_cover_the_mesh(hands, side):
    model = hands[side]
    for name in ("flat", "fist", "pinch", "spread"):
        out = _posed(model, name)
        body = C.hand_cylinders(out, model=model)
        assert len(body) == 20 and body.names == C.HAND_CYLINDER_NAMES
        cov = C.coverage(out.vertices[0], body)
        assert cov["fraction_outside"] < 0.15 and cov["max_outside_mm"] < 8.0, (name, cov)
        assert (body.radius > 0.004).all() and (body.radius < 0.025).all()


def test_left_hand_is_mirrored_right(hands):
    right = C.hand_cylinders(_posed(hands["right"], "fist"), model=hands["right"])
    left = C.hand_cylinders(_posed(hands["left"], "fist"), model=hands["left"])
    flip = np.array([1.0, 1.0, -1.0])
    np.testing.assert_allclose(left.p0, right.p0 * flip, atol=1e-6)
    np.testing.assert_allclose(left.radius, right.radius, atol=1e-6)


def test_self_collisions(hands):
    model = hands["right"]
    for name in ("flat", "spread", "pinch", "fist", "point"):   # natural poses: no collision
        i, j = C.self_collisions(C.hand_cylinders(_posed(model, name), model=model))
        assert i.size == 0, name
    # the middle finger swung 40 degrees sideways through the index finger
    cross = torch.zeros(1, 15, 3)
    cross[0, 3] = torch.tensor([0.0, np.deg2rad(40), 0.0])
    body = C.hand_cylinders(model(pose=cross), model=model)
    i, j = C.self_collisions(body)
    pairs = {(body.names[a], body.names[b]) for a, b in zip(i, j, strict=True)}
    assert ("index_2", "middle_2") in pairs
    # the exact cylinders (no compression) of a fist touch: fingers rest on each other
    fist = C.hand_cylinders(_posed(model, "fist"), model=model)
    assert C.self_collisions(fist, compression=0.0)[0].size > 0
    with pytest.raises(ValueError, match="compression"):
        C.self_collisions(fist, compression=1.0)
    body = C.Cylinders(body.p0, body.p1, body.radius * (1 - C.SELF_CONTACT_COMPRESSION),
                       body.names, body.parts, body.adjacent)
    i, j = C.self_collisions(body, compression=0.0)
    adj = {tuple(p) for p in body.adjacent.tolist()}
    assert not any((a, b) in adj for a, b in zip(i, j, strict=True))
    # brute force over all non-adjacent pairs gives the same set
    k, m = np.triu_indices(len(body), 1)
    hit = C.cylinders_intersect(body.p0[k], body.p1[k], body.radius[k],
                                body.p0[m], body.p1[m], body.radius[m])
    brute = {(a, b) for a, b, h in zip(k, m, hit, strict=True) if h and (a, b) not in adj}
    assert brute == set(zip(i.tolist(), j.tolist(), strict=True))


def test_hand_vs_hand_queries(hands):
    model = hands["right"]
    a = C.hand_cylinders(_posed(model, "flat"), model=model)
    for dy, expect in ((0.3, False), (0.03, True)):
        b = a.transform(np.eye(3), [0.0, dy, 0.0])
        assert C.bodies_collide(a, b) == expect
        i, j = C.colliding_pairs(a, b)
        full = C.cylinders_intersect(a.p0[:, None], a.p1[:, None], a.radius[:, None],
                                     b.p0[None], b.p1[None], b.radius[None])
        expected = set(zip(*np.nonzero(full), strict=True))
        assert set(zip(i.tolist(), j.tolist(), strict=True)) == expected
        assert (i.size > 0) == expect
    # vertices without a model: nearest-segment assignment still covers the mesh reasonably
    out = _posed(model, "flat")
    body = C.hand_cylinders(out.vertices, out.joints)
    assert C.coverage(out.vertices[0], body)["max_outside_mm"] < 10


# ------------------------------------------------------------------------------------------------
# The compiled kernels (numba) against the numpy reference
# ------------------------------------------------------------------------------------------------

def _adversarial_pairs(rng, n):
    """Pairs built to hit every branch: exact contact, parallel / anti-parallel / coaxial axes,
    shared end points, zero radii, identical and nested cylinders, tiny and huge scales."""
    a0, a1, ra, b0, b1, rb = (np.array(x, dtype=float) for x in random_pairs(n, rng))
    d = a1 - a0
    kind = rng.integers(0, 8, n)
    t = rng.uniform(-0.5, 1.5, (n, 1))
    side = np.cross(d, rng.normal(size=(n, 3)))
    side /= np.linalg.norm(side, axis=1)[:, None]
    gap = rng.choice([0.0, 1e-12, -1e-12, 5e-10, -5e-10, 2e-9, 1e-6], n)
    touch = (ra + rb + gap)[:, None] * side
    par = kind == 0            # parallel, side by side at a gap around 0
    b0[par], b1[par] = (a0 + t * d + touch)[par], (a1 + t * d + touch)[par]
    anti = kind == 1           # anti-parallel
    b0[anti], b1[anti] = (a1 + touch)[anti], (a0 + touch)[anti]
    coax = kind == 2           # coaxial, end to end at a gap around 0
    u = d / np.linalg.norm(d, axis=1)[:, None]
    b0[coax] = (a1 + gap[:, None] * u)[coax]
    b1[coax] = (b0 + 0.02 * u)[coax]
    shared = kind == 3         # V shape: a shared end point
    b0[shared] = a1[shared]
    same = kind == 4           # identical
    b0[same], b1[same], rb[same] = a0[same], a1[same], ra[same]
    zero = kind == 5           # zero radii (segments)
    ra[zero & (rng.random(n) < 0.5)] = 0.0
    rb[zero] = 0.0
    cap = kind == 6            # cap disk face on cap disk face, offset and tilted by 1e-9 rad
    b0[cap] = (a1 + 0.003 * side + gap[:, None] * u)[cap]
    b1[cap] = (b0 + 0.02 * (u + 1e-9 * side))[cap]
    scale = np.where(kind == 7, 10.0 ** rng.uniform(-3, 1, n), 1.0)[:, None]  # other scales
    return a0 * scale, a1 * scale, ra * scale[:, 0], b0 * scale, b1 * scale, rb * scale[:, 0]


@pytest.mark.skipif("numba" not in BACKENDS, reason="numba not installed")
def test_numba_kernels_match_numpy_reference():
    from handmesh_tutorial.collision import _common, _numba
    assert (_numba._PARALLEL_SIN, _numba._COPLANAR, _numba._AXES_PARALLEL_SIN) == (
        _common._PARALLEL_SIN, _common._COPLANAR, _common._AXES_PARALLEL_SIN)
    rng = np.random.default_rng(12)
    families = {"uniform": random_pairs(20000, rng), "near contact": near_contact_pairs(500, 13)[0],
                "adversarial": _adversarial_pairs(rng, 20000)}
    for name, pairs in families.items():
        ref = C.cylinders_intersect(*pairs, backend="numpy")
        for atol in (C.ATOL, 0.0, 1e-6):
            ref = C.cylinders_intersect(*pairs, atol=atol, backend="numpy")
            got = C.cylinders_intersect(*pairs, atol=atol, backend="numba")
            # same formulas in the same order: the answers are identical, not just close
            np.testing.assert_array_equal(got, ref, err_msg=f"{name}, atol {atol}")
        assert 0.05 < ref.mean() < 0.95, name  # both answers occur
    # broadcasting and scalars go through the same kernel
    a0, a1, ra, b0, b1, rb = random_pairs(9, rng)
    grid = [C.cylinders_intersect(a0[:, None], a1[:, None], ra[:, None], b0, b1, rb, backend=b)
            for b in BACKENDS]
    np.testing.assert_array_equal(grid[0], grid[1])
    with pytest.raises(ValueError, match="backend"):
        C.cylinders_intersect(a0, a1, ra, b0, b1, rb, backend="fortran")


@pytest.mark.skipif("numba" not in BACKENDS, reason="numba not installed")
def test_numba_body_queries_match_numpy_reference(hands):
    model = hands["right"]
    rng = np.random.default_rng(14)
    rod = C.Cylinders([[0, 0, -0.05]], [[0, 0, 0.05]], [0.01])
    n_hit = 0
    for k, name in enumerate(("flat", "fist", "pinch", "spread") * 6):
        a = C.hand_cylinders(_posed(model, name), model=model)
        t = rng.normal(size=3)
        t *= rng.uniform(0.0, 0.12) / np.linalg.norm(t)
        b = a.transform(Rotation.random(random_state=k).as_matrix(), t)
        for x, y in ((a, b), (b, rod), (a, a)):
            ref = C.colliding_pairs(x, y, backend="numpy")
            got = C.colliding_pairs(x, y, backend="numba")
            for r, g in zip(ref, got, strict=True):
                np.testing.assert_array_equal(g, r)
                assert g.dtype == np.int64
            hit = C.bodies_collide(x, y, backend="numba")
            assert hit == C.bodies_collide(x, y, backend="numpy") == (ref[0].size > 0)
            n_hit += hit
        for compression in (0.0, C.SELF_CONTACT_COMPRESSION):
            ref = C.self_collisions(b, compression=compression, backend="numpy")
            got = C.self_collisions(b, compression=compression, backend="numba")
            for r, g in zip(ref, got, strict=True):
                np.testing.assert_array_equal(g, r)
    assert 10 < n_hit < 3 * 24  # some poses collide, some do not


def test_backend_is_read_from_the_package(monkeypatch):
    """``hmt.collision.BACKEND`` set on the package reaches every submodule's queries."""
    from handmesh_tutorial.collision import _common
    a0, a1, ra, b0, b1, rb = random_pairs(5, np.random.default_rng(3))
    body = C.Cylinders(a0, a1, ra)
    monkeypatch.setattr(hmt.collision, "BACKEND", "fortran")
    for call in (lambda: C.cylinders_intersect(a0, a1, ra, b0, b1, rb),
                 lambda: C.bodies_collide(body, body), lambda: C.colliding_pairs(body, body),
                 lambda: C.self_collisions(body)):
        with pytest.raises(ValueError, match="backend"):
            call()
    monkeypatch.setattr(hmt.collision, "BACKEND", "numpy")
    assert _common._kernels(None) is None
    if "numba" in BACKENDS:
        monkeypatch.setattr(hmt.collision, "BACKEND", "numba")
        assert _common._kernels(None) is _common._kernels("numba") is not None


def test_project_to_cylinder_refuses_what_point_cylinder_distance_refuses():
    # issue 43 item 10: a zero-length axis gave NaN, a negative radius was used as given
    x, p0, p1 = np.zeros((2, 3)), np.zeros((2, 3)), np.array([[0, 0, 0.1], [0, 0, 0.0]])
    for f in (C.project_to_cylinder, C.point_cylinder_distance):
        with pytest.raises(ValueError, match=r"zero length at flat index 1 \(1 such"):
            f(x, p0, p1, 0.01)
        with pytest.raises(ValueError, match="radius must be non-negative, got min -0.01"):
            f(x[:1], p0[:1], p1[:1], -0.01)
        with pytest.raises(ValueError, match="points contains NaN"):
            f([[np.nan, 0, 0]], p0[:1], p1[:1], 0.01)
        with pytest.raises(ValueError, match=r"p1 must have shape \(\.\.\., 3\)"):
            f(x, p0, [0.0, 0.1], 0.01)


# -- issue 54: finger against finger over many poses, proxies and skin --------------------------

def _random_hand_poses(num: int, seed: int):
    import torch

    hand = hmt.hand.HandModel()
    rng = np.random.default_rng(seed)
    pose = torch.from_numpy(rng.uniform(-0.6, 0.9, (num, 15, 3)).astype(np.float32))
    return hand, hand(pose=pose)


def test_skin_collisions_own_triangle_test_agrees_with_python_fcl():
    fcl = pytest.importorskip("fcl", reason="python-fcl (the dev extra)")
    from handmesh_tutorial.collision import skin

    hand, out = _random_hand_poses(8, seed=54)
    fingers = skin.finger_of_vertices(hand)
    ours = skin.skin_collisions(out.vertices, hand.faces, fingers, backend="numpy")
    theirs = skin.skin_collisions(out.vertices, hand.faces, fingers, backend="fcl")
    assert ours == theirs and sum(map(len, ours)) >= 4  # these poses press fingers together
    assert skin.skin_collisions(hand().vertices, hand.faces, fingers) == [set()]  # rest pose
    with pytest.raises(ValueError, match="one entry per vertex"):
        skin.skin_collisions(hand().vertices, hand.faces, fingers[:-1])
    distal = skin.finger_of_vertices(hand, phalanges=(2,))
    assert set(np.unique(distal)) == {-1, 0, 1, 2, 3, 4}
    assert (np.isin(np.flatnonzero(distal >= 0), np.flatnonzero(fingers >= 0))).all()
    # one triangle pair at a time against fcl's own triangle test
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(300, 3, 3)), rng.normal(size=(300, 3, 3))
    want = []
    for ta, tb in zip(a, b, strict=True):
        objs = []
        for t in (ta, tb):
            m = fcl.BVHModel()
            m.beginModel(3, 1)
            m.addSubModel(t, np.array([[0, 1, 2]]))
            m.endModel()
            objs.append(fcl.CollisionObject(m, fcl.Transform()))
        want.append(fcl.collide(*objs, fcl.CollisionRequest()) > 0)
    got = skin.triangles_intersect(a, b)
    assert 0.1 < np.mean(want) < 0.9
    np.testing.assert_array_equal(got, want)


def test_finger_collisions_are_the_proxies_finger_pairs_pose_by_pose():
    from handmesh_tutorial.collision import skin

    hand, out = _random_hand_poses(4, seed=7)
    got = skin.finger_collisions(out, model=hand)
    loose = skin.finger_collisions(out.vertices, out.joints, hand, compression=0.0)
    for b in range(4):
        body = hmt.collision.hand_cylinders(out, model=hand, index=b)
        i, j = hmt.collision.self_collisions(body)
        want = set()
        for x, y in zip(i, j, strict=True):  # filtered by .parts by hand
            fx, fy = body.parts[x], body.parts[y]
            if fx != fy and max(fx, fy) < 5:
                want.add((min(fx, fy), max(fx, fy)))
        assert got[b] == want
        assert got[b] <= loose[b]  # unshrunk cylinders meet wherever shrunk ones do
    assert any(got)
