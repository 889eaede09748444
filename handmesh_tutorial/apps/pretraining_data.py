"""The scenes of a pretraining run (``handmesh pretrain``, ``handmesh pretrain-encoder``):
mixed-kind INTER-SH scenes generated within a time budget, as shards that a rerun keeps.

Used by [`build_pretrained`][handmesh_tutorial.apps.pretrain_network.build_pretrained] and
[`build_pretrained_encoder`][handmesh_tutorial.apps.pose_pretraining.build_pretrained_encoder];
docs pages "The pretrained model" and "Why the paper starts from pretrained weights".
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

__all__ = ["generate_training_scenes", "generate_train_val"]


def generate_training_scenes(root: str | os.PathLike, num: int, seed: int, *, render_size: int,
                             workers: int, max_seconds: float | None = None,
                             parts: int = 1, progress: bool = True, log=print) -> dict:
    """Generate up to ``num`` mixed-kind scenes into ``root``, within a time budget if given.

    With ``max_seconds``, the set is made as ``parts`` shards
    ([`generate_dataset`][handmesh_tutorial.data.generate.generate_dataset] ``shard=(k,
    parts)``) and no new shard is started when the mean time of the shards so far would overrun
    the budget; the shards made are hard-linked into ``root`` (``merge_shards``), so a set cut
    short is still a valid root of the scenes it has (``meta.json`` ranges list them).

    Returns:
        ``{"root": Path, "scenes": int, "seconds": float, "shards": int}``.
    """
    from ..data import InterSHDataset, merge_shards
    from .demo.run import generate_scenes

    root = Path(root)
    t0 = time.perf_counter()
    say = log or (lambda *_: None)
    if max_seconds is None or parts <= 1:
        generate_scenes(root, num, seed, render_size=render_size, workers=workers,
                        progress=progress)
        return {"root": root, "scenes": len(InterSHDataset(root)),
                "seconds": time.perf_counter() - t0, "shards": 1}
    unmerged = root.parent / f".{root.name}-shards"  # there until the shards are merged
    if (root / "meta.json").exists() and not unmerged.exists():
        # a rerun of the same build: keep the shards the first run made
        return _reuse_sharded_root(root, num, seed, render_size, parts, t0, say)
    shard_roots = []
    for k in range(parts):
        spent = time.perf_counter() - t0
        if k and spent + spent / k > max_seconds:
            say(f"      stopping after {k} of {parts} shards: {spent:.0f} s spent, the next "
                f"would end past the {max_seconds:.0f} s budget")
            break
        r = unmerged / f"{k:04d}"
        generate_scenes(r, num, seed, render_size=render_size, workers=workers,
                        progress=progress, shard=(k, parts))
        shard_roots.append(r)
    merge_shards(shard_roots, root, link=True, progress=False, durable=False)
    shutil.rmtree(unmerged)
    return {"root": root, "scenes": len(InterSHDataset(root)),
            "seconds": time.perf_counter() - t0, "shards": len(shard_roots)}


def generate_train_val(data: str | os.PathLike, train_scenes: int, val_scenes: int,
                       data_seed: int, *, render_size: int, workers: int = 0,
                       max_generate_seconds: float | None = None, progress: bool = True,
                       log=print) -> tuple[dict, dict, float]:
    """The scenes of a pretraining run: ``data/val`` (seed ``data_seed + 1``) in full, then
    ``data/train`` (seed ``data_seed``) in ten time-bounded shards when a budget is given
    ([`generate_training_scenes`][handmesh_tutorial.apps.pretrain_network.generate_training_scenes]).

    Args:
        workers: generator processes (0: one per CPU).

    Returns:
        ``(train, val, seconds)``: the two results of ``generate_training_scenes`` and the time.
    """
    say = log or (lambda *_: None)
    data = Path(data)
    workers = workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    say(f"[1/3] generating up to {train_scenes} training and {val_scenes} validation scenes "
        f"({render_size} px, {workers} workers) in {data}")
    val = generate_training_scenes(data / "val", val_scenes, data_seed + 1,
                                   render_size=render_size, workers=workers, progress=progress,
                                   log=log)
    budget = None if max_generate_seconds is None else max_generate_seconds - val["seconds"]
    tr = generate_training_scenes(data / "train", train_scenes, data_seed,
                                  render_size=render_size, workers=workers, max_seconds=budget,
                                  parts=10 if budget else 1, progress=progress, log=log)
    t_gen = time.perf_counter() - t0
    say(f"      {tr['scenes']} training + {val['scenes']} validation scenes in {t_gen:.0f} s")
    return tr, val, t_gen


def _reuse_sharded_root(root: Path, num: int, seed: int, render_size: int, parts: int,
                        t0: float, say) -> dict:
    """The scenes that an earlier run of the same time-bounded generation left in ``root``.

    A time budget decides how many shards a run makes, so a rerun with another budget (or on a
    faster machine) would make a different number and could not merge with the first; the first
    run's shards are kept instead and training resumes on them.
    """
    from ..data import InterSHDataset, read_meta

    meta = read_meta(root)
    want = {"seed": seed, "num_samples": num}
    if meta.get("image_size") is not None:  # the generator's scenes record it
        want["image_size"] = [render_size, render_size]
    differ = {k: (meta.get(k), v) for k, v in want.items() if meta.get(k) != v}
    if differ:
        raise ValueError(
            f"{root / 'meta.json'}: these scenes are not this build's (on disk, asked): {differ}; "
            "use another --out, or delete the folder to generate anew")
    ds = InterSHDataset(root)
    if ds.missing:
        raise ValueError(f"{root}: {len(ds.missing)} of its scenes are missing; delete the "
                         "folder to generate anew")
    shards = round(len(ds) * parts / num)
    say(f"      reusing the {len(ds)} scenes ({shards} of {parts} shards) that an earlier run "
        f"left in {root}")
    return {"root": root, "scenes": len(ds), "seconds": time.perf_counter() - t0,
            "shards": shards}
