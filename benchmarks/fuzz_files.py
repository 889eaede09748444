"""Fuzz run: damaged and crafted input files fed to the readers a user feeds files to.

A tiny corpus is made with the library (an INTER-SH root of toy samples at 32 px, a 1-epoch
network's checkpoint, a template ``.npz``, a MANO-format pickle, a FreiHAND-format folder), then
each case copies one target, damages it with one seeded mutation and reads it in a child
process under a memory cap (``RLIMIT_AS``) and a timeout. The outcome is classified:

* ``clean``: read fine and the values are plausible (finite, hands within metres of the camera,
  a template's faces index its vertices...);
* ``refused``: a ``ValueError`` (exit code 3 from ``handmesh``, or a sample that ``--skip-bad``
  leaves out) whose message names the damaged file or sample;
* a failure: ``crash`` (a signal), ``timeout``, ``memory``, ``exception`` (another type, or
  exit code 1 "a bug"), ``unnamed`` (refused without naming the file), ``implausible`` (accepted
  with absurd values), ``touched`` (a planted file of the user's, or anything outside the root,
  written, moved or deleted), ``clobbered`` (a file of the user's in ``--out`` changed).

Targets and readers: ``intersh-verify`` (``handmesh verify``), ``intersh-evaluate``
(``handmesh evaluate --skip-bad``), ``checkpoint`` (``load_checkpoint``, then ``evaluate`` on
the pristine root), ``template`` (``resolve_template`` + ``build_model_from_config``), ``mano``
(``load_mano`` + a forward pass), ``freihand-read`` (every item and mask of both splits),
``freihand-evaluate`` (``handmesh evaluate --dataset freihand --skip-bad``), ``intersh-repair``
(``handmesh verify --remove-bad``, then the ``generate`` that made the root), and the planted
targets of issue 43 (section at the end): ``hierarchy-cache`` (a damaged ``hierarchy_*.npz``
read by ``mesh_hierarchy``) and ``out-folder`` (the user's files in the ``--out`` of ``train``,
``evaluate`` or ``demo``). Mutations: ``bitflip``, ``truncate``, ``insert``, ``zero`` (a range),
``swap`` (a file swapped between samples or splits, or replaced by another target's file),
``value`` (a JSON value, a pickled or saved array or tensor edited: types, huge numbers, NaN,
nesting, shapes), ``header`` (an ``.npy`` member header, a zip header field, or an image's width
and height in a PNG's IHDR or a JPEG's SOF), and for INTER-SH roots ``foreign`` (a user's files,
links to outside (a sample folder, ``samples/``, a sample's file), non-ASCII names, a sample of
another set, a planned sample missing: issue 53) and ``extra`` (``annotation.json``
``extra`` fields). Byte positions are drawn half uniformly, half in a file's structure (zip
headers and directory, ``.npy`` headers, pickle opcodes).

    python benchmarks/fuzz_files.py [--cases 980] [--seed 0] [--timeout 60] [--mem-gb 2]
                                    [--targets a,b] [--mutations a,b] [--work DIR]
                                    [--case TARGET:MUTATION:N] [--nice 19] [--json FILE]

``--case`` reruns one case in this process (the reproducer printed for each failure) and shows
the traceback. Prints a table of outcomes per target and mutation; exits 1 on any failure.
A progress line every 250 cases; SIGINT or SIGTERM stops the run with the table of the cases
done. ``--nice`` is the reading child's niceness increment (default 19). Docs
page *Reliability*; ``tests/test_fuzz.py`` runs a small seeded subset.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import json
import os
import pickle
import pickletools
import random
import re
import resource
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import zipfile
from collections import Counter, defaultdict
from pathlib import Path

TARGETS = ("intersh-verify", "intersh-evaluate", "checkpoint", "template", "mano",
           "freihand-read", "freihand-evaluate", "intersh-repair")
MUTATIONS = ("bitflip", "truncate", "insert", "zero", "swap", "value", "header", "foreign",
             "extra")
ROOT_MUTATIONS = ("foreign", "extra")
"""What only an INTER-SH root can be given: entries that are no sample (a user's files, links
to outside, non-ASCII names, a sample of another set) and ``annotation.json`` ``extra`` fields."""
FAILURES = ("crash", "timeout", "memory", "exception", "unnamed", "implausible", "touched")
OUTCOMES = ("clean", "refused", *FAILURES, "skipped")
IMAGE = 32  # pixels, corpus images and crops

# ------------------------------------------------------------------ the corpus


def build_corpus(work: Path) -> Path:
    """Write the pristine files under ``work/base`` once (reused when present and made by this
    version of the library: a corpus of another version's ``meta.json`` reads as foreign)."""
    from handmesh_tutorial import __version__

    base = work / "base"
    if (base / "done").exists() and (base / "done").read_text() == __version__:
        return base
    import torch

    from handmesh_tutorial import train as T
    from handmesh_tutorial.data import generate_dataset
    from handmesh_tutorial.testing import toy_sample, write_freihand_root, write_mano_pickle

    shutil.rmtree(base, ignore_errors=True)
    base.mkdir(parents=True)
    generate_dataset(base / "intersh", functools.partial(toy_sample, image_size=IMAGE), num=4,
                     seed=3, kind="hand-hand", progress=False, durable=False)
    T.save_template(base / "template.npz", None)
    write_mano_pickle(base / "MANO_RIGHT.pkl")
    write_freihand_root(base / "freihand", 2, image_size=IMAGE)
    # untrained networks (the readers do not care); FreiHAND scores MANO's 778 vertices, so its
    # network is built on the MANO-format template
    for name, data, template in (("checkpoint.pt", "intersh", None),
                                 ("checkpoint_mano.pt", "freihand", "MANO_RIGHT.pkl")):
        cfg = T.TrainConfig(data=str(base / data), dataset=data, image_size=IMAGE,
                            encoder="resnet10", channels=(4, 4, 8, 8, 8), latent_channels=8,
                            template=template and str(base / template))
        torch.manual_seed(0)
        net = T.build_model_from_config(cfg)
        T.save_checkpoint(base / name, model=net, config=cfg,
                          template_id=T.template_hash(cfg.template), durable=False)
    _other_set(base)
    (base / "done").write_text(__version__)
    return base


def _other_set(base: Path) -> Path:
    """Another INTER-SH set (48 px, seed 9): its samples are foreign to ``base/intersh``."""
    other = base / "intersh-other"
    if not (other / "meta.json").exists():
        from handmesh_tutorial.data import generate_dataset
        from handmesh_tutorial.testing import toy_sample

        generate_dataset(other, functools.partial(toy_sample, image_size=48), num=4, seed=9,
                         kind="hand-hand", progress=False, durable=False)
    return other


def mutations_of(target: str) -> tuple[str, ...]:
    """The mutations that apply to a target (`ROOT_MUTATIONS` to INTER-SH roots only)."""
    if target.startswith("intersh"):
        return MUTATIONS
    return tuple(m for m in MUTATIONS if m not in ROOT_MUTATIONS)


def target_files(base: Path, target: str) -> tuple[str, list[str]]:
    """``(what to copy, the files inside it a mutation may damage)``, relative to ``base``."""
    if target.startswith("intersh"):
        root = base / "intersh"
        return "intersh", [str(p.relative_to(base)) for p in sorted(root.rglob("*"))
                           if p.is_file() and not p.name.startswith(".")]  # no lock
    if target.startswith("freihand"):
        root = base / "freihand"
        return "freihand", [str(p.relative_to(base)) for p in sorted(root.rglob("*"))
                            if p.is_file()]
    name = {"checkpoint": "checkpoint.pt", "template": "template.npz", "mano": "MANO_RIGHT.pkl"}
    return name[target], [name[target]]


# ------------------------------------------------------------------ mutations


def _zip_ranges(data: bytes) -> list[tuple[int, int]]:
    """Byte ranges of a zip's structure: local headers (+ the start of each member, where an
    ``.npy`` header or a pickle is) and the central directory."""
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except Exception:  # noqa: BLE001 - not a zip: no structure known
        return []
    out = []
    for i in infos:
        start = i.header_offset
        out.append((start, min(len(data), start + 30 + len(i.filename) + 256)))
        if i.filename.endswith("data.pkl"):
            out.append((start, min(len(data), start + 30 + len(i.filename) + 64 +
                                   i.compress_size)))
    first_cd = data.find(b"PK\x01\x02")
    if first_cd >= 0:
        out.append((first_cd, len(data)))
    return out


def _pickle_ranges(data: bytes) -> list[tuple[int, int]]:
    """Byte ranges around the opcodes of a pickle (not inside long binary strings)."""
    out = []
    try:
        for _op, arg, pos in pickletools.genops(data):
            out.append((pos, pos + 1 + (len(arg) if isinstance(arg, str) and len(arg) < 64
                                        else 8)))
    except Exception:  # noqa: BLE001 - a damaged pickle: what was found so far
        pass
    return out


def _position(rng: random.Random, data: bytes, name: str) -> int:
    if not data:
        return 0
    ranges = []
    if rng.random() < 0.5:
        ranges = _pickle_ranges(data) if name.endswith(".pkl") else _zip_ranges(data)
    if ranges:
        a, b = rng.choice(ranges)
        return min(len(data) - 1, rng.randrange(a, max(a + 1, b)))
    return rng.randrange(len(data))


_HUGE = ["1e308", "-1e30", "1" + "0" * 400, "1e999", "NaN", "-Infinity", "Infinity"]
_ODD = ['"x"', "null", "true", "[]", "{}", "[1, 2]", '{"a": 1}', "0", "-1", "3.5",
        "[" * 3000 + "]" * 3000, "[" * 100_000 + "]" * 100_000, '"' + "9" * 10_000 + '"']


def _edit_json(rng: random.Random, text: str) -> tuple[str, str]:
    """One value of a JSON document replaced (by a wrong type, a huge number, NaN, a deep
    nesting), a key removed, or the document replaced."""
    obj = json.loads(text)
    paths = []

    def walk(o, path, depth):
        paths.append(path)
        if depth > 6:
            return
        if isinstance(o, dict):
            for k, v in o.items():
                walk(v, path + [k], depth + 1)
        elif isinstance(o, list) and o:
            for i in sorted({0, len(o) - 1, rng.randrange(len(o))}):
                walk(o[i], path + [i], depth + 1)

    walk(obj, [], 0)
    path = rng.choice(paths)
    new = rng.choice(_HUGE + _ODD)
    token = "\x00REPLACED\x00"
    if not path:
        return new, f"document := {new[:30]}"
    parent = obj
    for k in path[:-1]:
        parent = parent[k]
    if isinstance(parent, dict) and rng.random() < 0.15:
        del parent[path[-1]]
        return json.dumps(obj), f"removed key {path}"
    parent[path[-1]] = token
    return json.dumps(obj).replace(json.dumps(token), new), f"{path} := {new[:30]}"


def _odd_array(rng: random.Random, a):
    import numpy as np

    choice = rng.randrange(9)
    a = np.array(a)
    if a.dtype.kind not in "biuf":  # a string (MANO's bs_style): numbers instead
        return np.zeros(3), "numbers for a string"
    if choice == 0 and a.size and a.dtype.kind == "f":
        a.flat[rng.randrange(a.size)] = rng.choice([np.nan, np.inf, 1e30, -1e300])
        return a, "a value NaN/inf/huge"
    if choice == 1:
        return a.reshape(-1), "flattened"
    if choice == 2:
        return a[: max(0, len(a) - 1)] if a.ndim else a, "one row less"
    if choice == 3:
        return a.astype(rng.choice([np.float16, np.int8, np.complex64, np.bool_, "U3"])), \
            "another dtype"
    if choice == 4:
        return np.zeros((0,) + a.shape[1:], a.dtype), "empty"
    if choice == 5 and a.dtype.kind in "iu" and a.size:
        a = a.astype(np.int64)
        a.flat[rng.randrange(a.size)] = rng.choice([-1, 2**31 - 1, 10**6])
        return a, "an index out of range"
    if choice == 6:
        return np.float64(3.0), "a scalar"
    if choice == 7 and a.ndim:
        return np.repeat(a, 2, axis=0), "rows doubled"
    return a * rng.choice([1e6, -1.0, 0.0]), "scaled"


def _edit_npz(rng: random.Random, data: bytes) -> tuple[bytes, str]:
    import numpy as np

    with np.load(io.BytesIO(data)) as z:
        arrays = {k: z[k] for k in z.files}
    key = rng.choice(sorted(arrays))
    arrays[key], what = _odd_array(rng, arrays[key])
    if rng.random() < 0.1:
        del arrays[key]
        what = "removed"
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue(), f"array '{key}': {what}"


def _edit_pickle(rng: random.Random, data: bytes) -> tuple[bytes, str]:
    import numpy as np

    params = pickle.loads(data)  # noqa: S301 - the corpus's own pristine file
    key = rng.choice(sorted(params))
    if rng.random() < 0.2:
        params[key] = rng.choice([None, "x", [1, 2], {"a": 1}, 7])
        what = "wrong type"
    elif hasattr(params[key], "toarray"):
        params[key] = np.asarray(params[key].toarray())
        params[key], what = _odd_array(rng, params[key])
    else:
        params[key], what = _odd_array(rng, params[key])
    return pickle.dumps(params, protocol=2), f"'{key}': {what}"


def _edit_checkpoint(rng: random.Random, data: bytes) -> tuple[bytes, str]:
    import torch

    ck = torch.load(io.BytesIO(data), weights_only=True)
    key = rng.choice(["model", "model", "model", "config", "history", "template_hash", "epoch"])
    if key == "model":
        name = rng.choice(sorted(ck["model"]))
        t = ck["model"][name]
        arr, what = _odd_array(rng, t.numpy())
        try:
            ck["model"][name] = torch.as_tensor(arr)
        except (TypeError, RuntimeError):
            ck["model"][name] = torch.zeros(0)
            what = "empty"
        what = f"weight '{name}': {what}"
    elif key == "config":
        field = rng.choice(sorted(ck["config"]))
        ck["config"][field] = rng.choice([None, "x", -1, 10**9, [1], 0.0, float("nan")])
        what = f"config '{field}' := {ck['config'][field]!r}"
    else:
        ck[key] = rng.choice([None, "x", -1, [1], {}])
        what = f"'{key}' := {ck[key]!r}"
    buf = io.BytesIO()
    torch.save(ck, buf)
    return buf.getvalue(), what


def _edit_header(rng: random.Random, data: bytes, name: str) -> tuple[bytes, str]:
    """An ``.npy`` member's header rewritten (npz), or a field of a zip header changed."""
    import numpy as np

    if name.endswith(".npz") and rng.random() < 0.6:
        src = zipfile.ZipFile(io.BytesIO(data))
        member = rng.choice([i.filename for i in src.infolist()])
        raw = src.read(member)
        version = np.lib.format.read_magic(io.BytesIO(raw))
        f = io.BytesIO(raw)
        np.lib.format.read_magic(f)
        read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                else np.lib.format.read_array_header_2_0)
        shape, fortran, dtype = read(f)
        body = raw[f.tell():]
        choice = rng.randrange(6)
        if choice == 0:
            shape = tuple(int(s * rng.choice([2, 1000, 10**6])) for s in shape) or (10**9,)
        elif choice == 1:
            dtype = np.dtype(rng.choice(["<f8", ">f4", "<c16", "|b1", "<i2", "V8", "<U4"]))
        elif choice == 2:
            fortran = not fortran
        elif choice == 3:
            shape = tuple(reversed(shape)) + (1,)
        h = io.BytesIO()
        if choice == 4:  # a header that is not a dict literal
            h.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", 118) + b"{'descr': os.system}"
                    + b" " * 97 + b"\n")
        elif choice == 5:
            h.write(raw[:10] + b"{'descr': '<f4', 'fortran_order': False, 'shape': (-5, 3)}"
                    .ljust(struct.unpack("<H", raw[8:10])[0] - 1) + b"\n")
        else:
            np.lib.format.write_array_header_1_0(h, {"descr": np.lib.format.dtype_to_descr(
                dtype), "fortran_order": fortran, "shape": shape})
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as zf:
            for i in src.infolist():
                zf.writestr(i, h.getvalue() + body if i.filename == member else src.read(i))
        return out.getvalue(), f"member '{member}' header: {h.getvalue()[10:80]!r}"
    if name.endswith((".png", ".jpg")):
        return _edit_image_header(rng, data, name)
    data = bytearray(data)
    heads = [m.start() for m in re.finditer(b"PK(\x03\x04|\x01\x02|\x05\x06)", bytes(data))]
    if not heads:
        return _bitflip(rng, bytes(data), name)
    at = rng.choice(heads)
    sig = bytes(data[at + 2:at + 4])
    fields = {b"\x03\x04": [(8, "H"), (14, "I"), (18, "I"), (22, "I"), (26, "H"), (28, "H")],
              b"\x01\x02": [(10, "H"), (16, "I"), (20, "I"), (24, "I"), (28, "H"), (30, "H"),
                            (42, "I")],
              b"\x05\x06": [(8, "H"), (10, "H"), (12, "I"), (16, "I"), (20, "H")]}[sig]
    off, fmt = rng.choice(fields)
    size = struct.calcsize(fmt)
    if at + off + size > len(data):
        return bytes(data[:at]), "truncated at a header"
    value = rng.choice([0, 1, 8, 2**(8 * size) - 1, rng.randrange(2**(8 * size))])
    data[at + off:at + off + size] = struct.pack("<" + fmt, value)
    return bytes(data), f"zip header at {at} (PK{sig.hex()}) field +{off} := {value}"


