"""Each notebook's "Before you start" cell and the Learning path page, with measured runtimes.

Usage (from the repository root, ``make execute-notebooks`` runs both steps):

    python tools/notebook_runtimes.py --measure-smoke [notebooks/NN_x.ipynb ...]
    python tools/notebook_runtimes.py            # rewrite the header cells and the page only
    python tools/notebook_runtimes.py --page-only   # rewrite the Learning path page only

``--measure-smoke`` executes each notebook top to bottom under ``HANDMESH_BUDGET=smoke`` with
nbclient, in memory (the committed file keeps its ``default`` outputs), and records the wall time
in the notebook's metadata (``metadata.handmesh.runtime_s.smoke``). The ``default`` runtime is read
from the committed run itself: nbclient/nbconvert store per-cell timestamps
(``metadata.execution``); the runtime is the first cell's start to the last cell's reply (kernel
start excluded). The header cell (second cell, marked with ``HEADER_MARK``) and the table in
``notebooks/learning_path.md`` (between ``<!-- path:start -->`` and ``<!-- path:end -->``) are
then rewritten from those numbers and the tables below. Only Markdown cells and metadata change:
outputs and execution counts are kept.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import datetime
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
NB_DIR = ROOT / "notebooks"
PATH_PAGE = NB_DIR / "learning_path.md"
HEADER_MARK = "<!-- before-you-start: written by tools/notebook_runtimes.py; edit the tables there -->"
MACHINE = "the 2-core laptop-class CPU that executed the committed outputs"

#: What each notebook teaches, in one line (the learning goals in its first cell say it in full).
LEARN = {
    "00_quickstart": "the whole pipeline in a few library calls: generate scenes, train MSMR-Net "
                     "briefly, predict and evaluate per visibility-ratio bin",
    "01_hand_model": "the MakeHuman hand on MANO's 16-joint tree: template, skinning, shape, "
                     "the 21 keypoints, left/right mirroring",
    "02_local_coordinate_systems": "a local coordinate system per joint, joint-angle limits and "
                                   "random valid poses (the generator's step 4)",
    "03_cylinder_collision": "line geometry (Plücker coordinates), the exact Ketchel–Larochelle "
                             "cylinder test, capsules, and a hand as 20 cylinders",
    "04_generating_interactions": "the six-step INTER-SH algorithm: place, approach, collide, "
                                  "articulate hand-hand, hand-object and hand-chain scenes",
    "05_rendering_and_visibility": "rendering scenes and label masks with pyrender, and the "
                                   "visibility ratio (VR) with its four bins",
    "06_mesh_hierarchy_and_spiral_conv": "the QSlim mesh hierarchy (vertex subsets, barycentric "
                                         "up-sampling) and SpiralConv",
    "07_multi_path_decoder": "single- vs multi-path spiral decoders, multi-resolution fusion, "
                             "the encoder's 2D joints and the coarse-mesh attention of the "
                             "pretrained network, and the fit test of the mesh decoder",
    "08_training": "a full MSMR-Net training run on the CPU with the paper's protocol (pretrained "
                   "encoder, decoder from scratch): loss curves, checkpoints, predictions",
    "09_evaluation": "FreiHAND-exact metrics (Procrustes with and without reflection, F-scores, "
                     "PCK/AUC) and the per-VR-bin table of a trained model",
    "10_ablation": "the paper's Table 3 at equal depth (single path, multi-path, multi-path + "
                   "attention) in two training configurations, on a decoder-neutral encoder",
    "11_your_own_data": "the shipped network on a photo file (hand box, crop, left-hand "
                        "mirroring), a FreiHAND-format folder read, scored and written back as "
                        "pred.json, and a MANO-format file as the template",
}
#: Notebooks to read first (the concepts each one builds on).
PREREQS = {
    "00_quickstart": [],
    "01_hand_model": [],
    "02_local_coordinate_systems": ["01_hand_model"],
    "03_cylinder_collision": ["01_hand_model"],
    "04_generating_interactions": ["02_local_coordinate_systems", "03_cylinder_collision"],
    "05_rendering_and_visibility": ["04_generating_interactions"],
    "06_mesh_hierarchy_and_spiral_conv": ["01_hand_model"],
    "07_multi_path_decoder": ["06_mesh_hierarchy_and_spiral_conv"],
    "08_training": ["05_rendering_and_visibility", "07_multi_path_decoder"],
    "09_evaluation": ["08_training"],
    "10_ablation": ["08_training"],
    "11_your_own_data": ["09_evaluation"],
}
#: Whether a notebook needs a trained model, and where it gets it.
TRAINED = {
    "00_quickstart": "trains a small one itself, and loads the shipped pretrained network",
    "07_multi_path_decoder": "loads the shipped pretrained network (section 4, one image)",
    "08_training": "trains it (this is the training notebook)",
    "09_evaluation": "yes: notebook 08's checkpoint (`runs/train08_<budget>/`; trains it if "
                     "absent), and the shipped pretrained network",
    "10_ablation": "trains 18 runs (3 variants x 3 seeds x 2 configurations) from the "
                   "decoder-neutral encoder",
    "11_your_own_data": "the shipped pretrained network; trains a tiny one on a MANO-format "
                        "template",
}

#: Where the committed ``default`` run picked up what an earlier run had left in ``notebooks/runs/``
#: (the notebooks reuse data sets and checkpoints): its time is then less than a first run's.
REUSED = {
    "00_quickstart": "the committed run generated its scenes and trained its ten steps "
                     "itself; a rerun reuses them from `notebooks/runs/`",
    "08_training": "the committed run generated its INTER-SH set too (about 4 min of the "
                   "total); a later run reuses it from `notebooks/runs/` and only trains",
    "09_evaluation": "reuses notebook 08's data set and checkpoint; it made section 5's 300 "
                     "test scenes and 600 training-set scenes itself",
    "10_ablation": "reuses notebook 08's data set; the committed run read back the 18 runs "
                   "that `benchmarks/dev/table3_two_configs.py` had trained into "
                   "`notebooks/runs/` (the same calls: 17 minutes for seeds 0-1 and "
                   "28 for seed 2 on the shared 2-core machine), and only evaluated them",
}


#: The same, in a few words, for the Learning path table.
TRAINED_SHORT = {
    "00_quickstart": "trains a small one; the pretrained one",
    "07_multi_path_decoder": "the pretrained one",
    "08_training": "trains it",
    "09_evaluation": "08's checkpoint; the pretrained one",
    "10_ablation": "trains 18",
    "11_your_own_data": "the pretrained one; trains a tiny one",
}


def title(nb) -> str:
    first = nb.cells[0].source.lstrip()
    return first.splitlines()[0].lstrip("# ").strip()


def short(name: str) -> str:
    return f"`{name}.ipynb`"


def default_seconds(nb) -> float | None:
    """First cell's start to the last cell's reply, from the committed run's cell timestamps."""
    starts, ends = [], []
    for c in nb.cells:
        ex = c.get("metadata", {}).get("execution", {})
        if c.cell_type == "code" and "iopub.execute_input" in ex and "shell.execute_reply" in ex:
            starts.append(datetime.fromisoformat(ex["iopub.execute_input"].replace("Z", "+00:00")))
            ends.append(datetime.fromisoformat(ex["shell.execute_reply"].replace("Z", "+00:00")))
    if not starts:
        return None
    return (max(ends) - min(starts)).total_seconds()


