"""The pinhole camera: intrinsics, projection to pixels, crop cameras and framing.

One convention for the whole library (docs page *Rendering and cameras*, "Camera conventions"):
the OpenCV camera frame (x right, y down, z forward, metres), intrinsics
``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels, pixel centres at integer coordinates: the
top-left pixel's centre is ``(0, 0)``, so the centre of a ``W``-wide image is ``cx = (W - 1) / 2``.
The FreiHAND annotations, the renderer, the crops of the training pipeline and the 2D keypoint
targets all project with `project` (`project_checked` adds the renderer's input checks).

Cameras: `intrinsics` builds ``K``, `check_intrinsics` validates it, `crop_camera` picks a ``K``
that frames given points (like cropping a photo) and `framing` measures how points sit in an image.

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "check_intrinsics",
    "crop_camera",
    "framing",
    "intrinsics",
    "project",
    "project_checked",
]


def project(points, K):
    """Project 3D camera-frame points to pixels with a pinhole intrinsic matrix.

    ``uv = (K @ p)[:2] / (K @ p)[2]``, FreiHAND's official ``projectPoints``, batched.

    Args:
        points: (..., P, 3) points in metres, OpenCV camera frame (z forward); numpy or torch.
        K: (..., 3, 3) intrinsic matrices, broadcastable against ``points``' batch dimensions.

    Returns:
        (..., P, 2) pixel coordinates (u right, v down), same library (numpy/torch) as
        ``points``.
    """
    if hasattr(points, "detach"):
        import torch

        k = torch.as_tensor(K, dtype=points.dtype, device=points.device)
        if points.shape[-1] != 3 or k.shape[-2:] != (3, 3):
            raise ValueError(f"points must be (...,P,3) and K (...,3,3), got {tuple(points.shape)}"
                             f" and {tuple(k.shape)}")
        uvw = points @ k.transpose(-1, -2)
        return uvw[..., :2] / uvw[..., 2:]
    p = np.asarray(points, dtype=np.float64)
    k = np.asarray(K, dtype=np.float64)
    if p.shape[-1] != 3 or k.shape[-2:] != (3, 3):
        raise ValueError(f"points must be (...,P,3) and K (...,3,3), got {p.shape} and {k.shape}")
    uvw = p @ np.swapaxes(k, -1, -2)
    return uvw[..., :2] / uvw[..., 2:]


def intrinsics(fx: float, fy: float | None = None, cx: float = 0.0, cy: float = 0.0) -> np.ndarray:
    """Build an OpenCV pinhole matrix.

    Args:
        fx: focal length along x, pixels.
        fy: focal length along y, pixels (default ``fx``).
        cx: principal point column, pixels (pixel centres at integers).
        cy: principal point row, pixels.

    Returns:
        ``K`` (3, 3) float64.

    Raises:
        ValueError: ``fx`` or ``fy`` not a finite number > 0, ``cx`` or ``cy`` not finite (as
            `check_intrinsics` refuses such a ``K``).
    """
    fy = fx if fy is None else fy
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)
    if not np.isfinite(K).all():
        raise ValueError(f"fx, fy, cx, cy must be finite numbers (pixels), got {fx}, {fy}, "
                         f"{cx}, {cy}")
    return check_intrinsics(K)


def check_intrinsics(K: Any) -> np.ndarray:
    """Check that ``K`` is one OpenCV pinhole matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.

    Args:
        K: (3, 3) intrinsics, pixels; ``fx, fy > 0`` and no skew.

    Returns:
        ``K`` as a (3, 3) float64 array.

    Raises:
        ValueError: another shape, ``fx`` or ``fy <= 0``, a skew or a last row other than
            ``(0, 0, 1)``.
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {K.shape}")
    if not (K[0, 0] > 0 and K[1, 1] > 0) or abs(K[0, 1]) > 1e-12 or np.any(K[2] != (0, 0, 1)):
        raise ValueError("K must be [[fx,0,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0, "
                         f"got {K.tolist()}")
    return K


def project_checked(points: Any, K: Any) -> np.ndarray:
    """`project` for one camera, with the renderer's input checks (``render.project``).

    The same arithmetic as `project` (float64); it first checks ``K`` with `check_intrinsics`,
    that ``points`` is one (N, 3) array and that every point lies in front of the camera.

    Args:
        points: (N, 3) points in the OpenCV camera frame, metres, ``Z > 0``.
        K: (3, 3) intrinsics.

    Returns:
        (N, 2) float64 pixel coordinates ``(u = column, v = row)``, pixel centres at integers.

    Raises:
        ValueError: bad shapes, ``K`` not of pinhole form, a NaN or infinite point, or a point
            with ``Z <= 0``.
    """
    K = check_intrinsics(K)
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("points contains NaN or inf")
    if np.any(P[:, 2] <= 0):
        raise ValueError("points must lie in front of the camera (Z > 0)")
    return project(P, K)


