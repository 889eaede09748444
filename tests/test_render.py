"""Tests of handmesh_tutorial.render: EGL offscreen, the NumPy 2 fix, exact label masks, OpenCV
camera convention, crop camera, backgrounds/lights, determinism."""

from __future__ import annotations

import os
import types

import numpy as np
import pytest
import trimesh
from scipy.ndimage import binary_erosion

from handmesh_tutorial import render as R

S = 64


@pytest.fixture(scope="module")
def renderer():
    with R.Renderer(S) as r:
        yield r


def _sphere(center, radius, label, color=(0.8, 0.6, 0.5)):
    m = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    v = m.vertices + np.asarray(center)
    return (v, m.faces, np.tile(color, (len(v), 1)), label)


def _box(center, size, label, color=(40, 90, 200)):
    m = trimesh.creation.box(extents=size)
    v = m.vertices + np.asarray(center)
    return (v, m.faces, np.tile(np.asarray(color, np.uint8), (len(v), 1)), label)


def _two_bodies():
    front = _sphere((0.0, 0.0, 0.40), 0.035, 1)
    back = _box((0.03, 0.02, 0.50), (0.07, 0.07, 0.07), 2)
    return [front, back]


def _K():
    return R.intrinsics(120.0, 120.0, (S - 1) / 2, (S - 1) / 2)


# ---------------------------------------------------------------- EGL + NumPy 2 fix


def test_egl_selected_without_display(renderer):
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        pytest.skip("a display exists; EGL is only forced when headless")
    assert os.environ["PYOPENGL_PLATFORM"] == "egl"
    from pyrender.platforms.egl import EGLPlatform

    assert isinstance(renderer._r._platform, EGLPlatform)


def test_headless_pyglet_without_x11_unless_the_user_chose_otherwise():
    """pyrender imports pyglet's window module; headless, pyglet must not load X11 (a GPU
    machine without X11 libraries failed there)."""
    import subprocess
    import sys

    code = ("from handmesh_tutorial.render.backend import import_pyrender; import_pyrender(); "
            "import sys, pyglet; print(pyglet.options['headless'], "
            "'pyglet.libs.x11.xlib' in sys.modules)")
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "PYGLET_HEADLESS")}

    def run(**extra):
        return subprocess.run([sys.executable, "-c", code], env={**env, **extra}, check=True,
                              capture_output=True, text=True).stdout.split()

    assert run() == ["True", "False"]
    assert run(PYGLET_HEADLESS="0")[0] == "False"  # a user's explicit choice wins


def test_numpy2_fix_formerly_broken_paths(renderer):
    pr = R.import_pyrender()
    tm = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    tm.apply_translation((0.05, -0.1, 0.6))
    mesh = pr.Mesh.from_trimesh(tm)
    np.testing.assert_allclose(mesh.bounds, tm.bounds, atol=1e-6)
    np.testing.assert_allclose(mesh.centroid, tm.bounds.mean(0), atol=1e-6)
    scene = pr.Scene()
    scene.add(mesh)
    scene.add(pr.IntrinsicsCamera(100, 100, 32, 32), pose=R.CV_TO_GL)
    scene.add(pr.DirectionalLight(intensity=2.0), pose=R.CV_TO_GL)
    np.testing.assert_allclose(scene.bounds, tm.bounds, atol=1e-6)
    np.testing.assert_allclose(scene.centroid, tm.bounds.mean(0), atol=1e-6)
    assert scene.scale == pytest.approx(np.linalg.norm(tm.extents), rel=1e-6)
    # directional shadows size their shadow camera from scene.bounds: render with them, offscreen
    color, depth = renderer._r.render(scene, flags=pr.RenderFlags.SHADOWS_DIRECTIONAL)
    assert color.shape == (S, S, 3) and (depth > 0).any()
    if int(np.__version__.split(".")[0]) >= 2:
        assert not hasattr(np, "infty"), "the fix must not resurrect np.infty globally"


def test_patch_is_local_and_idempotent():
    fake = types.ModuleType("fake_pyrender_mesh")
    fake.np = np
    applied = R.backend._patch_pyrender_numpy2(fake)
    assert applied == (not hasattr(np, "infty"))
    assert fake.np.infty == np.inf and fake.np.array is np.array
    assert R.backend._patch_pyrender_numpy2(fake) is False