def fmt(seconds: float | None) -> str:
    if seconds is None:
        return "not measured"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def runtimes(nb) -> dict:
    meta = nb.metadata.setdefault("handmesh", {}).setdefault("runtime_s", {})
    d = default_seconds(nb)
    if d is not None:
        meta["default"] = round(d, 1)
    return meta


def busy(rt: dict) -> str:
    m = rt.get("smoke_machine") or {}
    text = ""
    if m and m["load"] > m["cores"]:
        text = (f"; the smoke run shared the machine (load {m['load']} on {m['cores']} cores), so "
                "that number is an upper bound")
    # a note recorded by hand in the metadata when the committed default run shared the machine
    if rt.get("default_note"):
        text += f"; {rt['default_note']}"
    return text


def header_cell_text(stem: str, rt: dict) -> str:
    pre = PREREQS[stem]
    prereq = ", ".join(short(p) for p in pre) if pre else "none: start here"
    lines = [
        HEADER_MARK,
        "**Before you start**",
        "",
        f"- **You will learn:** {LEARN[stem]}.",
        f"- **Prerequisites:** {prereq}"
        + (" (the *Learning path* page, `notebooks/learning_path.md`, shows the order)."
           if pre else "."),
        f"- **Runtime on a laptop CPU:** {fmt(rt.get('default'))} under `default` (the outputs shown "
        f"here), {fmt(rt.get('smoke'))} under `HANDMESH_BUDGET=smoke`; measured on {MACHINE}"
        + (f" ({REUSED[stem]})" if stem in REUSED else "") + busy(rt) + ".",
        f"- **Needs a trained model:** {TRAINED.get(stem, 'no')}.",
    ]
    return "\n".join(lines)


