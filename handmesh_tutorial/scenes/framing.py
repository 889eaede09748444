"""Step 6, the camera: `frame_camera` frames the target hand like a FreiHAND 224-px crop;
`camera_pose` is a plain random look-at camera.

World -> OpenCV camera frame ``X_cam = R @ X + t`` (metres), intrinsics in pixels. Taught in
notebook 05 ("Rendering and visibility").
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ._common import _random_direction, _unit

__all__ = ["FRAME_FOCAL", "FRAME_MARGIN", "FRAME_SHARE", "camera_pose", "frame_camera"]


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

    Raises:
        ValueError: ``centre`` not a finite (3,) point, or ``distance`` not ``(min, max)`` with
            ``0 < min <= max`` finite (a negative distance put ``centre`` behind the camera).
    """
    c = np.asarray(centre, float)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise ValueError(f"centre must be a finite (3,) point, got {c.tolist()}")
    if len(distance) != 2 or not 0 < distance[0] <= distance[1] < np.inf:
        raise ValueError(f"distance must be (min, max) metres with 0 < min <= max, got "
                         f"{distance}")
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
roughly 40-80 %), see [`frame_camera`][handmesh_tutorial.scenes.framing.frame_camera].
"""
FRAME_FOCAL: tuple[float, float] = (1.8, 3.6)
"""Focal length as a multiple of the image side (403-806 px at 224 px, fields of view of
31-16 degrees: a crop of a hand from an ordinary camera), see
[`frame_camera`][handmesh_tutorial.scenes.framing.frame_camera].
"""
FRAME_MARGIN: float = 0.08
"""Free border, as a fraction of the image side, that the target hand never enters."""


def _check_share(share, margin: float = FRAME_MARGIN, name: str = "share") -> tuple[float, float]:
    """``share`` as ``(min, max)`` floats, or ValueError unless ``0 < min <= max <= 1 - 2 margin``
    (the whole target hand, with its margin on both sides, must fit in the image)."""
    try:
        lo, hi = (float(x) for x in share)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be two numbers (min, max), got {share!r}") from None
    top = 1.0 - 2.0 * margin
    if not 0.0 < lo <= hi <= top:
        raise ValueError(f"{name} must satisfy 0 < min <= max <= {top:.2f} (the target hand keeps "
                         f"a {margin:.0%} margin), got {share!r}")
    return lo, hi


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
        ValueError: a share, focal or margin range that cannot be met, an image side outside
            [32, 4096] pixels, or vertices that are not a finite (N, 3) array.
    """
    from ..budget import check_image_size
    from ..render import intrinsics

    V = np.asarray(target_vertices, float)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0 or not np.isfinite(V).all():
        raise ValueError(f"target_vertices must be a finite (N, 3) array with N >= 1, got "
                         f"shape {V.shape}")
    S = check_image_size(image_size)
    rng = np.random.default_rng(rng)
    if not 0 <= margin < 0.5:
        raise ValueError(f"need 0 <= margin < 0.5, got {margin}")
    lo_s, hi_s = _check_share(share, margin)
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
