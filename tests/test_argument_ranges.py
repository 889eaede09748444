"""Public functions refuse arguments outside their documented ranges, as their siblings do
(issue 43, item 10; the fresh probe of functions the issue did not list). Each case below
returned NaN or garbage, or failed deep inside without naming the argument."""

from __future__ import annotations

import numpy as np
import pytest

from handmesh_tutorial import collision, data, inference, render, scenes
from handmesh_tutorial.hand import HandModel, random_shape

NAN, INF = float("nan"), float("inf")


def _hand_points():
    return np.random.default_rng(0).normal(size=(21, 3)) * 0.03 + [0.0, 0.0, 0.5]


CASES = [
    # a NaN K, a zero focal length
    (lambda: render.intrinsics(NAN), "fx, fy, cx, cy must be finite numbers"),
    (lambda: render.intrinsics(0.0), r"fx, fy > 0"),
    (lambda: render.intrinsics(500.0, cx=INF), "must be finite numbers"),
    # a K of NaN from NaN points
    (lambda: render.crop_camera(_hand_points() * NAN, 64), "points3d contains NaN or inf"),
    (lambda: render.camera.project_checked(_hand_points() * NAN, np.eye(3)),
     "points contains NaN or inf"),
    # a camera of NaN for a 0-px image
    (lambda: scenes.frame_camera(_hand_points(), 0, 0),
     r"image_size must be an integer in \[32, 4096\] pixels, got 0"),
    (lambda: scenes.frame_camera(_hand_points() * NAN, 0, 64), "finite \\(N, 3\\) array"),
    # the centre behind the camera, a NaN translation
    (lambda: scenes.camera_pose(np.zeros(3), np.random.default_rng(0), distance=(-1, -0.5)),
     r"distance must be \(min, max\) metres with 0 < min <= max"),
    (lambda: scenes.camera_pose(np.full(3, NAN), np.random.default_rng(0)),
     r"centre must be a finite \(3,\) point"),
    # NaN shapes; numpy's 'negative dimensions'
    (lambda: random_shape(0, 1, scale=NAN), "scale must be a finite number >= 0, got nan"),
    (lambda: random_shape(0, -1), "batch must be an integer >= 0"),
    # overlapping bins: a value in both counted in the first only
    (lambda: data.vr_bins([(0.4, 0.7), (0.6, 0.9)]), "increasing and non-overlapping"),
    # 'SVD did not converge'
    (lambda: inference.root_from_keypoints(_hand_points(), np.full((21, 2), NAN), np.eye(3)),
     "keypoints_2d contains NaN or inf"),
]


@pytest.mark.parametrize("call, says", CASES)
def test_out_of_range_arguments_are_refused_naming_them(call, says):
    with pytest.raises(ValueError, match=says):
        call()


def test_coverage_refuses_a_tolerance_that_counts_every_vertex_as_covered():
    out = HandModel()()
    body = collision.hand_cylinders(out)
    far = out.vertices[0].numpy() + 1.0  # every vertex a metre away from the hand
    assert collision.coverage(far, body)["fraction_outside"] == 1.0
    for tol in (NAN, -1e-3, INF):
        with pytest.raises(ValueError, match="tol must be a finite distance >= 0"):
            collision.coverage(far, body, tol=tol)  # NaN said 0.0 outside


def test_the_values_inside_the_ranges_still_work():
    assert render.intrinsics(500.0, 400.0, 32.0, 31.5).tolist() == [[500, 0, 32], [0, 400, 31.5],
                                                                    [0, 0, 1]]
    assert random_shape(0, 0).shape == (0, 6) and not random_shape(0, 2, scale=0).any()
    assert data.vr_bins([(0.4, 0.6), (0.6, 1.0)]) == data.vr_bins([0.4, 0.6, 1.0])
    R, t, K = scenes.frame_camera(_hand_points(), 0, 64)
    assert np.isfinite(K).all() and K[0, 0] > 0


def _png_claiming(path, width: int, height: int) -> None:
    """A tiny PNG whose header claims ``width`` x ``height`` (its CRC fixed): 12000 x 12000
    pixels in a few hundred bytes."""
    import io
    import struct
    import zlib

    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 8)).save(buf, format="PNG")
    raw = bytearray(buf.getvalue())
    ihdr = raw.index(b"IHDR")
    raw[ihdr + 4:ihdr + 12] = struct.pack(">II", width, height)
    raw[ihdr + 17:ihdr + 21] = struct.pack(">I", zlib.crc32(bytes(raw[ihdr:ihdr + 17])))
    path.write_bytes(bytes(raw))


def test_an_input_image_of_too_many_pixels_is_refused_before_decoding(tmp_path):
    from handmesh_tutorial.budget import MAX_INPUT_PIXELS

    path = tmp_path / "huge.png"
    _png_claiming(path, 12_000, 12_000)  # decoded: 432 MB, and 4 GB on its way to the network
    assert path.stat().st_size < 1000
    with pytest.raises(ValueError, match=r"huge\.png: 12000 x 12000 pixels, more than the "
                                         r"67,108,864 \(MAX_INPUT_PIXELS"):
        inference.check_image(path)
    with pytest.raises(ValueError, match=r"huge\.png: 12000 x 12000 pixels"):
        inference.predict_hand(path, (0, 0, 100, 100), "right")
    big = np.broadcast_to(np.zeros((1, 1, 3), np.uint8), (9000, 8000, 3))  # no memory
    with pytest.raises(ValueError, match=r"image: 8000 x 9000 pixels, more than"):
        inference.check_image(big)
    assert 8192 * 8192 == MAX_INPUT_PIXELS
    assert inference.check_image(np.zeros((64, 48, 3), np.uint8)).shape == (64, 48, 3)
