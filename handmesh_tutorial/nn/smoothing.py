"""Fixed Laplacian smoothing of per-vertex fields on a mesh: the output smoothing of the MSMR
model (a sparse vertex map applied to the predicted vertices) and its length scale.

Taught in notebook 07 ("Multi-path mesh decoder"); docs page "The hand model".
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["smoothing_matrix", "mean_edge_length", "smoothing_steps"]


def smoothing_matrix(faces, steps: int, num_vertices: int | None = None,
                     weight: float = 0.5) -> sp.csr_matrix:
    """Fixed Laplacian smoothing of per-vertex fields: ``((1 - w) I + w D^-1 A)^steps``.

    ``A`` is the vertex adjacency of the mesh (1 per edge), ``D`` the vertex degrees, so each
    step moves every value a fraction ``w`` toward the mean of its 1-ring. Rows sum to 1 and are
    non-negative: constant fields (and hence translations) pass unchanged. Isolated vertices
    keep their value.

    Args:
        faces: ``(F, 3)`` int triangles.
        steps: number of smoothing steps (0 = identity).
        num_vertices: ``V`` (default ``faces.max() + 1``).
        weight: ``w`` in ``[0, 1]``.

    Returns:
        scipy CSR ``(V, V)`` float64.
    """
    f = np.asarray(faces, dtype=np.int64)
    n = int(f.max()) + 1 if num_vertices is None else int(num_vertices)
    if steps < 0 or int(steps) != steps:
        raise ValueError(f"steps must be a non-negative integer, got {steps}")
    if not 0.0 <= weight <= 1.0:
        raise ValueError(f"weight must lie in [0, 1], got {weight}")
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    adj = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                        shape=(n, n)).tocsr()
    deg = np.asarray(adj.sum(1)).ravel()
    isolated = deg == 0
    walk = sp.diags(np.where(isolated, 0.0, 1.0 / np.maximum(deg, 1))) @ adj
    step = sp.diags(np.where(isolated, 1.0, 1.0 - weight)) + weight * walk
    out = sp.identity(n, format="csr")
    for _ in range(int(steps)):
        out = step @ out
    return sp.csr_matrix(out)


def mean_edge_length(vertices, faces) -> float:
    """Mean length of the mesh's (unique) edges, in the unit of ``vertices``.

    Args:
        vertices: ``(V, 3)``.
        faces: ``(F, 3)`` int.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1),
                  axis=0)
    return float(np.linalg.norm(v[e[:, 1]] - v[e[:, 0]], axis=1).mean())


def smoothing_steps(vertices, faces, length: float) -> int:
    """Steps of [`smoothing_matrix`][handmesh_tutorial.nn.smoothing.smoothing_matrix] (weight 0.5)
    that smooth over a given length.

    Each step is half a step of a random walk on the edges, so ``k`` steps spread a value over
    about ``sigma = e * sqrt(k / 2)`` (``e`` the mean edge length): ``k = round(2 (sigma / e)^2)``.
    The same physical smoothing on a finer mesh takes more steps.

    Args:
        vertices: ``(V, 3)`` template vertices, metres.
        faces: ``(F, 3)`` int.
        length: ``sigma``, metres (0 = no smoothing).

    Returns:
        ``k >= 0``.
    """
    if length < 0:
        raise ValueError(f"length must be >= 0, got {length}")
    if length == 0:
        return 0
    return int(round(2.0 * (length / mean_edge_length(vertices, faces)) ** 2))
