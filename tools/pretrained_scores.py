"""Score a network file on fresh scenes of a seed the project never used, beside both constant
hands, the previous shipped file and a demo run, and write the tables the docs print.

Usage::

    PYOPENGL_PLATFORM=egl python tools/pretrained_scores.py --out runs/scores [--seed N|random]
        [--per-kind 100] [--checkpoint pretrained] [--previous FILE|git|none]
        [--demo runs/demo] [--train-data ROOT] [--write-docs] [--from-scores OUT/scores.json]

What it does, in order:

1. Test scenes: ``--per-kind`` VR-balanced scenes of each kind (224 px) with seeds ``S``,
   ``S + 1``, ``S + 2`` for hand-hand, hand-object and hand-chain. ``--seed random`` draws ``S``
   (``secrets``) so that no training run can have used it; the seed is recorded.
2. The mean training hand: the Procrustes mean of the network's own training scenes, from
   ``--train-data`` or else from the first ``--mean-scenes`` scenes of the training seed the file
   records (the same scenes: a sample depends only on its seed and index).
3. Each network (the file, the previous shipped file) on every test scene, with the rest hand
   and the mean hand on the same scenes; paired 95 % intervals per kind and pooled.
4. With ``--demo DIR`` (a ``handmesh demo`` folder): the file and the demo's own network on the
   demo's held-out scenes, paired.
5. ``OUT/scores.json`` (every number above and the per-scene errors) and ``OUT/scores.md``;
   ``--write-docs`` puts the tables between the ``<!-- pretrained-scores ... -->`` markers of
   README.md, docs/index.md and docs/concepts/pretrained.md (`render_block`).
"""

from __future__ import annotations

import argparse
import json
import re
import secrets
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("hand-hand", "hand-object", "hand-chain")
DOCS = ("README.md", "docs/index.md", "docs/concepts/pretrained.md")
MARKER = re.compile(r"(<!-- pretrained-scores (?P<what>[a-z-]+) -->\n)(?P<body>.*?)"
                    r"(<!-- /pretrained-scores -->)", re.S)


def _interval(d: dict) -> str:
    return f"{d['difference']:+.2f} ({d['low']:+.2f} to {d['high']:+.2f})"


def _than(d: dict) -> str:
    """``"2.46 mm (2.17 to 2.76) below"`` for a paired difference, or ``above``."""
    if d["difference"] < 0:
        return f"{-d['difference']:.2f} mm ({-d['high']:.2f} to {-d['low']:.2f}) below"
    return f"{d['difference']:.2f} mm ({d['low']:.2f} to {d['high']:.2f}) above"


