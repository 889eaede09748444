"""The template mesh a network is built on: rest vertices, faces and a joint regressor.

Everything topological in [`build_model`][handmesh_tutorial.nn.model.build_model] (hierarchy,
spirals, up/down maps, joint regressor) comes from a
[`MeshTemplate`][handmesh_tutorial.nn.mesh_template.MeshTemplate];
[`as_template`][handmesh_tutorial.nn.mesh_template.as_template] accepts the library's hand, a
user's MANO model, a mapping or a tuple. The names are re-exported by
[`handmesh_tutorial.nn.model`][handmesh_tutorial.nn.model]. Taught in notebook 07 ("The multi-path
decoder").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch

__all__ = ["MeshTemplate", "as_template", "root_centred_template"]


@dataclass
class MeshTemplate:
    """A template mesh with a joint regressor: all the model needs to know about the hand.

    Attributes:
        vertices: ``(V, 3)`` float64 rest positions, metres.
        faces: ``(F, 3)`` int64 triangles.
        joint_regressor: ``(J, V)`` float64; joints = ``joint_regressor @ vertices``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    joint_regressor: np.ndarray


def as_template(template=None) -> MeshTemplate:
    """Normalise a template argument.

    Args:
        template: ``None`` (the library's open right hand, ``hmt.hand.HandModel("right")``); a
            [`MeshTemplate`][handmesh_tutorial.nn.mesh_template.MeshTemplate]; a mapping with keys
            ``vertices``, ``faces``, ``joint_regressor``; a ``(vertices, faces, joint_regressor)``
            tuple; or any object with attributes ``faces``, ``joint_regressor`` and
            ``template_vertices`` or ``vertices`` (e.g. a ``HandModel`` or a user's MANO model).

    Returns:
        A validated [`MeshTemplate`][handmesh_tutorial.nn.mesh_template.MeshTemplate].

    Raises:
        ValueError: wrong shapes, face ids out of range, or a missing field.
    """
    if template is None:
        from ..hand import HandModel  # lazy: the hand is built only when needed

        template = HandModel("right")
    if isinstance(template, MeshTemplate):
        v, f, jr = template.vertices, template.faces, template.joint_regressor
    elif isinstance(template, Mapping):
        missing = {"vertices", "faces", "joint_regressor"} - set(template)
        if missing:
            raise ValueError(f"template mapping lacks keys {sorted(missing)}")
        v, f, jr = template["vertices"], template["faces"], template["joint_regressor"]
    elif isinstance(template, tuple | list):
        if len(template) != 3:
            raise ValueError("a template tuple must be (vertices, faces, joint_regressor), got "
                             f"{len(template)} items")
        v, f, jr = template
    else:
        v = getattr(template, "template_vertices", None)
        if v is None:
            v = getattr(template, "vertices", None)
        f = getattr(template, "faces", None)
        jr = getattr(template, "joint_regressor", None)
        if v is None or f is None or jr is None:
            raise ValueError("template object needs attributes faces, joint_regressor and "
                             f"template_vertices (or vertices); got {type(template).__name__}")
    v, f, jr = (np.asarray(_numpy(x)) for x in (v, f, jr))
    v = v.astype(np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"template vertices must be (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"template faces must be (F, 3) integers, got {f.shape} {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"template face ids must lie in [0, {len(v)}), got [{f.min()}, "
                         f"{f.max()}]")
    jr = jr.astype(np.float64)
    if jr.ndim != 2 or jr.shape[1] != len(v):
        raise ValueError(f"joint_regressor must be (J, {len(v)}), got {jr.shape}")
    return MeshTemplate(v, f.astype(np.int64), jr)


def root_centred_template(template) -> np.ndarray:
    """Template vertices centred like the training targets.

    Args:
        template: anything [`as_template`][handmesh_tutorial.nn.mesh_template.as_template] accepts.

    Returns:
        ``(V, 3)`` float64 vertices minus the root keypoint (joint 9, the middle-finger MCP,
        for a 21-joint regressor; the vertex centroid otherwise), metres.
    """
    t = as_template(template)
    root = (t.joint_regressor[9] @ t.vertices if len(t.joint_regressor) == 21
            else t.vertices.mean(0))
    return t.vertices - root


def _numpy(x):
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else x
