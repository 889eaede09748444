"""Compiled (numba) kernel of the signed distance to a closed mesh: one query point at a time.

The fast path of [`signed_distance`][handmesh_tutorial.scenes.contact.signed_distance] and of the
generator's settle step. The numpy code of ``contact.py`` stays the reference (and the fallback when
numba is missing); ``hmt.collision.BACKEND`` (or ``backend=``) selects the path, as for the cylinder
test. Both give the same distances: the closest-point formulas below repeat
``closest_points_on_triangles`` operation for operation (no ``fastmath``), the pseudo-normal of the
closest feature decides the sign in both, and both find the exact minimum over the mesh's faces.
They differ only in which faces they look at: numpy gathers candidate faces with k-d trees and then
tests all of them as arrays; this kernel walks every face of the mesh and skips those whose bounding
sphere lies farther than the best distance found so far (at first the nearest vertex's), so a point
costs a few thousand comparisons and a handful of exact tests, and nothing is allocated.
``tests/test_interact.py`` compares the two paths on hands, objects, and points near and far.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the numpy path's tolerances (one copy, in contact.py; numba freezes them when compiling)
from .contact import _SPHERE_ABS, _SPHERE_SLACK, _TINY

_jit = njit(cache=True, error_model="numpy", nogil=True)


@_jit
def _closest_on_triangle(p, a, b, c):
    """``closest_points_on_triangles`` for one point and one triangle: ``(q, region)``."""
    ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    ac0, ac1, ac2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    ap0, ap1, ap2 = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    bp0, bp1, bp2 = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    cp0, cp1, cp2 = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    # the numpy path overwrites its answer in this order: face, edges bc, ac, ab, corners c, b,
    # a; the last condition that holds wins, so test them the other way round
    if d1 <= 0 and d2 <= 0:
        return a[0], a[1], a[2], 4
    if d3 >= 0 and d4 <= d3:
        return b[0], b[1], b[2], 5
    if d6 >= 0 and d5 <= d6:
        return c[0], c[1], c[2], 6
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        t = d1 / max(d1 - d3, _TINY)
        return a[0] + ab0 * t, a[1] + ab1 * t, a[2] + ab2 * t, 3
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        t = d2 / max(d2 - d6, _TINY)
        return a[0] + ac0 * t, a[1] + ac1 * t, a[2] + ac2 * t, 2
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        t = (d4 - d3) / max((d4 - d3) + (d5 - d6), _TINY)
        return (b[0] + (c[0] - b[0]) * t, b[1] + (c[1] - b[1]) * t, b[2] + (c[2] - b[2]) * t, 1)
    denom = va + vb + vc
    if abs(denom) < _TINY:
        denom = _TINY
    v = vb / denom
    w = vc / denom
    return (a[0] + ab0 * v + ac0 * w, a[1] + ab1 * v + ac1 * w, a[2] + ab2 * v + ac2 * w, 0)


@_jit
def signed_distances(points, vertices, faces, face_normals, edge_normals, vertex_normals,
                     edge_of, centroid, rho):
    """(N,) signed distances of ``points`` (N,3) to a closed mesh, metres, negative inside.

    Args are the arrays of ``contact._MeshSDF`` (float64 / int64, C-contiguous): vertices (V,3),
    faces (F,3), face_normals (F,3), edge_normals (E,3), vertex_normals (V,3), edge_of (F,3) (edge
    ``i`` of a face is opposite its corner ``i``), centroid (F,3) and rho (F,) (bounding spheres).
    """
    n = points.shape[0]
    out = np.empty(n)
    p = np.empty(3)
    for i in range(n):
        p[0], p[1], p[2] = points[i, 0], points[i, 1], points[i, 2]
        # the nearest vertex bounds the distance to the surface
        best_v = np.inf
        for k in range(vertices.shape[0]):
            e0 = vertices[k, 0] - p[0]
            e1 = vertices[k, 1] - p[1]
            e2 = vertices[k, 2] - p[2]
            d2 = e0 * e0 + e1 * e1 + e2 * e2
            if d2 < best_v:
                best_v = d2
        reach = math.sqrt(best_v)
        best = np.inf
        best_face, best_region = -1, 0
        q0 = q1 = q2 = 0.0
        for f in range(faces.shape[0]):
            e0 = p[0] - centroid[f, 0]
            e1 = p[1] - centroid[f, 1]
            e2 = p[2] - centroid[f, 2]
            far = reach + rho[f] * _SPHERE_SLACK + _SPHERE_ABS
            if math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) > far:
                continue
            x0, x1, x2, region = _closest_on_triangle(p, vertices[faces[f, 0]],
                                                      vertices[faces[f, 1]],
                                                      vertices[faces[f, 2]])
            e0, e1, e2 = x0 - p[0], x1 - p[1], x2 - p[2]
            d2 = e0 * e0 + e1 * e1 + e2 * e2
            if d2 < best:
                best, best_face, best_region = d2, f, region
                q0, q1, q2 = x0, x1, x2
                reach = min(reach, math.sqrt(d2))
        # the sign: the side of the closest feature's pseudo-normal (face, edge or vertex)
        if best_region == 0:
            nrm = face_normals[best_face]
        elif best_region <= 3:
            nrm = edge_normals[edge_of[best_face, best_region - 1]]
        else:
            nrm = vertex_normals[faces[best_face, best_region - 4]]
        side = (p[0] - q0) * nrm[0] + (p[1] - q1) * nrm[1] + (p[2] - q2) * nrm[2]
        d = math.sqrt(best)
        out[i] = -d if side < 0 else d
    return out