# ---------------------------------------------------------------- label masks and depth


def test_label_mask_matches_per_body_depth_comparison(renderer):
    meshes = _two_bodies()
    K = _K()
    out = renderer.render(meshes, K, alone=True)
    # independent reference: each body alone, its depth; the nearest positive depth wins
    depths = []
    for m in meshes:
        d = renderer.render([m], K, color=False).depth
        depths.append(np.where(d > 0, d, np.inf))
    depths = np.stack(depths)
    ref = np.where(np.isfinite(depths).any(0), np.argmin(depths, 0) + 1, 0)
    assert (out.labels == ref).all()
    assert set(np.unique(out.labels)) == {0, 1, 2}
    # the occluded box's visible pixels = its alone mask minus the sphere's pixels
    a1, a2 = out.alone_masks[1], out.alone_masks[2]
    assert (a1 & a2).any(), "the test scene must have an overlap"
    assert ((out.labels == 2) == (a2 & ~a1)).all()
    assert ((out.labels == 1) == a1).all()
    # depth is positive exactly where some body is, and equals the nearest body depth
    assert ((out.depth > 0) == (out.labels > 0)).all()
    fg = out.labels > 0
    np.testing.assert_allclose(out.depth[fg], depths.min(0)[fg], rtol=1e-5)


def test_opencv_pixel_convention_rectangle(renderer):
    # a rectangle at Z = 1 whose edges project to u in [10.3, 20.3], v in [40.3, 50.7];
    # OpenCV pixel centres are integers, so columns 11..20 and rows 41..50 are covered
    fx, c = 100.0, 31.5
    K = R.intrinsics(fx, fx, c, c)
    u0, u1, v0, v1 = 10.3, 20.3, 40.3, 50.7
    X0, X1, Y0, Y1 = (u0 - c) / fx, (u1 - c) / fx, (v0 - c) / fx, (v1 - c) / fx
    v = np.array([[X0, Y0, 1.0], [X1, Y0, 1.0], [X1, Y1, 1.0], [X0, Y1, 1.0]])
    f = np.array([[0, 2, 1], [0, 3, 2]])  # facing the camera (-z)
    out = renderer.render([(v, f, np.ones((4, 3)), 7)], K)
    expected = np.zeros((S, S), bool)
    expected[41:51, 11:21] = True
    assert ((out.labels == 7) == expected).all()
    np.testing.assert_allclose(out.depth[expected], 1.0, rtol=1e-4)
    # +x right and +y down: the rectangle has X < 0, Y > 0 -> left half, lower half of the image
    assert X1 < 0 and Y0 > 0


def test_point_projects_to_K_X(renderer):
    X = np.array([0.05, -0.03, 0.5])
    K = _K()
    u, v = R.project(X[None], K)[0]
    out = renderer.render([_sphere(X, 0.004, 3)], K)
    mask = out.labels == 3
    assert mask[int(round(v)), int(round(u))]
    rows, cols = np.nonzero(mask)
    assert abs(cols.mean() - u) < 0.6 and abs(rows.mean() - v) < 0.6
    # +x right, -y up
    assert u > (S - 1) / 2 and v < (S - 1) / 2


def test_render_alone_images_and_color(renderer):
    meshes = _two_bodies()
    bg = R.random_background(1, S)
    masks = renderer.render_alone(meshes, _K())
    both = renderer.render_alone(meshes, _K(), images=True, background=bg)
    for lab, m in masks.items():
        mask, img = both[lab]
        assert (mask == m).all() and img.shape == (S, S, 3) and img.dtype == np.uint8
        # away from the body (and its anti-aliased rim) the alone image is the background
        far = ~_dilate(m, 2)
        assert (img[far] == bg[far]).all()
        assert (img[m] != bg[m]).any(axis=-1).mean() > 0.9


def _dilate(m, k):
    out = m.copy()
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            out |= np.roll(np.roll(m, dy, 0), dx, 1)
    return out


