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
