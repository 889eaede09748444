"""The matrices between two levels of the hierarchy: the 0/1 down (selection) matrix, the
closest-point barycentric up matrix, and their conversion to torch sparse tensors.

Down ``(V_coarse, V_fine)``, up ``(V_fine, V_coarse)``, scipy CSR float64. Taught in notebook 06
(mesh hierarchy and spiral convolution).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import trimesh

from ._common import _check_mesh

__all__ = ["selection_matrix", "barycentric_upsampling", "to_torch_sparse"]


def selection_matrix(kept, num_fine: int) -> sp.csr_matrix:
    """0/1 down-sampling matrix that picks the kept vertices.

    Args:
        kept: (V_coarse,) int ids of the fine vertices that survive, in coarse order.
        num_fine: V_fine, the number of fine vertices.

    Returns:
        (V_coarse, V_fine) float64 CSR matrix with a single 1 per row, at column ``kept[i]``.

    Shapes:
        ``kept (V_coarse,)`` -> ``(V_coarse, V_fine)``.
    """
    kept = np.asarray(kept, dtype=np.int64)
    n = len(kept)
    return sp.csr_matrix((np.ones(n), (np.arange(n), kept)), shape=(n, num_fine))


def barycentric_upsampling(fine_vertices, coarse_vertices, coarse_faces, kept=None,
                           chunk: int = 256) -> sp.csr_matrix:
    """Up-sampling matrix from closest-point barycentric coordinates on the coarse mesh.

    Every fine vertex is projected onto the closest point of the closest coarse triangle (an
    exact search over all triangles, pruned by bounding spheres, so the result does not depend
    on a spatial index; ties go to the lowest triangle id); the
    barycentric coordinates of that point, clipped at 0 and renormalised against rounding, are
    its row. Rows therefore sum to 1 and are non-negative, which makes the map commute with
    translations. Rows of kept vertices are set to exactly one 1.

    Args:
        fine_vertices: (V_fine, 3) positions of the fine mesh.
        coarse_vertices: (V_coarse, 3) positions of the coarse mesh.
        coarse_faces: (F_coarse, 3) int triangles of the coarse mesh.
        kept: optional (V_coarse,) ids of the fine vertices that are the coarse vertices.
        chunk: fine vertices processed at once (memory ~ chunk * F_coarse * 50 bytes).

    Returns:
        (V_fine, V_coarse) float64 CSR matrix with at most 3 non-zeros per row.

    Shapes:
        ``fine_vertices (V_fine, 3)``, ``coarse_vertices (V_coarse, 3)``,
        ``coarse_faces (F_coarse, 3)`` -> ``(V_fine, V_coarse)``.
    """
    fine = np.asarray(fine_vertices, dtype=np.float64)
    cv, cf = _check_mesh(coarse_vertices, coarse_faces)
    tris = cv[cf]  # (F, 3, 3)
    # Bounding spheres prune the exact search: the centroid is on the triangle (an upper bound
    # of the distance) and no triangle point is farther than `radius` from it (a lower bound).
    centre = tris.mean(axis=1)
    radius = np.linalg.norm(tris - centre[:, None], axis=2).max(axis=1)
    rows, cols, vals = [], [], []
    for start in range(0, len(fine), chunk):
        pts = fine[start:start + chunk]
        m = len(pts)
        dc = np.linalg.norm(pts[:, None] - centre[None], axis=2)  # (m, F)
        upper = dc.min(axis=1, keepdims=True)
        pi, ti = np.nonzero(dc - radius[None] <= upper * (1 + 1e-9) + 1e-12)
        closest = trimesh.triangles.closest_point(tris[ti], pts[pi])
        d2 = np.einsum("ij,ij->i", closest - pts[pi], closest - pts[pi])
        # Per point, the candidate with the smallest distance, ties to the lowest triangle id
        # (candidates come sorted by point, then triangle id).
        order = np.lexsort((ti, d2, pi))
        first = order[np.r_[True, pi[order][1:] != pi[order][:-1]]]
        best = ti[first]
        bary = trimesh.triangles.points_to_barycentric(tris[best], closest[first])
        bary = np.clip(bary, 0.0, None)
        bary /= bary.sum(axis=1, keepdims=True)
        rows.append(np.repeat(np.arange(start, start + m), 3))
        cols.append(cf[best].reshape(-1))
        vals.append(bary.reshape(-1))
    up = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(len(fine), len(cv))).tocsr()
    if kept is not None:
        kept = np.asarray(kept, dtype=np.int64)
        up = up.tolil()
        for i, k in enumerate(kept.tolist()):
            up.rows[k] = [i]
            up.data[k] = [1.0]
        up = up.tocsr()
    up.eliminate_zeros()
    up.sort_indices()
    return up


def to_torch_sparse(matrix: sp.spmatrix, dtype=None):
    """Convert a scipy sparse matrix to a coalesced ``torch.sparse_coo_tensor`` (float32).

    Args:
        matrix: (M, N) scipy sparse matrix, e.g. ``hierarchy.down[l]`` or ``hierarchy.up[l]``.
        dtype: torch dtype, default ``torch.float32``.

    Returns:
        (M, N) sparse COO tensor; use ``torch.sparse.mm(t, x)`` with ``x`` (N, C).

    Shapes:
        ``(M, N)`` scipy sparse -> ``(M, N)`` torch sparse COO.

    For a layer that applies such a map to batched ``(B, N, C)`` features (and exports to
    ONNX), use [`Pool`][handmesh_tutorial.nn.blocks.Pool].

    Examples:
        >>> import numpy as np, scipy.sparse as sp, torch
        >>> m = sp.csr_matrix(np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]]))
        >>> torch.sparse.mm(to_torch_sparse(m), torch.ones(3, 2))
        tensor([[1., 1.],
                [1., 1.]])
    """
    import torch

    coo = sp.coo_matrix(matrix)
    idx = torch.from_numpy(np.vstack([coo.row, coo.col]).astype(np.int64))
    val = torch.from_numpy(coo.data).to(dtype or torch.float32)
    return torch.sparse_coo_tensor(idx, val, coo.shape, check_invariants=True).coalesce()