def test_determinism_same_seed_same_bytes(renderer):
    def run(seed):
        rng = np.random.default_rng(seed)
        lights = R.random_lights(rng)
        bg = R.random_background(rng, S)
        return renderer.render(_two_bodies(), _K(), lights=lights, background=bg).image

    a, b, c = run(5), run(5), run(6)
    assert a.tobytes() == b.tobytes()
    assert a.tobytes() != c.tobytes()


# ---------------------------------------------------------------- cameras


def test_crop_camera_frames_points():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(200, 3)) * [0.04, 0.03, 0.02] + [0.1, -0.05, 0.6]
    for margin in (0.0, 0.1, 0.2):
        K = R.crop_camera(pts, 224, margin)
        uv = R.project(pts, K)
        # the image border lies at -0.5 and 223.5 (pixel centres are integers)
        lo, hi = margin * 224 - 0.5, 223.5 - margin * 224
        assert uv.min() >= lo - 1e-6 and uv.max() <= hi + 1e-6
        # tight along at least one axis, box centred on the image centre
        span = (uv.max(0) - uv.min(0)).max()
        assert span == pytest.approx((1 - 2 * margin) * 224, rel=1e-9)
        np.testing.assert_allclose((uv.max(0) + uv.min(0)) / 2, 111.5, atol=1e-9)
    centre = pts.mean(0)
    K = R.crop_camera(pts, 224, 0.1, center=centre)
    np.testing.assert_allclose(R.project(centre[None], K)[0], 111.5, atol=1e-9)
    assert R.project(pts, K).min() >= 0.1 * 224 - 0.5 - 1e-6
    f_fit = R.crop_camera(pts, 224, 0.1)[0, 0]
    K = R.crop_camera(pts, 224, 0.1, focal=0.5 * f_fit)
    assert K[0, 0] == 0.5 * f_fit
    with pytest.raises(ValueError, match="largest focal that fits"):
        R.crop_camera(pts, 224, 0.1, focal=2 * f_fit)
    with pytest.raises(ValueError, match="Z > 0"):
        R.crop_camera(pts * [1, 1, -1], 224)
    with pytest.raises(ValueError, match="shape"):
        R.crop_camera(pts[:, :2], 224)


def test_project_is_the_checked_camera_projection():
    """``render.project`` is ``camera.project`` (same numbers) plus the renderer's checks."""
    from handmesh_tutorial.render import camera

    assert R.project is camera.project_checked
    assert R.intrinsics is camera.intrinsics and R.crop_camera is camera.crop_camera
    pts = np.array([[0.01, -0.02, 0.5], [-0.03, 0.04, 0.7]])
    K = _K()
    assert R.project(pts, K).tobytes() == camera.project(pts, K).tobytes()
    with pytest.raises(ValueError, match="Z > 0"):
        R.project(pts * [1, 1, -1], K)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        R.project(pts[None], K)
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\)"):
        R.project(pts, np.eye(4))
    for bad in ([[100, 1, 30], [0, 100, 30], [0, 0, 1]], [[-1, 0, 30], [0, 100, 30], [0, 0, 1]],
                [[100, 0, 30], [0, 100, 30], [0, 0, 2]]):
        with pytest.raises(ValueError, match="fx, fy > 0"):
            camera.check_intrinsics(bad)


def test_crop_camera_render_keeps_body_inside(renderer):
    body = _sphere((0.07, 0.05, 0.45), 0.03, 1)
    K = R.crop_camera(body[0], S, margin=0.1)
    labels = renderer.render([body], K, color=False).labels
    border = int(0.1 * S) - 1
    assert (labels == 1).any()
    assert not (labels[:border].any() or labels[-border:].any()
                or labels[:, :border].any() or labels[:, -border:].any())


# ---------------------------------------------------------------- inputs and helpers


def test_random_background_kinds_and_determinism():
    for kind in ("gradient", "noise", "stripes", "checker"):
        a = R.random_background(3, 40, 50, kind=kind)
        assert a.shape == (40, 50, 3) and a.dtype == np.uint8
        assert a.std() > 1.0  # not a flat colour
        assert (a == R.random_background(3, 40, 50, kind=kind)).all()
    with pytest.raises(ValueError, match="unknown background kind"):
        R.random_background(0, 8, kind="photo")


