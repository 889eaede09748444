"""Procedural objects for hand-object scenes, with cylinder collision primitives and colours.

The paper uses YCB objects plus self-made ones; YCB is not downloadable here, so every object is
built by code (``trimesh`` + ``manifold3d`` booleans): watertight meshes of at most a few thousand
faces, sized like everyday objects, each with

* per-vertex colours from a random palette and a simple procedural pattern (solid, stripes,
  checker, speckle), and
* collision primitives as finite cylinders (`handmesh_tutorial.collision.Cylinders`), annuli
  as rings of short cylinders, so that the INTER-SH generator can test hand-object contact with
  the same Ketchel-Larochelle test it uses for two hands.

Static kinds (`OBJECT_KINDS`): ``cylinder`` (can), ``bottle``, ``box``, ``sphere``, ``torus``
(a ring a finger passes through), ``mug`` (the handle lets a finger through), ``plate`` (a
perforated plate: a lattice of bars whose square holes a finger fits through). The dynamic
chain of interlocking rings is built by `make_chain` and posed by `Chain.pose`.

Object frame: metres, origin at the centre of the bounding box; z is the axis of revolution
(cylinder, bottle, mug, torus normal), the box's edges are along x, y, z (z usually the longest),
the plate lies in the xy-plane, the mug's handle points to +x in the xz-plane.
``Body.transformed(R, t)`` places a body in a scene (OpenCV camera frame for rendering).

**Submodules**, all taught in notebook 04 ("Generating interactions"):

* [`body`][handmesh_tutorial.objects.body]: `Body`, a rigid mesh with colours and cylinders.
* [`colors`][handmesh_tutorial.objects.colors]: `random_colors`, palettes and patterns.
* [`static`][handmesh_tutorial.objects.static]: `make_object`, `OBJECT_KINDS`, `SIZE_RANGES`.
* [`chain`][handmesh_tutorial.objects.chain]: `Chain`, `make_chain`, `CHAIN_SIZE_RANGES`.
* [`fit`][handmesh_tutorial.objects.fit]: `primitive_fit`, `distance_to_cylinders`.

Every public name is importable from ``handmesh_tutorial.objects`` itself.
"""

from __future__ import annotations

from .body import Body
from .chain import CHAIN_SIZE_RANGES, Chain, make_chain
from .colors import random_colors
from .fit import distance_to_cylinders, primitive_fit  # noqa: F401 - the former not public
from .static import OBJECT_KINDS, SIZE_RANGES, make_object

__all__ = [
    "CHAIN_SIZE_RANGES",
    "OBJECT_KINDS",
    "SIZE_RANGES",
    "Body",
    "Chain",
    "make_chain",
    "make_object",
    "primitive_fit",
    "random_colors",
]