def _previous_file(out: Path) -> Path | None:
    """The newest committed shipped network whose bytes differ from the installed one."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from pretrained_speed import previous_file

    from handmesh_tutorial.pretrained import pretrained_path

    found = previous_file(pretrained_path(), out)
    return None if found is None else found[0]


def _generate(root: Path, kind: str, num: int, seed: int, balance: bool, workers: int) -> None:
    from handmesh_tutorial.scenes import generate_interactions

    generate_interactions(root, kind, num, seed, image_size=224, workers=workers,
                          balance_vr=balance, progress=True)


def score(checkpoint: str, out: Path, seed: int, per_kind: int, *, previous: str | None,
          demo: Path | None, train_data: Path | None, mean_scenes: int, workers: int) -> dict:
    """Every number of the module docstring's steps 1-4, as one JSON-able dict."""
    import handmesh_tutorial.train as T
    from handmesh_tutorial.data import InterSHTorchDataset
    from handmesh_tutorial.metrics.intervals import paired_difference
    from handmesh_tutorial.train.checkpoints import _read_checkpoint

    ck = _read_checkpoint(checkpoint)
    made = ck.get("pretrained") or {}
    if train_data is None:
        train_seed = (made.get("data") or {}).get("train_seed")
        if train_seed is None:
            raise SystemExit(f"{checkpoint} records no training seed: give --train-data")
        train_data = out / "data" / f"train_seed{train_seed}"
        _generate(train_data, "mixed", mean_scenes, int(train_seed), False, workers)
    train_set = InterSHTorchDataset(train_data, image_size=64, train=False)
    mean = T.mean_hand(train_set)

    nets = {"file": checkpoint, **({"previous": previous} if previous else {})}
    sizes = {checkpoint: ck["config"]["image_size"]}  # each file read once here
    if previous:
        sizes[previous] = _read_checkpoint(previous)["config"]["image_size"]
    result = {"checkpoint": str(checkpoint) if checkpoint == "pretrained" else Path(checkpoint).name,
              "seed": seed, "seeds": {k: seed + i for i, k in enumerate(KINDS)},
              "per_kind": per_kind, "mean_hand_from": str(train_data.name),
              "mean_hand_scenes": len(train_set),
              "made": {"data": made.get("data"), "date": made.get("date"),
                       "library_version": ck.get("library_version")},
              "kinds": {}}
    pooled: dict[str, list] = {}
    for i, kind in enumerate(KINDS):
        root = out / "data" / f"{kind}_seed{seed + i}"
        _generate(root, kind, per_kind, seed + i, True, workers)
        row: dict = {}
        for name, path in nets.items():
            ev = T.evaluate(path, str(root), image_size=sizes[path], device="cpu", progress=False,
                            mean_hand=mean, baseline=name == "file")
            row[name] = _summary(ev["scores"], ev["per_sample"])
            if name == "file":
                row["rest hand"] = _summary(ev["baseline"]["scores"], ev["baseline"]["per_sample"])
                row["mean hand"] = _summary(ev["mean_hand_baseline"]["scores"],
                                            ev["mean_hand_baseline"]["per_sample"])
        for name in row:
            pooled.setdefault(name, []).append(row[name]["per_scene"])
        row["intervals"] = _intervals(row, paired_difference)
        result["kinds"][kind] = row
    all_rows = {name: _pool(parts) for name, parts in pooled.items()}
    all_rows["intervals"] = _intervals(all_rows, paired_difference)
    result["all"] = all_rows
    if demo is not None:
        mine = demo / "train" / "checkpoint_best.pt"
        sizes[mine] = _read_checkpoint(mine)["config"]["image_size"]
        test = str(demo / "data" / "test")
        evs = {name: T.evaluate(path, test, device="cpu", progress=False, baseline=False,
                                image_size=sizes[path])
               for name, path in (("file", checkpoint), ("demo", mine))}
        rows = {n: _summary(e["scores"], e["per_sample"]) for n, e in evs.items()}
        result["demo"] = {"folder": demo.name, "file": rows["file"], "demo": rows["demo"],
                          "file - demo": paired_difference(rows["file"]["per_scene"]["pa_mpjpe"],
                                                           rows["demo"]["per_scene"]["pa_mpjpe"])}
    return result


def _summary(scores: dict, per_sample: dict) -> dict:
    keep = ("pa_mpjpe", "pa_mpvpe", "mpjpe", "roughness_deg", "flipped")
    return {"pa_mpjpe": float(scores["pa_mpjpe"]), "pa_mpvpe": float(scores["pa_mpvpe"]),
            "mpjpe": float(scores["mpjpe"]),
            "roughness_deg": float(scores.get("roughness_deg", float("nan"))),
            "flipped": float(scores.get("flipped", float("nan"))),
            "per_scene": {k: np.asarray(per_sample[k], float).round(4).tolist()
                          for k in keep if k in per_sample}}


def _pool(parts: list[dict]) -> dict:
    per = {k: sum((p[k] for p in parts), []) for k in parts[0]}
    out = {k: float(np.mean(v)) for k, v in per.items()}
    return {**out, "per_scene": per}


def _intervals(rows: dict, paired_difference) -> dict:
    a = rows["file"]["per_scene"]["pa_mpjpe"]
    return {f"file - {name}": paired_difference(a, rows[name]["per_scene"]["pa_mpjpe"])
            for name in ("rest hand", "mean hand", "previous") if name in rows}


