"""Spiral sequences on a triangle mesh and the spiral convolution (SpiralNet++).

A *spiral* orders the neighbourhood of a vertex into a fixed-length sequence: the vertex itself,
its 1-ring in rotational order, then the 2-ring continuing in the same rotational sense, and so
on. Because the order is fixed, a graph convolution can be an ordinary ``nn.Linear`` applied to
the concatenated features of the sequence (paper, eq. "graph_conv"; Lim et al. 2018, Gong et al.
2019):

```text
(f * g)_v = sum_i g_i f(e(v))_i        e(v) = spiral of v, length L
```

Conventions of [`spiral_indices`][handmesh_tutorial.nn.spiral.spiral_indices] (everything follows
from the faces alone):

* **Rotational order.** Around a vertex ``v`` every face ``(v, a, b)`` (rotated so that ``v`` is
  first, keeping the winding) says "``b`` follows ``a``". Following these links walks the
  neighbours in the faces' winding direction (counter-clockwise seen from outside for
  outward-oriented, counter-clockwise faces).
* **First ring.** An interior vertex starts at its lowest-id neighbour; a boundary vertex (open
  fan) starts at the first neighbour of its fan, i.e. the end from which the winding direction
  walks across the whole fan. Either way the ring then follows the winding direction.
* **Further rings.** For each vertex ``u`` of ring ``k`` in order, its neighbours are walked in
  winding direction starting right after the neighbour of ``u`` that entered the spiral most
  recently, and every neighbour not yet in the spiral is appended. On a regular mesh this
  continues the spiral outwards without jumps. (Open fans are walked as if they wrapped around.)
* **Length and dilation.** The sequence is grown to at least ``length * dilation`` vertices,
  truncated to that and then every ``dilation``-th entry is kept.
* **Running out.** When the vertex's connected component has fewer vertices than the sequence
  needs, the entries skipped by dilation are used first (still no duplicates); only when the
  component has fewer than ``length`` vertices is the sequence repeated cyclically from its start
  (the only case with duplicates). Isolated vertices repeat themselves.

Relabelling vertices (a permutation ``p`` applied to the faces) maps every spiral to ``p(spiral)``
exactly, except that an interior vertex's first ring may start at a different (lowest-id) neighbour:
the sequence is the same rotation read from another start, and every later ring follows from it
deterministically ([`vertex_spiral`][handmesh_tutorial.nn.spiral.vertex_spiral] takes that start
explicitly). Boundary vertices are exactly equivariant. (Non-manifold vertices, whose neighbours
form several fans, list the fans ordered by lowest id.)

**SpiralNet++'s convention** (``convention="spiralnet"``). SpiralNet++ (``sw-gong/spiralnet_plus``,
``utils/generate_spiral_seq.py``), and HandMesh/CMR/MobRecon after it, read the rings from
OpenMesh's vertex circulator: the same rings (BFS layers) in the opposite direction and from other
starts, so their weights do not fit this module's spirals. Their rule, reproduced here without
OpenMesh for meshes built from the faces in their stored order:

* *Direction*: clockwise, i.e. against the faces' winding.
* *First ring*: an interior vertex ``v`` starts at ``x`` of the **last** face ``(v, x, y)`` (rotated
  so that ``v`` is first) in face storage order (OpenMesh's outgoing half-edge after building);
  a boundary vertex starts at the end of its open fan, so its ring is this module's fan reversed.
* *Further rings*: each vertex ``u`` of ring ``k``, in order, walks its own clockwise list from
  its own start, beginning right after the first ring-``k`` vertex it meets (cyclically), and
  appends every vertex not yet in the spiral.
* *Running out*: SpiralNet++ then takes the ``length * dilation`` nearest vertices in space (a
  k-d tree on the positions); here the fallback above is used instead, so spirals differ only
  where a vertex's rings run out. Non-manifold vertices are refused (OpenMesh cannot build them).

Unlike this module's default, SpiralNet++ spirals depend on the order in which the faces are
stored; use the faces of the mesh file the weights were trained with.
``tests/fixtures/spiralnet_spirals.npz`` holds spirals written by SpiralNet++'s own function
(``tools/spiralnet_reference.py``) that the tests compare against.

Taught in notebook 06 ("Mesh hierarchy and spiral convolution").

"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

__all__ = ["CONVENTIONS", "SpiralConv", "rotational_neighbours", "spiral_indices", "vertex_spiral"]

CONVENTIONS = ("library", "spiralnet")
"""Spiral orderings of [`spiral_indices`][handmesh_tutorial.nn.spiral.spiral_indices]: this module's
(counter-clockwise from the lowest-id neighbour) and SpiralNet++'s (clockwise from OpenMesh's
start); see the module text."""


def _check_faces(faces, num_vertices: int | None) -> tuple[np.ndarray, int]:
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {tuple(f.shape)}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integer vertex ids, got dtype {f.dtype}")
    f = f.astype(np.int64)
    if f.size and f.min() < 0:
        raise ValueError(f"faces contain a negative vertex id ({f.min()})")
    n_used = int(f.max()) + 1 if f.size else 0
    n = n_used if num_vertices is None else int(num_vertices)
    if n < n_used:
        raise ValueError(f"num_vertices={n} but faces reference vertex id {n_used - 1}")
    if f.size and np.any((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])):
        raise ValueError("faces contain degenerate triangles (a repeated vertex id)")
    return f, n


def rotational_neighbours(faces, num_vertices: int | None = None) -> list[list[int]]:
    """Neighbours of every vertex in the faces' winding direction.

    Args:
        faces: (F, 3) int triangles, consistently oriented.
        num_vertices: V; default ``faces.max() + 1``.

    Returns:
        For each vertex, its neighbours in rotational order: an interior vertex starts at its
        lowest-id neighbour, a boundary vertex at the first neighbour of its open fan. A
        non-manifold vertex with several fans lists them one after the other, ordered by their
        lowest id. Isolated vertices get an empty list.

    Raises:
        ValueError: bad shape, or faces that are not consistently oriented / not manifold at an
            edge (two faces claim the same successor around a vertex).
    """
    f, n = _check_faces(faces, num_vertices)
    succ: list[dict[int, int]] = [{} for _ in range(n)]
    for a, b, c in f.tolist():
        for v, x, y in ((a, b, c), (b, c, a), (c, a, b)):
            if x in succ[v]:
                raise ValueError(
                    f"vertex {v}: two faces follow neighbour {x} in the same direction "
                    "(inconsistent orientation or a non-manifold edge)")
            succ[v][x] = y
    out: list[list[int]] = []
    for v in range(n):
        s = succ[v]
        has_pred = set(s.values())
        heads = sorted(x for x in s if x not in has_pred)  # starts of open fans
        seen: set[int] = set()
        fans: list[list[int]] = []
        for start in heads + sorted(s):
            if start in seen:
                continue
            fan = [start]
            seen.add(start)
            x = s.get(start)
            while x is not None and x not in seen:
                fan.append(x)
                seen.add(x)
                x = s.get(x)
            fans.append(fan)
        fans.sort(key=min)
        out.append([x for fan in fans for x in fan])
    return out


def _grow(order: list[list[int]], v: int, total: int, start: int | None) -> list[int]:
    """Spiral of ``v`` with at least ``total`` entries, or the whole component if smaller."""
    ring1 = order[v]
    if start is not None:
        if start not in ring1:
            raise ValueError(f"start={start} is not a neighbour of vertex {v}")
        i = ring1.index(start)
        ring1 = ring1[i:] + ring1[:i]
    seq = [v]
    pos = {v: 0}
    ring = []
    for x in ring1:
        pos[x] = len(seq)
        seq.append(x)
        ring.append(x)
    while ring and len(seq) < total:
        new_ring = []
        for u in ring:
            nb = order[u]
            if not nb:
                continue
            # Continue right after the neighbour of u that joined the spiral last.
            j = max(range(len(nb)), key=lambda k: pos.get(nb[k], -1))
            for k in range(1, len(nb) + 1):
                x = nb[(j + k) % len(nb)]
                if x not in pos:
                    pos[x] = len(seq)
                    seq.append(x)
                    new_ring.append(x)
        ring = new_ring
    return seq


def _spiralnet_neighbours(faces: np.ndarray, n: int) -> list[list[int]]:
    """Neighbours as SpiralNet++ reads them from OpenMesh's circulator (see the module text)."""
    succ: list[dict[int, int]] = [{} for _ in range(n)]
    last: list[int | None] = [None] * n
    for a, b, c in faces.tolist():
        for v, x, y in ((a, b, c), (b, c, a), (c, a, b)):
            succ[v][x] = y   # orientation already checked by rotational_neighbours
            last[v] = x
    out: list[list[int]] = []
    for v in range(n):
        pred = {y: x for x, y in succ[v].items()}  # one clockwise step: y -> x
        tails = [y for y in pred if y not in succ[v]]
        start = tails[0] if tails else last[v]
        ring: list[int] = []
        x = start
        while x is not None and x not in ring:
            ring.append(x)
            x = pred.get(x)
        if len(ring) != len(set(succ[v]) | set(pred)):
            raise ValueError(f"vertex {v} is not manifold (its faces form several fans); "
                             "SpiralNet++'s OpenMesh cannot build such a mesh")
        out.append(ring)
    return out


