"""The pinhole camera: projecting camera-frame points to pixels.

One convention for the whole library (docs page *Rendering and visibility*): the OpenCV camera
frame (x right, y down, z forward, metres), intrinsics ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``
in pixels, pixel centres at integer coordinates. The FreiHAND annotations, the renderer, the
crops of the training pipeline and the 2D keypoint targets all project with `project`.

Taught in notebook 05 ("Rendering and visibility").
"""

from __future__ import annotations

import numpy as np

__all__ = ["project"]


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
