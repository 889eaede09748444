"""Baselines: one hand predicted for every image, and a linear read-out of a frozen encoder.

The rest hand (the template's open hand, root-centred) and the mean training hand
([`mean_hand`][handmesh_tutorial.train.baselines.mean_hand]) are the bars a network must clear:
below the rest hand it has learnt the hand's articulation, below the mean hand it reads each hand's
pose from its image. Vertices (V, 3) / (N, V, 3) and joints (N, 21, 3) in metres, network frame.

The **linear read-out** ([`linear_readout`][handmesh_tutorial.train.baselines.linear_readout],
[`fit_linear_readout`][handmesh_tutorial.train.baselines.fit_linear_readout]) is the bar for what
*training the decoder* adds: the same frozen encoder, its features mapped to the vertices by a
closed-form ridge regression fitted on the training crops, no decoder, no gradient step. A network
trained on that encoder that does not beat it has learnt no more than a linear map of the features.

Taught in notebook 09 ("Evaluation") and used by notebook 08 (loss curves, what training adds).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from .. import metrics as M
from ..nn.model import root_centred_template
from .templates import resolve_template

__all__ = ["constant_hand_predictions", "constant_hand_scores", "mean_hand", "REST_HAND",
           "MEAN_HAND", "LINEAR_READOUT", "RidgeReadout", "LinearReadout", "fit_linear_readout",
           "linear_readout"]


REST_HAND, MEAN_HAND = "rest hand (no network)", "mean training hand (no network)"
"""Names of the two constant baselines in tables and reports."""

LINEAR_READOUT = "frozen encoder + ridge read-out (no decoder)"
"""Name of the linear read-out baseline in tables and reports."""

READOUT_ALPHAS = (1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)
"""Ridge penalties [`linear_readout`][handmesh_tutorial.train.baselines.linear_readout] tries on
the validation crops (standardised features, per sample)."""


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


@dataclass(frozen=True)
class RidgeReadout:
    """A fitted linear map from feature vectors to meshes (see
    [`fit_linear_readout`][handmesh_tutorial.train.baselines.fit_linear_readout]).

    Attributes:
        weight: ``(D, V * 3)`` float64, acting on the raw (not standardised) features.
        bias: ``(V * 3,)`` float64, metres.
        alpha: the ridge penalty it was fitted with.
    """

    weight: np.ndarray
    bias: np.ndarray
    alpha: float

    def predict(self, features) -> np.ndarray:
        """``(N, D)`` features (numpy or torch) -> ``(N, V, 3)`` float64 vertices, metres."""
        x = _features(features, "features")
        if x.shape[1] != self.weight.shape[0]:
            raise ValueError(f"features must be (N, {self.weight.shape[0]}), got {x.shape}")
        return (x @ self.weight + self.bias).reshape(len(x), -1, 3)


def _features(x, name: str) -> np.ndarray:
    a = np.asarray(x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else x, np.float64)
    if a.ndim != 2:
        raise ValueError(f"{name} must be (N, D), one feature vector per sample, got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} holds {int((~np.isfinite(a)).sum())} non-finite values")
    return a


def fit_linear_readout(features, vertices, alpha: float = 1.0) -> RidgeReadout:
    """Closed-form ridge regression from feature vectors to root-centred vertices.

    The features are standardised (each column to mean 0 and standard deviation 1; a constant
    column is only centred) and the weights ``W`` minimise
    ``mean_n ||x_n W + b - y_n||^2 + alpha ||W||^2`` with an unpenalised intercept ``b``, i.e.
    ``W = (X^T X + N alpha I)^-1 X^T Y`` on the centred data; the standardisation is then folded
    into the returned weights. With ``alpha = 0`` it is ordinary least squares (minimum-norm
    when ``N <= D``). Why: the cheapest map from an encoder's features to a mesh, the bar a trained
    decoder must clear to have added anything beyond the encoder.

    Args:
        features: ``(N, D)`` one feature vector per sample (e.g. a frozen encoder's ``features``),
            N >= 2.
        vertices: ``(N, V, 3)`` the target meshes, metres, root-centred in the network frame (as
            a [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] gives them).
        alpha: ridge penalty >= 0, per sample on standardised features (so it does not grow with
            N or with the features' scale); 1e-4 to 10 is the useful range.

    Returns:
        A [`RidgeReadout`][handmesh_tutorial.train.baselines.RidgeReadout];
        ``.predict(features)`` gives ``(N, V, 3)`` metres.

    Raises:
        ValueError: features not ``(N, D)``, vertices not ``(N, V, 3)`` with the same N, fewer
            than 2 samples, non-finite values, or ``alpha`` negative or not finite.
    """
    x = _features(features, "features")
    y = np.asarray(vertices.detach().cpu().numpy() if isinstance(vertices, torch.Tensor)
                   else vertices, np.float64)
    if y.ndim != 3 or y.shape[2] != 3:
        raise ValueError(f"vertices must be (N, V, 3) meshes in metres, got {y.shape}")
    if len(y) != len(x):
        raise ValueError(f"features and vertices must have one row per sample: {len(x)} feature "
                         f"vectors, {len(y)} meshes")
    if len(x) < 2:
        raise ValueError(f"a read-out needs at least 2 samples, got {len(x)}")
    if not np.isfinite(y).all():
        raise ValueError(f"vertices hold {int((~np.isfinite(y)).sum())} non-finite values")
    try:
        ok = not isinstance(alpha, bool) and math.isfinite(float(alpha)) and float(alpha) >= 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"alpha must be a finite number >= 0, got {alpha!r}")
    alpha = float(alpha)
    n = len(x)
    y = y.reshape(n, -1)
    mu, sd = x.mean(0), x.std(0)
    sd = np.where(sd > 1e-12 * max(1.0, float(np.abs(x).max())), sd, 1.0)
    xs = (x - mu) / sd
    ym = y.mean(0)
    yc = y - ym
    if alpha > 0:
        gram = xs.T @ xs
        gram[np.diag_indices_from(gram)] += n * alpha
        w = np.linalg.solve(gram, xs.T @ yc)
    else:
        w = np.linalg.lstsq(xs, yc, rcond=None)[0]
    weight = w / sd[:, None]
    return RidgeReadout(weight=weight, bias=ym - mu @ weight, alpha=float(alpha))


class LinearReadout(nn.Module):
    """A frozen encoder followed by a fitted linear map to the vertices: a network without a
    decoder, evaluated like one (``hmt.train.evaluate(readout, ...)``).

    Built by [`linear_readout`][handmesh_tutorial.train.baselines.linear_readout]. ``forward``
    takes crops ``(B, 3, S, S)``, ``decode`` the encoder's features ``(B, D)``; both return
    ``{"vertices": (B, V, 3), "joints": (B, 21, 3)}`` in metres (joints by the template's
    regressor, as the constant hands' are). ``faces``, ``template`` and ``joint_regressor`` are
    the network's it was made from; ``alpha`` the penalty used, ``validation`` ``{alpha: PA-MPVPE
    (mm) on the validation crops}`` when it was chosen there.
    """

    def __init__(self, encoder: nn.Module, readout: RidgeReadout, joint_regressor, faces=None,
                 template=None, validation: dict | None = None):
        super().__init__()
        self.encoder = copy.deepcopy(encoder)  # frozen here; the network's own is left as it is
        d, out = readout.weight.shape
        self.readout = nn.Linear(d, out)
        with torch.no_grad():
            self.readout.weight.copy_(torch.as_tensor(readout.weight.T, dtype=torch.float32))
            self.readout.bias.copy_(torch.as_tensor(readout.bias, dtype=torch.float32))
        self.requires_grad_(False)
        self.register_buffer("joint_regressor",
                             torch.as_tensor(joint_regressor, dtype=torch.float32).clone(),
                             persistent=False)
        if template is not None:
            self.register_buffer("template", torch.as_tensor(template, dtype=torch.float32)
                                 .clone(), persistent=False)
        else:
            self.template = None
        self.faces = None if faces is None else np.asarray(faces)
        self.alpha = readout.alpha
        self.validation = dict(validation or {})

    def decode(self, features: torch.Tensor) -> dict[str, torch.Tensor]:
        """``(B, D)`` features -> ``{"vertices": (B, V, 3), "joints": (B, 21, 3)}``, metres."""
        v = self.readout(features.float()).reshape(len(features), -1, 3)
        j = torch.einsum("jv,bvc->bjc", self.joint_regressor.to(v.dtype), v)
        return {"vertices": v, "joints": j}

    def forward(self, images: torch.Tensor) -> dict[str, torch.Tensor]:
        """``(B, 3, S, S)`` crops -> ``{"vertices", "joints"}`` (see the class)."""
        enc = self.encoder(images)
        return self.decode(enc["features"] if isinstance(enc, dict) else enc)


def _encoded(encoder: nn.Module, dataset, batch_size: int, progress: bool):
    from .features import EncodedDataset

    enc = EncodedDataset(dataset, encoder, batch_size=batch_size, progress=progress)
    items = [enc[i] for i in range(len(enc))]
    if not items:
        raise ValueError("the dataset is empty")
    return (torch.stack([it["features"] for it in items]).double().numpy(),
            torch.stack([it["vertices"] for it in items]).double().numpy())


def linear_readout(model: nn.Module, train_dataset, *, alpha: float | None = None,
                   val_dataset=None, alphas=READOUT_ALPHAS, batch_size: int = 64,
                   progress: bool = False) -> LinearReadout:
    """The frozen-encoder baseline: ``model``'s encoder, its features mapped to the vertices by a
    ridge regression fitted on ``train_dataset``'s crops (no decoder, no training).

    Args:
        model: an [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] whose ``encoder`` is the frozen
            one (a network trained with ``freeze_encoder`` covering every epoch, or one built from
            the config with the pretrained encoder loaded); its template, faces and joint
            regressor are reused. Only its encoder runs.
        train_dataset: non-augmented crops to fit on (the training split of
            [`make_datasets`][handmesh_tutorial.train.data.make_datasets] with ``augment=False``).
        alpha: the ridge penalty (see
            [`fit_linear_readout`][handmesh_tutorial.train.baselines.fit_linear_readout]); ``None``:
            the one of ``alphas`` with the lowest PA-MPVPE on ``val_dataset``.
        val_dataset: non-augmented held-out crops to choose ``alpha`` on (needed when ``alpha`` is
            ``None``). The test set is never used for the choice.
        alphas: the penalties tried, each >= 0.
        batch_size: encoding batch size.
        progress: tqdm bar while encoding.

    Returns:
        A [`LinearReadout`][handmesh_tutorial.train.baselines.LinearReadout] network (eval mode,
        no trainable parameters), to pass to [`evaluate`][handmesh_tutorial.train.evaluate].

    Raises:
        ValueError: the model has no ``encoder``, a dataset augments its crops or is empty,
            ``alpha`` is None without ``val_dataset``, or a bad ``alpha``.
    """
    encoder = getattr(model, "encoder", None)
    if not isinstance(encoder, nn.Module):
        raise ValueError(f"model must have an encoder module (an MSMRNet), got "
                         f"{type(model).__name__}")
    if alpha is None and val_dataset is None:
        raise ValueError("give alpha, or val_dataset to choose it on (never the test set)")
    x, y = _encoded(encoder, train_dataset, batch_size, progress)
    validation = {}
    if alpha is None:
        xv, yv = _encoded(encoder, val_dataset, batch_size, progress)
        for a in alphas:
            pv = fit_linear_readout(x, y, a).predict(xv)
            validation[float(a)] = 1000 * float(np.linalg.norm(
                M.procrustes_align(pv, yv) - yv, axis=-1).mean())
        alpha = min(validation, key=validation.get)
    fit = fit_linear_readout(x, y, alpha)
    tmpl = getattr(model, "template", None)
    readout = LinearReadout(encoder, fit, model.joint_regressor.detach().cpu(),
                            faces=getattr(model, "faces", None),
                            template=None if tmpl is None else tmpl.detach().cpu(),
                            validation=validation)
    return readout.eval()
