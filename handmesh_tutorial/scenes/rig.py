"""Articulated rigs: rigid collision cylinders attached to the nodes of a kinematic tree.

A rig is the generator's view of a body (a hand, a static object, the chain): it poses its
cylinders from LCS joint angles (numpy, fast) and answers the collision queries of the steps
(world cylinders of many candidate angles of one joint at once, self-collision, contact with
another rig). Lengths in metres, angles in radians. Taught in notebook 04 ("Generating
interactions").
"""

from __future__ import annotations

import functools

import numpy as np

from ..collision import Cylinders, bodies_collide, self_collisions
from ..lcs import rotation_from_lcs_angles

__all__: list[str] = []  # the rig is internal to the generator


def _tree_tables(parents: np.ndarray, attach: np.ndarray, adjacent: np.ndarray):
    """Per node: its subtree (node ids, breadth first), the cylinders that move with it, and the
    non-adjacent (moved, static) cylinder pairs whose intersection is a self-collision.

    Depends only on the tree and the cylinders' attachment, so it is made once per layout and
    shared (read-only) by every rig of that layout: the generator builds two or three rigs per
    scene, and these Python loops cost about a millisecond each time.
    """
    return _tree_tables_cached(np.asarray(parents, np.int64).tobytes(),
                               np.asarray(attach, np.int64).tobytes(),
                               np.asarray(adjacent, np.int64).reshape(-1, 2).tobytes())


@functools.lru_cache(maxsize=64)   # a handful of layouts per process (hands, objects, chains)
def _tree_tables_cached(parents_key: bytes, attach_key: bytes, adjacent_key: bytes):
    parents = np.frombuffer(parents_key, np.int64)
    attach = np.frombuffer(attach_key, np.int64)
    adjacent = np.frombuffer(adjacent_key, np.int64).reshape(-1, 2)
    n = len(parents)
    children = [[] for _ in range(n)]
    for k in range(1, n):
        children[parents[k]].append(k)
    subtree = []
    for k in range(n):
        order, stack = [], [k]
        while stack:
            m = stack.pop(0)
            order.append(m)
            stack.extend(children[m])
        subtree.append(np.array(order))
    adj = {(int(i), int(j)) for i, j in adjacent}
    moved, self_pairs = [], []
    for k in range(n):
        mv = np.flatnonzero(np.isin(attach, subtree[k]))
        st = np.setdiff1d(np.arange(len(attach)), mv)
        pairs = [(a, b) for a in mv for b in st if (min(a, b), max(a, b)) not in adj]
        p = np.array(pairs, int).reshape(-1, 2)
        pos = {int(c): i for i, c in enumerate(mv)}
        moved.append(mv)
        self_pairs.append((np.array([pos[a] for a in p[:, 0]], int), p[:, 1]))
    for a in [*subtree, *moved, *(x for pair in self_pairs for x in pair)]:
        a.setflags(write=False)
    return subtree, moved, self_pairs


