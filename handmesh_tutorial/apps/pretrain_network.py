"""The network's recipe of the shipped pretrained MSMR-Net (``handmesh pretrain``; ``make
pretrained`` runs it twice, frozen then fine-tuned, after the encoder's two stages): generate
mixed-kind INTER-SH scenes, train, export.

* [`PretrainedRecipe`][handmesh_tutorial.apps.pretrain_network.PretrainedRecipe] is the recipe, and
  [`build_pretrained`][handmesh_tutorial.apps.pretrain_network.build_pretrained] runs it.
* [`export_pretrained`][handmesh_tutorial.apps.pretrain_network.export_pretrained] turns a training
  checkpoint into the shipped file: int8 weights per output channel
  ([`quantize_state_dict`][handmesh_tutorial.nn.quantize.quantize_state_dict]), no optimiser
  state, plus what made it (data seeds and counts, recipe, seconds, hardware, commit).

The loader is the library's: [`hmt.pretrained.pretrained`][handmesh_tutorial.pretrained.pretrained].
Why a separate recipe from the demo's, and how the shipped weights were made: docs page "The
pretrained model".

Why one file: the recipe, the command that replays it and the export that records it must
agree field by field; kept together, a change of one is seen beside the others.
"""

from __future__ import annotations

import datetime
import math
import os
import platform
import subprocess
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from .. import _version
from .._io import atomic_write_bytes, file_identity, write_json
from .._version import PRETRAINED_FILE, __version__
from ..budget import MAX_BATCH_SIZE, check_count, check_image_size
from .pretraining_data import (
    check_device,
    check_run_options,
    check_start_file,
    claim_pretraining_dir,
    generate_train_val,
    generate_training_scenes,
)

__all__ = ["PretrainedRecipe", "build_pretrained", "export_pretrained",
           "generate_training_scenes", "generate_train_val", "replay_command"]

