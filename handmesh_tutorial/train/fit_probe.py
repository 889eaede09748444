"""The fit probe: can the mesh part of the model represent hands at all?

Before asking a network to recover hands from images, check that its mesh part (the FC to the coarse
mesh, the transformer and the spiral decoder, i.e.
[`MSMRNet.decode`][handmesh_tutorial.nn.model.MSMRNet.decode]) can reproduce a set of known hands.
The test is an *auto-decoder* (Park et al., DeepSDF 2019): every target mesh gets its own learnable
latent code in place of the image feature, and codes and network are optimised together with the
paper's L1 vertex loss. No image and no encoder are involved, so a failure here is a failure of the
decoder (its initialisation, normalisation, widths, output scale...), not of the data.

``fit_decoder`` reports the mean vertex error and the surface
metrics of [`handmesh_tutorial.metrics.surface`][handmesh_tutorial.metrics.surface] (roughness,
flipped faces), which catch crumpled outputs that a small vertex error can hide.

Taught in notebook 07 (the multi-path decoder), which fits the paper's xyz decoder and the
library's outputs with it; ``benchmarks/decoder_fit.py`` runs the longer comparison. What it
measured (the decoder before and after the affine output, the normal loss, the skinned output):
docs page "The network", section *What the fit probe measured*.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from handmesh_tutorial.metrics.surface import flipped_face_fraction, roughness_deg
from handmesh_tutorial.nn.losses import normal_loss

__all__ = ["CodeEncoder", "FitResult", "fit_decoder", "posed_hands", "shipped_fit_sweep",
           "SWEEP_FILE"]

SWEEP_FILE = "fit_sweep_results.json"
"""The shipped learning-rate sweep of the fit test (``assets/``; `shipped_fit_sweep`)."""


class CodeEncoder(nn.Identity):
    """A stand-in encoder whose "image features" are the input itself: ``(B, D) -> (B, D)``.

    Lets [`build_model`][handmesh_tutorial.nn.model.build_model] assemble the mesh part without an
    image encoder (``build_model(encoder=CodeEncoder(64), ...)``).

    Args:
        out_features: ``D``, the width of the codes.
    """

    def __init__(self, out_features: int = 64):
        super().__init__()
        self.out_features = int(out_features)


@dataclass
class FitResult:
    """Outcome of ``fit_decoder``.

    Attributes:
        losses: ``(steps,)`` L1 vertex error of every step, metres (mean over vertices and
            coordinates, as the paper's loss, whatever loss was optimised).
        error_mm: final mean vertex error ``mean ||pred - target||``, millimetres.
        roughness_deg: final mean
            [`roughness_deg`][handmesh_tutorial.metrics.surface.roughness_deg], degrees.
        flipped: final mean
            [`flipped_face_fraction`][handmesh_tutorial.metrics.surface.flipped_face_fraction].
        init_error_mm: mean vertex error of the model at initialisation (before any step), mm.
        init_roughness_deg: roughness at initialisation, degrees.
        seconds: wall time of the optimisation.
        cpu_seconds: CPU time of the optimisation (all threads of this process); on a shared
            machine a steadier measure of cost than ``seconds``.
        predictions: ``(N, V, 3)`` final predictions, metres.
        model: the fitted model (its ``decode`` path was trained).
        codes: ``(N, D)`` the fitted latent codes.
    """

    losses: np.ndarray
    error_mm: float
    roughness_deg: float
    flipped: float
    init_error_mm: float
    init_roughness_deg: float
    seconds: float
    cpu_seconds: float
    predictions: np.ndarray
    model: nn.Module
    codes: torch.Tensor

    def summary(self) -> str:
        """One line: error, roughness, flipped faces, time."""
        return (f"error {self.error_mm:.2f} mm, roughness {self.roughness_deg:.1f} deg, "
                f"flipped {100 * self.flipped:.1f}% (init {self.init_error_mm:.1f} mm, "
                f"{self.init_roughness_deg:.1f} deg), {len(self.losses)} steps in "
                f"{self.seconds:.0f} s ({self.cpu_seconds:.0f} CPU s)")


def posed_hands(num: int, seed: int = 0, side: str = "right", hand=None,
                rotate: bool = False) -> tuple[torch.Tensor, np.ndarray]:
    """Root-relative posed hands of the library's hand model, as training targets.

    Args:
        num: number of hands ``N``.
        seed: seed of the poses (and rotations).
        side: ``"right"`` or ``"left"``.
        hand: a [`HandModel`][handmesh_tutorial.hand.HandModel] (default ``HandModel(side)``).
        rotate: also apply a uniformly random global rotation to each hand.

    Returns:
        ``(vertices, faces)``: ``(N, V, 3)`` float32 tensor, metres, centred on the middle-finger
        MCP (joint 9, as the training targets), and the ``(F, 3)`` faces.
    """
    from handmesh_tutorial.hand import HandModel, random_pose

    hand = HandModel(side) if hand is None else hand
    rng = np.random.default_rng(seed)
    pose = torch.from_numpy(random_pose(rng, num, side=side))
    orient = None
    if rotate:
        from scipy.spatial.transform import Rotation

        rotvec = Rotation.random(num, random_state=rng).as_rotvec()
        orient = torch.from_numpy(rotvec.astype(np.float32))
    with torch.no_grad():
        out = hand(pose=pose, global_orient=orient)
    return out.vertices - out.joints[:, 9:10], np.asarray(hand.faces)


def _build(model_or_config, code_dim: int, template):
    from handmesh_tutorial.nn.model import MSMRNet, build_model

    if isinstance(model_or_config, MSMRNet):
        return model_or_config
    cfg = dict(model_or_config or {})
    cfg.setdefault("encoder", CodeEncoder(code_dim))
    if template is not None:
        cfg.setdefault("template", template)
    return build_model(**cfg)


@contextlib.contextmanager
def _flushed_subnormals():
    """Flush subnormal floats to zero inside the block (torch's default, off, is restored):
    the raw xyz decoder's activations decay into them and make CPU kernels several times slower."""
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(False)


def fit_decoder(model_or_config: nn.Module | Mapping | None, vertices, steps: int = 300,
                seed: int = 0, *, faces=None, lr: float = 1e-3, code_lr: float | None = None,
                code_dim: int = 64, batch_size: int | None = None, template=None,
                loss: str = "l1", normal_weight: float = 0.0,
                progress: bool = False) -> FitResult:
    """Auto-decoder fit of the model's mesh part to ``N`` given meshes.

    Each mesh gets a learnable code ``(D,)`` (initialised ``N(0, 1)``) fed to
    [`MSMRNet.decode`][handmesh_tutorial.nn.model.MSMRNet.decode] in place of the image features;
    codes and every parameter after the encoder are trained with Adam on the L1 vertex loss, with a
    cosine
    learning-rate decay to 0 over ``steps``.

    Args:
        model_or_config: an [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] (its ``encoder`` is not
            used; ``D`` = ``latent_to_mesh.in_features``), or a mapping of
            [`build_model`][handmesh_tutorial.nn.model.build_model] arguments (``None`` = defaults);
            a config without ``encoder`` gets a ``CodeEncoder``
            of
            width ``code_dim``.
        vertices: ``(N, V, 3)`` target meshes (numpy or torch), metres, in the model's template
            topology (root-relative as the training targets, e.g. from
            ``posed_hands``).
        steps: optimisation steps (full batch unless ``batch_size``).
        seed: seeds the model initialisation, the codes and the batches.
        faces: ``(F, 3)`` faces for the surface metrics (default: the model's ``faces``).
        lr: Adam learning rate of the network.
        code_lr: learning rate of the codes (default ``lr``).
        code_dim: ``D`` for a config without an encoder.
        batch_size: samples per step (default all ``N``).
        template: template for a config (default the open right hand).
        loss: ``"l1"`` (the paper's mean absolute error) or ``"l2"`` (mean squared error).
        normal_weight: weight of [`normal_loss`][handmesh_tutorial.nn.losses.normal_loss] added to
            the vertex loss (0 = off, the paper): penalises edges that leave the true surface's
            tangent plane, i.e. crumpled surfaces.
        progress: print the loss every 10% of the steps.

    Returns:
        ``FitResult`` with per-step losses, final error (mm),
        roughness (degrees), flipped-face fraction and the fitted model and codes.
    """
    if loss not in ("l1", "l2"):
        raise ValueError(f"loss must be 'l1' or 'l2', got {loss!r}")
    torch.manual_seed(seed)
    net = _build(model_or_config, code_dim, template)
    target = torch.as_tensor(np.asarray(vertices) if not torch.is_tensor(vertices) else vertices,
                             dtype=torch.float32)
    if target.dim() != 3 or target.shape[-1] != 3:
        raise ValueError(f"vertices must be (N, V, 3), got {tuple(target.shape)}")
    faces = net.faces if faces is None else faces
    if faces is None:
        raise ValueError("pass faces= (the model has none recorded)")
    if not normal_weight >= 0:
        raise ValueError(f"normal_weight must be >= 0, got {normal_weight}")
    face_index = torch.as_tensor(np.asarray(faces), dtype=torch.long)
    n = len(target)
    gen = torch.Generator().manual_seed(seed)
    codes = nn.Parameter(torch.randn(n, net.latent_to_mesh.in_features, generator=gen))
    params = [p for name, p in net.named_parameters() if not name.startswith("encoder.")]
    opt = torch.optim.Adam([{"params": params, "lr": lr},
                            {"params": [codes], "lr": lr if code_lr is None else code_lr}])
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(steps, 1))
    net.train()

    def predict() -> torch.Tensor:
        with torch.no_grad():
            return torch.cat([net.decode(codes[i:i + 64])["vertices"] for i in range(0, n, 64)])

    init = predict()
    init_err = 1000 * float((init - target).norm(dim=-1).mean())
    init_rough = float(roughness_deg(init, target, faces).mean())
    losses = np.zeros(steps)
    bs = n if batch_size is None else min(batch_size, n)
    t0, c0 = time.perf_counter(), time.process_time()
    with _flushed_subnormals():
        for step in range(steps):
            idx = (torch.arange(n) if bs == n
                   else torch.randperm(n, generator=gen)[:bs])
            pred = net.decode(codes[idx])["vertices"]
            diff = pred - target[idx]
            value = diff.abs().mean() if loss == "l1" else diff.square().mean()
            if normal_weight:
                value = value + normal_weight * normal_loss(pred, target[idx], face_index)
            opt.zero_grad(set_to_none=True)
            value.backward()
            opt.step()
            sched.step()
            losses[step] = diff.detach().abs().mean().item()
            if not np.isfinite(losses[step]):
                raise FloatingPointError(f"loss is {losses[step]} at step {step + 1}")
            if progress and (step + 1) % max(steps // 10, 1) == 0:
                print(f"step {step + 1:5d}  L1 {1000 * losses[step]:.3f} mm  "
                      f"{time.perf_counter() - t0:.0f} s, {time.process_time() - c0:.0f} CPU s",
                      flush=True)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    net.eval()
    pred = predict()
    return FitResult(
        losses=losses,
        error_mm=1000 * float((pred - target).norm(dim=-1).mean()),
        roughness_deg=float(roughness_deg(pred, target, faces).mean()),
        flipped=float(flipped_face_fraction(pred, target, faces).mean()),
        init_error_mm=init_err, init_roughness_deg=init_rough, seconds=seconds,
        cpu_seconds=cpu,
        predictions=pred.numpy(), model=net, codes=codes.detach())


def shipped_fit_sweep() -> dict:
    """The shipped fair fit test (``assets/fit_sweep_results.json``, made by
    ``benchmarks/dev/fit_lr_sweep.py``): for each decoder output a learning-rate sweep at a fixed
    number of steps, then its best rate with the steps doubled until the error gains less than the
    stop share.

    Returns:
        ``{"rows", "best", "settings", "provenance"}``: ``rows`` one dict per fit (``output``,
        ``lr``, ``steps``, ``error_mm``, ``roughness_deg``, ``flipped``, ``seconds``);
        ``best`` per output its best rate, the rates swept, and the row where the doubling
        ended (``converged_by_stop_rule``: a doubling gained under the stop share; else the
        step cap ended it);
        ``settings`` the sweep's arguments; ``provenance`` command, commit, date, hardware.

    Raises:
        FileNotFoundError: this installation has no such file.
    """
    import json

    from .. import _version

    path = _version.shipped_file(SWEEP_FILE, "python benchmarks/dev/fit_lr_sweep.py --install")
    return json.loads(path.read_text())