class _Rig:
    """A body as a kinematic tree of nodes carrying rigid cylinders (numpy, fast).

    Node 0 is the root, placed by ``(root_R, root_P)`` (its world rotation and position).
    Articulated node ``k >= 1`` turns by ``F R(a) F^T`` about its rest position relative to its
    parent (the convention of [`handmesh_tutorial.lcs`][handmesh_tutorial.lcs]), so for node ``k``:
    ``G_k = G_parent L_k`` and ``P_k = P_parent + G_parent (rest_k - rest_parent)``; a rest point
    ``x`` attached to node ``k`` is at ``G_k (x - rest_k) + P_k``. With ``zero_rotations``
    (``Articulation.zero_rotations``) a node turns by ``O F R(a) F^T`` instead.
    """

    def __init__(self, rest, parents, frames, lower, upper, cylinders: Cylinders, attach,
                 root_R=None, root_P=None, followers: dict | None = None, zero_rotations=None):
        # followers {node: (leader node, ratio)}: the node's flexion (y) angle is ``ratio`` times
        # its leader's and it has no freedom of its own (a finger's DIP following its PIP)
        self.followers = dict(followers or {})
        self.leads = {lead: (node, ratio) for node, (lead, ratio) in self.followers.items()}
        self.rest = np.asarray(rest, float)
        self.parents = np.asarray(parents, int)
        n = len(self.rest)
        self.frames = np.asarray(frames, float).reshape(n - 1, 3, 3)
        self.lower = np.asarray(lower, float).reshape(n - 1, 3)
        self.upper = np.asarray(upper, float).reshape(n - 1, 3)
        self.angles = np.zeros((n - 1, 3))
        self.local = np.tile(np.eye(3), (n, 1, 1))
        # nodes (1..J) whose zero angles are not the rest pose, and their zero rotations
        self.zero = {}
        if zero_rotations is not None:
            z = np.asarray(zero_rotations, float).reshape(n - 1, 3, 3)
            self.zero = {k + 1: z[k] for k in range(n - 1)
                         if np.abs(z[k] - np.eye(3)).max() > 0.0}
        self.rest_cyl = cylinders
        self.attach = np.asarray(attach, int)
        self.radius = cylinders.radius.copy()
        self.off0 = cylinders.p0 - self.rest[self.attach]
        self.off1 = cylinders.p1 - self.rest[self.attach]
        self.subtree, self.moved, self.self_pairs = _tree_tables(self.parents, self.attach,
                                                                 cylinders.adjacent)
        self.root_R = np.eye(3) if root_R is None else np.asarray(root_R, float)
        self.root_P = self.rest[0].copy() if root_P is None else np.asarray(root_P, float)
        self.update()

    @property
    def num_joints(self) -> int:
        return len(self.rest) - 1

    def place(self, R, P) -> None:
        self.root_R, self.root_P = np.asarray(R, float), np.asarray(P, float)
        self.update()

    def set_angles(self, angles) -> None:
        self.angles = np.array(angles, float).reshape(self.num_joints, 3)
        for node, (lead, ratio) in self.followers.items():
            self.angles[node - 1] = [0.0, ratio * self.angles[lead - 1, 1], 0.0]
        if self.num_joints:
            self.local[1:] = rotation_from_lcs_angles(self.frames, self.angles)
            for node, z in self.zero.items():
                self.local[node] = z @ self.local[node]
        self.update()

    def _local(self, node: int, angles) -> np.ndarray:
        """(K,3,3) local rotations of one node for K angle sets (K,3)."""
        L = rotation_from_lcs_angles(self.frames[node - 1:node], np.reshape(angles, (-1, 1, 3)))
        z = self.zero.get(node)
        return L[:, 0] if z is None else z @ L[:, 0]

    def set_joint(self, node: int, angles) -> None:
        """Set the LCS angles (3,) of one articulated node (1..J) and update the pose."""
        a = np.asarray(angles, float).reshape(1, 3)
        self.angles[node - 1] = a[0]
        self.local[node] = self._local(node, a)[0]
        if node in self.leads:
            f, ratio = self.leads[node]
            fa = np.array([[0.0, ratio * a[0, 1], 0.0]])
            self.angles[f - 1] = fa[0]
            self.local[f] = self._local(f, fa)[0]
        self.update()

    def update(self) -> None:
        n = len(self.rest)
        G = np.empty((n, 3, 3))
        P = np.empty((n, 3))
        G[0], P[0] = self.root_R @ self.local[0], self.root_P
        for k in range(1, n):
            p = self.parents[k]
            G[k] = G[p] @ self.local[k]
            P[k] = P[p] + G[p] @ (self.rest[k] - self.rest[p])
        self.G, self.P = G, P
        Ga = G[self.attach]
        self.p0 = np.einsum("cab,cb->ca", Ga, self.off0) + P[self.attach]
        self.p1 = np.einsum("cab,cb->ca", Ga, self.off1) + P[self.attach]

    def translate(self, d) -> None:
        d = np.asarray(d, float)
        self.root_P = self.root_P + d
        self.P = self.P + d
        self.p0 = self.p0 + d
        self.p1 = self.p1 + d

    def cylinders(self) -> Cylinders:
        c = self.rest_cyl   # its names, parts and adjacency are already checked
        return Cylinders._unchecked(self.p0.copy(), self.p1.copy(), self.radius.copy(), c.names,
                                    c.parts.copy(), c.adjacent.copy())

    def to_world(self, points, node: int = 0) -> np.ndarray:
        """Rest points attached to ``node`` -> world."""
        return (np.asarray(points) - self.rest[node]) @ self.G[node].T + self.P[node]

    def candidates(self, node: int, angles) -> tuple[np.ndarray, np.ndarray]:
        """World end points (K, Cm, 3) of the cylinders moving with ``node`` for K angle sets."""
        A = np.asarray(angles, float).reshape(-1, 1, 3)
        K = len(A)
        Lk = self._local(node, A)  # (K,3,3)
        follower = self.leads.get(node)
        if follower is not None:
            f, ratio = follower
            Af = np.zeros_like(A)
            Af[..., 1] = ratio * A[..., 1]
            Lf = self._local(f, Af)
        G = {}
        P = {}
        for m in self.subtree[node]:
            p = self.parents[m]
            if m == node:
                G[m] = self.G[p] @ Lk
                P[m] = np.broadcast_to(self.P[m], (K, 3))
            elif follower is not None and m == follower[0]:
                G[m] = G[p] @ Lf
                P[m] = P[p] + G[p] @ (self.rest[m] - self.rest[p])
            else:
                G[m] = G[p] @ self.local[m]
                P[m] = P[p] + G[p] @ (self.rest[m] - self.rest[p])
        mv = self.moved[node]
        Gs = np.stack([G[a] for a in self.attach[mv]], 1)  # (K,Cm,3,3)
        Ps = np.stack([P[a] for a in self.attach[mv]], 1)  # (K,Cm,3)
        q0 = np.einsum("kcab,cb->kca", Gs, self.off0[mv]) + Ps
        q1 = np.einsum("kcab,cb->kca", Gs, self.off1[mv]) + Ps
        return q0, q1

    def self_collides(self) -> bool:
        return len(self_collisions(self.cylinders())[0]) > 0

    def collides(self, other: _Rig) -> bool:
        """Does any cylinder of this rig meet any cylinder of ``other``?"""
        # bare bodies (no names, no adjacency): this runs at every step of the approach
        return bodies_collide(Cylinders._unchecked(self.p0, self.p1, self.radius),
                              Cylinders._unchecked(other.p0, other.p1, other.radius))
