"""Pretraining the hand image encoder (``handmesh pretrain-encoder``, ``make pretrained-encoder``).

Makes the file behind [`pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder]:
INTER-SH scenes -> one wide crop per target hand
([`crop_cache`][handmesh_tutorial.data.batched_crops.crop_cache]) -> training of a
[`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet] on random views of those crops made in
batches on the training device
([`augment_crops`][handmesh_tutorial.data.batched_crops.augment_crops]) -> the int8 file. The
docs page "Why the paper starts from pretrained weights" says why and how the shipped file was
made.

Runs are deterministic for a seed (the step's draws come from ``(seed, step)``) and resume: the
checkpoint holds weights, optimiser, the planned number of steps and the history.

Why one file: the recipe, the validation that decides what its history records, and the loop
read together as one procedure; the evaluation is shared with nothing else.
"""

from __future__ import annotations

import datetime
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from .._io import atomic_write_bytes, atomic_write_with, file_identity, single_writer, write_json
from .._progress import progress_bar
from .._untrusted import load_torch_file
from ..budget import MAX_BATCH_SIZE, check_count, check_image_size
from ..data.batched_crops import BOX_SCALE, augment_crops
from ..nn.losses import similarity_align
from ..nn.pose_encoder import (
    _JOINT_SCALE,
    ENCODER_FILE,
    PoseNet,
    build_pose_net,
    export_pose_encoder,
    pose_loss,
)
from .pretraining_data import (
    check_device,
    check_run_options,
    check_start_file,
    claim_pretraining_dir,
    crop_caches,
)

__all__ = ["PosePretrainConfig", "evaluate_pose", "pretrain_pose_encoder",
           "build_pretrained_encoder"]


