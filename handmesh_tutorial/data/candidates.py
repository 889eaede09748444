"""Making one sample: candidates from successive seeds, acceptance, and VR balancing.

Sample ``i`` is the first accepted candidate ``make_sample(sample_seed(seed, i, attempt))``; with
VR balancing it must also land in its bin (the bins a probe of
[`PROBE_MIN_HITS`][handmesh_tutorial.data.candidates.PROBE_MIN_HITS] hits can fill). This is
the work of one sample, done in the main process or in a worker
([`workers`][handmesh_tutorial.data.workers]). Taught in notebook 05 ("Rendering and the
visibility ratio").
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from ..visibility import vr_bin
from .files import _encode, _write_folder
from .schema import _canonical
from .seeds import _SEED_RULE, probe_seed, sample_seed

__all__ = ["SampleRejected"]

PROBE_MIN_HITS = 2
"""A bin is filled by VR balancing when at least this many probe candidates hit it: one lucky
hit would keep a bin reachable once in a hundred candidates, whose samples would then mostly end up
off their bin after ``max_attempts`` candidates each.
"""


class SampleRejected(Exception):
    """Raised by a ``make_sample`` callable for a seed that yields no valid sample.

    [`generate_dataset`][handmesh_tutorial.data.generate.generate_dataset] treats it as a
    rejected candidate (like ``accept`` returning ``False``): it tries the next attempt's seed
    instead of stopping. Any other exception stops generation.
    [`handmesh_tutorial.scenes.InteractionError`][handmesh_tutorial.scenes.InteractionError] (a
    scene the generator cannot build within its bounded retries) is one.
    """



@dataclass
class _Task:
    """What a worker needs to make and write samples (pickled once per worker)."""

    make_sample: Callable[[int], Mapping]
    accept: Callable[[dict], bool] | None
    seed: int
    kinds: tuple[str, ...]
    bins: tuple[tuple[float, float], ...] | None
    image_size: tuple[int, int] | None
    max_attempts: int
    samples_dir: str
    width: int
    durable: bool
    filled: tuple[int, ...] | None = None  # bins that balancing fills (None: all of them)



def _bin_distance(vr: float, b: tuple[float, float]) -> float:
    """How far ``vr`` lies outside bin ``b`` (0 inside)."""
    return max(b[0] - vr, vr - b[1], 0.0)


def _candidate(task: _Task, index: int | None, attempt: int, s_seed: int) -> dict | None:
    """``make_sample(s_seed)`` checked and canonicalised; ``None`` when it rejects its seed.

    ``index`` is the sample's global index, or ``None`` for a candidate of the VR probe.
    """
    what = f"sample {index}" if index is not None else f"VR probe candidate {attempt}"
    try:
        raw = task.make_sample(s_seed)
    except SampleRejected:
        return None  # e.g. a scene the generator cannot build: the next seed replaces it
    except Exception as e:
        if hasattr(e, "add_note"):  # Python >= 3.11
            e.add_note(f"while making {what} (attempt {attempt}, seed {s_seed})")
        raise
    if not isinstance(raw, Mapping):
        raise TypeError(f"make_sample({s_seed}) returned {type(raw).__name__}, expected a "
                        f"dict ({what})")
    sample = {**raw, "index": index, "seed": s_seed, "attempt": attempt}
    canon = _canonical(sample, lambda f: f"{what}: {f!r}")
    if canon["kind"] not in task.kinds:
        raise ValueError(f"{what}: kind {canon['kind']!r} is not one of the "
                         f"dataset's kinds {list(task.kinds)}")
    hw = canon["image"].shape[:2]
    if task.image_size is not None and tuple(hw) != tuple(task.image_size):
        raise ValueError(f"{what}: image size {tuple(hw)}, expected "
                         f"{tuple(task.image_size)}")
    return canon


def _make_and_write(task: _Task, index: int) -> dict:
    """Try seeds (seed, index, attempt) until a candidate is accepted; write it; summarise.

    With VR balancing, sample ``index`` wants bin ``filled[index % len(filled)]``; when no
    candidate of ``max_attempts`` falls in it, the accepted candidate whose target VR is nearest
    to the bin is written instead (``off_bin``), so balancing never stops a run.
    """
    want = None
    if task.bins:
        filled = task.filled if task.filled is not None else tuple(range(len(task.bins)))
        want = filled[index % len(filled)] if filled else None
    best = None  # (distance to the wanted bin, attempt, canonical sample)
    for attempt in range(task.max_attempts):
        s_seed = sample_seed(task.seed, index, attempt)
        canon = _candidate(task, index, attempt, s_seed)
        if canon is None:
            continue
        vr = canon["vr"][canon["target"]]
        if want is not None and vr_bin(vr, task.bins) != want:
            dist = _bin_distance(vr, task.bins[want])
            if (best is None or dist < best[0]) and (task.accept is None or task.accept(canon)):
                best = (dist, attempt, canon)
            continue
        if task.accept is not None and not task.accept(canon):
            continue
        _write_folder(Path(task.samples_dir) / f"{index:0{task.width}d}", _encode(canon),
                      task.durable)
        return {"index": index, "attempts": attempt + 1, "target_vr": vr, "off_bin": False}
    if best is not None:  # balancing missed its bin: the nearest accepted candidate
        canon = best[2]
        _write_folder(Path(task.samples_dir) / f"{index:0{task.width}d}", _encode(canon),
                      task.durable)
        return {"index": index, "attempts": task.max_attempts,
                "target_vr": canon["vr"][canon["target"]], "off_bin": True}
    raise RuntimeError(f"sample {index}: no candidate accepted in {task.max_attempts} attempts "
                       f"(seeds {_SEED_RULE} with attempt 0..{task.max_attempts - 1}); "
                       f"raise max_attempts or relax accept")


def _probe_outcome(task: _Task, k: int) -> int | None:
    """Probe candidate ``k`` (seed [`probe_seed`][handmesh_tutorial.data.seeds.probe_seed]):
    the VR bin of its target (-1 outside every bin), or ``None`` when it is rejected."""
    canon = _candidate(task, None, k, probe_seed(task.seed, k))
    if canon is None or (task.accept is not None and not task.accept(canon)):
        return None
    return vr_bin(canon["vr"][canon["target"]], task.bins)


def _probe_summary(task: _Task, outcomes) -> dict:
    """The probe of a balanced set from its candidates' outcomes (any order): hits per bin and
    the bins balancing fills (those with at least
    [`PROBE_MIN_HITS`][handmesh_tutorial.data.candidates.PROBE_MIN_HITS] hits)."""
    outcomes = list(outcomes)
    hits = [0] * len(task.bins)
    rejected = outside = 0
    for b in outcomes:
        if b is None:
            rejected += 1
        elif b < 0:
            outside += 1
        else:
            hits[b] += 1
    return {"candidates": len(outcomes), "hits": hits, "outside": outside, "rejected": rejected,
            "min_hits": PROBE_MIN_HITS,
            "filled": [b for b, h in enumerate(hits) if h >= PROBE_MIN_HITS]}


def _probe(task: _Task, num: int) -> dict:
    """VR probe of a balanced set in this process: ``num`` candidates, summarised by
    `_probe_summary` (the worker pool runs the same candidates in parallel)."""
    return _probe_summary(task, (_probe_outcome(task, k) for k in range(num)))