def test_random_lights_deterministic_and_valid():
    a, b = R.random_lights(11), R.random_lights(11)
    assert a == b and 2 <= len(a) <= 4 and a[0].kind == "directional"
    for light in a:
        if light.kind == "directional":
            assert np.isclose(np.linalg.norm(light.direction), 1) and light.direction[2] > 0


def test_bad_inputs_raise(renderer):
    m = _sphere((0, 0, 0.5), 0.03, 1)
    with pytest.raises(ValueError, match="duplicate label 1"):
        renderer.render([m, m], _K())
    with pytest.raises(ValueError, match="label must be in"):
        renderer.render([(*m[:3], 0)], _K())
    with pytest.raises(ValueError, match="colors must have shape"):
        renderer.render([(m[0], m[1], m[2][:5], 1)], _K())
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\)"):
        renderer.render([m], np.eye(4))
    with pytest.raises(ValueError, match="background must have shape"):
        renderer.render([m], _K(), background=np.zeros((S + 1, S, 3), np.uint8))
    with pytest.raises(ValueError, match="unknown light kind"):
        renderer.render([m], _K(), lights=[R.Light("spot")])


# ---------------------------------------------------------------- realistic appearance


def test_color_temperature_warm_to_cool():
    warm, day, cool = (np.array(R.color_temperature(k)) for k in (2700, 6600, 10000))
    for c in (warm, day, cool):
        assert c.max() == pytest.approx(1.0) and c.min() >= 0.0
    assert warm[0] == 1.0 and warm[2] < 0.3          # tungsten: orange
    np.testing.assert_allclose(day, 1.0, atol=0.03)  # ~6600 K: white
    assert cool[2] == 1.0 and cool[0] < 0.85         # shade: blue
    blue_share = [R.color_temperature(k)[2] / R.color_temperature(k)[0]
                  for k in (2000, 3000, 4000, 5000, 6000)]
    assert blue_share == sorted(blue_share)          # bluer as the temperature rises


def test_scene_lights_vary_colour_and_direction():
    sets = [R.scene_lights(s, 0.5) for s in range(60)]
    assert R.scene_lights(7, 0.5) == sets[7]
    keys = np.array([ls[0].color for ls in sets])
    assert (keys[:, 0] > keys[:, 2] + 0.05).any() and (keys[:, 2] > keys[:, 0] + 0.05).any()
    assert (keys.min(1) > 0.4).all()  # white-balanced: casts stay mild
    inten = [ls[0].intensity for ls in sets]
    assert max(inten) > 2 * min(inten)
    rims = [lt for ls in sets for lt in ls if lt.kind == "directional" and lt.direction[2] < 0]
    assert 5 <= len(rims) <= 35  # a light from behind the bodies in about 30 % of the scenes
    for ls in sets:
        assert ls[0].kind == "directional" and ls[0].direction[2] > 0  # the key faces the scene


def test_background_photos_are_bundled_in_the_wheel_and_free():
    """Only photographs the installed scikit-image ships (no pooch download), CC0 or public
    domain, each with its credit."""
    folder = R.backgrounds._skimage_data_dir()
    assert {ph.name for ph in R.BACKGROUND_PHOTOS} == {"coffee", "chelsea", "rocket", "brick",
                                                       "grass", "gravel"}
    for ph in R.BACKGROUND_PHOTOS:
        assert (folder / ph.file).is_file(), ph.file
        assert ph.licence in ("CC0", "public domain") and ph.credit and ph.description
        px = R.photo_pixels(ph.name)
        assert px.dtype == np.uint8 and not px.flags.writeable
        assert px.ndim == (2 if ph.texture else 3) and min(px.shape[:2]) >= 300
        assert bool(ph.tints) == ph.texture


def test_a_changed_photograph_is_reported(monkeypatch):
    import dataclasses

    changed = tuple(dataclasses.replace(ph, sha256="0" * 64) if ph.name == "coffee" else ph
                    for ph in R.BACKGROUND_PHOTOS)
    monkeypatch.setattr(R.backgrounds, "BACKGROUND_PHOTOS", changed)
    R.photo_pixels.cache_clear()
    try:
        with pytest.warns(UserWarning, match="coffee.png differs .* same seed will differ"):
            R.photo_pixels("coffee")
    finally:
        R.photo_pixels.cache_clear()