@dataclass
class PosePretrainConfig:
    """How the encoder is pretrained (defaults: the shipped file's recipe).

    Attributes:
        train_scenes: mixed-kind training scenes generated.
        val_scenes: validation scenes (seed ``data_seed + 1``).
        data_seed: seed of the training scenes. The demo, notebooks and docs test on seeds 0-10
            and 500; the shipped MSMR-Net used 100-801.
        render_size: scene image side, pixels.
        image_sizes: crop sides trained on, pixels, one per step in turn (the encoder then works
            at each; the demo uses 64).
        backbone: ResNet name.
        init: ``None`` (random weights), ``"network"`` (the encoder of the shipped MSMR-Net,
            ``hmt.pretrained.pretrained()``) or the path of a pose-encoder file.
        batch_size: crops per step.
        lr: AdamW peak learning rate (linear warm-up over ``warmup_steps``, then cosine to 0).
        weight_decay: AdamW weight decay.
        warmup_steps: warm-up steps.
        max_steps: the most steps; a time budget may plan fewer.
        rotation: in-plane rotation range, degrees. scale: zoom ``2 ** U(-scale, scale)``.
        shift: crop-centre shift, share of the side. colour: brightness, contrast and
            saturation factor range ``1 +- colour``.
        keypoint_weight: weight of the 2D term of
            [`pose_loss`][handmesh_tutorial.nn.pose_encoder.pose_loss].
        aligned_weight: weight of its aligned-joint term.
        seed: initialisation, order and augmentation seed.
        device: ``"auto"``, ``"cuda"`` or ``"cpu"``.
        precision: ``"bfloat16"`` (autocast on either device; its speed on a CPU: docs page
            "Why the paper starts from pretrained weights") or ``"float32"``.
        workers: scene-generator processes (0: one per CPU).
    """

    train_scenes: int = 40_000
    val_scenes: int = 400
    data_seed: int = 900
    render_size: int = 224
    image_sizes: tuple[int, ...] = (64, 96, 128)
    backbone: str = "resnet10"
    init: str | None = None
    batch_size: int = 256
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup_steps: int = 300
    max_steps: int = 60_000
    rotation: float = 45.0
    scale: float = 0.25
    shift: float = 0.1
    colour: float = 0.3
    keypoint_weight: float = 0.5
    aligned_weight: float = 1.0
    seed: int = 0
    device: str = "auto"
    precision: str = "bfloat16"
    workers: int = 0

    def __post_init__(self):
        check_device(self.device)  # before hours of scene generation (so are the checks below)
        if isinstance(self.image_sizes, str) or not all(
                hasattr(s, "__index__") and not isinstance(s, bool) for s in self.image_sizes):
            raise ValueError(f"image_sizes must be integers (crop sides in pixels, e.g. "
                             f"(64, 96, 128)), got {self.image_sizes!r}")
        self.image_sizes = tuple(int(s) for s in self.image_sizes)
        for name in ("train_scenes", "val_scenes", "batch_size", "max_steps", "render_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        check_count(self.batch_size, "batch_size", 1, MAX_BATCH_SIZE, "MAX_BATCH_SIZE")
        if self.batch_size > self.train_scenes:  # one crop per scene: not one batch
            raise ValueError(f"batch_size {self.batch_size} is more than the "
                             f"{self.train_scenes} training scenes (one crop each): use "
                             f"--batch-size {self.train_scenes} or less")
        if not self.image_sizes:
            raise ValueError("image_sizes must name at least one crop side")
        for side in self.image_sizes:
            check_image_size(side, "image_sizes")
        check_image_size(self.render_size, "render_size")
        if isinstance(self.lr, bool) or not isinstance(self.lr, int | float) \
                or not 0 < self.lr < math.inf:
            raise ValueError(f"lr must be a finite number > 0, got {self.lr!r}")
        if self.precision not in ("float32", "bfloat16"):
            raise ValueError(f"precision must be 'float32' or 'bfloat16', got {self.precision!r}")


def _draws(config: PosePretrainConfig, n: int, step: int, device) -> dict:
    """The augmentation draws of ``step`` (from ``(seed, step)``: resumable, order-free)."""
    g = torch.Generator().manual_seed(int(config.seed) * 1_000_003 + int(step))
    u = lambda *shape: torch.rand(*shape, generator=g) * 2 - 1  # noqa: E731 - U(-1, 1)
    c = config.colour
    d = {"angle": u(n) * math.radians(config.rotation), "zoom": 2.0 ** (config.scale * u(n)),
         "shift": u(n, 2) * config.shift, "brightness": 1 + c * u(n), "contrast": 1 + c * u(n),
         "saturation": 1 + c * u(n)}
    return {k: v.to(device) for k, v in d.items()}


# -- evaluation ------------------------------------------------------------------------------

def _procrustes_mean(joints: torch.Tensor, iterations: int = 3) -> torch.Tensor:
    """Mean shape of ``(N, J, 3)`` point sets after similarity alignment to it, ``(J, 3)``."""
    ref = joints[0]
    for _ in range(iterations):
        ref = similarity_align(joints.double(), ref.double().expand_as(joints)).mean(0).float()
    return ref - ref[9]


def evaluate_pose(net: PoseNet, cache: dict, sizes=(64, 128), batch_size: int = 256,
                  baselines: dict | None = None, per_crop: bool = False) -> dict:
    """Joint errors of ``net`` on the evaluation crops of ``cache`` (and of constant answers).

    Args:
        net: the network.
        cache: [`crop_cache`][handmesh_tutorial.data.batched_crops.crop_cache] of the
            validation scenes (on any device; ``net``'s is used).
        sizes: crop sides to score.
        baselines: ``{name: (21, 3) root-relative joints}`` predicted for every crop.
        per_crop: also return each crop's PA-MPJPE (mm, ``(N,)`` numpy) under
            ``"pa_per_crop"`` in each entry, for paired comparisons on the same crops.

    Returns:
        ``{f"{size}": {"mpjpe", "pa_mpjpe", "uv_px"}, name: {"mpjpe", "pa_mpjpe"}}`` in mm
        (``uv_px``: 2D error in crop pixels).
    """
    from ..nn.keypoints import normalised_keypoints

    dev = next(net.parameters()).device
    was = net.training
    net.eval()
    out = {}
    n = len(cache["image"])
    with torch.no_grad():
        for size in sizes:
            err, pa, uv = [], [], []
            for i in range(0, n, batch_size):
                b = {k: v[i:i + batch_size].to(dev) for k, v in cache.items()}
                v = augment_crops(b, size)
                o = net(v["image"])
                err.append((o["joints"] - v["joints"]).norm(dim=-1).mean(1))
                pa.append((similarity_align(o["joints"], v["joints"]) - v["joints"])
                          .norm(dim=-1).mean(1))
                t = normalised_keypoints(v["joints"], v["root"], v["K"], size)
                uv.append(((o["uv"] - t) * size / 2).norm(dim=-1).mean(1))
            out[str(size)] = {"mpjpe": 1000 * float(torch.cat(err).mean()),
                              "pa_mpjpe": 1000 * float(torch.cat(pa).mean()),
                              "uv_px": float(torch.cat(uv).mean())}
            if per_crop:
                out[str(size)]["pa_per_crop"] = 1000 * torch.cat(pa).double().cpu().numpy()
        gt = cache["joints"].to(dev)
        for name, joints in (baselines or {}).items():
            pred = torch.as_tensor(joints, dtype=torch.float32, device=dev).expand_as(gt)
            pa = (similarity_align(pred, gt) - gt).norm(dim=-1).mean(1)
            out[name] = {"mpjpe": 1000 * float((pred - gt).norm(dim=-1).mean()),
                         "pa_mpjpe": 1000 * float(pa.mean())}
            if per_crop:
                out[name]["pa_per_crop"] = 1000 * pa.double().cpu().numpy()
    net.train(was)
    return out


# -- training --------------------------------------------------------------------------------

def _lr_at(config: PosePretrainConfig, step: int, total: int) -> float:
    if step < config.warmup_steps:
        return config.lr * (step + 1) / config.warmup_steps
    t = (step - config.warmup_steps) / max(1, total - config.warmup_steps)
    return config.lr * 0.5 * (1 + math.cos(math.pi * min(1.0, t)))


def _lock(out: Path):
    """Refuse a second process training into the same folder."""
    out.mkdir(parents=True, exist_ok=True)
    return single_writer(out / ".pretrain.lock", f"{out} (pretraining)")


def _save(path: Path, obj: dict) -> None:
    atomic_write_with(path, lambda fh: torch.save(obj, fh))


def _init_weights(net: PoseNet, init: str | None) -> None:
    if init is None:
        return
    if init == "network":  # the encoder of the shipped MSMR-Net
        from ..pretrained import pretrained

        net.encoder.load_state_dict(pretrained().encoder.state_dict())
    else:
        from ..nn.pose_encoder import read_pose_encoder

        net.load_state_dict(read_pose_encoder(init)[0].state_dict())


def pretrain_pose_encoder(train_cache: dict, val_cache: dict, out: str | os.PathLike,
                          config: PosePretrainConfig | None = None, *,
                          max_train_seconds: float | None = None, stop_after: int | None = None,
                          info: dict | None = None,
                          checkpoint_seconds: float = 60.0, val_every: int = 1000,
                          progress: bool = True, log=print) -> dict:
    """Train a [`PoseNet`][handmesh_tutorial.nn.pose_encoder.PoseNet] on cached crops; resumable.

    ``out/checkpoint.pt`` is written every ``checkpoint_seconds`` and at the end; a second call
    with the same ``out`` continues from it (same config required). With a time budget the
    first 40 steps are timed and the run plans ``min(max_steps, steps that fit)``; the
    learning-rate schedule follows that plan, which the checkpoint keeps. After each validation
    the network is exported to ``out/hand_encoder_pretrained.pt`` (int8).

    Args:
        train_cache: [`crop_cache`][handmesh_tutorial.data.batched_crops.crop_cache] of the
            training scenes.
        val_cache: the same of the validation scenes.
        out: output folder.
        config: the recipe.
        max_train_seconds: training budget of this call (``None``: ``max_steps``).
        stop_after: stop once this many steps are done (validated, exported, checkpointed),
            leaving the planned schedule as it is: the learning rate is where the plan has it
            then, and a later call without it continues to the plan's end. ``None``: the plan.
        info: provenance stored in the exported file.
        checkpoint_seconds: seconds between checkpoints.
        val_every: steps between validations.
        progress: tqdm bar.
        log: one-line messages (``None``: silent).

    Returns:
        ``{"file", "history", "steps", "seconds"}``.

    Raises:
        ValueError: a checkpoint of another config in ``out``.
        RuntimeError: another process trains into ``out``.
        FloatingPointError: a non-finite loss (names the step).
    """
    config = config or PosePretrainConfig()
    check_device(config.device, probe=True)  # a CUDA device asked for: before generating
    say = log or (lambda *_: None)
    out = Path(out)
    dev = torch.device("cuda" if config.device == "auto" and torch.cuda.is_available()
                       else ("cpu" if config.device == "auto" else config.device))
    with _lock(out):
        torch.manual_seed(config.seed)
        net = build_pose_net(config.backbone)
        ck_path = out / "checkpoint.pt"
        ck = None
        if ck_path.exists():
            ck = load_torch_file(ck_path)
            saved = {k: v for k, v in ck["config"].items() if k not in ("device", "workers")}
            now = {k: v for k, v in _jsonable(asdict(config)).items()
                   if k not in ("device", "workers")}
            if saved != now:
                diff = {k: (saved.get(k), now.get(k)) for k in now if saved.get(k) != now[k]}
                raise ValueError(f"{ck_path}: a run of another config (checkpoint, now): {diff}; "
                                 "use another out")
            net.load_state_dict(ck["model"])
        else:
            _init_weights(net, config.init)
        net.to(dev)
        if dev.type == "cuda":
            net = net.to(memory_format=torch.channels_last)
            torch.backends.cudnn.benchmark = True
        opt = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        step, total, history = 0, config.max_steps, []
        if ck is not None:
            opt.load_state_dict(ck["optimizer"])
            step, total, history = int(ck["step"]), int(ck["total_steps"]), list(ck["history"])
            say(f"      resuming at step {step} of {total}")
        tc = {k: v.to(dev) for k, v in train_cache.items()}
        vc = {k: v.to(dev) for k, v in val_cache.items()}
        n = len(tc["image"])
        if n < config.batch_size:
            raise ValueError(f"{n} training crops, fewer than one batch of {config.batch_size}")
        if ck is None:  # the fresh head starts at the mean training joints, whatever the features
            with torch.no_grad():
                net.joint_head.weight.zero_()
                net.joint_head.bias.copy_(tc["joints"].mean(0).flatten() / _JOINT_SCALE)
        from ..hand import HandModel

        rest = HandModel()().joints[0].to(dev)
        baselines = {"rest hand": rest - rest[9],
                     "mean training hand": _procrustes_mean(tc["joints"][:4000])}
        half = config.precision == "bfloat16"
        per_epoch = n // config.batch_size
        t0 = time.perf_counter()
        t_ck = t0
        planned = ck is not None or max_train_seconds is None
        t_plan = None
        bar = progress_bar(total=total, initial=step, desc="pretraining the encoder",
                           disable=not progress, per="job")

        def checkpoint():
            _save(ck_path, {"model": {k: v.cpu() for k, v in net.state_dict().items()},
                            "optimizer": opt.state_dict(), "step": step, "total_steps": total,
                            "history": history, "config": _jsonable(asdict(config))})

        def validate():
            row = {"step": step, "seconds": round(time.perf_counter() - t0, 1),
                   **{f"{k}": v for k, v in evaluate_pose(net, vc, baselines=baselines).items()}}
            history.append(row)
            say(f"      step {step}/{total}: val PA-MPJPE {row['64']['pa_mpjpe']:.2f} mm at 64 px, "
                f"{row['128']['pa_mpjpe']:.2f} at 128 (mean training hand "
                f"{row['mean training hand']['pa_mpjpe']:.2f}, rest hand "
                f"{row['rest hand']['pa_mpjpe']:.2f}); MPJPE {row['64']['mpjpe']:.1f} mm")
            export_pose_encoder(net, out / ENCODER_FILE, info={**(info or {}), "steps": step,
                                                              "config": _portable(config)},
                                backbone=config.backbone, history=history,
                                preprocessing=_preprocessing(config))

        net.train()
        while step < total and (stop_after is None or step < stop_after):
            epoch, pos = divmod(step, per_epoch)
            perm = np.random.default_rng([config.seed, epoch]).permutation(n)
            idx = torch.as_tensor(perm[pos * config.batch_size:(pos + 1) * config.batch_size],
                                  device=dev)
            size = config.image_sizes[step % len(config.image_sizes)]
            b = {k: v[idx] for k, v in tc.items()}
            v = augment_crops(b, size, draws=_draws(config, len(idx), step, dev))
            lr = _lr_at(config, step, total)
            for g in opt.param_groups:
                g["lr"] = lr
            images = v["image"]
            if dev.type == "cuda":
                images = images.contiguous(memory_format=torch.channels_last)
            with torch.autocast(dev.type, dtype=torch.bfloat16, enabled=half):
                o = net(images)
            o = {k: t.float() for k, t in o.items()}
            loss, parts = pose_loss(o, v["joints"], v["root"], v["K"], size,
                                    config.keypoint_weight, config.aligned_weight)
            if not math.isfinite(float(loss.detach())):
                raise FloatingPointError(f"pose loss is {float(loss.detach())} at step "
                                         f"{step + 1}; the optimiser step was not taken (lr "
                                         f"{lr:g})")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            bar.update(1)
            bar.set_postfix(joints_mm=f"{1000 * parts['joints']:.1f}", lr=f"{lr:.2g}")
            if not planned and step == 10:
                t_plan = time.perf_counter()  # the first steps include cudnn's tuning
            if not planned and step == 40:
                rate = 30 / (time.perf_counter() - t_plan)
                spent = time.perf_counter() - t0
                fit = int(step + rate * (max_train_seconds - spent) * 0.9)
                total = max(step + 1, min(config.max_steps, fit))
                planned = True
                bar.total = total
                say(f"      {rate:.1f} steps/s: {total} steps planned for the "
                    f"{max_train_seconds:.0f} s budget")
            if step % val_every == 0 or step == total:
                validate()
            if step == total or time.perf_counter() - t_ck > checkpoint_seconds:
                checkpoint()
                t_ck = time.perf_counter()
            if max_train_seconds is not None and step < total and \
                    time.perf_counter() - t0 > max_train_seconds:
                checkpoint()
                say(f"      out of time at step {step} of {total}: rerun to resume")
                break
        bar.close()
        if stop_after is not None and stop_after <= step < total:
            say(f"      stopped after step {step} of {total} as asked (--stop-after-steps); "
                "rerun without it to continue")
        if not history or history[-1]["step"] != step:
            validate()
        checkpoint()
    return {"file": out / ENCODER_FILE, "history": history, "steps": step,
            "seconds": time.perf_counter() - t0}


def _preprocessing(config: PosePretrainConfig) -> dict:
    return {"crop": "square box around the target's projected mesh", "box_scale": BOX_SCALE,
            "mirror_left": True, "normalise": "x / 255 - 0.5 (RGB)",
            "image_sizes": list(config.image_sizes),
            "dataset": "InterSHTorchDataset(root, image_size=S, train=False) gives such crops"}


def _portable(config: PosePretrainConfig) -> dict:
    """The config as a weight file records it: a starting file by its name, not its path."""
    init = config.init if config.init in (None, "network") else Path(config.init).name
    return {**asdict(config), "init": init}


def _jsonable(d: dict) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


def build_pretrained_encoder(out: str | os.PathLike = "runs/pretrained_encoder",
                             config: PosePretrainConfig | None = None, *,
                             max_generate_seconds: float | None = None,
                             max_train_seconds: float | None = None,
                             stop_after: int | None = None, install: bool | str = False,
                             progress: bool = True, log=print, overwrite: bool = False,
                             scenes_from: str | os.PathLike | None = None) -> dict:
    """Make the pretrained encoder: scenes, crops, training, int8 file (``handmesh
    pretrain-encoder``). ``out`` is claimed first (``claim_pretraining_dir``: files it did not
    write refused unless ``overwrite``).

    ``out/data/train`` (seed ``data_seed``) and ``out/data/val`` (``data_seed + 1``) are generated
    as [`build_pretrained`][handmesh_tutorial.apps.pretrain_network.build_pretrained] does
    (time-bounded shards, kept on a rerun); their crops are cached in ``out/crops_*.pt``; training
    runs in
    ``out`` and resumes there. ``install=True`` (or ``"pretrained"``) copies the file into the
    package as the demo's encoder, ``install="neutral"`` as the decoder-neutral one
    ([`SHIPPED_ENCODERS`][handmesh_tutorial.nn.pose_encoder.SHIPPED_ENCODERS]).
    ``scenes_from``: another run's ``out`` whose scenes (and crops) are read in place, not
    generated (`scenes_of_run`; seeds and counts must be that run's).

    Returns:
        ``{"file", "history", "info"}``.
    """
    from .pretrain_network import _commit, _hardware, generate_train_val

    config = config or PosePretrainConfig()
    check_device(config.device, probe=True)  # a CUDA device asked for: before generating
    check_run_options(max_generate_seconds=max_generate_seconds,
                      max_train_seconds=max_train_seconds, stop_after=stop_after)
    if install:
        from ..nn.pose_encoder import SHIPPED_ENCODERS

        name = "pretrained" if install is True else str(install)
        if name not in SHIPPED_ENCODERS:
            raise ValueError(f"install must be one of {sorted(SHIPPED_ENCODERS)}, got {name!r}")
    from ..budget import check_workers

    check_workers(config.workers, "workers")  # the machine's bound: before any scene
    if config.init != "network":  # a missing or crafted file: in seconds, not after the scenes
        check_start_file(config.init, "encoder", "--init")
    say = log or (lambda *_: None)
    out = claim_pretraining_dir(out, "pretrain-encoder", overwrite)
    workers = config.workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    tr, val, t_gen = generate_train_val(
        out / "data", config.train_scenes, config.val_scenes, config.data_seed,
        render_size=config.render_size, workers=workers, max_generate_seconds=max_generate_seconds,
        progress=progress, log=log, scenes_from=scenes_from)
    caches = crop_caches(out, {"train": tr, "val": val}, scenes_from=scenes_from,
                         workers=max(0, workers - 1), progress=progress)
    t_crop = time.perf_counter() - t0 - t_gen
    dev = "cuda" if config.device == "auto" and torch.cuda.is_available() else config.device
    info = {"command": "handmesh pretrain-encoder", "recipe": _jsonable(_portable(config)),
            "max_generate_seconds": max_generate_seconds, "max_train_seconds": max_train_seconds,
            "stop_after": stop_after,
            "data": {"train_seed": config.data_seed, "train_scenes": tr["scenes"],
                     "val_seed": config.data_seed + 1, "val_scenes": val["scenes"],
                     "kinds": "mixed (hand-hand, hand-object, hand-chain)",
                     "render_size": config.render_size},
            "seconds": {"generate": round(t_gen, 1), "crop": round(t_crop, 1)},
            "hardware": _hardware(dev if dev != "auto" else "cpu"), "commit": _commit(),
            "torch": str(torch.__version__), "date": datetime.date.today().isoformat()}
    if config.init == "network":  # the chain of weights: what the start was made of
        from ..pretrained import pretrained_info

        info["init_from"] = {"weights": "the encoder of the shipped MSMR-Net",
                             "made_by": pretrained_info().get("pretrained")}
    elif config.init is not None:
        from ..nn.pose_encoder import read_pose_encoder

        info["init_from"] = read_pose_encoder(config.init)[1].get("pretrained")
        info["init_file"] = file_identity(config.init)  # by name and hash, not by path
    say(f"[2/3] training ({config.backbone}, batch {config.batch_size}, crops "
        f"{'/'.join(map(str, config.image_sizes))} px, init {config.init or 'random'}) in {out}")
    res = pretrain_pose_encoder(caches["train"], caches["val"], out, config,
                                max_train_seconds=max_train_seconds, stop_after=stop_after,
                                info=info,
                                progress=progress, log=log)
    write_json(out / "history.json", {"history": res["history"], "info": info})
    say(f"[3/3] exported {res['file']} ({res['file'].stat().st_size / 1e6:.1f} MB, int8)")
    if install:
        from .. import _version
        from ..nn.pose_encoder import SHIPPED_ENCODERS

        name = "pretrained" if install is True else str(install)
        if name not in SHIPPED_ENCODERS:
            raise ValueError(f"install must be one of {sorted(SHIPPED_ENCODERS)}, got {name!r}")
        target = _version.ASSET_DIR / SHIPPED_ENCODERS[name]
        atomic_write_bytes(target, res["file"].read_bytes(), True)
        say(f"      installed as {target}")
    return {"file": res["file"], "history": res["history"], "info": info}
