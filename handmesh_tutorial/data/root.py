"""A root being written: its ``meta.json`` check, the writer lock, stale temporaries, and
merging shard roots into one.

Taught in notebook 05 ("Rendering and the visibility ratio"; the ``handmesh generate`` command
line and ``docs/concepts/reliability.md`` show resuming and sharding).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._io import fsync_dir, single_writer
from .files import _temporary, _write_atomic, read_annotation
from .reader import _disagreements, _planned, _present, read_meta
from .schema import (
    _LOCK_FILE,
    _TMP_PREFIX,
    META_FILE,
    MIN_INDEX_WIDTH,
    SAME_SAMPLES_SINCE,
    SAMPLES_DIR,
    _sample_index,
)

__all__ = ["merge_shards"]


_TMP_NAME = re.compile(rf"^{re.escape(_TMP_PREFIX)}(?P<name>.+)-\d+-[0-9a-f]{{8}}$")
"""Names of this module's temporaries: ``.tmp-<final name>-<pid>-<8 hex digits>``."""
_SAMPLE_FILE = re.compile(r"^(image|scene_mask|alone_\d+|alone_rgb_\d+)\.png$"
                          r"|^annotation\.(npz|json)$")
"""Files a sample folder can hold (``_encode``): what a half-written sample may contain."""


def _is_own_temporary(p: Path) -> bool:
    """Whether ``p`` is a temporary that a writer of this module made (and may be removed).

    The name must be `_temporary`'s ``.tmp-<name>-<pid>-<8 hex>``; a folder may hold only sample
    files, a file must stand for ``meta.json`` or a sample file. Anything else, e.g. a user's
    ``.tmp-my-notes/``, is left alone.
    """
    m = _TMP_NAME.match(p.name)
    if m is None or p.is_symlink():
        return False
    if p.is_dir():
        return all(c.is_file() and not c.is_symlink() and _SAMPLE_FILE.match(c.name)
                   for c in p.iterdir())
    return p.is_file() and (m["name"] == META_FILE or _SAMPLE_FILE.match(m["name"]) is not None)



def _sample_files(folder: Path) -> list[str]:
    """The files of a sample folder that a copy takes (`merge_shards`), by the reader rule
    (`files._own_file`): only regular files of a sample's names, links never followed.

    Raises:
        ValueError: the folder holds anything else (a link, a sub-folder, another file), named;
            nothing is copied from it.
    """
    names = []
    for child in sorted(folder.iterdir()):
        if not _SAMPLE_FILE.match(child.name) or child.is_symlink() or not child.is_file():
            what = ("a symbolic link" if child.is_symlink() else "a folder" if child.is_dir()
                    else "no sample's file")
            raise ValueError(f"{child} is {what}: a merge copies only a sample's own files, "
                             "never through a link; `handmesh verify` the shard, move it away "
                             "and regenerate that sample")
        names.append(child.name)
    return names


def _remove_sample_folder(folder: Path) -> list[str]:
    """Delete a sample folder of the generator's, touching nothing else: a link at its place is
    unlinked (its target untouched); in a real folder only the files a sample has
    (`_SAMPLE_FILE` names, links among them unlinked) are deleted, then the folder if that
    emptied it.

    Returns:
        The names left in the folder (other files, sub-folders): empty when it was removed.

    Raises:
        OSError: a deletion failed (read-only or forbidden folder); names the path.
    """
    if folder.is_symlink() or not folder.is_dir():
        folder.unlink()
        return []
    left = []
    for child in sorted(folder.iterdir()):
        if _SAMPLE_FILE.match(child.name) and (child.is_symlink() or child.is_file()):
            child.unlink()
        else:
            left.append(child.name)
    if not left:
        folder.rmdir()
    return left


_SHARD_ROOT = re.compile(r"[0-9]{4}")
"""Names of the shard roots a run in parts makes (`generate._shards_folder`): ``0000``..."""