def test_photo_background_is_deterministic_and_varied():
    a = R.photo_background(4, 40, 50)
    assert a.shape == (40, 50, 3) and a.dtype == np.uint8 and a.std() > 2.0
    assert a.tobytes() == R.photo_background(4, 40, 50).tobytes()
    imgs = [R.photo_background(s, 32) for s in range(12)]
    assert len({im.tobytes() for im in imgs}) == 12
    for ph in R.BACKGROUND_PHOTOS:  # every photograph, colour or tinted texture, gives colour
        im = R.photo_background(1, 32, photo=ph.name).astype(float)
        assert im.std() > 2.0 and np.abs(im[..., 0] - im[..., 2]).mean() > 1.0, ph.name
    with pytest.raises(ValueError, match="unknown background photo"):
        R.photo_background(0, 8, photo="lena")


def test_scene_background_mixes_photos_and_procedural():
    rng = np.random.default_rng(3)
    rng.random()  # scene_background's own draw (photo or not)
    assert R.scene_background(3, 24, photo_prob=1.0).tobytes() == \
        R.photo_background(rng, 24).tobytes()
    rng = np.random.default_rng(3)
    rng.random()
    vivid = R.random_background(rng, 24).astype(float)
    muted = R.scene_background(3, 24, photo_prob=0.0).astype(float)
    chroma = [np.abs(im - im.mean(2, keepdims=True)).mean() for im in (vivid, muted)]
    assert chroma[1] < 0.85 * chroma[0]  # the same texture, its colours muted
    assert np.abs(vivid.mean((0, 1)).mean() - muted.mean((0, 1)).mean()) < 10
    with pytest.raises(ValueError, match="photo_prob"):
        R.scene_background(0, 8, photo_prob=1.5)


def test_ambient_colour(renderer):
    body = [_sphere((0.0, 0.0, 0.4), 0.04, 1, color=(1.0, 1.0, 1.0))]
    out = renderer.render(body, _K(), lights=[], ambient=(1.0, 0.0, 0.0))
    px = out.image[out.labels == 1].astype(float)
    assert px[:, 0].mean() > 100 and px[:, 1:].max() < 5  # lit red by the ambient term only
    grey = renderer.render(body, _K(), lights=[], ambient=0.5).image[out.labels == 1]
    assert np.ptp(grey.astype(int), axis=1).max() <= 1    # a scalar ambient stays grey


def test_framing_measures_share_and_inside():
    K = R.intrinsics(100.0, 100.0, 49.5, 49.5)
    pts = np.array([[-0.1, -0.1, 1.0], [0.1, 0.05, 1.0], [0.0, 0.0, 1.0], [0.45, 0.0, 1.0]])
    fr = R.framing(pts, K, 100, margin=0.08)
    assert fr["share"] == pytest.approx(0.55)  # u from 39.5 to 94.5
    assert fr["inside"] == 0.75                 # u = 94.5 lies within 8 px of the border
    np.testing.assert_allclose(fr["center"], [67.0, 47.0])


def test_closing_one_renderer_keeps_the_others_working(renderer):
    """EGL renderers share one display: closing a second one must not break the first."""
    body = [_sphere((0.0, 0.0, 0.4), 0.04, 1)]
    before = renderer.render(body, _K()).image
    with R.Renderer(32) as other:
        assert (other.render(body, _K() * [[0.5], [0.5], [1]]).labels == 1).any()
    after = renderer.render(body, _K()).image  # raised GLError 12296 before the fix
    assert after.tobytes() == before.tobytes()


