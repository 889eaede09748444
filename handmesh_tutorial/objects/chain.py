"""The articulated chain of interlocking rings of hand-chain scenes: `Chain`, `make_chain`.

Chain frame, metres; link angles in radians about each link's LCS axes. Taught in notebook 04
("Generating interactions").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

from ..collision import Cylinders
from ..lcs import Articulation, local_frames
from ._mesh import _pack, _ring_cyls
from .body import Body
from .colors import random_colors

__all__ = ["CHAIN_SIZE_RANGES", "Chain", "make_chain"]


CHAIN_SIZE_RANGES: dict[str, tuple[float, float]] = {
    "major_radius": (0.016, 0.022),
    "tube_ratio": (0.17, 0.21),
    "clearance": (0.001, 0.002),
}
"""Chain dimension ranges: ring centre-line radius (metres), tube radius as a fraction of it,
clearance at the hook (metres). Thin enough tubes keep link ``k`` and link ``k + 2`` (same plane)
apart: their tubes are ``2 major - 6 tube - 4 clearance`` apart at rest.
"""

_RING_CYLINDERS = 16  # short cylinders per ring (annulus primitive)


@dataclass
class Chain:
    """An articulated chain of interlocking rings (torus links), at rest, in the chain frame.

    Link ``k`` is a torus whose centre-line circle (radius ``major_radius``) lies in a plane that
    contains the chain axis ``z``: the xz-plane for even ``k``, the yz-plane for odd ``k``, so
    consecutive links are perpendicular. Centres are ``pitch`` apart along ``z`` with
    ``pitch = 2 (major_radius - tube_radius - clearance)``: each link passes through its
    neighbours' holes (interlocked) and, at rest, the two tubes are ``2 * clearance`` apart where
    they hook (not colliding); links ``k`` and ``k + 2`` share a plane and are
    ``params["skip_one_gap"]`` apart.

    Each link rotates about its **pivot**, the contact point with its parent: the midpoint of
    the two centres (for link 0, the same distance below its centre). The per-link LCS (paper,
    supplementary: "LCS for dynamic objects") comes from `handmesh_tutorial.lcs.local_frames`
    with joints = pivots, ``z`` towards the next pivot (the far end of the ring for the last link)
    and ``x`` towards a flexion point in the link's own plane, so ``y`` is the ring's normal.

    Attributes:
        links: rest links as `Body` (``kind="chain_link"``), chain frame, metres.
        pivots: (L, 3) rest pivot of each link.
        parents: (L,) int parent link, -1 for link 0.
        articulation: ``lcs.Articulation`` with the rest frames and angle limits (radians), axis
            order ``(x, y, z)``; angles are composed as in `handmesh_tutorial.lcs`.
        params: ``major_radius``, ``tube_radius``, ``clearance``, ``pitch`` (metres), ``num_links``.
    """

    links: list[Body]
    pivots: np.ndarray
    parents: np.ndarray
    articulation: Any
    params: dict

    @property
    def num_links(self) -> int:
        """Number of links L."""
        return len(self.links)

    def zero_angles(self) -> np.ndarray:
        """(L, 3) zeros: the rest pose."""
        return np.zeros((self.num_links, 3))

    def link_transforms(self, angles: Any) -> tuple[np.ndarray, np.ndarray]:
        """Rigid transform of every link for per-link LCS angles (forward kinematics).

        Link ``k`` turns by ``F_k R(a_k) F_k^T`` about its pivot, relative to its parent:
        ``G_k = G_parent R_k``, ``P_k = P_parent + G_parent (pivot_k - pivot_parent)``, and a rest
        point ``x`` of link ``k`` goes to ``G_k (x - pivot_k) + P_k``.

        Args:
            angles: (L, 3) radians about each link's LCS axes ``(x, y, z)``.

        Returns:
            ``(R, t)``: (L, 3, 3) rotations and (L, 3) translations, ``x -> R_k x + t_k``.
        """
        a = np.asarray(angles, dtype=np.float64)
        if a.shape != (self.num_links, 3):
            raise ValueError(f"angles must have shape ({self.num_links}, 3), got {a.shape}")
        local = self.articulation.rotations(a)  # (L, 3, 3) in rest axes
        G = np.empty_like(local)
        P = np.empty((self.num_links, 3))
        for k, p in enumerate(self.parents):
            if p < 0:
                G[k], P[k] = local[k], self.pivots[k]
            else:
                G[k] = G[p] @ local[k]
                P[k] = P[p] + G[p] @ (self.pivots[k] - self.pivots[p])
        t = P - np.einsum("kab,kb->ka", G, self.pivots)
        return G, t

    def pose(self, angles: Any = None, R: Any = None, t: Any = None) -> list[Body]:
        """The posed links (meshes and ring cylinders), optionally moved rigidly as a whole.

        Args:
            angles: (L, 3) radians per link (``None`` = rest pose).
            R: optional (3, 3) rotation of the whole chain (applied after the articulation).
            t: optional (3,) translation of the whole chain, metres.

        Returns:
            L `Body` objects; their cylinders concatenated with
            ``Cylinders.concat([b.cylinders for b in bodies])`` give the chain's primitives.
        """
        a = self.zero_angles() if angles is None else angles
        G, tr = self.link_transforms(a)
        Rw = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
        tw = np.zeros(3) if t is None else np.asarray(t, dtype=np.float64)
        return [link.transformed(Rw @ G[k], Rw @ tr[k] + tw) for k, link in enumerate(self.links)]

    def cylinders(self, angles: Any = None, R: Any = None, t: Any = None) -> Cylinders:
        """All ring cylinders of the posed chain, one ``Cylinders`` (``parts`` = link index).

        Cylinder pairs of the same link are marked adjacent and pairs of different links are
        not, so ``collision.self_collisions(chain.cylinders(angles))`` lists exactly the
        link-link contacts: the test that keeps interlocked links from passing through each
        other while the chain moves.
        """
        return Cylinders.concat([b.cylinders for b in self.pose(angles, R, t)])

    def joint_positions(self, angles: Any = None) -> np.ndarray:
        """(L, 3) posed pivots (chain frame)."""
        a = self.zero_angles() if angles is None else angles
        G, tr = self.link_transforms(a)
        return np.einsum("kab,kb->ka", G, self.pivots) + tr


def make_chain(num_links: int = 4, rng: np.random.Generator | int | None = None,
               limit_deg: float = 60.0, root_fixed: bool = True,
               pattern: str | None = None) -> Chain:
    """Build a chain of ``num_links`` interlocking rings (see `Chain`).

    Args:
        num_links: number of links L (>= 2).
        rng: a ``numpy.random.Generator`` or a seed (sizes from `CHAIN_SIZE_RANGES`,
            palette).
        limit_deg: symmetric limit on every LCS axis of every link, degrees (the paper limits
            hand joints to 60 degrees; collisions between links bound the motion further).
        root_fixed: when ``True`` link 0's limits are zero (it is placed by the rigid ``R, t``
            of `Chain.pose` instead).
        pattern: colour pattern of `random_colors` (``None`` draws one).

    Returns:
        A `Chain` at rest, chain frame centred on its bounding box, axis ``z``.

    Raises:
        ValueError: ``num_links < 2``.
    """
    if int(num_links) < 2:
        raise ValueError(f"num_links must be >= 2, got {num_links}")
    L = int(num_links)
    rng = np.random.default_rng(rng)
    R = float(rng.uniform(*CHAIN_SIZE_RANGES["major_radius"]))
    r = R * float(rng.uniform(*CHAIN_SIZE_RANGES["tube_ratio"]))
    gap = float(rng.uniform(*CHAIN_SIZE_RANGES["clearance"]))
    pitch = 2.0 * (R - r - gap)
    colour_seed = int(rng.integers(2**32))
    ez = np.array([0.0, 0.0, 1.0])
    centres = np.array([[0.0, 0.0, k * pitch] for k in range(L)])
    centres -= 0.5 * (centres[0] + centres[-1])  # bounding box centred at the origin
    pivots = centres - 0.5 * pitch * ez
    torus = trimesh.creation.torus(R, r, major_sections=40, minor_sections=12)
    base_v = np.asarray(torus.vertices, dtype=np.float64)  # in the xy-plane, normal z
    faces = np.asarray(torus.faces, dtype=np.int64)
    links, flex = [], []
    for k in range(L):
        in_plane = np.array([1.0, 0, 0]) if k % 2 == 0 else np.array([0, 1.0, 0])
        normal = np.cross(in_plane, ez)  # ring normal (-y for even, +x for odd links)
        rot = np.stack([in_plane, ez, normal], axis=1)  # rotation: torus x, y, z -> these
        v = base_v @ rot.T + centres[k]
        cols = random_colors(base_v, colour_seed, pattern)
        cyls = _pack(_ring_cyls(centres[k], normal, R, r, _RING_CYLINDERS, f"link{k}"),
                     np.zeros(3), part=k)
        links.append(Body(f"chain_link{k}", "chain_link", v, faces, cols, cyls,
                          {"major_radius": R, "tube_radius": r}))
        flex.append(pivots[k] + R * in_plane)
    children = np.vstack([pivots[1:], centres[-1] + R * ez])
    frames = local_frames(pivots, children, np.array(flex))
    lim = np.full((L, 3), np.deg2rad(limit_deg))
    lower, upper = -lim, lim.copy()
    if root_fixed:
        lower[0] = upper[0] = 0.0
    art = Articulation(names=tuple(f"link{k}" for k in range(L)), joints=pivots, frames=frames,
                       lower=lower, upper=upper, child_points=children,
                       flexion_points=np.array(flex), joint_ids=np.arange(L), side=None,
                       limits_name="custom")
    params = {"major_radius": R, "tube_radius": r, "clearance": gap, "pitch": pitch,
              "num_links": L, "inner_diameter": 2 * (R - r),
              "skip_one_gap": 2 * R - 6 * r - 4 * gap}  # tube gap of links k and k+2 at rest
    return Chain(links, pivots, np.arange(L) - 1, art, params)