def _check_shards_folder(folder: Path) -> None:
    """Refuse a shards folder (where a run in parts keeps its shards until they are merged)
    that is a symbolic link or holds anything but shard roots (``NNNN`` folders): such a run
    writes, and after the merge deletes, only its own shards.

    Raises:
        ValueError: a link, a file, or foreign entries (listed); nothing was written.
    """
    if folder.is_symlink():
        raise ValueError(f"{folder} is a symbolic link (to {os.readlink(folder)}): the shards of "
                         "a run in parts are never written through a link; remove the link "
                         "and rerun")
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{folder} is a file: a run in parts keeps its shards there; move it "
                         "away and rerun")
    foreign = sorted(p.name for p in folder.iterdir() if not (
        _SHARD_ROOT.fullmatch(p.name) and p.is_dir() and not p.is_symlink())) \
        if folder.is_dir() else []
    if foreign:
        shown = ", ".join(foreign[:8]) + (f" and {len(foreign) - 8} more" if len(foreign) > 8
                                          else "")
        raise ValueError(f"{folder} holds what a run in parts did not write ({shown}): it keeps "
                         "its shards there and deletes them after merging; move these away "
                         "and rerun (nothing was written)")


def _remove_shards(folder: Path) -> list[str]:
    """Delete the merged shard roots of a run in parts, touching nothing else: in each
    ``NNNN`` root its sample folders (`_remove_sample_folder`), ``meta.json``, the writer lock
    and this module's temporaries; then every folder that this left empty.

    Returns:
        The entries left (relative to ``folder``'s parent), e.g. a user's file put into a shard
        while it ran; empty when ``folder`` is gone.
    """
    left: list[str] = []
    for shard in sorted(folder.iterdir()):
        if not (_SHARD_ROOT.fullmatch(shard.name) and shard.is_dir()
                and not shard.is_symlink()):
            left.append(f"{folder.name}/{shard.name}")
            continue
        samples = shard / SAMPLES_DIR
        if samples.is_dir() and not samples.is_symlink():
            for p in sorted(samples.iterdir()):
                if _sample_index(p.name) is not None and (p.is_dir() or p.is_symlink()):
                    _remove_sample_folder(p)  # what it leaves is listed below
            _clean_stale(samples)
        for name in (META_FILE, _LOCK_FILE):
            p = shard / name
            if p.is_file() or p.is_symlink():
                p.unlink()
        _clean_stale(shard)
        for d in (samples, shard):
            if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
                d.rmdir()
        if shard.exists():
            left += [f"{folder.name}/{p.relative_to(folder)}" for p in sorted(shard.rglob("*"))
                     if not p.is_dir() or p.is_symlink()]
    if not any(folder.iterdir()):
        folder.rmdir()
    return left


def _coalesce(ranges: Sequence[Sequence[int]]) -> list[list[int]]:
    out: list[list[int]] = []
    for a, b in sorted((int(a), int(b)) for a, b in ranges if b > a):
        if out and a < out[-1][1]:
            raise ValueError(f"index ranges overlap: [{out[-1][0]}, {out[-1][1]}) and [{a}, {b})")
        if out and a == out[-1][1]:
            out[-1][1] = b
        else:
            out.append([a, b])
    return out