def _edit_image_header(rng: random.Random, data: bytes, name: str) -> tuple[bytes, str]:
    """The width or height in a PNG's IHDR (its CRC recomputed) or a JPEG's SOF changed."""
    import zlib

    data = bytearray(data)
    value = rng.choice([0, 1, IMAGE + 1, 5000, 65535] + ([2**31 - 1] if name.endswith(".png")
                                                        else []))
    if name.endswith(".png"):
        off = rng.choice([16, 20])
        data[off:off + 4] = struct.pack(">I", value)
        data[29:33] = struct.pack(">I", zlib.crc32(bytes(data[12:29])))
        return bytes(data), f"IHDR {'width' if off == 16 else 'height'} := {value}"
    sof = data.find(b"\xff\xc0")
    if sof < 0:
        return _bitflip(rng, bytes(data), name)
    off = sof + rng.choice([5, 7])
    data[off:off + 2] = struct.pack(">H", value)
    return bytes(data), f"SOF0 {'height' if off == sof + 5 else 'width'} := {value}"


def _bitflip(rng: random.Random, data: bytes, name: str) -> tuple[bytes, str]:
    data = bytearray(data)
    flips = []
    for _ in range(rng.choice([1, 1, 2, 8])):
        if not data:
            break
        p = _position(rng, bytes(data), name)
        bit = rng.randrange(8)
        data[p] ^= 1 << bit
        flips.append(f"{p}.{bit}")
    return bytes(data), "bits " + ",".join(flips)


