"""The bodies during generation: a hand (`_Hand`), a static object (`_Static`) and the chain
(`_ChainBody`), each a rig ([`rig`][handmesh_tutorial.scenes.rig]) plus what makes its mesh.

World frame, metres. Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.spatial.transform import Rotation

from ..collision import Cylinders, hand_cylinders
from ..lcs import (
    DIP_FOLLOWS_PIP,
    DIP_PIP_RATIO,
    THUMB_ZERO_ELEVATION_DEG,
    hand_lcs,
    palm_normal,
)
from .rig import _Rig

__all__ = ["FOREARM_LENGTH"]


@functools.lru_cache(maxsize=4)
def _hand_assets(side: str, thumb_zero_elevation: float | None = THUMB_ZERO_ELEVATION_DEG):
    """(HandModel, Articulation) of one side, built once per process."""
    from ..hand import HandModel

    model = HandModel(side)
    return model, hand_lcs(model, "anatomical", thumb_zero_elevation=thumb_zero_elevation)


# rest node of each of the 20 hand cylinders (collision.HAND_CYLINDER_NAMES): phalanx s of finger
# f leaves FreiHAND keypoint 1 + 4 f + s, i.e. MANO joint MANO_TO_FREIHAND[...]; palm -> wrist
def _hand_attach() -> np.ndarray:
    from ..hand import MANO_TO_FREIHAND

    att = [MANO_TO_FREIHAND[1 + 4 * f + s] for f in range(5) for s in range(3)]
    return np.array(att + [0] * 5, int)


FOREARM_LENGTH: float = 0.25
"""Length of the forearm drawn behind each hand, metres (scenery: not a collision body)."""


class _Hand:
    """A hand during generation: its rig plus what is needed to produce the mesh."""

    def __init__(self, side: str, shape: np.ndarray, limits: str, label: int, colors,
                 tone: int | None = None,
                 thumb_zero_elevation: float | None = THUMB_ZERO_ELEVATION_DEG):
        self.side, self.label, self.kind, self.colors = side, label, "hand", colors
        self.tone = tone   # index into SKIN_TONES (None: colours given some other way)
        self.name = f"{side}_hand"
        self.model, art = _hand_assets(side, thumb_zero_elevation)
        self.art = art.with_limits(limits)
        self.shape = np.asarray(shape, np.float32)
        import torch

        with torch.no_grad():
            rest = self.model(shape=torch.as_tensor(self.shape[None]))
        self.rest_joints21 = rest.joints[0].numpy().astype(float)
        rest16 = rest.joints_mano[0].numpy().astype(float)
        cyl = hand_cylinders(rest, model=self.model)
        # natural hands: each finger's DIP follows its PIP (the paper's +-60 deg: independent)
        followers = ({dip: (pip, DIP_PIP_RATIO) for dip, pip in DIP_FOLLOWS_PIP.items()}
                     if limits == "anatomical" else None)
        self.rig = _Rig(rest16, self.model.parents, self.art.frames, self.art.lower,
                        self.art.upper, cyl, _hand_attach(), followers=followers,
                        zero_rotations=self.art.zero_rotations)
        self.dynamic = True
        self.target = None   # natural poses: the LCS angles its joints move towards (step 4)

    def mesh(self):
        """(vertices (V,3), joints (21,3)) world, via the hand model (LBS), float64."""
        import torch

        pose = self.art.to_pose(self.rig.angles)
        go = Rotation.from_matrix(self.rig.root_R).as_rotvec()
        transl = self.rig.root_P - self.rig.rest[0]
        with torch.no_grad():
            out = self.model(pose=torch.as_tensor(pose[None]),
                             shape=torch.as_tensor(self.shape[None]),
                             global_orient=torch.as_tensor(go[None], dtype=torch.float32),
                             transl=torch.as_tensor(transl[None], dtype=torch.float32))
        return out.vertices[0].numpy().astype(float), out.joints[0].numpy().astype(float)

    @property
    def faces(self):
        return self.model.faces

    def palm(self):
        """Rest palm centre (3,), palm normal (3,) and distal direction (3,), hand frame."""
        j = self.rest_joints21
        centre = j[[0, 5, 9, 13, 17]].mean(0)
        distal = j[9] - j[0]
        return centre, palm_normal(j, self.side), distal / np.linalg.norm(distal)


class _Static:
    """A static object during generation (rig with a root only)."""

    def __init__(self, body, label: int):
        self.body, self.label, self.kind, self.name = body, label, "object", body.name
        self.side, self.colors, self.dynamic = None, body.colors, False
        c = body.cylinders
        self.rig = _Rig(np.zeros((1, 3)), [-1], np.zeros((0, 3, 3)), np.zeros((0, 3)),
                        np.zeros((0, 3)), c, np.zeros(len(c), int))

    def mesh(self):
        return self.rig.to_world(self.body.vertices), None

    @property
    def faces(self):
        return self.body.faces


class _ChainBody:
    """The articulated chain during generation: node 0 a fixed root at link 0's pivot."""

    def __init__(self, chain, label: int):
        self.chain, self.label, self.kind, self.name = chain, label, "chain", "chain"
        self.side, self.dynamic = None, True
        L = chain.num_links
        art = chain.articulation
        rest = np.vstack([chain.pivots[:1], chain.pivots])
        parents = np.r_[-1, np.arange(L)]
        cyl = Cylinders.concat([b.cylinders for b in chain.links])
        self.rig = _Rig(rest, parents, art.frames, art.lower, art.upper, cyl, cyl.parts + 1)
        self.colors = np.concatenate([b.colors for b in chain.links])
        off = np.cumsum([0] + [len(b.vertices) for b in chain.links[:-1]])
        self._faces = np.concatenate([b.faces + o for b, o in zip(chain.links, off, strict=True)])

    def mesh(self):
        v = [self.rig.to_world(b.vertices, k + 1) for k, b in enumerate(self.chain.links)]
        return np.concatenate(v), None

    @property
    def faces(self):
        return self._faces