def _grow_spiralnet(order: list[list[int]], v: int, total: int) -> list[int]:
    """SpiralNet++'s ring-by-ring spiral of ``v`` (whole component if it runs out)."""
    def next_ring(ring: list[int], taken: set[int]) -> list[int]:
        in_ring, res, seen = set(ring), [], set()
        for u in ring:
            nb = order[u]
            i = next((k for k, x in enumerate(nb) if x in in_ring), -1)
            for x in nb[i + 1:] + nb[:max(i, 0)]:
                if x not in taken and x not in in_ring and x not in seen:
                    res.append(x)
                    seen.add(x)
        return res

    spiral, ring = [v], list(order[v])
    taken = {v}
    nxt = next_ring(ring, taken)
    spiral += ring
    taken.update(ring)
    while len(spiral) + len(nxt) < total and nxt:
        ring = nxt
        nxt = next_ring(ring, taken)
        spiral += ring
        taken.update(ring)
    return spiral + nxt


def _finish(seq: list[int], length: int, dilation: int) -> list[int]:
    picks = seq[: length * dilation][::dilation]
    if len(picks) < length:  # component too small for the dilated sequence
        chosen = set(picks)
        picks += [x for x in seq if x not in chosen][: length - len(picks)]
    if len(picks) < length:  # component smaller than `length`: repeat cyclically
        picks = [picks[i % len(picks)] for i in range(length)]
    return picks


