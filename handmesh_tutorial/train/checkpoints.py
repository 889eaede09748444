"""Checkpoints and the other files of a run folder (``metrics.csv``, ``steps.csv``).

A checkpoint (format [`CHECKPOINT_FORMAT`][handmesh_tutorial.train.checkpoints.CHECKPOINT_FORMAT])
holds the model, optimiser, scheduler, epoch, step, the torch / numpy / python RNG states, the
history and the config as a dict (no class paths: nothing in it names library code). Everything is
stored as tensors, lists and numbers, so ``torch.load(..., weights_only=True)`` reads it. Every
file is written atomically (temporary file in the same folder, then ``os.replace``).

Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import csv
import io
import math
import os
import random
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .._io import atomic_write_bytes as _atomic_write_bytes
from .._io import claim_out_dir, json_record, leftover_temporaries, remove_outputs
from .._untrusted import load_torch_file
from .._version import PRETRAINED_FILE, __version__, shipped_file
from ..nn.quantize import dequantize_state_dict, quantize_state_dict  # noqa: F401 - as in 0.1
from ._distributed import _resolve_device
from .config import TrainConfig
from .templates import build_model_from_config, resolve_template, template_hash

__all__ = ["save_checkpoint", "load_checkpoint", "METRIC_COLUMNS"]

CHECKPOINT_FORMAT = "handmesh_tutorial.checkpoint/1"
"""``format`` entry of every checkpoint written by
[`save_checkpoint`][handmesh_tutorial.train.checkpoints.save_checkpoint]."""
METRIC_COLUMNS = ("epoch", "step", "train_loss", "lr", "seconds", "val_loss", "val_mpjpe",
                  "val_mpvpe", "val_pa_mpjpe", "val_pa_mpvpe", "val_auc_joints", "val_auc_verts",
                  "val_f_at_5mm", "val_f_at_15mm")
"""Columns of ``metrics.csv``, in order (empty cells where a value does not exist)."""


def _rng_state() -> dict:
    name, keys, pos, has_gauss, cached = np.random.get_state()  # noqa: NPY002 - global state
    version, state, gauss_next = random.getstate()
    out = {
        "torch": torch.get_rng_state(),
        "numpy": {"name": name, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
                  "has_gauss": int(has_gauss), "cached_gaussian": float(cached)},
        "python": {"version": int(version), "state": torch.tensor(state, dtype=torch.int64),
                   "gauss_next": gauss_next},
    }
    if torch.cuda.is_available():
        out["cuda"] = torch.cuda.get_rng_state_all()
    return out


def _set_rng_state(s: Mapping) -> None:
    torch.set_rng_state(s["torch"].cpu())
    n = s["numpy"]
    keys = n["keys"].cpu().numpy().astype(np.uint32)  # on the GPU when read with map_location
    np.random.set_state((n["name"], keys, n["pos"], n["has_gauss"],  # noqa: NPY002
                         n["cached_gaussian"]))
    p = s["python"]
    random.setstate((p["version"], tuple(int(x) for x in p["state"].tolist()), p["gauss_next"]))
    if "cuda" in s and torch.cuda.is_available() and len(s["cuda"]) == torch.cuda.device_count():
        torch.cuda.set_rng_state_all([t.cpu() for t in s["cuda"]])


def save_checkpoint(path: str | os.PathLike, *, model: nn.Module, config: TrainConfig,
                    template_id: str, optimizer=None, scheduler=None, epoch: int = 0,
                    step: int = 0, history: Sequence[Mapping] = (), step_losses=(),
                    best: float = math.inf, extra: Mapping | None = None,
                    durable: bool = True) -> Path:
    """Write a checkpoint atomically (temporary file in the same folder, then ``os.replace``).

    Args:
        path: output file (``.pt``).
        model: the network (a DDP wrapper is unwrapped).
        config: the run's config (stored as a dict).
        template_id: [`template_hash`][handmesh_tutorial.train.templates.template_hash] of the
            template.
        optimizer: its ``state_dict`` is stored when given.
        scheduler: its ``state_dict`` is stored when given.
        epoch: completed epochs.
        step: completed optimiser steps.
        history: rows of ``metrics.csv``.
        step_losses: per-step losses.
        best: best validation PA-MPVPE so far (mm).
        extra: more weights-only-safe entries.
        durable: fsync before the rename.

    Returns:
        The path. The file loads with ``torch.load(path, weights_only=True)``.
    """
    net = model.module if hasattr(model, "module") else model
    ck = {
        "format": CHECKPOINT_FORMAT,
        "model": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "optimizer": optimizer.state_dict() if optimizer is not None else None,
        "scheduler": scheduler.state_dict() if scheduler is not None else None,
        "epoch": int(epoch), "step": int(step),
        "rng": _rng_state(),
        "config": config.to_dict(),
        "template_hash": template_id,
        "num_vertices": int(net.joint_regressor.shape[1]) if hasattr(net, "joint_regressor")
        else None,
        "history": [dict(r) for r in history],
        "step_losses": torch.tensor(list(step_losses), dtype=torch.float64),
        "best": float(best),
        "torch_version": str(torch.__version__),
        "library_version": __version__,
        **dict(extra or {}),
    }
    buf = io.BytesIO()
    torch.save(ck, buf)
    path = Path(path)
    _atomic_write_bytes(path, buf.getvalue(), durable)
    return path


def _shorten(text: str, width: int = 160) -> str:
    """``text`` cut at a word (with ``...``) to at most ``width`` characters, for one line."""
    return textwrap.shorten(text, width, placeholder=" ...") or text[:width]


# what every checkpoint holds (save_checkpoint; a weights-only one has optimizer None)
_REQUIRED_KEYS = ("model", "config", "template_hash", "epoch", "step", "history", "best")


def _read_checkpoint(path: str | os.PathLike, map_location="cpu") -> dict:
    if str(path) == "pretrained":
        path = shipped_file(PRETRAINED_FILE, "make pretrained")
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    try:
        ck = load_torch_file(path, map_location=map_location)
    except (RuntimeError, EOFError, OSError, KeyError, IndexError, ValueError, TypeError,
            AttributeError) as err:  # garbage makes torch's unpickler fail in many ways
        if isinstance(err, ValueError) and str(err).startswith(f"{path}:"):
            raise  # load_torch_file's own refusal names the file and says why already
        why = (str(err).strip().splitlines() or [type(err).__name__])[0]
        raise ValueError(f"{path}: unreadable checkpoint (truncated or not a torch file: "
                         f"{type(err).__name__}: {_shorten(why)})") from err
    if not isinstance(ck, dict) or ck.get("format") != CHECKPOINT_FORMAT:
        got = ck.get("format") if isinstance(ck, dict) else type(ck).__name__
        raise ValueError(f"{path}: not a handmesh_tutorial checkpoint (format {got!r}, "
                         f"expected {CHECKPOINT_FORMAT!r})")
    missing = sorted(k for k in _REQUIRED_KEYS if k not in ck)
    if missing:
        raise ValueError(f"{path}: not a handmesh_tutorial checkpoint (missing keys {missing})")
    if ck.get("weights") == "int8":  # an exported, quantized file (pretrained.export_pretrained)
        ck["model"] = dequantize_state_dict(ck["model"], ck["scales"])
    return ck


def load_checkpoint(path: str | os.PathLike, device: str | torch.device = "cpu",
                    template=None) -> tuple[nn.Module, dict]:
    """Rebuild the network of a checkpoint and load its weights (``weights_only=True``).

    Args:
        path: a file written by [`train`][handmesh_tutorial.train.loop.train] /
            [`save_checkpoint`][handmesh_tutorial.train.checkpoints.save_checkpoint].
        device: where the model goes (``map_location`` too).
        template: the mesh template (default: the config's ``template``, i.e. the MakeHuman hand
            unless a template file was used); its hash must equal the checkpoint's.

    Returns:
        ``(model, checkpoint)``: the network in eval mode, and the checkpoint dict (``config``,
        ``epoch``, ``step``, ``history``...).

    Raises:
        FileNotFoundError: no such file (or template file).
        ValueError: not a checkpoint, an invalid config, a different template, weights that
            do not fit the architecture or hold NaN or infinity (the message names the file
            and the mismatching keys).
    """
    device = _resolve_device(device)
    ck = _read_checkpoint(path, map_location=device)
    try:
        cfg = TrainConfig.from_dict(ck["config"])
    except (ValueError, TypeError) as e:  # TrainConfig's checks name no file
        raise ValueError(f"{path}: its 'config' is not a valid TrainConfig ({e}); the file was "
                         "altered or damaged") from None
    tmpl = resolve_template(cfg.template if template is None else template)
    got = template_hash(tmpl)
    if got != ck["template_hash"]:
        raise ValueError(
            f"{path}: trained with template {ck['template_hash']} "
            f"({ck.get('num_vertices')} vertices), but the template given has hash {got} "
            f"({len(tmpl.vertices)} vertices); pass template= the training template")
    try:
        net = build_model_from_config(cfg, tmpl)
    except (ValueError, TypeError, IndexError) as e:
        raise ValueError(f"{path}: its config {cfg.architecture()} builds no network "
                         f"({type(e).__name__}: {e})") from None
    state = ck["model"] if isinstance(ck["model"], dict) else {}
    bad = next((k for k, v in state.items() if isinstance(v, torch.Tensor)
                and v.is_floating_point() and not torch.isfinite(v).all()), None)
    if bad is not None:  # a diverged run or an altered file: every prediction would be NaN
        raise ValueError(f"{path}: weight '{bad}' holds NaN or infinity (a diverged run or an "
                         "altered file); use an earlier checkpoint")
    want = net.state_dict()
    missing = [k for k in want if k not in state]
    unexpected = [str(k) for k in state if k not in want]
    if missing or unexpected:  # named by count and a few keys: not a line of every key
        raise ValueError(f"{path}: weights do not fit the architecture {cfg.architecture()}: "
                         + "; ".join(f"{len(keys)} {what} (first {', '.join(keys[:3])})"
                                     for keys, what in ((missing, "missing"),
                                                        (unexpected, "unexpected")) if keys))
    try:
        net.load_state_dict(ck["model"], strict=True)
    except RuntimeError as e:
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        raise ValueError(f"{path}: weights do not fit the architecture {cfg.architecture()}: "
                         f"{_shorten(lines[1] if len(lines) > 1 else str(e))}") from None
    return net.to(device).eval(), ck


RUN_CHECKPOINTS = ("checkpoint_last.pt", "checkpoint_best.pt")
"""Files of a run that a fresh start would replace ([`train`][handmesh_tutorial.train.loop.train]
refuses them by default)."""
RUN_OUTPUTS = (*RUN_CHECKPOINTS, "metrics.csv", "steps.csv", "skipped.json", "config.json")
"""Every file a run writes in its ``out_dir``: ``overwrite=True`` removes them all before the new
run starts, so none of an earlier run (a best checkpoint the new run never writes) is left."""


def claim_run_dir(out_dir, *, overwrite: bool, lock: str, fresh: bool = False) -> Path:
    """``_io.claim_out_dir`` for a training run: a folder
    holding files ``train`` did not write is refused unless ``overwrite`` (a run of an older
    version is recognised by `is_train_run`); ``fresh``: then remove every file of an earlier
    run (``RUN_OUTPUTS``), so that none is taken for the new run's (a stale best checkpoint).

    Raises:
        ValueError, NotADirectoryError, FileExistsError, OSError: as ``claim_out_dir``.
    """
    out = claim_out_dir(out_dir, "train", RUN_OUTPUTS, overwrite=overwrite,
                        recognise=is_train_run, hidden=(lock,))
    if fresh:
        remove_outputs(out, RUN_OUTPUTS)
    return out


def is_train_run(out_dir) -> bool:
    """Whether ``out_dir`` holds a run of an older version (before the ``.handmesh-train``
    marker): its ``config.json`` record (``config``, ``template_hash``) or a checkpoint."""
    out = Path(out_dir)
    return json_record(out / "config.json", "config", "template_hash") or bool(existing_run(out))


def existing_run(out_dir) -> list[str]:
    """Names of the checkpoints in ``out_dir`` that a fresh (non-resumed) run would replace."""
    out = Path(out_dir)
    return [n for n in RUN_CHECKPOINTS if (out / n).exists()]


def _remove_stale_temp_files(out_dir) -> list[Path]:
    """Delete the half-written temp files a killed run left in ``out_dir``.

    Only names that this module's atomic writes make (``.<file>.<random>.tmp`` for its own
    checkpoint, metrics and config files) are removed, never other files of the folder.

    Returns:
        The removed paths.
    """
    out = Path(out_dir)
    gone = [tmp for name in RUN_OUTPUTS for tmp in leftover_temporaries(out / name)]
    for tmp in gone:
        tmp.unlink()
    return gone


def _write_csv(path: Path, rows: Sequence[Mapping], columns: Sequence[str],
               durable: bool = True) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        cells = []
        for c in columns:
            v = r.get(c)
            cells.append("" if v is None or (isinstance(v, float) and math.isnan(v)) else
                         (repr(v) if isinstance(v, float) else v))
        w.writerow(cells)
    _atomic_write_bytes(path, buf.getvalue().encode(), durable)


def _write_logs(out: Path, history: list[dict], step_losses: list[float], durable: bool) -> None:
    """``metrics.csv`` (one row per epoch) and ``steps.csv`` (one loss per step)."""
    _write_csv(out / "metrics.csv", history, METRIC_COLUMNS, durable)
    _write_csv(out / "steps.csv", [{"step": i + 1, "loss": x} for i, x in enumerate(step_losses)],
               ("step", "loss"), durable)
