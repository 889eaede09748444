"""Tests of handmesh_tutorial.objects: procedural objects, their cylinder primitives, the chain."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from handmesh_tutorial import collision as C
from handmesh_tutorial import objects as O

# expected outer sizes (metres) per kind, checked on the mesh itself
FINGER_RADIUS = 0.008  # a finger of 16 mm diameter must pass through holes and handles


@pytest.fixture(scope="module")
def bodies():
    return {k: O.make_object(k, i) for i, k in enumerate(O.OBJECT_KINDS)}


def _mesh(b):
    return trimesh.Trimesh(b.vertices, b.faces, process=False)


def _collide(a: C.Cylinders, b: C.Cylinders) -> np.ndarray:
    return C.cylinders_intersect(a.p0[:, None], a.p1[:, None], a.radius[:, None],
                                 b.p0[None], b.p1[None], b.radius[None])


def test_kinds():
    assert set(O.OBJECT_KINDS) >= {"cylinder", "bottle", "box", "sphere", "torus", "mug", "plate"}
    with pytest.raises(ValueError, match="unknown object kind 'teapot'"):
        O.make_object("teapot", 0)


def test_watertight_and_small(bodies):
    for kind, b in bodies.items():
        m = _mesh(b)
        assert m.is_watertight and m.is_volume, kind
        assert m.volume > 0, kind
        assert len(b.faces) <= 4000, (kind, len(b.faces))
        assert b.colors.shape == b.vertices.shape and 0 <= b.colors.min() <= b.colors.max() <= 1
        np.testing.assert_allclose(m.bounds.mean(0), 0, atol=1e-9)  # object frame: bbox centred
        assert C.self_collisions(b.cylinders)[0].size == 0  # rigid: all pairs adjacent


def test_sizes_like_everyday_objects():
    for seed in range(3):
        ext = {k: _mesh(O.make_object(k, seed)).extents for k in O.OBJECT_KINDS}
        for k in ("cylinder", "bottle", "sphere"):
            assert 0.059 <= ext[k][0] <= 0.081 and 0.059 <= ext[k][1] <= 0.081, (k, ext[k])
        assert 0.059 <= ext["sphere"][2] <= 0.081
        assert 0.08 <= ext["cylinder"][2] <= 0.14 and 0.16 <= ext["bottle"][2] <= 0.22
        assert np.all(ext["box"] >= 0.039) and np.all(ext["box"] <= 0.161)
        tor = O.make_object("torus", seed)
        assert 0.030 <= tor.params["inner_diameter"] <= 0.040
        # the mesh's hole: no vertex within the inner radius of the axis
        r_xy = np.hypot(tor.vertices[:, 0], tor.vertices[:, 1])
        assert r_xy.min() == pytest.approx(tor.params["inner_diameter"] / 2, abs=5e-4)
        assert 0.07 <= ext["mug"][2] <= 0.12


def _ray_hits(mesh, origin, direction):
    locs, _, _ = mesh.ray.intersects_location([origin], [direction])
    return len(locs) > 0


def test_finger_passes_through_torus_mug_handle_and_plate_holes():
    finger_len = 0.2
    # torus: a finger along the axis
    tor = O.make_object("torus", 1)
    f = C.Cylinders([[0, 0, -finger_len / 2]], [[0, 0, finger_len / 2]], [FINGER_RADIUS])
    assert not _collide(f, tor.cylinders).any()
    # plate: a finger through the centre of each hole, along z
    plate = O.make_object("plate", 2)
    pitch, bar, holes, L = (plate.params[k] for k in ("pitch", "bar", "holes", "size"))
    assert plate.params["hole_size"] >= 2 * FINGER_RADIUS + 0.002
    m = _mesh(plate)
    for i in range(holes):
        for j in range(holes):
            c = -L / 2 + bar + pitch / 2 - bar / 2
            x, y = c + i * pitch, c + j * pitch
            f = C.Cylinders([[x, y, -0.1]], [[x, y, 0.1]], [FINGER_RADIUS])
            assert not _collide(f, plate.cylinders).any(), (i, j)
            assert not _ray_hits(m, [x, y, -0.1], [0, 0, 1])
    # mug: a finger through the handle (along y, the handle's normal, at the handle's opening)
    mug = O.make_object("mug", 3)
    r, gap = mug.params["radius"], mug.params["handle_gap"]
    x_axis = mug.vertices.min(0)[0] + r  # the frame is bbox-centred: the cup axis is off 0
    xf = x_axis + r + gap / 2  # midway between the outer wall and the handle
    f = C.Cylinders([[xf, -0.1, 0]], [[xf, 0.1, 0]], [min(FINGER_RADIUS, gap / 2 - 0.001)])
    assert gap >= 0.02
    assert not _collide(f, mug.cylinders).any()
    assert not _ray_hits(_mesh(mug), [xf, -0.1, 0], [0, 1, 0])
    # ... while the handle is really there: a ray a little further out hits it
    assert _ray_hits(_mesh(mug), [xf + gap / 2 + mug.params["handle_tube_radius"], -0.1, 0],
                     [0, 1, 0])
    assert _ray_hits(_mesh(mug), [xf - gap / 2 - 0.002, -0.1, 0], [0, 1, 0])  # the wall


@pytest.mark.parametrize("kind", ["cylinder", "bottle", "box", "sphere", "torus", "mug", "plate"])
def test_primitives_cover_mesh(kind, bodies):
    fit = O.primitive_fit(bodies[kind], samples=800, rng=0)
    assert fit["coverage"] >= 0.99, fit
    assert fit["uncovered_max_mm"] <= 2.0, fit
    assert fit["excess_p95_mm"] <= 3.0, fit
    assert fit["excess_max_mm"] <= 5.0, fit


def test_distance_to_cylinders_independent():
    cyl = C.Cylinders([[0, 0, 0]], [[0, 0, 1]], [0.5])
    pts = np.array([[0, 0, 0.5], [1, 0, 0.5], [0, 0, 2], [1.5, 0, -1]])
    np.testing.assert_allclose(O.distance_to_cylinders(pts, cyl), [0, 0.5, 1, np.hypot(1, 1)])


def test_determinism_and_transform():
    a, b, c = O.make_object("mug", 7), O.make_object("mug", 7), O.make_object("mug", 8)
    assert a.vertices.tobytes() == b.vertices.tobytes()
    assert a.colors.tobytes() == b.colors.tobytes()
    assert a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices)
    R = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_matrix()
    t = np.array([0.1, -0.2, 0.5])
    moved = a.transformed(R, t)
    np.testing.assert_allclose(moved.vertices, a.vertices @ R.T + t)
    np.testing.assert_allclose(moved.cylinders.p0, a.cylinders.p0 @ R.T + t)
    np.testing.assert_allclose(moved.cylinders.radius, a.cylinders.radius)
    # primitives move with the mesh: the fit is unchanged
    assert O.primitive_fit(moved, 300, rng=1)["coverage"] == O.primitive_fit(a, 300, rng=1)[
        "coverage"]
    with pytest.raises(ValueError, match="rotation matrix"):
        a.transformed(np.diag([1.0, 1.0, -1.0]), t)
    v, f, col, lab = a.render_mesh(4)
    assert lab == 4 and v is a.vertices


# ---------------------------------------------------------------- the chain


def _linking_crossings(ca, na, Ra, cb, nb, Rb, n=4000):
    """How many times circle a passes through the disc of radius Rb of circle b."""
    h = np.array([1.0, 0, 0]) if abs(na[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(na, h)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(na, e1)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    p = ca + Ra * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
    s = (p - cb) @ nb
    idx = np.flatnonzero(np.sign(s) != np.sign(np.roll(s, -1)))
    cross = [p[i] - s[i] / (s[i] - s[(i + 1) % n]) * (p[i] - p[(i + 1) % n]) for i in idx]
    return sum(np.linalg.norm(x - cb) < Rb for x in cross)


def _ring_geometry(link):
    """Centre and normal of a posed link from its vertices (the torus is symmetric)."""
    c = link.vertices.mean(0)
    _, _, vt = np.linalg.svd(link.vertices - c)
    return c, vt[2]


@pytest.fixture(scope="module")
def chain():
    return O.make_chain(5, 3)


def test_chain_interlocked_not_colliding_at_rest(chain):
    R, r = chain.params["major_radius"], chain.params["tube_radius"]
    links = chain.pose()
    hole = R - r
    cyl = chain.cylinders()
    assert np.array_equal(cyl.parts, np.repeat(np.arange(5), len(links[0].cylinders)))
    assert C.self_collisions(cyl)[0].size == 0
    for i in range(chain.num_links):
        for j in range(i + 1, chain.num_links):
            hit = _collide(links[i].cylinders, links[j].cylinders).any()
            assert not hit, (i, j)
            ci, ni = _ring_geometry(links[i])
            cj, nj = _ring_geometry(links[j])
            crossings = _linking_crossings(ci, ni, R, cj, nj, hole)
            assert crossings == (1 if j == i + 1 else 0), (i, j)
            if j == i + 1:
                assert abs(ni @ nj) < 1e-6  # perpendicular
    # watertight links, primitives fit
    assert _mesh(links[0]).is_watertight
    fit = O.primitive_fit(links[1], 500, rng=0)
    assert fit["coverage"] >= 0.99 and fit["excess_max_mm"] <= 3.0, fit


def test_chain_lcs_frames(chain):
    F = chain.articulation.frames
    np.testing.assert_allclose(F @ np.swapaxes(F, 1, 2), np.broadcast_to(np.eye(3), F.shape),
                               atol=1e-12)
    assert np.allclose(np.linalg.det(F), 1.0)
    for k, link in enumerate(chain.pose()):
        _, n = _ring_geometry(link)
        assert abs(abs(F[k][:, 1] @ n) - 1) < 1e-6  # y = the ring's normal
        assert abs(F[k][:, 2] @ [0, 0, 1] - 1) < 1e-9  # z along the chain axis at rest


def test_posing_moves_only_descendants(chain):
    rest = chain.pose()
    for k in (1, 2, 4):
        a = chain.zero_angles()
        a[k] = [0.3, -0.4, 0.2]
        posed = chain.pose(a)
        for i in range(chain.num_links):
            same = np.array_equal(posed[i].vertices, rest[i].vertices)
            assert same == (i < k), (k, i)
        # link k turns about its pivot: the pivot stays, the distance of every vertex to it too
        piv = chain.pivots[k]
        np.testing.assert_allclose(chain.joint_positions(a)[k], piv, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(posed[k].vertices - piv, axis=1),
                                   np.linalg.norm(rest[k].vertices - piv, axis=1), atol=1e-12)
    with pytest.raises(ValueError, match=r"angles must have shape \(5, 3\)"):
        chain.pose(np.zeros((4, 3)))


def test_chain_random_moves_like_the_generator(chain):
    """Step 4 of the paper's algorithm on the chain alone: random increments about the LCS axes
    within the limits, rejected when two links would collide."""
    rng = np.random.default_rng(0)
    art = chain.articulation
    assert np.all(art.lower[0] == 0) and np.all(art.upper[0] == 0)  # root fixed by default
    angles = chain.zero_angles()
    accepted = 0
    for _ in range(60):
        k = int(rng.integers(1, chain.num_links))
        trial = angles.copy()
        trial[k] += rng.normal(0, np.deg2rad(8), 3)
        trial = art.clip(trial)
        i, _ = C.self_collisions(chain.cylinders(trial))
        if i.size == 0:
            angles, accepted = trial, accepted + 1
    assert accepted > 5
    # and the test does bite: link 1 twisted 90 degrees lies in link 0's plane, through its tube
    twist = chain.zero_angles()
    twist[1, 2] = np.pi / 2
    i, j = C.self_collisions(chain.cylinders(twist))
    links_hit = {tuple(sorted(p)) for p in zip(chain.cylinders().parts[i],
                                              chain.cylinders().parts[j], strict=True)}
    assert (0, 1) in links_hit
    assert art.within_limits(angles)
    assert np.abs(angles).max() > np.deg2rad(5)  # it really moved
    with pytest.raises(ValueError, match="num_links"):
        O.make_chain(1, 0)


def test_chain_determinism(chain):
    again = O.make_chain(5, 3)
    for a, b in zip(chain.links, again.links, strict=True):
        assert a.vertices.tobytes() == b.vertices.tobytes()
        assert a.colors.tobytes() == b.colors.tobytes()
    assert chain.params == again.params


def test_chains_of_many_seeds_rest_without_collision():
    for seed in range(6):
        ch = O.make_chain(4, seed)
        assert C.self_collisions(ch.cylinders())[0].size == 0, seed
        assert ch.params["skip_one_gap"] > 2 * ch.params["clearance"]
        assert 0.025 <= ch.params["inner_diameter"] <= 0.04