def _check_length(length: int, dilation: int) -> None:
    if int(length) != length or length < 1:
        raise ValueError(f"length must be a positive integer, got {length}")
    if int(dilation) != dilation or dilation < 1:
        raise ValueError(f"dilation must be a positive integer, got {dilation}")


def spiral_indices(faces, length: int, dilation: int = 1, num_vertices: int | None = None,
                   convention: str = "library") -> np.ndarray:
    """Spiral sequence of every vertex (SpiralNet++), deterministic from the faces alone.

    See the module docstring for the exact conventions (start, direction, rings, fallback).

    Args:
        faces: (F, 3) int triangles, consistently oriented.
        length: L, entries per spiral (9 in MobRecon, 27 in CMR).
        dilation: keep every ``dilation``-th vertex of the first ``length * dilation``.
        num_vertices: V; default ``faces.max() + 1`` (pass it when trailing vertices are
            isolated).
        convention: ``"library"`` (default, this module's ordering) or ``"spiralnet"``
            (SpiralNet++/HandMesh's, for their weights; depends on the faces' storage order).

    Returns:
        (V, L) int64 array; row ``v`` starts with ``v``, followed by its 1-ring, then further
        rings. No duplicates in a row whenever ``v``'s connected component has ``>= L``
        vertices.

    Raises:
        ValueError: bad ``faces``, ``length``, ``dilation`` or ``convention``; inconsistent
            orientation; a non-manifold vertex with ``convention="spiralnet"``.

    Examples:
        >>> import trimesh
        >>> from handmesh_tutorial.nn.spiral import spiral_indices
        >>> ico = trimesh.creation.icosahedron()  # 12 vertices, 5 neighbours each
        >>> s = spiral_indices(ico.faces, 7)
        >>> s.shape, int(s[5, 0])  # (V, L); entry 0 is the vertex itself
        ((12, 7), 5)
        >>> sorted(s[0, 1:6].tolist()) == sorted(ico.vertex_neighbors[0])  # then its 1-ring
        True
    """
    _check_length(length, dilation)
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {CONVENTIONS}, got {convention!r}")
    order = rotational_neighbours(faces, num_vertices)
    total = length * dilation
    if convention == "spiralnet":
        order = _spiralnet_neighbours(_check_faces(faces, num_vertices)[0], len(order))
    out = np.empty((len(order), length), dtype=np.int64)
    for v in range(len(order)):
        seq = (_grow_spiralnet(order, v, total) if convention == "spiralnet"
               else _grow(order, v, total, None))
        out[v] = _finish(seq, length, dilation)
    return out


def vertex_spiral(faces, vertex: int, length: int, dilation: int = 1,
                  start: int | None = None) -> np.ndarray:
    """Spiral of one vertex, optionally starting its first ring at a chosen neighbour.

    ``vertex_spiral(faces, v, L)`` equals ``spiral_indices(faces, L)[v]``. With ``start`` the first
    ring is read from that neighbour on (same rotational direction), and all later rings follow
    from it; this is what relabelling the vertices does to a spiral.

    Args:
        faces: (F, 3) int triangles, consistently oriented.
        vertex: the centre vertex id.
        length: L, entries of the spiral.
        dilation: keep every ``dilation``-th vertex.
        start: a neighbour of ``vertex`` that begins the first ring (default: the convention of
            [`spiral_indices`][handmesh_tutorial.nn.spiral.spiral_indices]).

    Returns:
        (L,) int64 vertex ids.

    Raises:
        ValueError: ``vertex`` out of range or ``start`` not a neighbour of it.
    """
    _check_length(length, dilation)
    f, n = _check_faces(faces, None)
    if not 0 <= vertex < n:
        raise ValueError(f"vertex {vertex} out of range [0, {n})")
    order = rotational_neighbours(f, n)
    seq = _grow(order, int(vertex), length * dilation, start)
    return np.asarray(_finish(seq, length, dilation), dtype=np.int64)


