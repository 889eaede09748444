"""Collision detection between finite solid cylinders (Ketchel–Larochelle), capsules and bodies.

The INTER-SH generator (paper, supplementary "Generating Mesh Interactions") approximates hands and
objects by cylinders and annuli and moves them until two primitives intersect. Taught in notebook 03
(cylinder collision); the generator that uses it in notebook 04. Submodules (every public name is
re-exported here, so ``hmt.collision.cylinders_intersect`` and
``from handmesh_tutorial.collision import Cylinders`` keep working):

* ``cylinders``: [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders], a body as a batch
  of cylinders (metres), and the ring / box builders.
* ``exact``: [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect], the
  exact batched test for finite solid cylinders;
  [`capsules_intersect`][handmesh_tutorial.collision.exact.capsules_intersect], the simple
  conservative alternative (a cylinder lies in its capsule); the segment-segment distance.
* ``distance``: point-cylinder distance, projection, support function, sphere-cylinder test.
* ``oracle``: [`distance_bounds`][handmesh_tutorial.collision.oracle.distance_bounds], an
  independent oracle that certifies the exact test.
* ``queries``: scene queries [`bodies_collide`][handmesh_tutorial.collision.queries.bodies_collide],
  [`colliding_pairs`][handmesh_tutorial.collision.queries.colliding_pairs],
  [`self_collisions`][handmesh_tutorial.collision.queries.self_collisions].
* ``hand_proxies``: the hand as cylinders:
  [`hand_cylinders`][handmesh_tutorial.collision.hand_proxies.hand_cylinders],
  [`fit_cylinders`][handmesh_tutorial.collision.hand_proxies.fit_cylinders],
  [`coverage`][handmesh_tutorial.collision.hand_proxies.coverage].
* ``skin``: finger against finger over a batch of poses, with the proxies
  ([`finger_collisions`][handmesh_tutorial.collision.skin.finger_collisions]) and on the skin
  ([`skin_collisions`][handmesh_tutorial.collision.skin.skin_collisions], python-fcl or an exact
  triangle test), and what each is for.
* ``_numba`` (private, the default when numba imports): compiled mirrors of the exact kernels;
  ``_common`` (private): input checks, tolerances, vector kernels, the backend switch.
"""

from __future__ import annotations

from .cylinders import Cylinders, box_cylinders, ring_cylinders
from .distance import (  # noqa: F401 - cylinder_support: not public, importable as in 0.1
    cylinder_support,
    point_cylinder_distance,
    project_to_cylinder,
    sphere_cylinder_intersect,
)
from .exact import ATOL, capsules_intersect, cylinders_intersect, segment_segment_distance
from .hand_proxies import (  # noqa: F401 - fit_cylinders, hand_segments: not public
    HAND_CYLINDER_NAMES,
    coverage,
    fit_cylinders,
    hand_cylinders,
    hand_segments,
)
from .oracle import distance_bounds
from .queries import (
    SELF_CONTACT_COMPRESSION,
    bodies_collide,
    colliding_pairs,
    self_collisions,
)
from .skin import finger_collisions, finger_of_vertices, skin_collisions, triangles_intersect

BACKEND: str = "auto"
"""Which implementation the exact tests use: ``"auto"`` (the default: the compiled kernels of
``handmesh_tutorial.collision._numba`` when numba imports, else numpy), ``"numba"`` (those kernels,
an error without numba) or ``"numpy"`` (the vectorised reference). Both give the same answers
(tested pair by pair); the kernels are faster, and their first call in a process loads (once
after installation: compiles) them; speeds and costs: docs page "Performance". Set it on this
package (``hmt.collision.BACKEND = "numpy"``); every query reads it at call time. Every public test
also takes ``backend=``."""

__all__ = [
    "ATOL",
    "BACKEND",
    "HAND_CYLINDER_NAMES",
    "SELF_CONTACT_COMPRESSION",
    "Cylinders",
    "bodies_collide",
    "box_cylinders",
    "capsules_intersect",
    "colliding_pairs",
    "coverage",
    "cylinders_intersect",
    "distance_bounds",
    "finger_collisions",
    "finger_of_vertices",
    "hand_cylinders",
    "point_cylinder_distance",
    "project_to_cylinder",
    "ring_cylinders",
    "segment_segment_distance",
    "skin_collisions",
    "triangles_intersect",
    "self_collisions",
    "sphere_cylinder_intersect",
]
