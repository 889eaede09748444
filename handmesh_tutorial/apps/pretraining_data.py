"""The scenes of a pretraining run (``handmesh pretrain``, ``handmesh pretrain-encoder``):
mixed-kind INTER-SH scenes generated within a time budget, as shards that a rerun keeps (options
of the one scene driver,
[`scenes.generate_interactions`][handmesh_tutorial.scenes.generate.generate_interactions]).

Used by [`build_pretrained`][handmesh_tutorial.apps.pretrain_network.build_pretrained] and
[`build_pretrained_encoder`][handmesh_tutorial.apps.pose_pretraining.build_pretrained_encoder];
docs pages "The pretrained model" and "Why the paper starts from pretrained weights".
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["crop_caches", "generate_training_scenes", "generate_train_val", "scenes_of_run"]

PRETRAINING_OUTPUTS = {
    "pretrain": ("data", "train", "msmr_net_pretrained.pt", "msmr_net_float16.pt"),
    "pretrain-encoder": ("data", "checkpoint.pt", "crops_train.pt", "crops_val.pt",
                         "history.json", "hand_encoder_pretrained.pt"),
}
"""What each pretraining command writes in its ``--out`` (the weight files are
``_version.PRETRAINED_FILE`` and ``nn.pose_encoder.ENCODER_FILE``; tested)."""

_DEVICE = re.compile(r"auto|cpu|cuda(:\d+)?|mps")


def check_device(device, *, probe: bool = False) -> str:
    """Check a training device name before any scene is generated (``--device``).

    Args:
        device: ``"auto"``, ``"cpu"``, ``"cuda"``, ``"cuda:N"`` or ``"mps"``.
        probe: also check that a CUDA device asked for exists (in a child process when torch is
            not imported yet: importing it here would make the scene generator's workers start
            by ``spawn`` instead of ``fork``).

    Returns:
        ``device``.

    Raises:
        ValueError: another name, or (``probe``) a CUDA device this machine does not have.
    """
    if not isinstance(device, str) or not _DEVICE.fullmatch(device):
        raise ValueError(f"device must be 'auto', 'cpu', 'cuda', 'cuda:N' or 'mps', got "
                         f"{device!r}")
    if probe and device.startswith("cuda"):
        code = "import torch; print(torch.cuda.device_count() if torch.cuda.is_available() else 0)"
        if "torch" in sys.modules:
            import torch

            count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        else:
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 timeout=600)
            count = int(out.stdout.strip() or 0) if out.returncode == 0 else 0
        want = int(device.split(":")[1]) if ":" in device else 0
        if want >= count:
            raise ValueError(f"device {device!r}: this machine has {count} CUDA device(s) "
                             "(torch.cuda.is_available() says so); use --device cpu or auto")
    return device


_READ_START = {
    "checkpoint": "from handmesh_tutorial.train.checkpoints import _read_checkpoint as read",
    "encoder": "from handmesh_tutorial.nn.pose_encoder import read_pose_encoder, "
               "encoder_source_path\nread = lambda p: read_pose_encoder(encoder_source_path(p))",
}


def check_start_file(path, kind: str, option: str) -> None:
    """Read a run's starting weights (``--init``, ``--init-encoder``) before any scene is
    generated, as training will, so that a missing or crafted file fails in seconds, not after
    hours of generation. Read in a child process when torch is not imported yet (importing it
    here would make the scene generator's workers start by ``spawn`` instead of ``fork``).

    Args:
        path: the file; ``None`` or a shipped name (``"pretrained"``, ``"neutral"``): nothing
            to check.
        kind: ``"checkpoint"`` (a network) or ``"encoder"`` (a pose-encoder file).
        option: the option, for the message (``"--init"``).

    Raises:
        FileNotFoundError: no such file (named).
        ValueError: the file cannot be read as ``kind`` (the reader's message, after the
            option's name).
    """
    if path is None or str(path) in ("pretrained", "neutral"):  # the shipped files: tested
        return
    code = _READ_START[kind] + "\nimport sys\ntry:\n    read(sys.argv[1])\n" \
        "except (FileNotFoundError, ValueError) as e:\n" \
        "    print(type(e).__name__, str(e).splitlines()[0] if str(e) else '', sep='\\n')\n" \
        "    sys.exit(3)\n"
    if "torch" in sys.modules:
        scope: dict = {}
        exec(_READ_START[kind], scope)  # noqa: S102 - one of two fixed import lines
        try:
            scope["read"](str(path))
        except (FileNotFoundError, ValueError) as err:
            raise type(err)(_named(option, path, str(err))) from None
        return
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                         text=True, timeout=600)
    if out.returncode == 3:
        name, _, message = out.stdout.partition("\n")
        error = FileNotFoundError if name == "FileNotFoundError" else ValueError
        raise error(_named(option, path, message))
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no message"])[-1]
        raise ValueError(f"{option} {path}: cannot be read ({last[:200]})")


def _named(option: str, path, message: str) -> str:
    """``"--init FILE: why"`` in one line (the file named once, if the reader named it)."""
    message = (message.strip().splitlines() or [""])[0]
    return f"{option} {message}" if message.startswith(str(path)) else \
        f"{option} {path}: {message}"


def check_run_options(*, max_generate_seconds=None, max_train_seconds=None,
                      stop_after=None) -> None:
    """The numbers of a pretraining command, checked before any scene (``None``: not set).

    Raises:
        ValueError: a budget that is not a finite number > 0 of seconds, or ``stop_after`` that
            is not a positive integer (steps); the message names the option.
    """
    for option, v in (("--max-generate-seconds", max_generate_seconds),
                      ("--max-train-seconds", max_train_seconds)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)
                              or not 0 < v < float("inf")):
            raise ValueError(f"{option} must be a finite number of seconds > 0, got {v!r}")
    if stop_after is not None and (isinstance(stop_after, bool) or not isinstance(stop_after, int)
                                   or stop_after < 1):
        raise ValueError(f"--stop-after-steps must be a positive integer (steps), got "
                         f"{stop_after!r}")


def claim_pretraining_dir(out: str | os.PathLike, command: str,
                          overwrite: bool = False) -> Path:
    """``_io.claim_out_dir`` for ``handmesh pretrain`` / ``pretrain-encoder`` (before any scene):
    a folder holding files the command did not write is refused unless ``overwrite``, a link
    where it writes always; a run folder of an older version (no marker) is recognised by its
    scenes' ``meta.json`` as the command's own (its scenes then resume if a version of
    ``data.schema.SAME_SAMPLES_SINCE`` or later wrote them, and are refused by name otherwise).

    Raises:
        ValueError, NotADirectoryError, FileExistsError, OSError: as ``claim_out_dir``.
    """
    from .._io import claim_out_dir, json_record

    def older(folder: Path) -> bool:
        return any(json_record(folder / "data" / split / "meta.json", "seed", "num_samples")
                   for split in ("val", "train"))

    return claim_out_dir(out, command, PRETRAINING_OUTPUTS[command], overwrite=overwrite,
                         recognise=older, hidden=(".pretrain.lock",))


def generate_training_scenes(root: str | os.PathLike, num: int, seed: int, *, render_size: int,
                             workers: int, max_seconds: float | None = None,
                             parts: int = 1, progress: bool = True, log=print) -> dict:
    """Generate up to ``num`` mixed-kind scenes into ``root``, within a time budget if given.

    A thin call of the one scene driver,
    [`scenes.generate_interactions`][handmesh_tutorial.scenes.generate.generate_interactions]
    (``kind="mixed"``): with ``max_seconds``, the set is made as ``parts`` shards merged into
    ``root``, and a rerun keeps the root that the first run made.

    Returns:
        ``{"root": Path, "scenes": int, "seconds": float, "shards": int}``.
    """
    from ..scenes import generate_interactions

    say = log or (lambda *_: None)
    sharded = max_seconds is not None and parts > 1
    kept = sharded and (Path(root) / "meta.json").exists()
    s = generate_interactions(root, "mixed", num, seed, image_size=render_size, workers=workers,
                              progress=progress, parts=parts if sharded else 1,
                              max_seconds=max_seconds if sharded else None)
    scenes = s.written + s.skipped
    if kept and s.written == 0:
        say(f"      reusing the {scenes} scenes ({s.shards} of {parts} shards) that an earlier "
            f"run left in {root}")
    elif sharded and s.shards < parts:
        say(f"      stopped after {s.shards} of {parts} shards: {s.seconds:.0f} s spent, the "
            f"next would have ended past the {max_seconds:.0f} s budget")
    return {"root": Path(root), "scenes": scenes, "seconds": s.seconds, "shards": s.shards}


def generate_train_val(data: str | os.PathLike, train_scenes: int, val_scenes: int,
                       data_seed: int, *, render_size: int, workers: int = 0,
                       max_generate_seconds: float | None = None, progress: bool = True,
                       log=print, scenes_from: str | os.PathLike | None = None,
                       ) -> tuple[dict, dict, float]:
    """The scenes of a pretraining run: ``data/val`` (seed ``data_seed + 1``) in full, then
    ``data/train`` (seed ``data_seed``) in ten time-bounded shards when a budget is given
    ([`generate_training_scenes`][handmesh_tutorial.apps.pretrain_network.generate_training_scenes]).

    Args:
        workers: generator processes (0: one per CPU).
        scenes_from: another run's ``out``: its scenes are read in place instead (`scenes_of_run`,
            ``--scenes-from``; nothing generated or written, 0 seconds).

    Returns:
        ``(train, val, seconds)``: the two results of ``generate_training_scenes`` and the time.
    """
    say = log or (lambda *_: None)
    if scenes_from is not None:  # a later stage of a chain: the scenes of the run before
        tr, val = scenes_of_run(scenes_from, train_scenes, val_scenes, data_seed,
                                render_size=render_size)
        say(f"[1/3] {tr['scenes']} training and {val['scenes']} validation scenes of "
            f"{Path(scenes_from).name}, read in place")
        return tr, val, 0.0
    data = Path(data)
    workers = workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    say(f"[1/3] generating up to {train_scenes} training and {val_scenes} validation scenes "
        f"({render_size} px, {workers} workers) in {data}")
    val = generate_training_scenes(data / "val", val_scenes, data_seed + 1,
                                   render_size=render_size, workers=workers, progress=progress,
                                   log=log)
    budget = None if max_generate_seconds is None else max_generate_seconds - val["seconds"]
    if budget is not None:  # the validation scenes may have taken it all: cut at once
        budget = max(0.0, budget)
    parts = min(10, train_scenes) if budget is not None else 1  # a shard holds a scene at least
    tr = generate_training_scenes(data / "train", train_scenes, data_seed,
                                  render_size=render_size, workers=workers, max_seconds=budget,
                                  parts=parts, progress=progress, log=log)
    t_gen = time.perf_counter() - t0
    say(f"      {tr['scenes']} training + {val['scenes']} validation scenes in {t_gen:.0f} s")
    return tr, val, t_gen


def scenes_of_run(folder: str | os.PathLike, train_scenes: int, val_scenes: int,
                  data_seed: int, *, render_size: int) -> tuple[dict, dict]:
    """The scenes another pretraining run generated (its ``data/train`` and ``data/val``), read
    in place: what ``generate_train_val`` returns, nothing written (``--scenes-from``).

    A later stage of a chain (``handmesh pretrain-encoder --init <file> --scenes-from <run>``)
    trains on the scenes of the stage before it without generating them again.

    Returns:
        ``(train, val)``: ``{"root", "scenes", "seconds": 0.0, "shards"}`` each.

    Raises:
        FileNotFoundError: a split or its ``meta.json`` is missing (named).
        ValueError: the split was made with another seed, count or image size, or samples of
            the planned set are missing (named, with what was asked).
    """
    from ..data.reader import _planned, _present, read_meta

    folder = Path(folder)
    got = []
    for split, seed, num in (("train", data_seed, train_scenes),
                             ("val", data_seed + 1, val_scenes)):
        root = folder / "data" / split
        if not (root / "meta.json").is_file():
            raise FileNotFoundError(f"{root / 'meta.json'}: no scenes of a pretraining run "
                                    "there (--scenes-from names a run's --out folder)")
        meta = read_meta(root)
        asked = {"seed": seed, "num_samples": num, "image_size": [render_size, render_size]}
        wrong = {k: meta.get(k) for k, v in asked.items() if meta.get(k) != v}
        if wrong:
            raise ValueError(f"{root / 'meta.json'}: {wrong} on disk, but this run asks for "
                             f"{ {k: asked[k] for k in wrong} } (--data-seed, --train-scenes, "
                             "--val-scenes, --render-size must be the other run's)")
        present = set(_present(root / "samples", meta["index_width"]))
        absent = [i for i in _planned(meta) if i not in present]
        if absent:
            raise ValueError(f"{root}: {len(absent)} of its planned samples are missing (first "
                             f"{absent[:5]}): finish that run's generation first")
        got.append({"root": root, "scenes": len(present & set(_planned(meta))), "seconds": 0.0,
                    "shards": len(meta.get("shards", [])) or 1})
    return got[0], got[1]


def crop_caches(out: Path, splits: dict, *, scenes_from: str | os.PathLike | None = None,
                workers: int = 0, progress: bool = True) -> dict:
    """The crops of each split (``{"train": scenes, "val": scenes}`` as `generate_train_val`
    returns them): ``out/crops_<split>.pt`` when it holds as many crops as the split has scenes,
    else the other run's (``scenes_from``, read only) when it does, else cropped now and saved in
    ``out``. A file read is checked as any untrusted input (`check_crop_cache`; a link in its
    place is refused).

    Returns:
        ``{"train": cache, "val": cache}`` (``data.batched_crops.crop_cache`` dicts).

    Raises:
        ValueError: a ``crops_<split>.pt`` that is a link, unreadable, or no crop cache of
            ``CACHE_SIZE`` crops with finite, plausible values (named, with what is wrong).
    """
    import torch

    from .._io import atomic_write_with
    from .._untrusted import load_torch_file
    from ..data.batched_crops import check_crop_cache, crop_cache
    from ..data.files import _own_file

    caches = {}
    for split, scenes in splits.items():
        places = [out] + ([Path(scenes_from)] if scenes_from is not None else [])
        for place in places:
            path = place / f"crops_{split}.pt"
            if os.path.lexists(path):  # read as any untrusted file: no link, checked contents
                cache = check_crop_cache(load_torch_file(_own_file(path)), str(path))
                if len(cache["image"]) == scenes["scenes"]:
                    caches[split] = cache
                    break
        else:
            caches[split] = crop_cache(scenes["root"], workers=workers, progress=progress)
            atomic_write_with(out / f"crops_{split}.pt",
                              lambda fh, c=caches[split]: torch.save(c, fh))
    return caches
