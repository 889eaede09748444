"""The hand as a torch module: pose and shape in, mesh and 21 keypoints out.

[`HandModel`][handmesh_tutorial.hand.model.HandModel] loads the shipped MakeHuman template
([`handmesh_tutorial.hand.template`][handmesh_tutorial.hand.template]) and poses it with linear
blend skinning ([`lbs`][handmesh_tutorial.hand.skinning.lbs]) along MANO's 16-joint tree;
[`HandOutput`][handmesh_tutorial.hand.model.HandOutput] is the output of this model and of
[`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel]. Inputs are axis-angle (radians), outputs
float32 metres; ``vertices`` (B,V,3), ``joints`` (B,21,3) in FreiHAND order.

Taught in notebook 01 (the hand model); used by every later notebook.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from ._common import (
    _as_batch,
    _batch_size,
    _boundary_loop,
    _check_side,
    _keypoints21,
    _rest_keypoints,
    _translate,
)
from .appearance import _layout_skin_colors, _skin_layout, knuckle_weights
from .joints import MANO_PARENTS, MANO_TO_FREIHAND
from .skinning import axis_angle_to_matrix, lbs
from .template import SHAPE_PARAM_NAMES, HandTemplate, load_template

__all__ = ["HandOutput", "HandModel"]


@dataclass
class HandOutput:
    """Output of [`HandModel`][handmesh_tutorial.hand.model.HandModel] (and of
    [`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel]).

    Attributes:
        vertices: (B,V,3) float32, metres.
        joints: (B,21,3) float32, metres, FreiHAND order (16 posed joints + 5 tip vertices).
        joints_mano: (B,16,3) float32, metres, posed skeleton joints in MANO order.
        transforms: (B,16,4,4) float32 world transform of each joint: rotation = the joint's
            accumulated rotation (its rest frame has the template axes), translation = its
            posed position (``transl`` included).
    """

    vertices: torch.Tensor
    joints: torch.Tensor
    joints_mano: torch.Tensor | None = None
    transforms: torch.Tensor | None = None


class HandModel(nn.Module):
    """The MakeHuman hand as a torch module: pose and shape in, mesh and 21 keypoints out.

    Loads the shipped template (no rebuild). Right hand by default; the left hand is its exact
    mirror (z negated, see the module docstring for mirroring poses). Parameters follow MANO's
    conventions: axis-angle per joint, each joint's rotation expressed in the rest-pose axes and
    relative to its parent, applied about the joint; ``global_orient`` rotates the whole hand
    about the wrist joint (which sits at the origin); ``transl`` is added last. No pose-dependent
    corrective shapes (plain LBS).

    Attributes (numpy, read-only by convention):
        faces: (F,3) int64. template_vertices: (V,3) float32 metres. skinning_weights: (V,16).
        rest_joints: (16,3) MANO order. fingertip_vertex_ids: (5,) thumb..pinky.
        parents: (16,) int64. joint_regressor: (21,V) float32 (FreiHAND order; rows sum to 1,
        reproduces the rest keypoints to < 2.5 mm). shape_dirs: (V,3,6). bone_radii: (16,).
        palmar: (V,) palm-side label in [0,1]. side: "right" | "left".

    Examples:
        >>> import torch
        >>> from handmesh_tutorial.hand import HandModel
        >>> model = HandModel("right")
        >>> out = model(pose=torch.zeros(2, 15, 3))  # batch of 2, 15 joints, axis-angle
        >>> out.vertices.shape, out.joints.shape  # float32 metres
        (torch.Size([2, 779, 3]), torch.Size([2, 21, 3]))
        >>> bool(torch.allclose(out.vertices[0], torch.from_numpy(model.template_vertices)))
        True
        >>> left = HandModel("left")(pose=torch.zeros(1, 15, 3))  # the mirror: z negated
        >>> bool(torch.allclose(left.vertices[0], out.vertices[0] * torch.tensor([1, 1, -1])))
        True
    """

    num_joints: int = 16
    num_shape_params: int = len(SHAPE_PARAM_NAMES)

    def __init__(self, side: str = "right", template: HandTemplate | None = None):
        """Args:
            side: ``"right"`` or ``"left"``.
            template: a right- or left-hand template to use instead of the shipped asset (for a
                rebuilt or modified hand); mirrored when its side differs from ``side``.

        Raises:
            ValueError: unknown side.
        """
        super().__init__()
        _check_side(side)
        tpl = load_template() if template is None else template
        if tpl.side != side:
            tpl = tpl.mirrored()
        self.side = side
        self.template = tpl
        self.faces = np.asarray(tpl.faces, np.int64)
        self.parents = np.asarray(MANO_PARENTS, np.int64)
        self.template_vertices = np.asarray(tpl.vertices, np.float32)
        self.skinning_weights = np.asarray(tpl.weights, np.float32)
        self.rest_joints = np.asarray(tpl.rest_joints, np.float32)
        self.fingertip_vertex_ids = np.asarray(tpl.tip_ids, np.int64)
        self.joint_regressor = np.asarray(tpl.joint_regressor, np.float32)
        self.shape_dirs = np.asarray(tpl.shape_dirs, np.float32)
        self.bone_radii = np.asarray(tpl.bone_radii, np.float32)
        self.palmar = np.asarray(tpl.palmar, np.float32)
        f32 = torch.float32
        self.register_buffer("v_template", torch.as_tensor(self.template_vertices, dtype=f32))
        self.register_buffer("weights", torch.as_tensor(self.skinning_weights, dtype=f32))
        self.register_buffer("j_template", torch.as_tensor(self.rest_joints, dtype=f32))
        self.register_buffer("v_shapedirs", torch.as_tensor(self.shape_dirs, dtype=f32))
        self.register_buffer("j_shapedirs", torch.as_tensor(tpl.joint_shape_dirs, dtype=f32))
        self.register_buffer("tip_ids", torch.as_tensor(self.fingertip_vertex_ids))
        self.register_buffer("to_freihand", torch.as_tensor(MANO_TO_FREIHAND, dtype=torch.long))

    @property
    def wrist_loop(self) -> np.ndarray:
        """(L,) int64 ids of the wrist's boundary loop (the rim of the cap), ordered like the
        cap's faces: consecutive ids ``(loop[i], loop[i+1])`` run opposite to the skin's boundary
        half-edges, as an outward face glued to the rim does (see
        [`forearm_mesh`][handmesh_tutorial.hand.mesh.forearm_mesh]).
        """
        loop = self.__dict__.get("_wrist_loop")
        if loop is None:   # a walk in Python over the mesh's edges: computed once per model
            skin = self.faces[~np.asarray(self.template.cap_faces, bool)]
            loop = _boundary_loop(skin)[::-1].copy()   # the boundary half-edges, walked backwards
            self.__dict__["_wrist_loop"] = loop
        return loop.copy()

    @property
    def num_vertices(self) -> int:
        """Number of mesh vertices V."""
        return int(self.template_vertices.shape[0])

    @property
    def rest_keypoints(self) -> np.ndarray:
        """(21,3) float32 rest keypoints in FreiHAND order (joints + tip vertices), metres."""
        return _rest_keypoints(self.rest_joints, self.template_vertices,
                               self.fingertip_vertex_ids, MANO_TO_FREIHAND)

    def forward(self, pose=None, shape=None, global_orient=None, transl=None) -> HandOutput:
        """Pose and shape the hand.

        Args:
            pose: (B,15,3) or (B,45) axis-angle (radians) of the 15 articulated joints in MANO
                order (index1..thumb3): joint k's rotation in the rest-pose axes, relative to its
                parent, about the joint. ``None`` = flat rest pose.
            shape: (B,6) shape parameters
                [`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.template.SHAPE_PARAM_NAMES] (MakeHuman
                phenotypes); 0 = the template, adult ranges in
                [`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.template.SHAPE_SAMPLE_RANGES].
            global_orient: (B,3) axis-angle of the whole hand about the wrist joint.
            transl: (B,3) translation, metres, added last.

        Returns:
            [`HandOutput`][handmesh_tutorial.hand.model.HandOutput] with ``vertices`` (B,V,3),
            ``joints``
            (B,21,3) FreiHAND order, ``joints_mano`` (B,16,3), ``transforms`` (B,16,4,4); float32,
            metres. The batch size comes from whichever input is given (1 when none).

        Raises:
            ValueError: an input has the wrong shape or batch sizes disagree.
        """
        like = self.v_template
        pose = _as_batch(pose, "pose", ((15, 3), (45,)), like)
        shape = _as_batch(shape, "shape", ((self.num_shape_params,),), like)
        go = _as_batch(global_orient, "global_orient", ((3,),), like)
        transl = _as_batch(transl, "transl", ((3,),), like)
        batch = _batch_size(pose, shape, go, transl)
        dev, f32 = self.v_template.device, self.v_template.dtype
        if pose is None:
            pose = torch.zeros(batch, 15, 3, device=dev, dtype=f32)
        if go is None:
            go = torch.zeros(batch, 3, device=dev, dtype=f32)
        full = torch.cat([go[:, None], pose.reshape(batch, 15, 3)], 1)         # (B,16,3)
        verts = self.v_template.expand(batch, -1, -1)
        joints = self.j_template.expand(batch, -1, -1)
        if shape is not None:
            verts = verts + torch.einsum("vcs,bs->bvc", self.v_shapedirs, shape)
            joints = joints + torch.einsum("jcs,bs->bjc", self.j_shapedirs, shape)
        posed, transforms = lbs(verts, joints, axis_angle_to_matrix(full), self.weights,
                                self.parents)
        if transl is not None:
            posed, transforms = _translate(posed, transforms, transl)
        joints_mano = transforms[..., :3, 3]
        joints21 = _keypoints21(joints_mano, posed, self.tip_ids, self.to_freihand)
        return HandOutput(vertices=posed, joints=joints21, joints_mano=joints_mano,
                          transforms=transforms)

    # -- appearance ------------------------------------------------------------------------------
    def _knuckles(self) -> np.ndarray:
        """(V,) in [0,1]: the back-of-hand skin over the MCP, PIP and DIP joints (rest pose)."""
        return knuckle_weights(self.template_vertices, self.rest_joints, self.palmar)

    def vertex_colors(self, tone=None, rng: np.random.Generator | int | None = None,
                      variation: float = 0.04) -> np.ndarray:
        """Per-vertex skin colour: a tone, lighter palm, darker knuckles, pinkish nails, blotches.

        Args:
            tone: index into [`SKIN_TONES`][handmesh_tutorial.hand.appearance.SKIN_TONES], an RGB
                triple in [0,1], or ``None``: a random palette tone when ``rng`` is given,
                else tone 1.
            rng: ``numpy.random.Generator`` or seed for the tone choice and the variation;
                ``None`` = fixed seed 0 (same colours every call).
            variation: amplitude of the low-frequency brightness variation.

        Returns:
            (V,3) float32 RGB in [0,1].

        Raises:
            ValueError: bad tone index or triple.
        """
        layout = self.__dict__.get("_skin_layout")
        if layout is None:   # the rest mesh's part, made once per model (not per hand drawn)
            layout = _skin_layout(self.template_vertices, self.faces, self.rest_joints,
                                  self.palmar)
            self.__dict__["_skin_layout"] = layout
        return _layout_skin_colors(layout, self.palmar, self.template.nail, tone, rng, variation)
