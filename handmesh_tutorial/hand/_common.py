"""Private helpers shared by the submodules of ``hand`` (and by ``makehuman`` and ``mano``).

Mesh-graph helpers (the wrist's boundary loop, the vertex adjacency), a unit-vector helper, and
the input checks and output assembly that [`HandModel`][handmesh_tutorial.hand.model.HandModel]
and [`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel] share (one copy for both models).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _boundary_loop(faces: np.ndarray) -> np.ndarray:
    """The vertices of the mesh's single boundary loop, in order along the loop."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    n = int(e.max()) + 1 if e.size else 1
    # half-edges with no twin (a, b) -> (b, a), as integer codes (a set of tuples took ~0.1 s
    # per hand model, at every worker's first sample)
    twinless = ~np.isin(e[:, 1] * n + e[:, 0], e[:, 0] * n + e[:, 1])
    boundary = [(a, b) for a, b in e[twinless].tolist()]
    nxt = dict(boundary)
    if len(nxt) != len(boundary):
        raise ValueError("the boundary is not a set of simple loops")
    start = boundary[0][0]
    loop = [start]
    while nxt[loop[-1]] != start:
        loop.append(nxt[loop[-1]])
    if len(loop) != len(boundary):
        raise ValueError(f"expected one boundary loop (the wrist), found {len(boundary)} boundary "
                         f"edges of which one loop has {len(loop)}")
    return np.asarray(loop, np.int64)


def _adjacency(f: np.ndarray, nv: int) -> sp.csr_matrix:
    """(V,V) 0/1 symmetric vertex adjacency of a triangle mesh."""
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(nv, nv)).tocsr()
    return ((a + a.T) > 0).astype(np.float64)


def _check_side(side: str) -> None:
    """Raise ValueError unless ``side`` is ``"right"`` or ``"left"``."""
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")


# ------------------------------------------------------------------------------------------------
# Shared by HandModel and ManoModel: input checks and output assembly
# ------------------------------------------------------------------------------------------------

def _as_batch(x, name: str, shapes: tuple[tuple[int, ...], ...], like: torch.Tensor, *,
              unbatched: bool = False) -> torch.Tensor | None:
    """``x`` as a (B,*shape) tensor with ``like``'s device and dtype, or None for None.

    ``shapes`` lists the accepted per-sample shapes; with ``unbatched`` an input of exactly one
    of them gets a batch axis of 1. Raises ValueError naming ``name`` otherwise.
    """
    if x is None:
        return None
    # float32 (or the module's dtype after .double()), on the module's device
    t = torch.as_tensor(x, device=like.device).to(like.dtype)
    for shp in shapes:
        if t.dim() == len(shp) + 1 and tuple(t.shape[1:]) == shp:
            return t
        if unbatched and tuple(t.shape) == shp:
            return t[None]
    want = " or ".join("(B," + ",".join(map(str, s)) + ")" for s in shapes)
    raise ValueError(f"{name} must have shape {want}, got {tuple(t.shape)}")


def _batch_size(*tensors, broadcast: bool = False) -> int:
    """The batch size of the given (B,...) tensors (None ignored; 1 when all are None).

    Without ``broadcast`` all batch sizes must be equal; with it a batch of 1 broadcasts.
    """
    sizes = {t.shape[0] for t in tensors if t is not None} or {1}
    batch = max(sizes)
    if any(s not in ((1, batch) if broadcast else (batch,)) for s in sizes):
        raise ValueError("inconsistent batch sizes among pose/shape/global_orient/transl: "
                         f"{sorted(sizes)}")
    return batch


def _bottom_row(t: torch.Tensor) -> torch.Tensor:
    """(...,1,4) rows ``[0, 0, 0, 1]`` completing (...,3,4) rigid transforms ``t``."""
    row = torch.zeros(*t.shape[:-2], 1, 4, dtype=t.dtype, device=t.device)
    row[..., 0, 3] = 1
    return row


def _translate(vertices: torch.Tensor, transforms: torch.Tensor,
               transl: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Add ``transl`` (B,3) to posed vertices (B,V,3) and to joint transforms (B,J,4,4)."""
    vertices = vertices + transl[:, None]
    rt = torch.cat([transforms[..., :3, :3], transforms[..., :3, 3:] + transl[:, None, :, None]],
                   -1)
    return vertices, torch.cat([rt, _bottom_row(rt)], -2)


def _keypoints21(joints_mano: torch.Tensor, vertices: torch.Tensor, tip_ids: torch.Tensor,
                 to_freihand: torch.Tensor) -> torch.Tensor:
    """(B,21,3) FreiHAND-order keypoints: 16 posed joints (B,16,3) + 5 tip vertices of (B,V,3)."""
    return torch.cat([joints_mano, vertices[:, tip_ids]], 1)[:, to_freihand]


def _rest_keypoints(rest_joints: np.ndarray, vertices: np.ndarray, tip_ids: np.ndarray,
                    to_freihand) -> np.ndarray:
    """(21,3) rest keypoints in FreiHAND order: rest joints (16,3) + tip vertices of (V,3)."""
    return np.concatenate([rest_joints, vertices[tip_ids]])[list(to_freihand)]