def render_block(result: dict, what: str) -> str:
    """The markdown that ``--write-docs`` puts between the ``<!-- pretrained-scores WHAT -->``
    markers: ``table`` (per kind and pooled) or ``summary`` (one sentence)."""
    groups = [(k, result["kinds"][k]) for k in KINDS] + [("all", result["all"])]
    if what == "summary":
        a = result["all"]
        ratio = a["file"]["pa_mpjpe"] / a["rest hand"]["pa_mpjpe"]
        text = (f"On {3 * result['per_kind']} fresh scenes (seed {result['seed']}, never used "
                f"for training) it scores PA-MPJPE {a['file']['pa_mpjpe']:.2f} mm, "
                f"{ratio:.2f}x the rest hand ({a['rest hand']['pa_mpjpe']:.2f} mm) and "
                f"{_than(a['intervals']['file - mean hand'])} the mean training hand "
                f"({a['mean hand']['pa_mpjpe']:.2f} mm)")
        if "demo" in result:
            d = result["demo"]
            text += (f"; on the demo's {len(d['file']['per_scene']['pa_mpjpe'])} held-out "
                     f"scenes {d['file']['pa_mpjpe']:.2f} mm "
                     f"against the demo network's {d['demo']['pa_mpjpe']:.2f} mm, paired "
                     f"difference {_interval(d['file - demo'])}"
                     + (", not told apart" if d["file - demo"]["low"] <= 0
                        <= d["file - demo"]["high"] else ""))
        return text + ". Intervals: paired, 95 %.\n"
    if what != "table":
        raise ValueError(f"unknown block {what!r}: 'table' or 'summary'")
    prev = "previous" in result["all"]
    head = ("| kind | scenes | shipped | rest hand | mean hand | shipped / rest | shipped - mean "
            "(95 %) |" + (" previous file | shipped - previous (95 %) |" if prev else "")
            + " MPJPE shipped / rest (mm) | roughness (deg) | flipped faces |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for name, g in groups:
        f, r, m = g["file"], g["rest hand"], g["mean hand"]
        cells = [name, str(len(f["per_scene"]["pa_mpjpe"])), f"{f['pa_mpjpe']:.2f}",
                 f"{r['pa_mpjpe']:.2f}", f"{m['pa_mpjpe']:.2f}",
                 f"{f['pa_mpjpe'] / r['pa_mpjpe']:.2f}",
                 _interval(g["intervals"]["file - mean hand"])]
        if prev:
            cells += [f"{g['previous']['pa_mpjpe']:.2f}",
                      _interval(g["intervals"]["file - previous"])]
        cells += [f"{f['mpjpe']:.0f} / {r['mpjpe']:.0f}", f"{f['roughness_deg']:.1f}",
                  f"{100 * f['flipped']:.2f} %"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_docs(result: dict, root: Path = ROOT) -> list[str]:
    """Replace every marked block in `DOCS` (each file written atomically); returns the files
    changed."""
    from handmesh_tutorial._io import atomic_write_text

    changed = []
    for rel in DOCS:
        path = root / rel
        text = path.read_text()
        new = MARKER.sub(lambda m: m.group(1) + render_block(result, m.group("what"))
                         + m.group(4), text)
        if new != text:
            atomic_write_text(path, new)
            changed.append(rel)
    return changed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--seed", default="random", help="test-scene seed, or 'random' (default)")
    p.add_argument("--per-kind", type=int, default=100)
    p.add_argument("--checkpoint", default="pretrained")
    p.add_argument("--previous", default="git",
                   help="the file to compare with: a path, 'git' (the previous shipped file in "
                        "git history, default) or 'none'")
    p.add_argument("--demo", type=Path, help="a handmesh demo folder to compare with")
    p.add_argument("--train-data", type=Path, help="the network's training scenes (mean hand)")
    p.add_argument("--mean-scenes", type=int, default=600)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--write-docs", action="store_true")
    p.add_argument("--from-scores", type=Path, metavar="JSON",
                   help="no scoring: render (and with --write-docs write) an earlier scores.json")
    a = p.parse_args(argv)
    if a.from_scores is not None:
        result = json.loads(a.from_scores.read_text())
        print(render_block(result, "table") + "\n" + render_block(result, "summary"))
        if a.write_docs:
            print("rewrote:", ", ".join(write_docs(result)) or "nothing (no markers)")
        return 0
    seed = secrets.randbelow(2**31 - 10) + 10_000 if a.seed == "random" else int(a.seed)
    a.out.mkdir(parents=True, exist_ok=True)
    previous = {"git": None, "none": None}.get(a.previous, a.previous)
    if a.previous == "git":
        found = _previous_file(a.out / "previous_msmr_net.pt")
        previous = None if found is None else str(found)
    result = score(a.checkpoint, a.out, seed, a.per_kind, previous=previous, demo=a.demo,
                   train_data=a.train_data, mean_scenes=a.mean_scenes, workers=a.workers)
    result["commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                      capture_output=True, text=True).stdout.strip() or None
    (a.out / "scores.json").write_text(json.dumps(result, indent=1) + "\n")
    md = render_block(result, "table") + "\n" + render_block(result, "summary")
    (a.out / "scores.md").write_text(md)
    print(md)
    if a.write_docs:
        print("rewrote:", ", ".join(write_docs(result)) or "nothing (no markers)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
