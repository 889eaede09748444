"""Constant baselines: one hand predicted for every image, no network.

The rest hand (the template's open hand, root-centred) and the mean training hand
([`mean_hand`][handmesh_tutorial.train.baselines.mean_hand]) are the bars a network must clear:
below the rest hand it has learnt the hand's articulation, below the mean hand it reads each hand's
pose from its image. Vertices (V, 3) / (N, V, 3) and joints (N, 21, 3) in metres, network frame.

Taught in notebook 09 ("Evaluation") and used by notebook 08's loss curves.
"""

from __future__ import annotations

import numpy as np
import torch

from .. import metrics as M
from ..nn.model import root_centred_template
from .templates import resolve_template

__all__ = ["constant_hand_predictions", "constant_hand_scores", "mean_hand", "REST_HAND",
           "MEAN_HAND"]


REST_HAND, MEAN_HAND = "rest hand (no network)", "mean training hand (no network)"
"""Names of the two constant baselines in tables and reports."""


def constant_hand_predictions(template_vertices, joint_regressor, num: int):
    """A constant baseline's answer for ``num`` images: the same hand every time.

    Args:
        template_vertices: ``(V, 3)`` the constant hand in the network frame (the rest hand,
            [`root_centred_template`][handmesh_tutorial.nn.model.root_centred_template], or
            [`mean_hand`][handmesh_tutorial.train.baselines.mean_hand]), metres; numpy or torch.
        joint_regressor: ``(21, V)`` regressor the network uses for its joints.
        num: number of predictions.

    Returns:
        ``(vertices (num, V, 3), joints (num, 21, 3))`` float32 tensors, metres.

    Shapes:
        ``template_vertices (V, 3)``, ``joint_regressor (21, V)`` -> ``(num, V, 3)``,
        ``(num, 21, 3)``.
    """
    tv = torch.as_tensor(template_vertices, dtype=torch.float32).detach().cpu()
    jr = torch.as_tensor(joint_regressor, dtype=torch.float32).detach().cpu()
    if tv.ndim != 2 or tv.shape[1] != 3 or jr.ndim != 2 or jr.shape[1] != tv.shape[0]:
        raise ValueError(f"template_vertices must be (V, 3) and joint_regressor (J, V), got "
                         f"{tuple(tv.shape)} and {tuple(jr.shape)}")
    return tv.expand(num, -1, -1).clone(), (jr @ tv).expand(num, -1, -1).clone()


def mean_hand(dataset, template=None, iterations: int = 5) -> np.ndarray:
    """The mean training hand: the generalised Procrustes mean of a dataset's target meshes.

    Each target is aligned to the current mean by a similarity transform (rotations only, no
    reflection) and the aligned meshes are averaged, ``iterations`` times, starting from the rest
    hand. The result is the average *articulation* of the data with orientation and size removed:
    predicted for every image it is a constant answer, like the rest hand, but the best one for
    the aligned metrics. A network whose PA- errors are not below it has learnt the data's mean
    pose, not to read each hand's pose from its image.

    Args:
        dataset: a [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] (e.g.
            the training split of [`make_datasets`][handmesh_tutorial.train.data.make_datasets]; its
            ``target_shape``, without images) or any dataset of items with ``vertices``.
        template: the network's template (default: the library's hand).
        iterations: alignment-and-average rounds (the mean changes by < 0.01 mm after 3 on
            INTER-SH).

    Returns:
        ``(V, 3)`` float64 vertices in the network frame (aligned to the root-centred rest hand,
        then joint 9 moved to the origin), metres.

    Shapes:
        items' ``vertices (V, 3)`` -> ``(V, 3)``.
    """
    tmpl = resolve_template(template)
    if len(dataset) == 0:
        raise ValueError("the dataset is empty")
    rest = _rest_template(tmpl)
    shape = getattr(dataset, "target_shape", None)  # without images where the dataset can
    verts = np.stack([shape(i) if shape else dataset[i]["vertices"].double().numpy()
                      for i in range(len(dataset))])
    if verts.shape[1:] != rest.shape:
        raise ValueError(f"the dataset's vertices {verts.shape[1:]} do not match the template's "
                         f"{rest.shape}")
    mean = rest
    for _ in range(int(iterations)):
        mean = M.procrustes_align(verts, np.broadcast_to(mean, verts.shape),
                                  allow_reflection=False).mean(0)
    mean = M.procrustes_align(mean[None], rest[None], allow_reflection=False)[0]
    return mean - tmpl.joint_regressor[9] @ mean


def _rest_template(template):
    return root_centred_template(template)


def constant_hand_scores(dataset, vertices=None, template=None) -> dict:
    """FreiHAND-style scores of one constant mesh predicted for every item (no network).

    Args:
        dataset: a [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] (or a
            ``Subset``
            of one); only its ``vertices`` and ``joints`` are read.
        vertices: ``(V, 3)`` the constant mesh in the network frame, e.g.
            [`mean_hand`][handmesh_tutorial.train.baselines.mean_hand]; default the rest hand (the
            template's root-centred open hand).
        template: the network's template (default: the library's hand); its joint regressor
            gives the constant mesh's joints.

    Returns:
        [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] (mm, AUC, F-scores).

    Shapes:
        ``vertices (V, 3)``; items' ``vertices (V, 3)`` and ``joints (21, 3)``.
    """
    tmpl = resolve_template(template)
    if len(dataset) == 0:
        raise ValueError("the dataset is empty")
    items = [dataset[i] for i in range(len(dataset))]
    gv = torch.stack([it["vertices"] for it in items])
    gj = torch.stack([it["joints"] for it in items])
    const = _rest_template(tmpl) if vertices is None else vertices
    rv, rj = constant_hand_predictions(const, tmpl.joint_regressor, len(items))
    return M.freihand_scores(pred_joints=rj, gt_joints=gj, pred_verts=rv, gt_verts=gv)
