"""Figures of `handmesh_tutorial.viz` that tests can check by their numbers (limits, artists)."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from handmesh_tutorial import collision, viz  # noqa: E402


@pytest.mark.parametrize("capsule", [False, True])
def test_plot_cylinders_autoscales_on_the_cylinders_only(capsule):
    # matplotlib (3.11) stores ragged polygon lists in an np.empty array and autoscales the axes
    # on all of it, unused padding included: a cylinder's 24-gon caps next to its quads let
    # whatever the heap held reach the axis limits (seen in notebook 03: infinite limits,
    # "Singular matrix"). Fill freed memory of the padded array's size with huge numbers first.
    body = collision.Cylinders([[0, 0, 0], [0.01, 0, 0]], [[0, 0, 0.03], [0.01, 0.02, 0.03]],
                               [0.008, 0.006])
    lo = np.minimum(body.p0, body.p1).min(0) - body.radius.max()
    hi = np.maximum(body.p0, body.p1).max(0) + body.radius.max()
    for _ in range(5):
        junk = [np.full((26, 24, 3), 1e300) for _ in range(200)]
        del junk
        fig = plt.figure()
        ax = fig.add_subplot(projection="3d")
        artists = viz.plot_cylinders(ax, body, capsule=capsule)
        assert len(artists) == 2
        limits = np.array([ax.xy_dataLim.intervalx, ax.xy_dataLim.intervaly,
                           ax.zz_dataLim.intervalx])
        plt.close(fig)
        assert np.isfinite(limits).all()
        assert (limits[:, 0] >= lo - 1e-9).all() and (limits[:, 1] <= hi + 1e-9).all(), limits


def _matplotlib_viewing_direction(ax) -> np.ndarray:
    """The direction matplotlib's projection looks along, from its projection matrix alone: the
    data direction that leaves the screen position unchanged, oriented towards growing depth."""
    from mpl_toolkits.mplot3d import proj3d

    ax.figure.canvas.draw()
    m = ax.get_proj()
    centre = np.array([np.mean(ax.get_xlim3d()), np.mean(ax.get_ylim3d()),
                       np.mean(ax.get_zlim3d())])
    step = 1e-4 * (ax.get_xlim3d()[1] - ax.get_xlim3d()[0])

    def project(p):
        return np.array(proj3d.proj_transform(*(np.asarray(p)[:, None]), m)).ravel()

    jac = np.stack([(project(centre + step * e) - project(centre - step * e)) / (2 * step)
                    for e in np.eye(3)], axis=1)          # (3 outputs: x, y, depth) x (3 inputs)
    d = np.cross(jac[0], jac[1])
    d /= np.linalg.norm(d)
    return d if d @ jac[2] > 0 else -d


def test_the_hand_camera_is_a_three_quarter_view_never_from_the_wrist_end():
    # hand template frame: +x wrist -> fingers, palm -y (back +y), right thumb -z
    d = viz.view_direction(viz.HAND_VIEW)
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    viz.set_axes_equal(ax, np.array([[-1.0, -1, -1], [1, 1, 1]]))
    ax.view_init(**viz.HAND_VIEW)
    seen = _matplotlib_viewing_direction(ax)
    plt.close(fig)
    assert np.degrees(np.arccos(np.clip(seen @ d, -1, 1))) < 1.0, (seen, d)
    eye = -d
    assert abs(d[0]) < 0.8, f"looks along the wrist-fingers axis: {d}"
    assert eye[0] > -0.2, f"the eye sits behind the wrist (views from the wrist end): {eye}"
    assert eye[1] > 0.5, f"the eye does not look at the back of the hand from above: {eye}"
    assert abs(eye[2]) > 0.3, f"not a three-quarter view (no side component): {eye}"


def test_view_direction_follows_matplotlib_for_every_vertical_axis():
    for view in ({"elev": 30, "azim": -60}, {"elev": -20, "azim": 100, "vertical_axis": "x"},
                 {"elev": 10, "azim": 200, "vertical_axis": "y"}):
        fig = plt.figure()
        ax = fig.add_subplot(projection="3d")
        viz.set_axes_equal(ax, np.array([[-1.0, -1, -1], [1, 1, 1]]))
        ax.view_init(**view)
        seen = _matplotlib_viewing_direction(ax)
        plt.close(fig)
        assert np.allclose(seen, viz.view_direction(view), atol=1e-3), view
    with pytest.raises(ValueError, match="vertical_axis"):
        viz.view_direction({"elev": 0, "azim": 0, "vertical_axis": "w"})


def test_hand_figures_use_the_shared_camera_by_default():
    from handmesh_tutorial import hand

    model = hand.HandModel("right")
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    viz.plot_hand(ax, model.template_vertices, model.faces)
    ax2 = viz.hand_axes(fig, 1, 2, 2)
    got = [(a.elev, a.azim) for a in (ax, ax2)]
    plt.close(fig)
    assert got == [(viz.HAND_VIEW["elev"], viz.HAND_VIEW["azim"])] * 2


@pytest.mark.parametrize("capsule", [False, True])
def test_plot_cylinders_light_shades_outward_faces_in_one_artist(capsule):
    # one cylinder along z, one along x; light travelling towards -x: the faces whose outward
    # normal is +x are lit fully, those facing -x keep the 0.35 ambient share of their colour
    body = collision.Cylinders([[0, 0, 0], [0.02, 0, 0]], [[0, 0, 0.03], [0.05, 0, 0]],
                               [0.008, 0.006])
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    artists = viz.plot_cylinders(ax, body, colors=["#ff0000", "#00ff00"], alpha=1.0,
                                 light=(-1.0, 0.0, 0.0), capsule=capsule)
    assert len(artists) == 1            # one artist: polygons depth-sorted across cylinders
    # polygons and their colours in drawing order as matplotlib holds them (private names,
    # matplotlib 3.11; get_facecolor() is the depth-sorted 2D order): (P, k, 3), each polygon
    # padded with copies of its last vertex (their means stay on the polygon's side)
    rgba = np.asarray(artists[0]._facecolor3d)
    centres = np.asarray(artists[0]._faces).mean(axis=1)
    plt.close(fig)
    assert len(centres) == len(rgba) and np.allclose(rgba[:, 3], 1.0)
    brightness = rgba[:, :3].max(1)
    z_cyl = rgba[:, 1] == 0              # the z cylinder's faces (red: green channel 0)
    assert np.isclose(brightness[z_cyl].max(), 1.0, atol=0.02)
    assert np.isclose(brightness.min(), 0.35, atol=1e-6)
    # lit faces sit on the +x side of their cylinder, faces in shadow on the -x side
    axis_x = np.where(z_cyl, 0.0, np.clip(centres[:, 0], 0.02, 0.05))
    lit, dark = brightness > 0.9, brightness < 0.36
    assert (centres[lit & z_cyl, 0] > 0.005).all() and (centres[dark & z_cyl, 0] < 1e-9).all()
    assert (centres[lit, 0] >= axis_x[lit] - 1e-9).all()
    beyond = ~z_cyl & (centres[:, 0] > 0.05 - 1e-9)     # the +x end: flat cap or half ball
    assert beyond.any() and brightness[beyond].min() > 0.4 and brightness[beyond].max() > 0.9
    behind = ~z_cyl & (centres[:, 0] < 0.02 + 1e-9)     # the -x end faces away from the light
    assert behind.any() and np.allclose(brightness[behind], 0.35)
    # flat colours stay the default, one artist per cylinder
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    flat = viz.plot_cylinders(ax, body, colors=["#ff0000", "#00ff00"], alpha=1.0)
    assert len(flat) == 2 and np.allclose(flat[0].get_facecolor()[:, :3], [1, 0, 0])
    with pytest.raises(ValueError, match="non-zero"):
        viz.plot_cylinders(ax, body, light=(0, 0, 0))
    # one opacity per cylinder, in both modes
    see = viz.plot_cylinders(ax, body, alpha=[0.25, 1.0], light=(-1.0, 0.0, 0.0))[0]
    assert sorted(set(np.round(np.asarray(see._facecolor3d)[:, 3], 6))) == [0.25, 1.0]
    assert [a.get_facecolor()[0, 3] for a in viz.plot_cylinders(ax, body, alpha=[0.25, 1])] \
        == [0.25, 1.0]
    with pytest.raises(ValueError, match="2 values"):
        viz.plot_cylinders(ax, body, alpha=[0.2, 0.3, 0.4])

def test_overlay_titles_stay_clear_of_the_row_above():
    # notebook 09's best/worst figure: the prediction panels' two-line titles ran into the images
    # of the row above under tight_layout
    rng = np.random.default_rng(0)
    K = np.array([[100.0, 0, 32], [0, 100.0, 32], [0, 0, 1]])
    verts = rng.normal(0, 0.02, (30, 3)) + [0, 0, 0.5]
    faces = np.array([[0, 1, 2], [2, 3, 4]])
    sample = {"image": np.zeros((64, 64, 3), np.uint8), "K": K, "meshes": {1: (verts, faces)},
              "target": 1, "kind": "hand-hand", "vr": {1: 0.5}}
    n = 6
    fig = viz.plot_overlays([sample] * n, np.stack([verts] * n), faces,
                            [f"worst hand-hand: {i + 17.4:.1f} mm" for i in range(n)])
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    axes = np.array(fig.axes).reshape(-1, 6)
    for r in range(1, len(axes)):
        for c in range(6):
            title = axes[r, c].title.get_window_extent(renderer)
            above = axes[r - 1, c].get_window_extent(renderer)
            assert title.y1 > title.y0 and title.y1 <= above.y0 + 0.5, (r, c)
    plt.close(fig)


def test_loss_curves_legend_covers_none_of_the_baseline_lines():
    # notebook 08's loss figure: the validation legend sat on the rest / mean hand lines
    history = [{"epoch": e, "step": 10 * e, "train_loss": 0.01 / e, "val_pa_mpjpe": 9.0 - e,
                "val_pa_mpvpe": 8.5 - e, "val_mpjpe": 14.0 - e} for e in range(1, 6)]
    base = {"rest hand": {"pa_mpjpe": 11.2, "pa_mpvpe": 10.3},
            "mean hand": {"pa_mpjpe": 8.2, "pa_mpvpe": 7.6}}
    fig = viz.plot_loss_curves(history, np.linspace(0.04, 0.005, 50), base)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[1]
    legend = ax.get_legend().get_window_extent(renderer)
    panel = ax.get_window_extent(renderer)
    assert legend.x0 >= panel.x1, "the legend lies on the panel, over its lines"
    assert legend.x1 <= fig.bbox.x1 + 0.5, "the legend runs off the figure"
    assert len(ax.get_legend().get_texts()) == 7  # 3 curves, 2 baselines each for PA- errors
    plt.close(fig)
