"""Mesh hierarchy for the decoder: QSlim decimation to vertex subsets, down and up matrices.

MSMR-Net (paper, "Multi-path Mesh Decoder") decodes on five resolutions of the hand mesh. Each
coarser mesh is made by *contracting edges* in order of the quadric error metric (Garland and
Heckbert's QSlim, as in COMA, Ranjan et al. 2018) until the vertex count drops by a factor (2):
778 -> 389 -> 195 -> 98 -> 49 for a MANO-size mesh.

Two choices make the matrices between levels simple and exact:

* **Vertex subsets.** A contracted edge keeps the *cheaper* of its two end points at its original
  position (as COMA's QSlim does) instead of moving it to an optimal point. Every coarse vertex is
  therefore an original vertex, and the down matrix ``D`` (``V_{l+1} x V_l``) is a 0/1 selection
  with one 1 per row: ``D @ V_l == V_{l+1}`` exactly.
* **True barycentric up matrices.** Each fine vertex is projected onto the closest triangle of the
  coarse mesh; the barycentric coordinates of that closest point are its row of ``U``
  (``V_l x V_{l+1}``). Rows are non-negative and sum to 1, so ``U`` commutes with translations
  (``U (V + t) = U V + t``), and a vertex kept in the coarse mesh maps to itself exactly.
  COMA's published code instead solves a small least-squares problem per vertex, whose rows neither
  sum to 1 nor stay non-negative; we do not reproduce that.

Every contraction is checked so that the coarse meshes stay manifold and keep their orientation:
the *link condition* (the end points share exactly the neighbours opposite the edge), no interior
edge between two boundary vertices, no duplicate faces, no triangle that flips or degenerates.

The hierarchy depends only on the template and the factors, so it is cached on disk (``.npz``
read with ``allow_pickle=False``) under a key that hashes the vertices, faces, factors and the
algorithm version; every level of a cached file is checked before use, and a bad file is rebuilt
with a warning.

Taught in notebook 06 (mesh hierarchy and spiral convolution). Submodules (every public name is
re-exported here, so ``hmt.nn.hierarchy.mesh_hierarchy`` and
``from handmesh_tutorial.nn.hierarchy import decimate`` keep working):

* ``qslim``: [`vertex_quadrics`][handmesh_tutorial.nn.hierarchy.qslim.vertex_quadrics] and
  [`decimate`][handmesh_tutorial.nn.hierarchy.qslim.decimate], QSlim keeping vertex subsets.
* ``matrices``: [`selection_matrix`][handmesh_tutorial.nn.hierarchy.matrices.selection_matrix]
  (down), [`barycentric_upsampling`][handmesh_tutorial.nn.hierarchy.matrices.barycentric_upsampling]
  (up), [`to_torch_sparse`][handmesh_tutorial.nn.hierarchy.matrices.to_torch_sparse].
* ``hierarchy``: [`MeshHierarchy`][handmesh_tutorial.nn.hierarchy.hierarchy.MeshHierarchy],
  [`mesh_hierarchy`][handmesh_tutorial.nn.hierarchy.hierarchy.mesh_hierarchy] and its disk cache.
* ``_common`` (private): the mesh input checks.
"""

from __future__ import annotations

# ALGORITHM_VERSION, default_cache_dir: not public, importable as in 0.1
from .hierarchy import (  # noqa: F401
    ALGORITHM_VERSION,
    MeshHierarchy,
    default_cache_dir,
    mesh_hierarchy,
)
from .matrices import barycentric_upsampling, selection_matrix, to_torch_sparse  # noqa: F401
from .qslim import decimate, vertex_quadrics

__all__ = [
    "MeshHierarchy",
    "barycentric_upsampling",
    "decimate",
    "mesh_hierarchy",
    "selection_matrix",
    "to_torch_sparse",
    "vertex_quadrics",
]