def crop_camera(points3d: Any, image_size: int, margin: float = 0.1, focal: float | None = None,
                center: Any = None) -> np.ndarray:
    """A pinhole ``K`` for a square image that frames given 3D points (a "crop camera").

    The camera stays at the origin of the OpenCV camera frame (the points do not move); only the
    focal length and the principal point are chosen, exactly like cropping and rescaling a larger
    photo. The framing point ``center`` (default: the centre of the points' projected bounding box)
    lands on the image centre ``((S-1)/2, (S-1)/2)`` and every point lands at least
    ``margin * S`` pixels inside the image border (which lies at ``-0.5`` and ``S - 0.5`` in
    pixel coordinates, since pixel centres are integers).

    Args:
        points3d: (N, 3) points in the camera frame, metres, ``Z > 0`` (e.g. the target hand's
            vertices).
        image_size: side ``S`` of the square image, pixels (e.g. 224).
        margin: free border on each side as a fraction of ``S``, in ``[0, 0.5)``.
        focal: fixed focal length in pixels; ``None`` picks the largest focal that fits.
        center: optional (3,) point to centre on (e.g. the interaction centre), camera frame.

    Returns:
        ``K`` (3, 3) float64 with ``fx = fy``.

    Raises:
        ValueError: bad shapes, NaN or infinite points, ``Z <= 0``, a margin outside
            ``[0, 0.5)``, or a fixed ``focal`` too long to keep all points inside (the message
            gives the largest focal that fits).
    """
    P = np.asarray(points3d, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        raise ValueError(f"points3d must have shape (N, 3) with N >= 1, got {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("points3d contains NaN or inf")
    if np.any(P[:, 2] <= 0):
        raise ValueError("points3d must lie in front of the camera (Z > 0)")
    if not 0.0 <= margin < 0.5:
        raise ValueError(f"margin must be in [0, 0.5), got {margin}")
    S = int(image_size)
    if S < 1:
        raise ValueError(f"image_size must be a positive integer, got {image_size}")
    n = P[:, :2] / P[:, 2:3]  # normalised image coordinates
    if center is None:
        c = 0.5 * (n.min(0) + n.max(0))
    else:
        C = np.asarray(center, dtype=np.float64).reshape(-1)
        if C.shape != (3,) or C[2] <= 0:
            raise ValueError(f"center must be a (3,) point with Z > 0, got {np.asarray(center)}")
        c = C[:2] / C[2]
    half = (0.5 - margin) * S  # pixels available between centre and the margin
    reach = float(np.abs(n - c).max())
    f_fit = half / reach if reach > 0 else float(S)
    if focal is None:
        f = f_fit
    else:
        f = float(focal)
        if f <= 0:
            raise ValueError(f"focal must be > 0, got {focal}")
        if f > f_fit * (1 + 1e-9):
            raise ValueError(f"focal {f:.1f} px puts points outside the {margin:.2f} margin; "
                             f"the largest focal that fits is {f_fit:.1f} px")
    mid = (S - 1) / 2.0
    return intrinsics(f, f, mid - f * c[0], mid - f * c[1])


def framing(points3d: Any, K: Any, image_size: int, margin: float = 0.08) -> dict:
    """How a body is framed in a square image: its share of the image and what lies inside.

    Args:
        points3d: (N, 3) points in the camera frame, metres, ``Z > 0`` (a hand's vertices or
            its 21 joints).
        K: (3, 3) intrinsics.
        image_size: side ``S`` of the square image, pixels.
        margin: border, as a fraction of ``S``, that counts as outside for ``inside``.

    Returns:
        dict with ``share`` (the longer side of the points' projected bounding box over ``S``),
        ``inside`` (fraction of the points at least ``margin * S`` pixels inside the image
        border, which lies at ``-0.5`` and ``S - 0.5``) and ``center`` ((2,) bounding-box centre,
        pixels).
    """
    uv = project_checked(points3d, K)
    S = int(image_size)
    lo, hi = uv.min(0), uv.max(0)
    m = margin * S
    ok = ((uv >= -0.5 + m) & (uv <= S - 0.5 - m)).all(1)
    return {"share": float((hi - lo).max() / S), "inside": float(ok.mean()),
            "center": 0.5 * (lo + hi)}