def _diff(a: Any, b: Any, prefix: str = "") -> list[str]:
    """Dotted names of the keys where two JSON values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _diff(a.get(k, "<absent>"), b.get(k, "<absent>"), f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]


def _version_tuple(v: Any) -> tuple[int, ...] | None:
    try:
        return tuple(int(x) for x in str(v).split("."))
    except ValueError:
        return None


def _meta_diff(old: Mapping, new: Mapping, ignore: Sequence[str] = ()) -> list[str]:
    """`_diff` of two ``meta.json`` dicts, less ``ignore`` and less ``generator_version`` when
    both versions make the same samples (`SAME_SAMPLES_SINCE` up to this library's version)."""
    from .._version import __version__

    keys = [k for k in _diff(old, new) if k.split(".")[0] not in ignore]
    if "generator_version" in keys:
        since, now = _version_tuple(SAME_SAMPLES_SINCE), _version_tuple(__version__)
        got = _version_tuple(old.get("generator_version"))
        if None not in (since, got, now) and since <= got <= now:  # "0.6.0.dev1": None
            keys.remove("generator_version")
    return keys


def _diff_message(path: Path, old: dict, new: dict, keys: Sequence[str]) -> str:
    def get(d: Any, dotted: str) -> Any:
        for part in dotted.split("."):
            d = d.get(part, "<absent>") if isinstance(d, dict) else "<absent>"
        return d

    lines = [f"  {k}: {get(old, k)!r} on disk, {get(new, k)!r} now" for k in keys]
    return (f"{path} was written with different parameters; differing keys: {', '.join(keys)}\n"
            + "\n".join(lines))


def _lock(root: Path):
    """One writer per root (an flock the OS drops if the process dies, even on SIGKILL)."""
    return single_writer(root / _LOCK_FILE, str(root))


def _clean_stale(folder: Path) -> int:
    """Remove the temporaries a killed writer left in ``folder``; returns how many.

    Only this module's own temporaries (`_is_own_temporary`) are removed.
    """
    n = 0
    if folder.is_dir():
        for p in folder.iterdir():
            if p.name.startswith(_TMP_PREFIX) and _is_own_temporary(p):
                shutil.rmtree(p) if p.is_dir() else p.unlink()
                n += 1
    return n


def _foreign_entries(root: Path, meta: Mapping) -> list[str]:
    """What in a root without ``meta.json`` is not the set's own: the entries (relative paths,
    with why) other than the writer lock, this module's temporaries and ``samples/`` holding only
    sample folders of ``meta``'s planned indices whose files are a sample's and whose
    ``annotation.json`` agrees with ``meta`` (`reader._disagreements`: kind, image size, seed
    rule, index). Empty: the folder may become this set's root."""
    out: list[str] = []
    for p in sorted(root.iterdir()):
        if p.name == _LOCK_FILE or (p.name.startswith(_TMP_PREFIX) and _is_own_temporary(p)):
            continue
        if p.name != SAMPLES_DIR or p.is_symlink() or not p.is_dir():
            out.append(p.name)
            continue
        for q in sorted(p.iterdir()):
            rel = f"{SAMPLES_DIR}/{q.name}"
            if q.name.startswith(_TMP_PREFIX) and _is_own_temporary(q):
                continue
            index = _sample_index(q.name, meta["index_width"])
            if index is None or not any(a <= index < b for a, b in meta["ranges"]):
                out.append(f"{rel} (not a sample this run plans)")
            elif q.is_symlink() or not q.is_dir():
                out.append(f"{rel} (not a folder)")
            elif other := [c.name for c in q.iterdir()
                           if not _SAMPLE_FILE.match(c.name) or c.is_symlink() or c.is_dir()]:
                out.append(f"{rel} (holds {', '.join(map(repr, sorted(other)[:3]))}, no sample's "
                           "file)")
            else:
                try:
                    why = [w for _, w in _disagreements(read_annotation(q), q, meta)]
                except (OSError, ValueError) as err:
                    why = [str(err).splitlines()[0]]
                if why:
                    out.append(f"{rel} ({why[0]})")
    return out


def _check_root(root: Path, meta: Mapping) -> None:
    """Refuse, before anything is written, a root that is not this set's: a symbolic link as
    its ``samples`` folder, or (without ``meta.json``) files the generator did not write or
    samples of another set (`_foreign_entries`).

    Raises:
        ValueError: naming the entries (at most five) and what to do.
    """
    samples = root / SAMPLES_DIR
    if samples.is_symlink():
        raise ValueError(f"{samples} is a symbolic link (to {os.readlink(samples)}): a generator "
                         "writes only inside its own folder, found without following links; "
                         "replace the link by the folder itself (nothing was written)")
    if (root / META_FILE).exists():
        return
    foreign = _foreign_entries(root, meta)
    if foreign:
        shown = "; ".join(foreign[:5]) + (f"; and {len(foreign) - 5} more" if len(foreign) > 5
                                          else "")
        raise ValueError(f"{root} has no {META_FILE} but holds what this run did not write: "
                         f"{shown}. Generate into an empty or new folder, or move these out "
                         f"(nothing was written; a set whose {META_FILE} was lost resumes only "
                         "with the parameters its samples were made with)")


def _open_root(root: Path, meta: dict) -> int:
    """Create or check ``root/meta.json`` (written only after `_check_root`: the folder is empty
    or the set's own); clean stale temporaries. Returns their count."""
    _check_root(root, meta)
    path = root / META_FILE
    if path.exists():
        old = read_meta(root)
        keys = _meta_diff(old, meta)
        if keys:
            raise ValueError(_diff_message(path, old, meta, keys))
    else:
        _write_atomic(path, (json.dumps(meta, indent=2, sort_keys=True) + "\n").encode())
    (root / SAMPLES_DIR).mkdir(exist_ok=True)
    return _clean_stale(root / SAMPLES_DIR) + _clean_stale(root)



def merge_shards(shard_roots: Sequence[str | os.PathLike], out_root: str | os.PathLike, *,
                 link: bool = False, progress: bool = True, durable: bool = True) -> dict:
    """Merge shard roots (made with ``generate_dataset(..., shard=(k, n))``) into one root.

    Samples keep their global indices, so merging all shards gives the same files as one
    unsharded run (``meta.json`` included). Resumable: samples already in ``out_root`` are kept.

    Args:
        shard_roots: the shard folders; their ``meta.json`` must agree on everything except the
            shards, and their index ranges must not overlap.
        out_root: the merged dataset folder (created).
        link: hard-link files instead of copying (same filesystem only).
        progress: show a tqdm bar.
        durable: fsync copied files and folders.

    Returns:
        ``{"copied": int, "skipped": int, "ranges": [[start, stop], ...], "complete": bool}``.

    Raises:
        ValueError: incompatible metas (differing keys named), overlapping shards, a shard with
            missing samples, or an ``out_root`` made from other shards.
    """
    from .._progress import progress_bar

    if not shard_roots:
        raise ValueError("merge_shards needs at least one shard root")
    roots = [Path(r) for r in shard_roots]
    metas = [read_meta(r) for r in roots]
    ignore = ("shards", "ranges")
    base = {k: v for k, v in metas[0].items() if k not in ignore}
    for r, m in zip(roots[1:], metas[1:], strict=True):
        keys = _diff(base, {k: v for k, v in m.items() if k not in ignore})
        if keys:
            raise ValueError(f"cannot merge {roots[0]} and {r}: " +
                             _diff_message(r / META_FILE, base, m, keys))
    for r, m in zip(roots, metas, strict=True):
        present = set(_present(r / SAMPLES_DIR, m.get("index_width", MIN_INDEX_WIDTH)))
        absent = [i for i in _planned(m) if i not in present]
        if absent:
            raise ValueError(f"shard {r} is incomplete: {len(absent)} samples missing (first "
                             f"{absent[:5]}); finish it by re-running its generate command")
    ranges = _coalesce([rg for m in metas for rg in m["ranges"]])
    complete = ranges == [[0, base["num_samples"]]]
    # A root holding every index is recorded as shard 0 of 1: identical to an unsharded run.
    shards = [[0, 1]] if complete else sorted({tuple(s) for m in metas for s in m["shards"]})
    meta = {**base, "shards": [list(s) for s in shards], "ranges": ranges}
    out = Path(out_root)
    out.mkdir(parents=True, exist_ok=True)
    width = base["index_width"]
    copied = skipped = 0
    with _lock(out):
        _open_root(out, meta)
        jobs = [(r, i) for r, m in zip(roots, metas, strict=True) for i in _planned(m)]
        for r, i in progress_bar(jobs, disable=not progress, desc="merge", unit="sample"):
            name = f"{i:0{width}d}"
            dst = out / SAMPLES_DIR / name
            if dst.exists():
                skipped += 1
                continue
            src = r / SAMPLES_DIR / name
            names = _sample_files(src)
            tmp = _temporary(dst)
            try:
                tmp.mkdir()
                for f in names:
                    (os.link if link else shutil.copyfile)(src / f, tmp / f)
                if durable and not link:
                    for p in tmp.iterdir():
                        with open(p, "rb+") as fh:
                            os.fsync(fh.fileno())
                os.replace(tmp, dst)
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
            copied += 1
        if durable:
            fsync_dir(out / SAMPLES_DIR)
    return {"copied": copied, "skipped": skipped, "ranges": ranges, "complete": complete}