def test_occluders_hide_but_carry_no_label(renderer):
    """Scenery (a forearm) is drawn and hides bodies, reads as background in the masks, and
    hides its owner in the owner's alone mask too (so VR counts only other bodies)."""
    bodies = _two_bodies()
    plain = renderer.render(bodies, _K(), alone=True)
    # a thin plate in front of both bodies, covering the centre of the image
    plate = _box((0.0, 0.0, 0.30), (0.02, 0.2, 0.01), 0, color=(230, 25, 25))
    occ = (plate[0], plate[1], plate[2], 1)                        # owned by body 1
    out = renderer.render(bodies, _K(), alone=True, occluders=[occ])
    hidden = plain.labels != out.labels
    assert hidden.sum() > 50
    assert np.all(out.labels[hidden] == 0)                         # covered pixels: background
    assert set(np.unique(out.labels)) <= {0, 1, 2}
    assert not np.array_equal(out.image, plain.image)
    red = (out.image[..., 0] > 150) & (out.image[..., 1] < 80)
    assert red[hidden].mean() > 0.9                                # the plate is what we see
    # owner's alone mask loses the covered part; the other body's alone mask does not
    plate_px = renderer.render([(plate[0], plate[1], plate[2], 3)], _K()).labels == 3
    assert (plain.alone_masks[1] & plate_px).sum() > 20
    np.testing.assert_array_equal(out.alone_masks[1], plain.alone_masks[1] & ~plate_px)
    np.testing.assert_array_equal(out.alone_masks[2], plain.alone_masks[2])


def test_the_same_scene_renders_to_the_same_bytes_every_time():
    # pyrender keeps its mesh and light nodes in sets (object-id order): a pixel where a hand's
    # wrist rim meets its forearm (same depth) and the order in which lights are summed changed
    # from one render to the next (1 pixel in about 1 image in 200). These four scenes showed it.
    from handmesh_tutorial import scenes as interact

    scenes = [(2225977598304645, "hand-hand"), (5283688704410008, "hand-object"),
              (850257826479516, "hand-hand"), (5452981206712262, "hand-hand")]
    first = [interact.make_sample(s, k, 128)["image"] for s, k in scenes]
    for _ in range(4):
        again = [interact.make_sample(s, k, 128)["image"] for s, k in scenes]
        for a, b in zip(first, again, strict=True):
            assert np.array_equal(a, b)


def test_given_normals_shade_and_only_shade(renderer):
    """Normals passed with a mesh are what the colour pass shades with (the renderer's own area
    normals reproduce the default image exactly); masks and depth never depend on them; a
    normal array of the wrong shape or a zero normal is refused by name."""
    v, f, c, lab = _sphere((0.0, 0.0, 0.40), 0.035, 1)
    own = R.renderer._vertex_normals(np.asarray(v, float), np.asarray(f))
    plain = renderer.render([(v, f, c, lab)], _K())
    same = renderer.render([R.RenderMesh(v, f, c, lab, own * 3.0)], _K())   # normalised there
    assert same.image.tobytes() == plain.image.tobytes()
    flat = np.tile([0.0, 0.0, -1.0], (len(v), 1))      # every normal facing the camera
    turned = renderer.render([(v, f, c, lab, flat)], _K())
    np.testing.assert_array_equal(turned.labels, plain.labels)
    np.testing.assert_array_equal(turned.depth, plain.depth)
    inside = binary_erosion(plain.labels == 1, iterations=2)       # away from blended edges
    # a sphere's shading varies across it; with one normal everywhere it is uniform
    assert plain.image[inside].std(0).max() > 5.0
    assert turned.image[inside].std(0).max() < 0.5
    with pytest.raises(ValueError, match=r"meshes\[0\] normals must have shape"):
        renderer.render([(v, f, c, lab, flat[:-1])], _K())
    with pytest.raises(ValueError, match=r"meshes\[0\] normals must be finite and non-zero"):
        renderer.render([(v, f, c, lab, flat * 0.0)], _K())
    with pytest.raises(ValueError, match=r"occluders\[0\] must be"):
        renderer.render([(v, f, c, lab)], _K(), occluders=[(v, f, c, 1, flat, 0)])


# -- issue 54: a scene of one's own meshes, rendered with one's own camera ----------------------