@dataclass
class PretrainedRecipe:
    """How the shipped network is made (defaults: the shipped file's recipe).

    Attributes:
        train_scenes: mixed-kind training scenes (hand-hand, hand-object, hand-chain).
        val_scenes: validation scenes (their own seed), scored after every epoch.
        data_seed: seed of the training scenes; validation uses ``data_seed + 1``. Evaluate on
            other seeds (the demo and the notebooks use 0 to 10).
        render_size: scene image side, pixels (FreiHAND's 224).
        image_size: network input crop side, pixels.
        encoder: image encoder; ``resnet10`` keeps the int8 file under 10 MB.
        recipe: ``"cpu"`` or ``"paper"`` ([`RECIPES`][handmesh_tutorial.apps.demo.config.RECIPES]).
        epochs: training epochs.
        batch_size: training batch size.
        lr: Adam learning rate; multiplied by ``lr_gamma`` after every third of the epochs.
        lr_gamma: learning-rate decay factor.
        augment: random rotation, scale, shift and colour of the training crops.
        precision: ``"bfloat16"`` (autocast; on GPUs and CPUs with bfloat16 units) or
            ``"float32"``.
        workers: scene-generator processes (0: one per CPU).
        loader_workers: data-loader processes while training (0: one per CPU, less one).
        seed: network initialisation, data order and augmentation seed.
        device: ``"auto"`` (CUDA when available), ``"cuda"`` or ``"cpu"``.
        init: start from these weights instead of random ones (``"pretrained"``: the shipped
            network, so that each run on new seeds adds to the last; or a checkpoint path). The
            architecture fields above must then be the file's.
        init_encoder: start only the encoder from a pose-encoder file (``handmesh
            pretrain-encoder``) or a shipped one (``"neutral"``, ``"pretrained"``); the paper's
            protocol. Excludes ``init``.
        freeze_encoder: epochs at the start with the encoder fixed; with ``augment=False`` and
            ``freeze_encoder >= epochs`` each crop is encoded once and only the decoder trains.
        encoder_lr_scale: the encoder's learning rate as a share of ``lr`` once unfrozen.
    """

    train_scenes: int = 20_000
    val_scenes: int = 300
    data_seed: int = 100
    render_size: int = 224
    image_size: int = 128
    encoder: str = "resnet10"
    recipe: str = "cpu"
    epochs: int = 16
    batch_size: int = 128
    lr: float = 1e-3
    lr_gamma: float = 0.3
    augment: bool = True
    precision: str = "bfloat16"
    workers: int = 0
    loader_workers: int = 0
    seed: int = 0
    device: str = "auto"
    init: str | None = None
    init_encoder: str | None = None
    freeze_encoder: int = 0
    encoder_lr_scale: float = 1.0

    def __post_init__(self):
        from .demo.config import RECIPES  # the names only: no torch before the generator

        if self.recipe not in RECIPES:
            raise ValueError(f"recipe must be one of {sorted(RECIPES)}, got {self.recipe!r}")
        for name in ("train_scenes", "val_scenes", "epochs", "batch_size", "render_size",
                     "image_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if self.init is not None and self.init_encoder is not None:
            raise ValueError("init and init_encoder exclude each other: init starts the whole "
                             "network from a checkpoint, init_encoder only its encoder")
        for name in ("workers", "loader_workers", "freeze_encoder"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
        # what training would refuse, refused before hours of scene generation
        check_count(self.batch_size, "batch_size", 1, MAX_BATCH_SIZE, "MAX_BATCH_SIZE")
        if self.batch_size > 2 * self.train_scenes:  # as train.EpochBatchSampler refuses
            raise ValueError(f"batch_size {self.batch_size} is more than twice the "
                             f"{self.train_scenes} training scenes: use --batch-size "
                             f"{2 * self.train_scenes} or less")
        check_image_size(self.image_size)
        check_image_size(self.render_size, "render_size")
        for name, ok, want in (("lr", lambda x: 0 < x < math.inf, "a finite number > 0"),
                               ("lr_gamma", lambda x: 0 < x <= 1, "in (0, 1]"),
                               ("encoder_lr_scale", lambda x: 0 <= x < math.inf,
                                "a finite number >= 0")):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not ok(v):
                raise ValueError(f"{name} must be {want}, got {v!r}")
        if self.precision not in ("float32", "bfloat16"):
            raise ValueError(f"precision must be 'float32' or 'bfloat16', got "
                             f"{self.precision!r}")
        check_device(self.device)

    def train_config(self, data, val_data, out_dir, progress: bool = True):
        """The [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig] of the training run: the
        ``pretraining`` preset
        ([`TrainConfig.preset`][handmesh_tutorial.train.config.TrainConfig.preset]) at this
        recipe's values, validated on ``val_data``, the learning rate decayed after every third
        of the epochs."""
        from ..train import TrainConfig
        from .demo.config import _recipe_fields

        cpus = os.cpu_count() or 1
        fields = _recipe_fields(self.recipe)
        if self.recipe == "paper" and self.init_encoder is not None:
            # the pretrained encoder read as it was trained: pooled at its own 2D joints
            fields["model_kwargs"] = {**fields["model_kwargs"], "keypoints": True}
        return TrainConfig.preset(
            "pretraining", data=str(data), val_data=str(val_data), image_size=self.image_size,
            epochs=self.epochs, batch_size=self.batch_size, lr=self.lr,
            lr_step=max(1, math.ceil(self.epochs / 3)), lr_gamma=self.lr_gamma,
            augment=self.augment, encoder=self.encoder, seed=self.seed, device=self.device,
            num_workers=self.loader_workers or max(0, cpus - 1), precision=self.precision,
            out_dir=str(out_dir), progress=progress, init=self.init,
            init_encoder=self.init_encoder, freeze_encoder=self.freeze_encoder,
            encoder_lr_scale=self.encoder_lr_scale, **fields)


def _resumed_plan(saved: dict, history: list, epochs: int,
                  max_train_seconds: float) -> tuple[int, int]:
    """``(epochs, lr_step)`` for resuming a time-budgeted run from its checkpoint.

    A run's first epoch is timed alone (its checkpoint says ``epochs=1``); the run then plans the
    epochs that fit and continues, and every later checkpoint holds that plan, which a resume
    keeps. A run stopped before its second epoch wrote a checkpoint plans now, from the first
    epoch's training seconds in ``history`` (validation not included: the plan may be an epoch
    long, and the budget check after each epoch still stops it in time).

    Args:
        saved: the checkpoint's config (a dict). history: its rows (``seconds`` per epoch).
        epochs: the recipe's epochs, the most a plan may give. max_train_seconds: the budget.
    """
    if int(saved["epochs"]) > 1 or epochs == 1:
        return int(saved["epochs"]), int(saved["lr_step"])
    return _plan(epochs, float(history[0]["seconds"]), max_train_seconds)


def _prior_train_seconds(clock: Path, history: list[dict]) -> float:
    """Training seconds spent before this invocation, so that a resumed run records them all:
    ``clock``'s (written after each epoch) plus the epochs of the checkpoint's ``history``
    beyond it; without ``clock`` (a run of before 0.6.0) the history's per-epoch seconds."""
    done = {"epoch": 0, "seconds": 0.0}
    if os.path.lexists(clock):
        from ..data.files import _read_json  # the reader rule: no link, the file named

        done = _read_json(clock)
        ok = isinstance(done, dict) and all(
            isinstance(done.get(k), int | float) and not isinstance(done.get(k), bool)
            and math.isfinite(done[k]) and done[k] >= 0 for k in ("epoch", "seconds"))
        if not ok:
            raise ValueError(f"{clock}: expected {{\"epoch\": N, \"seconds\": S}} (numbers >= "
                             f"0), got {str(done)[:80]}; it is rewritten after each epoch: "
                             "delete it to count only the checkpoint's epochs")
    return float(done["seconds"]) + sum(float(r.get("seconds", 0.0)) for r in history
                                        if int(r["epoch"]) > int(done["epoch"]))


def _plan(epochs: int, per_epoch: float, max_train_seconds: float) -> tuple[int, int]:
    """``(epochs, lr_step)`` that fit the budget at ``per_epoch`` seconds each: at least one, at
    most ``epochs``, the learning rate decayed after every third of them."""
    fit = max(1, min(epochs, int(max_train_seconds // max(per_epoch, 1e-9))))
    return fit, max(1, math.ceil(fit / 3))


def _hardware(device) -> str:
    import torch

    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            name = next(ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    cpu = f"{name}, {os.cpu_count()} CPUs"
    if str(device).startswith("cuda") and torch.cuda.is_available():
        return f"{torch.cuda.get_device_name(0)}; {cpu}"
    return cpu


def _commit() -> str | None:
    """The library's git commit: ``HANDMESH_COMMIT`` when set (a copied tree whose ``.git`` is
    not the code's), else ``git rev-parse HEAD``."""
    if os.environ.get("HANDMESH_COMMIT"):
        return os.environ["HANDMESH_COMMIT"]
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent,
                             capture_output=True, text=True, timeout=10, check=True)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def export_pretrained(checkpoint: str | os.PathLike, out: str | os.PathLike, *,
                      weights: str = "int8", info: dict | None = None) -> Path:
    """Write a training checkpoint as a small, loadable pretrained file (atomically).

    Keeps the config, template hash, epoch, step and history; drops the optimiser, scheduler,
    random states and per-step losses. ``weights="int8"``: per-channel int8 weights
    ([`quantize_state_dict`][handmesh_tutorial.nn.quantize.quantize_state_dict]), about a
    quarter of float32; ``"float16"``: half. Both load with ``load_checkpoint`` (float32 again).

    Args:
        checkpoint: a ``checkpoint_*.pt`` of [`train`][handmesh_tutorial.train.loop.train].
        out: the file to write.
        weights: ``"int8"`` or ``"float16"``.
        info: stored as ``pretrained`` (recipe, data, seconds, hardware...).

    Returns:
        ``out`` as a ``Path``.
    """
    import io

    import torch

    from .._io import atomic_write_bytes
    from ..nn.quantize import quantize_state_dict
    from ..train.checkpoints import _read_checkpoint
    from ..train.config import TrainConfig
    from ..train.templates import build_model_from_config, resolve_template

    if weights not in ("int8", "float16"):
        raise ValueError(f"weights must be 'int8' or 'float16', got {weights!r}")
    ck = _read_checkpoint(checkpoint)
    cfg = TrainConfig.from_dict(ck["config"])
    net = build_model_from_config(cfg, resolve_template(cfg.template))
    names = {n for n, _ in net.named_parameters()}
    if weights == "int8":
        model, scales = quantize_state_dict(ck["model"], names)
    else:
        model = {k: (v.half() if k in names and v.is_floating_point() else v)
                 for k, v in ck["model"].items()}
        scales = {}
    small = {k: ck[k] for k in ("format", "config", "template_hash", "num_vertices", "epoch",
                                "step", "history", "best", "torch_version")}
    # a shipped file names the data and starting files it was made from, not this machine's
    # folders: absolute paths keep their last part
    small["config"] = {k: (Path(v).name if k in _FILE_KEYS and isinstance(v, str)
                           and os.path.isabs(v) else v) for k, v in small["config"].items()}
    small.update(model=model, scales=scales, weights=weights, optimizer=None, scheduler=None,
                 pretrained=dict(info or {}), library_version=__version__)
    buf = io.BytesIO()
    torch.save(small, buf)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out, buf.getvalue(), True)
    return out


_FILE_KEYS = ("data", "val_data", "out_dir", "init", "init_encoder")

_NO_OPTION = ("lr_gamma",)
"""Recipe fields ``handmesh pretrain`` has no option for (`replay_command` names them apart)."""


def replay_command(recipe: PretrainedRecipe, *, max_generate_seconds: float | None = None,
                   max_train_seconds: float | None = None,
                   scenes_from: str | os.PathLike | None = None) -> str:
    """The ``handmesh pretrain`` line that makes ``recipe`` again: one option per field that
    differs from `PretrainedRecipe`'s default, files and run folders by name (no folder of this
    machine), plus the time budgets and ``--scenes-from``. Recorded as ``command`` in the file,
    so its lineage reads as commands.

    Raises:
        ValueError: a field that differs from its default has no command-line option
            (`_NO_OPTION`): the line would make another network.
    """
    from dataclasses import fields

    default, words = PretrainedRecipe(), ["handmesh", "pretrain"]
    for f in fields(recipe):
        v = getattr(recipe, f.name)
        if v == getattr(default, f.name):
            continue
        if f.name in _NO_OPTION:
            raise ValueError(f"{f.name}={v!r} has no option of handmesh pretrain")
        if f.name == "augment":
            words.append("--no-augment")
            continue
        if f.name in ("init", "init_encoder") and v not in ("pretrained", "neutral"):
            v = Path(str(v)).name
        words += [f"--{f.name.replace('_', '-')}", str(v)]
    for name, v in (("max_generate_seconds", max_generate_seconds),
                    ("max_train_seconds", max_train_seconds)):
        if v is not None:
            words += [f"--{name.replace('_', '-')}", f"{v:g}"]
    if scenes_from is not None:
        words += ["--scenes-from", Path(scenes_from).name]
    return " ".join(words)


class _OutOfTime(Exception):
    pass


def build_pretrained(out: str | os.PathLike = "runs/pretrained",
                     recipe: PretrainedRecipe | None = None, *,
                     max_generate_seconds: float | None = None,
                     max_train_seconds: float | None = None, install: bool = False,
                     export_every: float = 60.0, progress: bool = True, log=print,
                     overwrite: bool = False,
                     scenes_from: str | os.PathLike | None = None) -> dict:
    """Make the pretrained MSMR-Net: generate the scenes, train, export (``handmesh pretrain``).

    Steps: ``out/data/train`` (``recipe.train_scenes``, seed ``data_seed``) and ``out/data/val``
    (``val_scenes``, seed ``data_seed + 1``); training in ``out/train`` (a normal run of
    [`train`][handmesh_tutorial.train.loop.train]); the last checkpoint is exported to
    ``out/msmr_net_pretrained.pt`` (int8) and ``out/msmr_net_float16.pt`` after the first epoch,
    then after each epoch that ends ``export_every`` seconds or more after the last export, and
    after the last epoch, so a run cut short still leaves a usable file. ``install=True`` copies
    the int8 file into the package (``handmesh_tutorial/assets/``), where
    [`pretrained`][handmesh_tutorial.pretrained.pretrained] finds it.

    Calling it again with the same ``out`` resumes: the scenes already generated are kept (also
    under another ``max_generate_seconds``; other seeds or counts are refused), and training
    continues from ``out/train/checkpoint_last.pt`` with the epochs and schedule planned for it
    (``_resumed_plan``); the training budget counts from the resumed call.

    Args:
        out: output folder.
        recipe: the recipe (default: the shipped file's).
        max_generate_seconds: stop generating training scenes when the next of 10 shards would
            end past this budget (``None``: all ``train_scenes``).
        max_train_seconds: fit the training to this budget (``None``: all ``epochs``). The
            first epoch is timed alone; then as many epochs as fit (at most ``epochs``) are
            planned, with the learning-rate schedule of that many (``epochs_planned`` in the
            file). Training also stops after an epoch that leaves less than one epoch's time.
        install: copy the result into the package.
        export_every: seconds between exports while training (they cost seconds each).
        progress: tqdm bars.
        log: one-line messages (``None``: silent).
        overwrite: write into an ``out`` holding files this command did not write
            (``claim_pretraining_dir``, before any scene; a link where it writes is refused).
        scenes_from: another ``handmesh pretrain`` run's ``out`` whose scenes are read in place
            instead of generated (``scenes_of_run``: the same seed, counts and render size), so
            that a later stage of a chain (``init`` = that run's checkpoint) skips generation.

    Returns:
        dict with ``file`` (the int8 export), ``float16``, ``info`` (what the file records) and
        ``history``.
    """
    recipe = recipe or PretrainedRecipe()
    check_device(recipe.device, probe=True)  # a CUDA device asked for: before generating
    check_run_options(max_generate_seconds=max_generate_seconds,
                      max_train_seconds=max_train_seconds)
    from ..budget import check_workers

    check_workers(recipe.workers, "workers")  # the machine's bounds: before any scene
    check_workers(recipe.loader_workers, "loader_workers")
    # the starting weights read as training will: in seconds, not after hours of scenes
    check_start_file(recipe.init, "checkpoint", "--init")
    check_start_file(recipe.init_encoder, "encoder", "--init-encoder")
    say = log or (lambda *_: None)
    out = claim_pretraining_dir(out, "pretrain", overwrite)
    tr, val, t_gen = generate_train_val(out / "data", recipe.train_scenes, recipe.val_scenes,
                                        recipe.data_seed, render_size=recipe.render_size,
                                        workers=recipe.workers,
                                        max_generate_seconds=max_generate_seconds,
                                        progress=progress, log=log, scenes_from=scenes_from)

    # torch only now: the generator's workers fork only from a process without torch
    import torch

    from ..train import train
    from ..train.checkpoints import _read_checkpoint

    config = recipe.train_config(tr["root"], val["root"], out / "train", progress)
    info = {"command": replay_command(recipe, max_generate_seconds=max_generate_seconds,
                                      max_train_seconds=max_train_seconds,
                                      scenes_from=scenes_from),
            "recipe": asdict(recipe), "max_generate_seconds": max_generate_seconds,
            "max_train_seconds": max_train_seconds,
            "data": {"train_seed": recipe.data_seed, "train_scenes": tr["scenes"],
                     "val_seed": recipe.data_seed + 1, "val_scenes": val["scenes"],
                     "kinds": "mixed (hand-hand, hand-object, hand-chain)",
                     "render_size": recipe.render_size},
            "seconds": {"generate": round(t_gen, 1)}, "torch": str(torch.__version__),
            "commit": _commit(), "date": datetime.date.today().isoformat()}
    if recipe.init is not None:  # the chain of runs: what the starting weights were made of
        info["init_from"] = (_read_checkpoint(recipe.init).get("pretrained")
                             or Path(str(recipe.init)).name)
        if recipe.init != "pretrained":
            info["recipe"]["init"] = Path(recipe.init).name  # no machine paths in the file
            info["init_file"] = file_identity(recipe.init)
    if recipe.init_encoder is not None:  # the encoder's chain, from its own file
        from ..nn.pose_encoder import encoder_lineage, encoder_source_path, read_pose_encoder

        source = encoder_source_path(recipe.init_encoder)
        meta = read_pose_encoder(source)[1]
        info["init_encoder_from"] = {"file": file_identity(source),
                                     "lineage": encoder_lineage(meta)["sentence"],
                                     "made_by": meta.get("pretrained")}
        if recipe.init_encoder not in ("neutral", "pretrained"):
            info["recipe"]["init_encoder"] = source.name
    files = {"file": out / PRETRAINED_FILE, "float16": out / "msmr_net_float16.pt"}
    plan = {"config": config}  # the run's config; its epochs may be fitted to the time budget
    last = out / "train" / "checkpoint_last.pt"
    clock = out / "train" / "train_seconds.json"  # the seconds of earlier invocations
    saved = _read_checkpoint(last) if last.exists() else None  # the run being resumed
    prior = _prior_train_seconds(clock, (saved or {}).get("history") or [])
    t_train = time.perf_counter()
    exported = [-math.inf]  # when the files were last written

    def export(epoch: int) -> None:
        info["seconds"]["train"] = round(prior + time.perf_counter() - t_train, 1)
        info["epochs_done"] = int(epoch)
        info["hardware"] = _hardware(config.device if config.device != "auto" else
                                     ("cuda" if torch.cuda.is_available() else "cpu"))
        export_pretrained(last, files["file"], weights="int8", info=info)
        export_pretrained(last, files["float16"], weights="float16", info=info)
        exported[0] = time.perf_counter()

    def after_epoch(row):
        spent = time.perf_counter() - t_train
        write_json(clock, {"epoch": int(row["epoch"]), "seconds": round(prior + spent, 1)})
        final = row["epoch"] >= plan["config"].epochs
        stop = (max_train_seconds is not None and not final
                and spent * (1 + 1 / row["epoch"]) > max_train_seconds)
        # exports cost seconds (two files from a checkpoint with optimiser state): not after
        # every short epoch, but always after the last one and before stopping
        if final or stop or time.perf_counter() - exported[0] >= export_every:
            export(row["epoch"])
        say(f"      epoch {row['epoch']}: train loss {1000 * row['train_loss']:.2f} mm, val "
            f"PA-MPJPE {row.get('val_pa_mpjpe', float('nan')):.2f} mm, {spent:.0f} s")
        if stop:
            raise _OutOfTime

    say(f"[2/3] training ({recipe.epochs} epochs, batch {recipe.batch_size}, "
        f"{recipe.image_size}-px crops, {recipe.encoder}) in {out / 'train'}")
    resume = saved is not None
    if resume and max_train_seconds is not None:  # keep the plan of the run being resumed
        fit, lr_step = _resumed_plan(saved["config"], saved["history"], config.epochs,
                                     max_train_seconds)
        plan["config"] = replace(config, epochs=fit, lr_step=lr_step)
        info["epochs_planned"] = fit
        say(f"      resuming after epoch {int(saved['epoch'])} of the {fit} planned")
    try:
        if max_train_seconds is not None and not resume and config.epochs > 1:
            # One epoch first, to see how many fit the budget; then the learning-rate schedule
            # is planned for that many (a resumed run may change epochs and lr_step, and it
            # continues exactly where the first epoch ended).
            plan["config"] = replace(config, epochs=1)
            train(plan["config"], callback=after_epoch)
            per_epoch = time.perf_counter() - t_train
            fit, lr_step = _plan(config.epochs, per_epoch, max_train_seconds)
            plan["config"] = replace(config, epochs=fit, lr_step=lr_step)
            info["epochs_planned"] = fit
            say(f"      the first epoch took {per_epoch:.0f} s: {fit} of {config.epochs} epochs "
                f"fit the {max_train_seconds:.0f} s budget, the schedule is planned for {fit}")
            resume = True
        train(plan["config"], resume=resume, callback=after_epoch)
    except _OutOfTime:
        say(f"      stopped after epoch {info['epochs_done']} of {plan['config'].epochs}: the "
            f"next would end past the {max_train_seconds:.0f} s budget")
    if "epochs_done" not in info:  # a finished run resumed: nothing trained, export it now
        export(int(_read_checkpoint(last)["epoch"]))
    say(f"[3/3] exported {files['file']} ({files['file'].stat().st_size / 1e6:.1f} MB, int8) and "
        f"{files['float16'].name}")
    if install:
        assets = _version.ASSET_DIR
        assets.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(assets / PRETRAINED_FILE, files["file"].read_bytes(), True)
        say(f"      installed as {assets / PRETRAINED_FILE}")
    return {**files, "info": info}