class SpiralConv(nn.Module):
    """Spiral convolution: gather each vertex's spiral, concatenate, one shared ``nn.Linear``.

    ``out[b, v] = linear(concat_i x[b, indices[v, i]])`` with the concatenation neighbour-major
    (the first ``Cin`` inputs of ``linear`` belong to the vertex itself, the next ``Cin`` to the
    second spiral entry, ...). Weights: Xavier-uniform, bias zero (as SpiralNet++).

    Args:
        in_channels: Cin, features per input vertex.
        out_channels: Cout, features per output vertex.
        indices: (V, L) int spiral indices (numpy or tensor), e.g. from
            [`spiral_indices`][handmesh_tutorial.nn.spiral.spiral_indices]. Stored as a
            non-persistent buffer, so ``.to(device)`` moves it and checkpoints do not contain it.

    Shape:
        input (B, V, Cin) -> output (B, V, Cout); an unbatched (V, Cin) -> (V, Cout).

    Raises:
        ValueError: ``indices`` not (V, L) integers in ``[0, V)``; an input not (B, V, Cin).

    Examples:
        >>> import torch, trimesh
        >>> from handmesh_tutorial.nn.spiral import SpiralConv, spiral_indices
        >>> ico = trimesh.creation.icosahedron()
        >>> conv = SpiralConv(3, 8, spiral_indices(ico.faces, 7))
        >>> conv.linear  # one Linear over the L * Cin gathered features
        Linear(in_features=21, out_features=8, bias=True)
        >>> conv(torch.zeros(2, 12, 3)).shape
        torch.Size([2, 12, 8])
        >>> conv(torch.zeros(12, 3)).shape  # one mesh, unbatched
        torch.Size([12, 8])
    """

    def __init__(self, in_channels: int, out_channels: int, indices):
        super().__init__()
        idx = torch.as_tensor(np.asarray(indices) if not torch.is_tensor(indices) else indices)
        if idx.ndim != 2:
            raise ValueError(f"indices must have shape (V, L), got {tuple(idx.shape)}")
        if idx.dtype.is_floating_point or idx.dtype == torch.bool:
            raise ValueError(f"indices must be integers, got {idx.dtype}")
        idx = idx.to(torch.long)
        if idx.numel() and (idx.min() < 0 or idx.max() >= idx.shape[0]):
            raise ValueError(f"indices must lie in [0, {idx.shape[0]}) (V = rows of indices), "
                             f"got [{int(idx.min())}, {int(idx.max())}]")
        self.in_channels = int(in_channels)
        self.out_channels = int(out_channels)
        self.num_vertices, self.seq_length = idx.shape
        self.register_buffer("indices", idx.contiguous(), persistent=False)
        self.linear = nn.Linear(self.in_channels * self.seq_length, self.out_channels)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """Xavier-uniform weights and zero bias."""
        nn.init.xavier_uniform_(self.linear.weight)
        nn.init.zeros_(self.linear.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Apply the convolution.

        Args:
            x: (B, V, Cin) vertex features, or (V, Cin) for one mesh.

        Returns:
            (B, V, Cout) vertex features ((V, Cout) for an unbatched input).
        """
        if x.dim() == 2 and x.shape == (self.num_vertices, self.in_channels):
            return self.forward(x[None])[0]
        if x.dim() != 3 or x.shape[1] != self.num_vertices or x.shape[2] != self.in_channels:
            raise ValueError(f"SpiralConv expects input (B, {self.num_vertices}, "
                             f"{self.in_channels}) or ({self.num_vertices}, "
                             f"{self.in_channels}), got {tuple(x.shape)}")
        b = x.shape[0]
        # One index_select over the flattened spiral table: (B, V*L, Cin) -> (B, V, L*Cin).
        gathered = x.index_select(1, self.indices.view(-1))
        gathered = gathered.reshape(b, self.num_vertices, self.seq_length * self.in_channels)
        return self.linear(gathered)

    def extra_repr(self) -> str:
        return (f"{self.in_channels}, {self.out_channels}, vertices={self.num_vertices}, "
                f"length={self.seq_length}")