def _composed():
    import torch

    import handmesh_tutorial as hmt
    from handmesh_tutorial.scenes import Scene, SceneBody

    hand = hmt.hand.HandModel("right")
    out = hand(global_orient=torch.tensor([[np.pi, 0.0, 0.0]]))  # palm to the camera
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.025)
    ball.apply_translation(out.joints[0, 9].numpy() + [0.02, 0.0, -0.1])  # in front of it
    scene = Scene.compose([SceneBody.from_mesh(ball.vertices, ball.faces, label=2, name="ball"),
                           SceneBody.from_hand(out, side="right", label=1, model=hand)])
    K = np.array([[260.0, 0, 63.5], [0, 260.0, 63.5], [0, 0, 1]])
    centre = out.joints[0, 9].numpy()
    camera = (np.eye(3), np.array([0.0, 0.0, 0.4]) - centre, K)
    return hand, out, ball, scene, camera


def test_a_composed_scene_renders_with_masks_and_vr_of_its_own_camera():
    from handmesh_tutorial.render.camera import project
    from handmesh_tutorial.scenes import render_scene

    _, out, ball, scene, camera = _composed()
    assert scene.target == 1 and [b.label for b in scene.bodies] == [1, 2]
    assert len(scene.body(1).cylinders) == 20 and len(scene.body(2).cylinders) == 1
    s = render_scene(scene, 0, 128, camera=camera, photo_prob=0.0)
    hand_alone, ball_alone = s["alone_masks"][1], s["alone_masks"][2]
    # the ball is in front: the hand's VR is its pixels the ball leaves uncovered
    want = 1.0 - (hand_alone & ball_alone).sum() / hand_alone.sum()
    assert 0.3 < want < 0.99 and s["vr"][2] == 1.0
    assert s["vr"][1] == pytest.approx(want, abs=0.01)
    # the ball's silhouette: pixels within its projected radius (independent of the renderer)
    R, t, K = camera
    c = project((ball.vertices.mean(0) @ R.T + t)[None], K)[0]
    depth = (ball.vertices.mean(0) @ R.T + t)[2]
    rad = K[0, 0] * 0.025 / np.sqrt(depth**2 - 0.025**2)
    v, u = np.mgrid[:128, :128]
    disc = (u - c[0]) ** 2 + (v - c[1]) ** 2 <= rad**2
    iou = (disc & ball_alone).sum() / (disc | ball_alone).sum()
    assert iou > 0.93
    np.testing.assert_allclose(s["joints"][1], out.joints[0].numpy() @ R.T + t, atol=1e-6)


def test_make_samples_retries_a_seed_whose_scene_cannot_be_made(monkeypatch):
    import handmesh_tutorial as hmt
    from handmesh_tutorial.scenes import InteractionError
    from handmesh_tutorial.scenes import sample as S

    tried = []

    def fake(seed, kind="hand-hand", image_size=224, **kw):
        tried.append(seed)
        if len(tried) % 2:  # every first try of a sample fails
            raise InteractionError(kind, seed, "no contact")
        return {"image": np.zeros((image_size, image_size, 3), np.uint8)}

    monkeypatch.setattr(S, "make_sample", fake)
    got = S.make_samples(2, seed=9, kind="hand-object", image_size=32)
    seeds = [hmt.data.sample_seed(9, i, a) for i in range(2) for a in range(2)]
    assert tried == seeds and [g["attempt"] for g in got] == [1, 1]
    assert [g["seed"] for g in got] == [seeds[1], seeds[3]]
    monkeypatch.setattr(S, "make_sample", lambda *a, **k: (_ for _ in ()).throw(
        InteractionError("hand-hand", 0, "never")))
    with pytest.raises(InteractionError, match="3 seeds failed.*never"):
        S.make_samples(1, seed=1, max_attempts=3)


def test_network_input_of_a_sample_is_predict_hands_crop():
    import handmesh_tutorial as hmt
    from handmesh_tutorial.render.camera import project
    from handmesh_tutorial.scenes import render_scene

    _, out, _, scene, camera = _composed()
    s = render_scene(scene, 1, 128, camera=camera)
    item = hmt.data.InterSHTorchDataset.network_input(s, 128)
    uv = project(s["meshes"][1][0].astype(np.float64), s["K"])
    box = (*uv.min(0), *uv.max(0))
    crop = hmt.inference.crop_hand(s["image"], box, "right", image_size=128, K=s["K"])
    np.testing.assert_allclose(item["image"].numpy(), crop.image.numpy(), atol=1e-5)