def _digest(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def _outside_tree(case_root: Path) -> dict:
    """Every entry under ``case_root/outside`` (links not followed): path -> sha256 or kind."""
    out = case_root / "outside"
    return {p.relative_to(out).as_posix(): ("link" if p.is_symlink() else "dir" if p.is_dir()
                                            else _digest(p))
            for p in sorted(out.rglob("*"))} if out.is_dir() else {}


FOREIGN_KINDS = ("user-files", "photo", "photo-in-bad", "non-ascii", "samples-link", "lock-link",
                 "sample-link", "other-set", "file-at-name", "file-link", "partial")
"""What `_plant_foreign` plants (one per case, drawn first)."""


def _plant_foreign(rng: random.Random, case_root: Path, base: Path) -> tuple[str, list[str]]:
    """Put what is no sample of the root's into ``case_root/intersh``: a user's files, links to
    ``case_root/outside``, non-ASCII names, a sample of another set. What a reader must leave
    as it is goes to ``case_root/planted.json`` (path -> sha256, or ``None``: must not exist),
    checked after the read with ``outside/`` (`_untouched`)."""
    root, outside = case_root / "intersh", case_root / "outside"
    samples = root / "samples"
    outside.mkdir()
    (outside / "keep.txt").write_text("a file outside the root")
    planted: dict[str, str | None] = {}

    def plant(rel: str, data: bytes) -> None:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
        planted[f"intersh/{rel}"] = _digest(root / rel)

    kind = rng.choice(FOREIGN_KINDS)
    i = rng.randrange(4)
    name = f"{i:06d}"
    names = [name]
    if kind == "user-files":
        plant("samples/notes.txt", b"a user's notes")
        plant("samples/99", b"a file named by digits")
        plant("samples/2024/notes.txt", b"a folder named by digits")
        plant(".tmp-my-notes/todo.txt", b"a user's temporary-looking folder")
        names = ["notes.txt", "99", "2024"]
    elif kind in ("photo", "photo-in-bad"):
        plant(f"samples/{name}/photo.jpg", b"\xff\xd8 a user's photo")
        if kind == "photo-in-bad":
            npz = samples / name / "annotation.npz"
            npz.write_bytes(npz.read_bytes()[:100])
        names += ["photo.jpg"]
    elif kind == "non-ascii":
        digits = rng.choice(["\u0660\u0661\u0662\u0663\u0664\u0665\u0666\u0667\u0668\u0669",
                             "\uff10\uff11\uff12\uff13\uff14\uff15\uff16\uff17\uff18\uff19"])
        copy = "".join(digits[int(c)] for c in name)
        shutil.copytree(samples / name, samples / copy)
        (samples / "\u00b2").mkdir()
        for p in (samples / copy).iterdir():
            planted[f"intersh/samples/{copy}/{p.name}"] = _digest(p)
        names += [copy, "\u00b2"]
    elif kind == "samples-link":  # samples/ itself a link to a folder outside the root
        shutil.move(samples, outside / "samples")
        samples.symlink_to(outside / "samples", target_is_directory=True)
        (outside / "samples" / "31").write_text("a user's file beside the samples")
        npz = outside / "samples" / name / "annotation.npz"
        npz.write_bytes(npz.read_bytes()[:100])  # one bad sample: a repair would delete it
        names += ["samples", "31"]
    elif kind == "lock-link":
        (root / ".generate.lock").unlink(missing_ok=True)  # the corpus's own lock
        (root / ".generate.lock").symlink_to(outside / "nologin")
        planted["outside/nologin"] = None
        npz = samples / name / "annotation.npz"
        npz.write_bytes(npz.read_bytes()[:100])
        names += [".generate.lock"]
    elif kind == "sample-link":  # a sample folder that is a link to a copy outside
        shutil.move(samples / name, outside / name)
        (samples / name).symlink_to(outside / name, target_is_directory=True)
    elif kind == "file-link":  # a sample's image a link to a file outside (issue 53)
        shutil.move(samples / name / "image.png", outside / "image.png")
        (samples / name / "image.png").symlink_to(outside / "image.png")
    elif kind == "partial":  # a planned sample missing: said by every reader (issue 53)
        shutil.rmtree(samples / name)
    elif kind == "other-set":
        other = _other_set(base)
        shutil.rmtree(samples / name)
        shutil.copytree(other / "samples" / name, samples / name)
    else:  # a file where a sample folder belongs
        shutil.rmtree(samples / name)
        plant(f"samples/{name}", b"a user's file named like a sample")
    (case_root / "planted.json").write_text(json.dumps({"planted": planted,
                                                        "outside": _outside_tree(case_root)}))
    return kind, names


_SHADOWS = ({"image": 5}, {"attempt": "zz"}, {"vr": {"1": 42}}, {"target": 7},
            {"K": [[1, 0], [0, 1]]}, {"seed": None}, {"kind": "hand-object"}, {"index": 3})
_ODD_EXTRAS = ({"note": [1, {"a": None}]}, {"x": 1e308}, {"deep": [[[[[]]]]]}, {"s": "\u00b2"})


def _edit_extra(rng: random.Random, case_root: Path) -> tuple[str, list[str]]:
    """An ``annotation.json`` ``extra`` entry: one shadowing a field, an odd but legal value,
    a non-identifier key, ``extra`` not an object, or ``extra_arrays`` naming a field."""
    name = f"{rng.randrange(4):06d}"
    path = case_root / "intersh" / "samples" / name / "annotation.json"
    ann = json.loads(path.read_text())
    how = rng.choice(["shadow", "shadow", "odd", "key", "type", "arrays"])
    if how == "shadow":
        ann["extra"] = dict(rng.choice(_SHADOWS))
    elif how == "odd":
        ann["extra"] = dict(rng.choice(_ODD_EXTRAS))
    elif how == "key":
        ann["extra"] = {rng.choice(["not an id", "\u00b2", "1x", ""]): 1}
    elif how == "type":
        ann["extra"] = rng.choice([[1, 2], "image", 5, None])
    else:
        ann["extra_arrays"] = [rng.choice(["K", "image", "vertices_1", "joints_1"])]
    path.write_text(json.dumps(ann))
    return f"{name}: {how} {json.dumps(ann.get('extra'))[:60]}", [name, "annotation.json"]


def mutate(rng: random.Random, mutation: str, case_root: Path, files: list[str], base: Path,
           target: str) -> tuple[str, list[str]]:
    """Damage the copy under ``case_root`` in place; returns (what was done, names that a
    refusal must mention: any one of them)."""
    if mutation in ROOT_MUTATIONS:
        if not target.startswith("intersh"):
            raise ValueError(f"{mutation} applies to INTER-SH roots only")
        return (_plant_foreign(rng, case_root, base) if mutation == "foreign"
                else _edit_extra(rng, case_root))
    name = rng.choice(files)
    if mutation == "value":
        editable = [f for f in files if f.endswith((".json", ".npz", ".pkl", ".pt"))]
        name = rng.choice(editable)
    if mutation == "header":
        zips = [f for f in files if f.endswith((".npz", ".pt", ".png", ".jpg"))]
        name = rng.choice(zips) if zips else name
    path = case_root / name
    data = path.read_bytes()
    names = [Path(name).name, str(Path(name).parent.name)]
    if mutation == "bitflip":
        new, what = _bitflip(rng, data, name)
    elif mutation == "truncate":
        new = data[:_position(rng, data, name)]
        what = f"truncated to {len(new)} of {len(data)} bytes"
    elif mutation == "insert":
        p = _position(rng, data, name)
        junk = bytes(rng.randrange(256) for _ in range(rng.choice([1, 4, 64])))
        new, what = data[:p] + junk + data[p:], f"{len(junk)} bytes inserted at {p}"
    elif mutation == "zero":
        p = _position(rng, data, name)
        n = rng.choice([1, 16, 4096])
        new = data[:p] + bytes(len(data[p:p + n])) + data[p + n:]
        what = f"bytes {p}..{p + n} zeroed"
    elif mutation == "swap":
        if len(files) > 1:  # the same file name of another sample / split, else any other file
            same = [f for f in files if f != name and Path(f).name == Path(name).name]
            kin = [f for f in files if f != name and Path(f).suffix == Path(name).suffix]
            other = rng.choice(same or kin or [f for f in files if f != name])
            a, b = case_root / name, case_root / other
            da, db = a.read_bytes(), b.read_bytes()
            a.write_bytes(db)
            b.write_bytes(da)
            names += [Path(other).name, str(Path(other).parent.name)]
            return f"{name} <-> {other}", names
        donor = rng.choice([f for f in ("checkpoint.pt", "template.npz", "MANO_RIGHT.pkl",
                                        "intersh/meta.json") if f != name])
        new, what = (base / donor).read_bytes(), f"replaced by {donor}"
    elif mutation == "value":
        if name.endswith(".json"):
            new, what = _edit_json(rng, data.decode())
            new = new.encode()
        elif name.endswith(".npz"):
            new, what = _edit_npz(rng, data)
        elif name.endswith(".pkl"):
            new, what = _edit_pickle(rng, data)
        else:
            new, what = _edit_checkpoint(rng, data)
    elif mutation == "header":
        new, what = _edit_header(rng, data, name)
    else:
        raise ValueError(f"unknown mutation {mutation!r}")
    path.write_bytes(new)
    return f"{name}: {what}", names


# ------------------------------------------------------------------ readers


def _finite(*arrays) -> bool:
    import numpy as np

    return all(np.isfinite(np.asarray(a, dtype=np.float64)).all() for a in arrays)


def _cli(argv: list[str]) -> tuple[int, str]:
    from handmesh_tutorial.apps.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue() + err.getvalue()


def _plausible_sample(s: dict) -> str | None:
    import numpy as np

    pts = [s["K"], *(v for v, _ in s["meshes"].values()), *s["joints"].values()]
    if not _finite(*pts):
        return "non-finite values"
    far = max(float(np.abs(v).max()) for v, _ in s["meshes"].values())
    if far > 10:
        return f"a vertex {far:.3g} m away"
    if s["image"].shape != (IMAGE, IMAGE, 3) or s["K"][0, 0] <= 0:
        return f"image {s['image'].shape}, fx {s['K'][0, 0]}"
    return None


def _exactly_the_set(ds) -> str | None:
    """Why ``ds`` is not the corpus's four samples (a copy counted twice, one missing)."""
    got = [int(i) for i in ds.indices]
    return None if got == [0, 1, 2, 3] else f"samples {got}, expected [0, 1, 2, 3]"


def _untouched(case_root: Path) -> list[str]:
    """What a read changed of what it must leave: planted files (`_plant_foreign`) and
    everything under ``case_root/outside``."""
    path = case_root / "planted.json"
    if not path.exists():
        return []
    rec = json.loads(path.read_text())
    if "planted" not in rec:  # the --out and cache targets keep their own record (see below)
        return []
    out = []
    for rel, digest in rec["planted"].items():
        p = case_root / rel
        if digest is None and (p.exists() or p.is_symlink()):
            out.append(f"{rel} created")
        elif digest is not None and (not p.is_file() or _digest(p) != digest):
            out.append(f"{rel} deleted or changed")
    now = _outside_tree(case_root)
    out += [f"outside/{k} deleted or changed" for k in rec["outside"] if now.get(k) !=
            rec["outside"][k]]
    out += [f"outside/{k} created" for k in now if k not in rec["outside"]]
    return out


def read(target: str, case_root: Path, base: Path) -> dict:
    """Run the target's reader on the damaged copy: ``{"ok": True, "implausible": why | None}``
    or ``{"ok": False, "error": type, "message": ..., "code": exit code}``."""
    import numpy as np
    import torch

    torch.set_num_threads(1)
    if target == "intersh-verify":
        from handmesh_tutorial.data import InterSHDataset

        code, text = _cli(["verify", str(case_root / "intersh"), "--quiet"])
        if code != 0:
            return {"ok": False, "code": code, "message": text}
        ds = InterSHDataset(case_root / "intersh")
        why = _exactly_the_set(ds) or next(
            filter(None, (_plausible_sample(ds[i]) for i in range(len(ds)))), None)
        return {"ok": True, "implausible": why}
    if target == "intersh-repair":  # `verify --remove-bad`, then the generate that made it
        from handmesh_tutorial.data import InterSHDataset, generate_dataset
        from handmesh_tutorial.testing import toy_sample

        code, text = _cli(["verify", str(case_root / "intersh"), "--remove-bad", "--quiet"])
        if code != 0:
            return {"ok": False, "code": code, "message": text}
        generate_dataset(case_root / "intersh", functools.partial(toy_sample, image_size=IMAGE),
                         num=4, seed=3, kind="hand-hand", progress=False, durable=False)
        ds = InterSHDataset(case_root / "intersh")
        why = _exactly_the_set(ds) or next(
            filter(None, (_plausible_sample(ds[i]) for i in range(len(ds)))), None)
        return {"ok": True, "implausible": why}
    if target.endswith("-evaluate"):
        data = case_root / ("intersh" if target.startswith("intersh") else "freihand")
        ck = base / ("checkpoint.pt" if target.startswith("intersh") else "checkpoint_mano.pt")
        argv = ["evaluate", "--checkpoint", str(ck), "--data", str(data),
                "--skip-bad", "--threads", "1", "--no-progress", "--batch-size", "4",
                "--device", "cpu"]
        if target.startswith("freihand"):
            argv += ["--dataset", "freihand", "--split", "training"]
        code, text = _cli(argv)
        if code != 0:
            return {"ok": False, "code": code, "message": text}
        if "skipped" in text:
            return {"ok": False, "code": 0, "message": text, "skipped": True}
        if target.startswith("intersh") and "planned samples" not in text and sum(
                p.is_dir() and not p.is_symlink() for p in (data / "samples").iterdir()) < 4:
            return {"ok": True, "implausible": "a root missing planned samples (or one a link "
                                               "outside) scored without saying so"}
        m = re.search(r"MPVPE (\S+) mm", text)
        bad = m is None or not np.isfinite(float(m.group(1)))
        return {"ok": True, "implausible": f"scores: {text[-200:]}" if bad else None}
    if target == "checkpoint":
        from handmesh_tutorial.train import evaluate
        from handmesh_tutorial.train.checkpoints import load_checkpoint

        net, _ = load_checkpoint(case_root / "checkpoint.pt")
        params = [p.detach() for p in net.parameters()]
        if not all(torch.isfinite(p).all() for p in params):
            return {"ok": True, "implausible": "non-finite weights"}
        # and as `handmesh evaluate --checkpoint` uses it, on the pristine data
        ev = evaluate(case_root / "checkpoint.pt", base / "intersh", baseline=False,
                      progress=False, threads=1, device="cpu")
        if not np.isfinite(ev["scores"]["mpjpe"]):
            return {"ok": True, "implausible": f"scores {ev['scores']}"}
        return {"ok": True, "implausible": None}
    if target == "template":
        from handmesh_tutorial.train import TrainConfig
        from handmesh_tutorial.train.templates import build_model_from_config, resolve_template

        t = resolve_template(case_root / "template.npz")
        v, f, r = (np.asarray(x) for x in (t.vertices, t.faces, t.joint_regressor))
        why = None
        if not _finite(v, r) or np.abs(v).max(initial=0) > 1:
            why = "vertices or regressor non-finite or beyond 1 m"
        elif f.size and (f.min() < 0 or f.max() >= len(v)):
            why = f"faces index {f.min()}..{f.max()} of {len(v)} vertices"
        else:
            cfg = TrainConfig(image_size=IMAGE, encoder="resnet10", channels=(4, 4, 8, 8, 8),
                              latent_channels=8, template=str(case_root / "template.npz"))
            net = build_model_from_config(cfg, t).eval()  # as `train --template` does
            with torch.no_grad():
                out = net(torch.zeros(1, 3, IMAGE, IMAGE))
            if not torch.isfinite(out["vertices"]).all():
                why = "non-finite output"
        return {"ok": True, "implausible": why}
    if target == "mano":
        from handmesh_tutorial.hand.mano import load_mano

        m = load_mano(case_root / "MANO_RIGHT.pkl", side="right")
        with torch.no_grad():
            o = m(pose=torch.full((1, 15, 3), 0.2), shape=torch.zeros(1, 10))
        v, j = o.vertices.numpy(), o.joints.numpy()
        why = None
        if not _finite(v, j) or np.abs(v).max() > 1 or np.abs(j).max() > 1:
            why = "posed hand non-finite or beyond 1 m"
        elif np.asarray(m.faces).max() >= m.num_vertices or np.asarray(m.faces).min() < 0:
            why = "faces index missing vertices"
        return {"ok": True, "implausible": why}
    if target == "freihand-read":
        from handmesh_tutorial.data.freihand import FreiHAND

        for split in ("training", "evaluation"):
            ds = FreiHAND(case_root / "freihand", split)
            for i in range(len(ds)):
                s = ds[i]
                pts = [s["K"]] + [s[k] for k in ("joints", "vertices") if s[k] is not None]
                if not _finite(*pts) or max(np.abs(p).max() for p in pts[1:]) > 10:
                    return {"ok": True, "implausible": f"{split} item {i}: absurd values"}
                if split == "training":
                    ds.load_mask(i)
        return {"ok": True, "implausible": None}
    raise ValueError(f"unknown target {target!r}")


def run_case(base: Path, scratch: Path, target: str, mutation: str, n: int) -> dict:
    """Copy, damage and read one case (in the calling process)."""
    rng = random.Random(n)
    case_root = scratch / f"case-{n}"
    shutil.rmtree(case_root, ignore_errors=True)
    case_root.mkdir(parents=True)
    copy_what, files = target_files(base, target)
    src = base / copy_what
    (shutil.copytree if src.is_dir() else shutil.copy)(src, case_root / copy_what)
    try:
        what, names = mutate(rng, mutation, case_root, files, base, target)
    except Exception as e:  # noqa: BLE001 - a mutation that does not apply: not a reader's fault
        return {"outcome": "skipped", "what": f"mutation failed: {type(e).__name__}: {e}"}
    t = time.perf_counter()
    try:
        res = read(target, case_root, base)
    except MemoryError as e:
        res = {"ok": False, "error": "MemoryError", "message": str(e)}
    except Exception as e:  # noqa: BLE001 - classified below
        res = {"ok": False, "error": type(e).__name__, "value_error": isinstance(e, ValueError),
               "message": str(e)[:2000]}
    res.update(what=what, names=names, seconds=round(time.perf_counter() - t, 3))
    res["touched"] = _untouched(case_root)
    res["outcome"] = classify(res)
    shutil.rmtree(case_root, ignore_errors=True)
    return res


def classify(r: dict) -> str:
    if r.get("touched"):  # a file outside the run's own written, moved or deleted
        return "touched"
    if r.get("ok"):
        return "implausible" if r.get("implausible") else "clean"
    if r.get("error") == "MemoryError":
        return "memory"
    named = any(n and n in r.get("message", "") for n in r["names"])
    if "code" in r:  # a CLI run: 0 with the sample skipped, 3..5 (bad input), 6 (a link as
        if r["code"] in (0, 3, 4, 5, 6):  # the lock, a read-only root: the environment)
            return "refused" if named else "unnamed"
        return "memory" if "MemoryError" in r["message"] else "exception"
    if r.get("value_error") or r.get("error") in ("FileNotFoundError",):
        return "refused" if named else "unnamed"
    return "exception"


# ------------------------------------------------------------------ the capped child

_CHILD = r"""
import json, sys
from pathlib import Path
sys.path.insert(0, {here!r})
import fuzz_files as F
base, scratch = Path(sys.argv[1]), Path(sys.argv[2])
for line in sys.stdin:
    t, m, n = json.loads(line)
    r = F.run_case(base, scratch, t, m, n)
    print(json.dumps(r), flush=True)
"""


class Child:
    """One child process reading cases from stdin under a memory cap; restarted after a
    crash or a timeout."""

    def __init__(self, base: Path, scratch: Path, mem_bytes: int, nice: int = 19):
        self.args = (base, scratch, mem_bytes, nice)
        self.proc = None

    def _start(self):
        base, scratch, mem, nice = self.args

        def limit():
            resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
            os.nice(nice)

        env = dict(os.environ, OMP_NUM_THREADS="1", HANDMESH_BUDGET="smoke")
        code = _CHILD.format(here=str(Path(__file__).resolve().parent))
        self.proc = subprocess.Popen([sys.executable, "-c", code, str(base), str(scratch)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env,
                                     preexec_fn=limit)

    def run(self, case: tuple, timeout: float) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.proc.stdin.write(json.dumps(case) + "\n")
        self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        line = self.proc.stdout.readline() if ready else ""
        if line:
            return json.loads(line)
        if ready:  # EOF: the child died
            self.proc.wait()
            err = self.proc.stderr.read()[-400:]
            code = self.proc.returncode
            self.proc = None
            kind = "memory" if "MemoryError" in err or code == -9 else "crash"
            return {"outcome": kind, "message": f"child exit {code}: {err}", "what": "?"}
        self.close()
        return {"outcome": "timeout", "message": f"no answer in {timeout} s", "what": "?"}

    def close(self):
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None


def cases(n: int, seed: int, targets, mutations=MUTATIONS) -> list[tuple[str, str, int]]:
    """``n`` cases, targets and mutations in turn (those of ``mutations`` that apply to each
    target), case ``i`` seeded ``seed * 10**6 + i``."""
    out = []
    for i in range(n):
        t = targets[i % len(targets)]
        ms = [m for m in mutations_of(t) if m in mutations]
        m = ms[(i // len(targets)) % len(ms)]
        out.append((t, m, seed * 10**6 + i))
    return out


def fuzz(base: Path, todo, timeout: float = 60, mem_bytes: int = 2 * 2**30,
         progress=None, nice: int = 19) -> list[dict]:
    """Run ``todo`` cases in a capped child (``nice``: its niceness increment); returns the
    results in order. A ``KeyboardInterrupt`` (SIGINT) ends the run early with the cases done."""
    results = []
    with tempfile.TemporaryDirectory(prefix="fuzz-") as scratch:
        child = Child(base, Path(scratch), mem_bytes, nice)
        try:
            for case in todo:
                r = child.run(case, timeout)
                r.update(target=case[0], mutation=case[1], n=case[2])
                results.append(r)
                if progress:
                    progress(r)
        except KeyboardInterrupt:
            print(f"interrupted: {len(results)} of {len(todo)} cases done", flush=True)
        finally:
            child.close()
    return results


def table(results: list[dict]) -> str:
    counts = defaultdict(Counter)
    for r in results:
        counts[(r["target"], r["mutation"])][r["outcome"]] += 1
    cols = [o for o in OUTCOMES if any(c[o] for c in counts.values())]
    lines = ["| target | mutation | cases | " + " | ".join(cols) + " |",
             "|---|---|---|" + "---|" * len(cols)]
    for (t, m), c in sorted(counts.items(), key=lambda kv: (TARGETS.index(kv[0][0]),
                                                            MUTATIONS.index(kv[0][1]))):
        lines.append(f"| {t} | {m} | {sum(c.values())} | "
                     + " | ".join(str(c[o]) for o in cols) + " |")
    total = Counter(r["outcome"] for r in results)
    lines.append(f"| all | all | {len(results)} | " + " | ".join(str(total[o]) for o in cols)
                 + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=980)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per case")
    ap.add_argument("--mem-gb", type=float, default=2.0, help="the child's RLIMIT_AS")
    ap.add_argument("--targets", default=",".join(TARGETS))
    ap.add_argument("--mutations", default=",".join(MUTATIONS),
                    help="comma-separated (default: all that apply to each target)")
    ap.add_argument("--work", default=None, help="folder of the corpus (kept; default a temp)")
    ap.add_argument("--case", default=None, help="TARGET:MUTATION:N: rerun one case here")
    ap.add_argument("--json", default=None, help="write every result to this file")
    ap.add_argument("--nice", type=int, default=19,
                    help="niceness increment of the reading child (default 19)")
    args = ap.parse_args(argv)
    work = Path(args.work or tempfile.mkdtemp(prefix="fuzz-corpus-"))
    base = build_corpus(work)
    if args.case:
        t, m, n = args.case.split(":")
        with tempfile.TemporaryDirectory() as scratch:
            rng = random.Random(int(n))
            case_root = Path(scratch) / "case"
            case_root.mkdir()
            copy_what, files = target_files(base, t)
            src = base / copy_what
            (shutil.copytree if src.is_dir() else shutil.copy)(src, case_root / copy_what)
            print(mutate(rng, m, case_root, files, base, t))
            try:
                print(read(t, case_root, base))
            except Exception:  # noqa: BLE001 - show it
                traceback.print_exc()
        return 0
    targets = [t for t in args.targets.split(",") if t]
    todo = cases(args.cases, args.seed, targets, args.mutations.split(","))
    t0 = time.perf_counter()

    seen = Counter()

    def show(r):
        seen[r["outcome"]] += 1
        if r["outcome"] not in ("clean", "refused"):
            print(f"{r['outcome']}: {r['target']} {r['mutation']} ({r.get('what', '?')[:100]})"
                  f": {r.get('error', '')} {r.get('message', '')[-300:]!r}", flush=True)
        if seen.total() % 250 == 0:  # a progress line (SIGINT stops with a table of these)
            print(f"{seen.total()} of {len(todo)} cases, {time.perf_counter() - t0:.0f} s: "
                  f"{dict(seen)}", flush=True)

    def stop(signum, frame):  # SIGINT or SIGTERM: stop, then the table of the cases done
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):  # also when started with SIGINT ignored (&)
        signal.signal(sig, stop)
    results = fuzz(base, todo, args.timeout, int(args.mem_gb * 2**30), show, args.nice)
    print(f"\n{len(results)} cases in {time.perf_counter() - t0:.0f} s (seed {args.seed}, "
          f"cap {args.mem_gb:g} GB, timeout {args.timeout:g} s)\n")
    print(table(results))
    failed = [r for r in results if r["outcome"] in FAILURES]
    for r in failed:
        print(f"\nFAIL {r['outcome']}: {r.get('what', '?')}\n  {r.get('message', '')[-400:]}\n"
              f"  reproduce: python benchmarks/fuzz_files.py --work {work} --case "
              f"{r['target']}:{r['mutation']}:{r['n']}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 1 if failed else 0



# ------------------------------------------------------------------ issue 43: planted caches and
# files of the user's in --out. Appended as its own section: it extends TARGETS, FAILURES and the
# dispatch above (target_files, mutate, read, classify) by wrapping them.
#
# ``hierarchy-cache``: the mesh-hierarchy cache of the library's hand (``hierarchy_*.npz``)
# damaged by the mutations above, then read by ``mesh_hierarchy`` and applied by the network's
# ``SparseVertexMap``: the hierarchy must equal a fresh build (``refused`` = rebuilt with a
# warning naming the file; a changed hierarchy is ``implausible``, a crash ``crash``).
# ``out-folder``: files of the user's (named like the command's outputs or not, a symlink to a
# file outside, a sub-folder) planted in the ``--out`` of ``train``, ``evaluate`` or ``demo``; the
# command must refuse the folder naming them (exit 5) or, in a folder that is its own, leave
# them (a link named like one of its outputs there is refused, exit 5, named). A planted file
# changed, removed or written through is the failure ``clobbered``.

PLANTED_TARGETS = ("hierarchy-cache", "out-folder")
TARGETS = (*TARGETS, *PLANTED_TARGETS)
FAILURES = (*FAILURES, "clobbered")
OUTCOMES = ("clean", "refused", *FAILURES, "skipped")

_OUT_COMMANDS = ("train", "evaluate", "demo", "evaluate-own")
_OUT_NAMES = {"train": ["config.json", "metrics.csv", "steps.csv", "checkpoint_best.pt"],
              "evaluate": ["eval.json", "predictions.npz", "vr.png", "pred.json"],
              "demo": ["report.md", "loss.png", "demo.json", "overlays.png"]}
_base_target_files, _base_mutate, _base_read, _base_classify = (target_files, mutate, read,
                                                                 classify)


def _planted_corpus(base: Path) -> None:
    """The pristine cache under ``base/cache`` and an empty ``base/out`` (made once)."""
    if not list((base / "cache").glob("hierarchy_*.npz")):
        from handmesh_tutorial.hand import HandModel
        from handmesh_tutorial.nn.hierarchy import mesh_hierarchy

        t = HandModel().template
        mesh_hierarchy(t.vertices, t.faces, cache_dir=base / "cache")
    (base / "out").mkdir(exist_ok=True)


def target_files(base: Path, target: str) -> tuple[str, list[str]]:  # noqa: F811 - extended
    if target == "hierarchy-cache":
        _planted_corpus(base)
        return "cache", [str(p.relative_to(base)) for p in sorted((base / "cache").iterdir())]
    if target == "out-folder":
        _planted_corpus(base)
        return "out", ["out"]
    return _base_target_files(base, target)


def _digest_file(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def _plant_user_files(rng: random.Random, mutation: str, case_root: Path) -> tuple[str, list]:
    """Plant the user's files in ``case_root/out`` (the mutation picks their contents);
    ``planted.json`` records what must stay untouched."""
    out = case_root / "out"
    command = rng.choice(_OUT_COMMANDS)
    own = command == "evaluate-own"
    names = [] if own else rng.sample(_OUT_NAMES[command], rng.randrange(1, 3))
    names += rng.sample(["notes.txt", "photo.jpg", "my results.csv", "données.md"],
                        rng.randrange(0 if names else 1, 3))
    outside = case_root / "outside.txt"
    outside.write_text("a file outside --out\n")
    for name in names:
        data = {"bitflip": b"\x00\x01", "truncate": b"", "value": b'{"config": {}}'}.get(
            mutation, f"the user's own {name} ({mutation})\n".encode())
        (out / name).write_bytes(data)
    if not own and rng.random() < 0.5:  # a link named like an output, to a file outside
        link = rng.choice(_OUT_NAMES[command])
        if link not in names:
            (out / link).symlink_to(outside)
            names.append(link)
    if not own and rng.random() < 0.3:
        (out / "sub").mkdir()
        (out / "sub" / "keep.txt").write_text("mine")
        names.append("sub")
    if own:  # the command's own folder (its marker): the user's other files are left there
        (out / ".handmesh-evaluate").write_text("{}")
        if rng.random() < 0.5:  # ... but a link where it writes is refused, never written over
            link = rng.choice(_OUT_NAMES["evaluate"])
            (out / link).symlink_to(outside)
            names.append(link)
    record = {"command": command.removesuffix("-own"), "own": own,
              "files": {str(p.relative_to(case_root)): _digest_file(p)
                        for p in [outside, *sorted(out.rglob("*"))]
                        if p.is_file() and not p.name.startswith(".handmesh-")}}
    (case_root / "planted.json").write_text(json.dumps(record))
    return f"{command}: {names}", names


def mutate(rng: random.Random, mutation: str, case_root: Path, files: list[str],  # noqa: F811
           base: Path, target: str) -> tuple[str, list[str]]:
    if target == "out-folder":
        return _plant_user_files(rng, mutation, case_root)
    return _base_mutate(rng, mutation, case_root, files, base, target)


def _read_cache(case_root: Path) -> dict:
    import warnings

    import numpy as np
    import torch

    from handmesh_tutorial.hand import HandModel
    from handmesh_tutorial.nn.blocks import SparseVertexMap
    from handmesh_tutorial.nn.hierarchy import mesh_hierarchy

    t = HandModel().template
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        h = mesh_hierarchy(t.vertices, t.faces, cache_dir=case_root / "cache")
    ref = mesh_hierarchy(t.vertices, t.faces, use_cache=False)
    for m in h.up + h.down:  # as the network applies them (a bad index crashed scipy here)
        SparseVertexMap(m)(torch.ones(1, m.shape[1], 2))
    same = all(np.array_equal(a.toarray(), b.toarray()) for a, b in
               zip(h.up + h.down, ref.up + ref.down, strict=True)) and all(
        np.array_equal(a, b) for a, b in zip(h.faces + h.vertices, ref.faces + ref.vertices,
                                             strict=True))
    if not same:
        return {"ok": True, "implausible": "the planted cache changed the hierarchy"}
    warned = [str(w.message) for w in caught if "mesh-hierarchy cache" in str(w.message)]
    if warned:  # rebuilt, with a warning naming the file
        return {"ok": False, "value_error": True, "message": warned[0]}
    return {"ok": True, "implausible": None}


def _read_out(case_root: Path, base: Path) -> dict:
    record = json.loads((case_root / "planted.json").read_text())
    out = str(case_root / "out")
    command = record["command"]
    if command == "train":
        argv = ["train", "--data", str(base / "intersh"), "--out", out, "--epochs", "1",
                "--batch-size", "4", "--image-size", str(IMAGE), "--encoder", "resnet10",
                "--channels", "4,4,8,8,8", "--latent-channels", "8", "--threads", "1",
                "--no-progress", "--no-fsync"]
    elif command == "evaluate":
        argv = ["evaluate", "--checkpoint", str(base / "checkpoint.pt"), "--data",
                str(base / "intersh"), "--out", out, "--threads", "1", "--no-progress",
                "--batch-size", "4", "--device", "cpu"]
    else:
        argv = ["demo", "--out", out, "--budget", "smoke", "--no-progress"]
    code, text = _cli(argv)
    changed = [name for name, digest in record["files"].items()
               if not (case_root / name).is_file() or _digest_file(case_root / name) != digest]
    res = {"ok": code == 0, "code": code, "message": text, "implausible": None}
    if changed:
        res["clobbered"] = changed
    if record["own"] and code == 0 and not (case_root / "out" / "eval.json").is_file():
        res["implausible"] = "evaluate exited 0 without eval.json"
    return res


def read(target: str, case_root: Path, base: Path) -> dict:  # noqa: F811 - extended
    if target == "hierarchy-cache":
        return _read_cache(case_root)
    if target == "out-folder":
        return _read_out(case_root, base)
    return _base_read(target, case_root, base)


def classify(r: dict) -> str:  # noqa: F811 - extended
    if r.get("clobbered"):
        r["message"] = f"changed: {r['clobbered']}; {r.get('message', '')}"
        return "clobbered"
    if r.get("code") == 5 and not r.get("ok"):
        named = any(n and n in r.get("message", "") for n in r["names"])
        return "refused" if named else "unnamed"
    return _base_classify(r)


if __name__ == "__main__":
    sys.exit(main())
