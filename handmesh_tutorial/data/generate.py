"""The generation driver: ``generate_dataset`` (resumable, sharded, parallel, within a time
budget) and its summary.

The driver knows nothing about hands or rendering: it calls ``make_sample(sample_seed) -> dict``.
[`synthetic_sample`][handmesh_tutorial.testing.synthetic_sample] is a tiny stand-in (two spheres
ray-cast with numpy) for tests and demos;
[`scenes.generate_interactions`][handmesh_tutorial.scenes.generate.generate_interactions] passes
the INTER-SH generator.
Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..budget import check_workers
from .candidates import _probe, _probe_summary, _Task
from .files import read_annotation
from .reader import _disagreements, _planned, _present, read_meta
from .root import (
    _check_root,
    _check_shards_folder,
    _coalesce,
    _diff_message,
    _lock,
    _meta_diff,
    _open_root,
    _remove_shards,
    merge_shards,
)
from .schema import (
    _LOCK_FILE,
    FORMAT_NAME,
    FORMAT_VERSION,
    KINDS,
    MAX_LABEL,
    MAX_SAMPLES,
    META_FILE,
    SAMPLES_DIR,
    _sample_index,
)
from .seeds import _SEED_RULE, index_width, sample_seed, shard_range, vr_bins, vr_histogram
from .workers import _callable_name, _check_for_workers, _Pool, _run, _start_method, _worker_probe

__all__ = ["GenerationSummary", "generate_dataset"]


def _fmt_bin(b: Sequence[float]) -> str:
    return f"[{b[0]:.2f}, {b[1]:.2f}{']' if b[1] >= 1 else ')'}"


@dataclass
class GenerationSummary:
    """What [`generate_dataset`][handmesh_tutorial.data.generate.generate_dataset] did
    (``str(summary)`` is a short report).

    Attributes:
        root: dataset folder.
        indices: (start, stop) global index ranges of this run's shard.
        written: samples written by this call.
        skipped: samples already on disk (a resumed run).
        attempts: ``make_sample`` calls of this call (> written when candidates were rejected).
        stale_removed: temporary folders of a killed run that were removed.
        seconds: wall time of this call.
        vr_bins: the VR bins of the histogram.
        vr_histogram: target-hand VR counts per bin over all samples of the shard on disk.
        vr_outside: samples whose target VR is in no bin.
        vr_probe: with VR balancing, the probe (``candidates``, ``hits`` per bin, ``outside``,
            ``rejected``, ``filled``: the bin indices balancing fills), else ``None``.
        off_bin: balanced samples of this call written outside their bin (no candidate of
            ``max_attempts`` reached it: the nearest one was kept).
        probe_attempts: ``make_sample`` calls of the probe in this call (0 when reused from
            ``meta.json``).
        shards: shards the root was made of when generated in ``parts`` (a time budget may stop
            before the last); 1 otherwise.
    """

    root: str
    indices: list[list[int]]
    written: int
    skipped: int
    attempts: int
    stale_removed: int
    seconds: float
    vr_bins: list[tuple[float, float]]
    vr_histogram: list[int]
    vr_outside: int
    vr_probe: dict | None = None
    off_bin: int = 0
    probe_attempts: int = 0
    shards: int = 1

    @property
    def vr_unreachable(self) -> list[tuple[float, float]]:
        """Bins that VR balancing left out because its probe (almost) never reached them."""
        if not self.vr_probe:
            return []
        return [b for k, b in enumerate(self.vr_bins) if k not in self.vr_probe["filled"]]

    @property
    def samples_per_second(self) -> float:
        """Samples written per second of wall time in this call."""
        return self.written / self.seconds if self.seconds > 0 else float("nan")

    def __str__(self) -> str:
        hist = ", ".join(f"[{lo:.2f}, {hi:.2f}{']' if hi >= 1 else ')'}: {n}" for (lo, hi), n
                         in zip(self.vr_bins, self.vr_histogram, strict=True))
        # lines of at most about 100 characters: they are printed in notebooks and logs
        text = (f"{self.root}: wrote {self.written}, skipped {self.skipped} already present "
                f"(indices {self.indices})\n  {self.attempts} make_sample calls, "
                f"{self.samples_per_second:.2f} samples/s, {self.stale_removed} stale temp "
                f"removed\ntarget VR histogram: {hist}\n  outside bins: {self.vr_outside}")
        if self.vr_probe:
            gone = ", ".join(_fmt_bin(b) for b in self.vr_unreachable) or "none"
            text += (f"\nVR balancing: bins left out (reached by fewer than "
                     f"{self.vr_probe['min_hits']} of {self.vr_probe['candidates']} probe "
                     f"candidates): {gone}\n  samples written outside their bin: {self.off_bin}")
        return text


def generate_dataset(
    root: str | os.PathLike,
    make_sample: Callable[[int], Mapping],
    num: int,
    seed: int,
    kind: str | Sequence[str],
    *,
    shard: tuple[int, int] | None = None,
    workers: int = 1,
    progress: bool = True,
    params: Mapping | None = None,
    image_size: int | tuple[int, int] | None = None,
    accept: Callable[[dict], bool] | None = None,
    balance_vr: bool | Sequence = False,
    max_attempts: int = 100,
    vr_probe: int = 64,
    worker_init: Callable[[], Any] | None = None,
    durable: bool = True,
    mp_context: str = "auto",
    parts: int = 1,
    max_seconds: float | None = None,
) -> GenerationSummary:
    """Generate (or resume generating) an INTER-SH root.

    Sample ``i`` is ``make_sample(sample_seed(seed, i, attempt))`` for the first ``attempt`` whose
    candidate is accepted, written to ``root/samples/<i>/`` atomically. Its bytes depend only on
    ``(seed, i)``: not on ``workers``, ``shard``, order, or interruptions. Re-running the same call
    after a crash or Ctrl-C skips the samples on disk and removes stale temporary folders.

    Args:
        root: output folder (created).
        make_sample: ``make_sample(sample_seed) -> dict``, a sample as described in
            [`InterSHDataset`][handmesh_tutorial.data.reader.InterSHDataset] (without
            ``index``/``seed``). Must be deterministic in its seed and, for ``workers > 1``,
            importable by the worker processes (a function of a module, or a ``functools.partial``
            of one; not one defined in a notebook cell).
        num: number of samples of the whole dataset (all shards), at most
            [`MAX_SAMPLES`][handmesh_tutorial.data.schema.MAX_SAMPLES].
        seed: base seed, non-negative.
        kind: the kind(s) of scene ``make_sample`` produces (see ``KINDS``).
        shard: ``(shard_index, num_shards)``: make only
            [`shard_range`][handmesh_tutorial.data.seeds.shard_range] of it (one machine's part;
            join parts with [`merge_shards`][handmesh_tutorial.data.root.merge_shards]). ``None``
            = all.
        workers: processes; each makes and writes its own samples.
        progress: show a tqdm bar.
        params: free-form JSON-able creation parameters (renderer, light, object set...),
            stored in ``meta.json`` and compared on resume.
        image_size: expected image size (int side or (H, W)); checked per sample if given.
        accept: optional filter ``accept(sample) -> bool``; a rejected candidate is replaced by the
            next attempt's seed. A ``make_sample`` that raises
            [`SampleRejected`][handmesh_tutorial.data.candidates.SampleRejected] rejects its seed
            the same way.
        balance_vr: ``True`` (bins from [`vr_bins`][handmesh_tutorial.data.seeds.vr_bins]) or a
            list of bins: the target VRs are spread evenly over the bins that ``make_sample`` can
            reach. First a *probe* makes ``vr_probe`` candidates (seeds
            [`probe_seed`][handmesh_tutorial.data.seeds.probe_seed], not samples; in the
            workers when ``workers > 1``, in this process otherwise) and counts
            their target VRs per bin; bins it hits fewer than
            [`PROBE_MIN_HITS`][handmesh_tutorial.data.candidates.PROBE_MIN_HITS] times (e.g.
            [0.40, 0.60) for hand-chain scenes, whose thin rings rarely hide half a hand) are
            reported at once (a ``UserWarning``) and left out. Sample ``i`` then wants bin
            ``filled[i % len(filled)]``; if none of its ``max_attempts`` candidates lands there, the
            accepted candidate nearest to the bin is written (counted in ``off_bin``): balancing
            never stops a run. The probe is stored in ``meta.json`` (``vr_probe``) and reused on
            resume; it is deterministic in ``seed``, so shards agree.
        max_attempts: candidates per sample; RuntimeError when none is accepted (every seed
            rejected by ``make_sample`` or ``accept``).
        vr_probe: candidates of the VR probe (only with ``balance_vr``), >= 1.
        worker_init: called once in each worker process (and once in-process when
            ``workers == 1``) before any ``make_sample``, e.g. to create a renderer.
        durable: fsync every file and folder (safe against power cuts, slower).
        mp_context: multiprocessing start method of the worker pool: ``"auto"`` forks on Linux
            when it is safe (this process has opened no OpenGL context, not imported torch and
            runs no other threads: ``handmesh generate``, the demo) and spawns otherwise (a
            Jupyter kernel, a process that rendered or trained before); ``"spawn"`` is always
            safe with OpenGL and torch, but each worker imports everything again (seconds;
            docs page "Performance").
            The bytes written are the same either way. A ``make_sample`` defined in a notebook
            needs ``"fork"``.
        parts: make the set as this many shards (``shard=(k, parts)``, in
            ``.<root name>-shards/`` beside ``root``), then hard-link them into ``root``
            ([`merge_shards`][handmesh_tutorial.data.root.merge_shards]): the same files as one
            run. That folder must hold nothing but these shards (a link there, or another
            entry, is refused before anything is written); after the merge only the shards'
            own files are deleted. With a time budget, a set cut short is still a valid root
            of the scenes it has. A rerun after the merge keeps the root as it is (a budget
            decides how many shards a run makes, so a rerun under another budget could not
            merge with the first).
        max_seconds: time budget of a run in ``parts``: no new shard starts when the mean
            time of the shards so far would end it past the budget (the first always runs).
            ``None``: all parts.

    Returns:
        A [`GenerationSummary`][handmesh_tutorial.data.generate.GenerationSummary].

    Raises:
        ValueError: bad arguments, or ``root`` holds a dataset made with different parameters
            (the message lists the differing ``meta.json`` keys), or a root made in parts has
            lost samples.
        RuntimeError: no candidate accepted within ``max_attempts``, or another process is
            writing into ``root``.
    """
    from .. import __version__

    t0 = time.perf_counter()
    kinds = (kind,) if isinstance(kind, str) else tuple(kind)
    if not kinds or any(k not in KINDS for k in kinds):
        raise ValueError(f"kind must be one of {KINDS} (or a list of them), got {kind!r}")
    if isinstance(num, bool) or not isinstance(num, int) or not 1 <= num <= MAX_SAMPLES:
        raise ValueError(f"num must be an integer in [1, {MAX_SAMPLES:,}] (MAX_SAMPLES: the "
                         f"most samples a meta.json may declare), got {num!r}")
    sample_seed(seed, 0)  # validates seed
    if workers < 1 or max_attempts < 1 or vr_probe < 1:
        raise ValueError(f"workers, max_attempts and vr_probe must be >= 1, got {workers}, "
                         f"{max_attempts}, {vr_probe}")
    check_workers(workers, "workers", low=1)  # each a process: bounded by the cores
    if isinstance(parts, bool) or not isinstance(parts, int) or not 1 <= parts <= num:
        raise ValueError(f"parts must be an integer in [1, num={num}], got {parts!r}")
    if max_seconds is not None and (parts == 1 or not max_seconds >= 0):
        raise ValueError(f"max_seconds must be None or a number >= 0 with parts > 1 (a run is "
                         f"cut between shards), got {max_seconds!r} with parts={parts}")
    if parts > 1 and shard is not None:
        raise ValueError(f"shard and parts exclude each other, got shard={shard}, parts={parts}")
    k, n = shard if shard is not None else (0, 1)
    indices = shard_range(num, k, n)
    if isinstance(image_size, int):
        image_size = (image_size, image_size)
    bins = vr_bins(None if balance_vr is True or balance_vr is False else balance_vr)
    try:
        params = json.loads(json.dumps(dict(params or {}), allow_nan=False, sort_keys=True))
    except (TypeError, ValueError) as e:
        raise ValueError(f"params must be JSON-serialisable: {e}") from e
    _start_method(mp_context)  # validates
    if workers > 1:
        _check_for_workers((make_sample, accept, worker_init), mp_context)
    width = index_width(num)
    meta = {
        "format": FORMAT_NAME, "format_version": FORMAT_VERSION, "generator_version": __version__,
        "kinds": sorted(kinds), "seed": int(seed), "num_samples": num,
        "image_size": list(image_size) if image_size is not None else None,
        "camera": {"convention": "OpenCV", "axes": "x right, y down, z forward",
                   "units": "metres", "intrinsics": "K per sample in annotation.npz, pixels"},
        "labels": {"background": 0, "bodies": f"1..{MAX_LABEL}, per sample; names, sides, "
                   "target in annotation.json", "scene_mask_png": "8-bit if all labels <= 255, "
                   "else 16-bit", "alone_png": "1-bit"},
        "vr_bins": [list(b) for b in bins], "balance_vr": bool(balance_vr),
        "make_sample": _callable_name(make_sample), "accept": _callable_name(accept),
        "seed_rule": _SEED_RULE, "index_width": width, "params": params,
        "shards": [[k, n]], "ranges": _coalesce([[indices.start, indices.stop]]),
    }
    root = Path(root)
    if parts > 1:
        def one(k: int) -> GenerationSummary:
            return generate_dataset(
                _shards_folder(root) / f"{k:04d}", make_sample, num, seed, kinds,
                shard=(k, parts), workers=workers, progress=progress, params=params,
                image_size=image_size, accept=accept, balance_vr=balance_vr,
                max_attempts=max_attempts, vr_probe=vr_probe, worker_init=worker_init,
                durable=durable, mp_context=mp_context)

        return _generate_in_parts(root, meta, one, parts, max_seconds, bins, durable, t0)
    root.mkdir(parents=True, exist_ok=True)
    task = _Task(make_sample, accept, int(seed), kinds, bins if balance_vr else None,
                 tuple(image_size) if image_size else None, int(max_attempts),
                 str(root / SAMPLES_DIR), width, durable)
    probe, probe_calls, pool = None, 0, None
    new_lock = not os.path.lexists(root / _LOCK_FILE)
    with _lock(root), contextlib.ExitStack() as stack:
        try:  # before the probe: a folder that is not this set's is refused, left as it was
            _check_root(root, meta)
        except ValueError:
            if new_lock:
                (root / _LOCK_FILE).unlink(missing_ok=True)
            raise
        if balance_vr:
            old = read_meta(root) if (root / META_FILE).exists() else {}
            probe = old.get("vr_probe")
            if not (isinstance(probe, dict) and probe.get("candidates") == vr_probe):
                if workers > 1 and vr_probe > 1:
                    # the probe's candidates in the workers, which then make the samples: this
                    # process renders nothing, so the pool can fork (mp_context="auto")
                    # no more workers than there is work: the candidates, then the samples
                    pool = _Pool(task, min(workers, max(vr_probe, len(indices))), worker_init,
                                 mp_context)
                    stack.callback(pool.close)
                    outcomes: list = []
                    pool.map(_worker_probe, [(k,) for k in range(vr_probe)], outcomes.append)
                    probe = _probe_summary(task, outcomes)
                else:
                    if worker_init is not None:
                        worker_init()  # the probe runs in this process
                    probe = _probe(task, vr_probe)
                probe_calls = vr_probe
            task.filled = tuple(probe["filled"])
            meta["vr_probe"] = probe
            gone = [bins[b] for b in range(len(bins)) if b not in probe["filled"]]
            if gone:
                how = ("no bin is reachable: the samples are not balanced" if not probe["filled"]
                       else "the other bins share the samples evenly")
                warnings.warn(f"VR balancing: {len(gone)} of {len(bins)} bins reached by fewer "
                              f"than {probe['min_hits']} of {vr_probe} probe candidates (hits "
                              f"per bin {probe['hits']}, "
                              f"outside all bins {probe['outside']}, rejected "
                              f"{probe['rejected']}): {', '.join(_fmt_bin(b) for b in gone)} "
                              f"left out; {how}", UserWarning, stacklevel=2)
        stale = _open_root(root, meta)
        samples_dir = root / SAMPLES_DIR
        done_vr: dict[int, float] = {}
        for i in _present(samples_dir, width):
            if i not in indices:
                continue
            d = samples_dir / f"{i:0{width}d}"
            ann = read_annotation(d)
            why = [w for _, w in _disagreements(ann, d, meta)]
            if ann.get("index") != i or ann.get("seed") != sample_seed(seed, i,
                                                                        ann.get("attempt") or 0):
                why.insert(0, f"{d / 'annotation.json'}: index/seed {ann.get('index')}/"
                              f"{ann.get('seed')} do not match this dataset (seed {seed})")
            if why:  # a sample of another set (kind, image size, seed): never counted as done
                raise ValueError(f"{why[0]}; remove the folder or use another root")
            done_vr[i] = float(ann["vr"][ann["target"]])
        # a link where a planned sample folder belongs: no sample (the reader rule), never
        # written through (a file there stops the rename, named: NotADirectoryError)
        blocked = sorted(p.name for p in samples_dir.iterdir()
                         if (i := _sample_index(p.name, width)) is not None and i in indices
                         and p.is_symlink())
        if blocked:
            raise ValueError(f"{samples_dir}: {', '.join(blocked[:5])} "
                             f"{'is a link' if len(blocked) == 1 else 'are links'} where a "
                             "sample folder belongs (not the generator's): `handmesh verify "
                             "--remove-bad` unlinks them, then rerun")
        skipped = len(done_vr)
        todo = [i for i in indices if i not in done_vr]
        results = _run(task, todo, workers, worker_init, progress, len(indices), skipped,
                       mp_context, f"INTER-SH {'/'.join(kinds)}",
                       initialised=probe_calls > 0 and pool is None, pool=pool)
    for r in results:
        done_vr[r["index"]] = r["target_vr"]
    hist = vr_histogram(list(done_vr.values()), bins)
    outside = len(done_vr) - sum(hist)
    return GenerationSummary(str(root), meta["ranges"], len(results), skipped,
                             sum(r["attempts"] for r in results), stale,
                             time.perf_counter() - t0, list(bins), hist, outside, probe,
                             sum(r["off_bin"] for r in results), probe_calls)


def _shards_folder(root: Path) -> Path:
    """Where a run in ``parts`` keeps its shards until they are merged into ``root``."""
    return root.parent / f".{root.name}-shards"


def _generate_in_parts(root: Path, meta: dict, one: Callable[[int], GenerationSummary],
                       parts: int, max_seconds: float | None, bins, durable: bool,
                       t0: float) -> GenerationSummary:
    """``generate_dataset(parts=...)``: the shards that fit the budget, merged into ``root``."""
    if (root / META_FILE).exists() and not os.path.lexists(_shards_folder(root)):
        return _kept_parts(root, meta, parts, bins, t0)
    _check_shards_folder(_shards_folder(root))  # no link, nothing but shard roots
    made: list[GenerationSummary] = []
    for k in range(parts):
        spent = time.perf_counter() - t0
        if k and max_seconds is not None and spent + spent / k > max_seconds:
            break
        made.append(one(k))
    merge_shards([s.root for s in made], root, link=True, progress=False, durable=durable)
    left = _remove_shards(_shards_folder(root))  # only the shards' own files
    if left:
        warnings.warn(f"{_shards_folder(root)}: left {', '.join(left[:8])} (not written by this "
                      f"run); the merged set in {root} is complete", UserWarning, stacklevel=3)
    hist = [sum(h) for h in zip(*(s.vr_histogram for s in made), strict=True)]
    return GenerationSummary(
        str(root), read_meta(root)["ranges"], sum(s.written for s in made),
        sum(s.skipped for s in made), sum(s.attempts for s in made),
        sum(s.stale_removed for s in made), time.perf_counter() - t0, list(bins), hist,
        sum(s.vr_outside for s in made), made[0].vr_probe, sum(s.off_bin for s in made),
        sum(s.probe_attempts for s in made), len(made))


def _kept_parts(root: Path, meta: dict, parts: int, bins, t0: float) -> GenerationSummary:
    """The root that an earlier run in ``parts`` left: checked against this call, kept as is."""
    old = read_meta(root)
    keys = _meta_diff(old, meta, ignore=("shards", "ranges", "vr_probe"))
    if keys:
        raise ValueError(_diff_message(root / META_FILE, old, meta, keys) + "\nuse another "
                         "root, or delete the folder to generate anew")
    samples, width = root / SAMPLES_DIR, old["index_width"]
    present = set(_present(samples, width))
    planned = _planned(old)
    absent = [i for i in planned if i not in present]
    if absent:
        raise ValueError(f"{root}: {len(absent)} of its {len(planned)} samples are missing "
                         f"(first {absent[:5]}); delete the folder to generate anew")
    vrs = []
    for i in planned:
        ann = read_annotation(samples / f"{i:0{width}d}")
        vrs.append(float(ann["vr"][ann["target"]]))
    hist = vr_histogram(vrs, bins)
    return GenerationSummary(str(root), old["ranges"], 0, len(planned), 0, 0,
                             time.perf_counter() - t0, list(bins), hist, len(vrs) - sum(hist),
                             old.get("vr_probe"), 0, 0,
                             round(len(planned) * parts / old["num_samples"]))