def update_notebook(path: Path, smoke_seconds: float | None = None, write: bool = True) -> dict:
    """Rewrite a notebook's header cell (unless ``write`` is false); returns its table row."""
    nb = nbformat.read(path, as_version=4)
    stem = path.stem
    rt = runtimes(nb)
    if smoke_seconds is not None:
        rt["smoke"] = round(smoke_seconds, 1)
        rt["smoke_machine"] = machine_load()
    text = header_cell_text(stem, rt)
    if len(nb.cells) > 1 and nb.cells[1].cell_type == "markdown" and nb.cells[1].source.startswith(
            HEADER_MARK):
        nb.cells[1].source = text
    else:
        nb.cells.insert(1, nbformat.v4.new_markdown_cell(text))
    if write:
        path.write_text(nbformat.writes(nb) + "\n", encoding="utf-8")
    return {"stem": stem, "title": title(nb), **rt}


def measure_smoke(path: Path, timeout: int = 1800) -> float:
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    os.environ["HANDMESH_BUDGET"] = "smoke"
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    client.execute()
    return time.perf_counter() - t0


def machine_load() -> dict:
    """Load average and core count while measuring: a busy machine makes the numbers pessimistic."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        return {}
    return {"load": round(load, 1), "cores": os.cpu_count() or 1}


def path_row_link(row: dict) -> str:
    """The first cell of a Learning path row: the notebook's number, as the *read first* column
    and the site's navigation (``NN · Title``) name it, then its title, linked."""
    return f"**[{row['stem'][:2]} · {row['title']}]({row['stem']}.ipynb)**"


def write_path_page(rows: list[dict]) -> None:
    table = [
        "| notebook: what you will learn | read first | `default` | `smoke` | trained model |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        pre = ", ".join(p[:2] for p in PREREQS[r["stem"]]) or "–"
        table.append(
            f"| {path_row_link(r)}<br>{LEARN[r['stem']]} | {pre} | "
            f"{fmt(r.get('default'))}{'*' if r['stem'] in REUSED else ''} | {fmt(r.get('smoke'))} | "
            f"{TRAINED_SHORT.get(r['stem'], 'no')} |"
        )
    total_d = sum(r.get("default") or 0 for r in rows)
    total_s = sum(r.get("smoke") or 0 for r in rows)
    table.append(f"| **all, in order** | | **{fmt(total_d)}** | **{fmt(total_s)}** | |")
    table.append("")
    table.append("\\* The committed `default` run reused data sets or checkpoints an earlier run had "
                 "left in `notebooks/runs/` (" + "; ".join(f"{k[:2]}: {v}" for k, v in REUSED.items())
                 + "). A first run from nothing takes longer.")
    loads = [r["smoke_machine"] for r in rows if (r.get("smoke_machine") or {}).get("load", 0)
             > (r.get("smoke_machine") or {}).get("cores", 1e9)]
    if loads:
        table.append("")
        table.append(f"The `smoke` column was measured on a machine shared with other jobs (load "
                     f"average {max(m['load'] for m in loads)} on {loads[0]['cores']} cores): "
                     "read it as an upper bound for a quiet laptop.")
    text = PATH_PAGE.read_text(encoding="utf-8")
    start, end = "<!-- path:start -->", "<!-- path:end -->"
    head, _, rest = text.partition(start)
    _, _, tail = rest.partition(end)
    PATH_PAGE.write_text(head + start + "\n" + "\n".join(table) + "\n" + end + tail, encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("notebooks", nargs="*", type=Path)
    ap.add_argument("--measure-smoke", action="store_true",
                    help="execute the notebooks under HANDMESH_BUDGET=smoke and record the time")
    ap.add_argument("--page-only", action="store_true",
                    help="rewrite the Learning path page only (the notebooks are read, not written)")
    args = ap.parse_args(argv)
    if args.page_only and args.measure_smoke:
        ap.error("--page-only writes no notebook, so it cannot record --measure-smoke times")
    chosen = {p.resolve() for p in args.notebooks}
    rows = []
    for path in sorted(NB_DIR.glob("[0-9][0-9]_*.ipynb")):
        smoke = None
        if args.measure_smoke and (not chosen or path.resolve() in chosen):
            print(f"{path.name}: executing under smoke ...", flush=True)
            smoke = measure_smoke(path)
            print(f"{path.name}: {smoke:.1f} s", flush=True)
        row = update_notebook(path, smoke, write=not args.page_only)
        rows.append(row)
        print(f"{path.name}: default {fmt(row.get('default'))}, smoke {fmt(row.get('smoke'))}")
    write_path_page(rows)
    print(f"updated {0 if args.page_only else len(rows)} notebook headers and "
          f"{PATH_PAGE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
