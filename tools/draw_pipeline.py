"""Draw the module pipeline of the home page as an SVG (matplotlib only; no CDN, no mermaid).

Usage: ``python tools/draw_pipeline.py [docs/img/pipeline.svg]``. The output is committed; rerun
this script when the data flow in ``shared/DESIGN.md`` / ``docs/index.md`` changes. The same
seed-free drawing gives the same bytes (fixed SVG hash salt, no date).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

# name: (column, row, first line, second line); rows from the top (0) down
BOXES = {
    "hand": (0, 0, "hand/, mano/", "MakeHuman hand, skin"),
    "lcs": (1, 0, "lcs/", "local frames, limits"),
    "col": (2, 0, "collision/", "cylinders, capsules"),
    "obj": (3, 0, "objects/", "objects, chain"),
    "inter": (4, 0, "scenes/", "6-step algorithm"),
    "render": (5, 0, "render/", "RGB + label masks"),
    "vis": (6, 0, "visibility.py", "VR metric"),
    "data": (7, 0, "data/", "INTER-SH on disk"),
    "samp": (0, 1, "nn/hierarchy/", "mesh hierarchy"),
    "spiral": (1, 1, "nn/spiral.py", "SpiralConv"),
    "blocks": (2, 1, "nn/blocks.py", "residual, fusion"),
    "dec": (3, 1, "nn/decoder.py", "single / multi-path"),
    "model": (5, 1, "nn/model.py", "MSMRNet"),
    "enc": (5, 2, "nn/encoder.py", "ResNet, HRNet"),
    "train": (7, 1, "train/", "loop, checkpoints"),
    "metrics": (7, 2, "metrics/", "FreiHAND-exact, VR bins"),
}
EDGES = [
    ("hand", "lcs"), ("lcs", "col"), ("col", "obj"), ("obj", "inter"), ("inter", "render"),
    ("render", "vis"), ("vis", "data"), ("samp", "spiral"), ("spiral", "blocks"),
    ("blocks", "dec"), ("dec", "model"), ("enc", "model"), ("data", "train"), ("model", "train"),
    ("train", "metrics"),
]
# background bands: (label, first column, last column, first row, last row, colour)
GROUPS = [
    ("INTER-SH generator (data)", 0, 7, 0, 0, "#e3f2fd"),
    ("MSMR-Net (model)", 0, 5, 1, 2, "#fff3e0"),
    ("training, evaluation", 7, 7, 1, 2, "#e8f5e9"),
]
LABEL_AT_BOTTOM = {"training, evaluation"}  # the arrow from data/ comes in at the top
DX, DY = 2.0, 1.25  # grid pitch
W, H = 1.72, 0.78  # box size


def centre(key: str) -> tuple[float, float]:
    col, row = BOXES[key][:2]
    return col * DX, -row * DY


def draw(path: Path) -> None:
    plt.rcParams.update({"svg.hashsalt": "handmesh-pipeline", "font.size": 10})
    fig, ax = plt.subplots(figsize=(15.5, 4.6))
    for label, c0, c1, r0, r1, colour in GROUPS:
        x0, y1 = c0 * DX - W / 2 - 0.12, -r0 * DY + H / 2 + 0.32
        x1, y0 = c1 * DX + W / 2 + 0.12, -r1 * DY - H / 2 - (0.36 if label in LABEL_AT_BOTTOM else 0.12)
        ax.add_patch(FancyBboxPatch((x0, y0), x1 - x0, y1 - y0, boxstyle="round,pad=0,rounding_size=0.12",
                                    fc=colour, ec="none", zorder=0))
        bottom = label in LABEL_AT_BOTTOM
        ax.text(x0 + 0.1, y0 + 0.04 if bottom else y1 - 0.05, label, ha="left",
                va="bottom" if bottom else "top", fontsize=9.5, style="italic", color="#37474f", zorder=1)
    for key, (_, _, name, what) in BOXES.items():
        x, y = centre(key)
        ax.add_patch(FancyBboxPatch((x - W / 2, y - H / 2), W, H, boxstyle="round,pad=0,rounding_size=0.08",
                                    fc="white", ec="#546e7a", lw=1.2, zorder=2))
        ax.text(x, y + 0.13, name, ha="center", va="center", family="monospace", fontsize=10,
                weight="bold", color="#263238", zorder=3)
        ax.text(x, y - 0.16, what, ha="center", va="center", fontsize=8.8, color="#455a64", zorder=3)
    for a, b in EDGES:
        (xa, ya), (xb, yb) = centre(a), centre(b)
        if ya == yb:  # same row: side to side
            s = 1 if xb > xa else -1
            p0, p1 = (xa + s * W / 2, ya), (xb - s * W / 2, yb)
        elif xa == xb:  # same column: top to bottom
            s = 1 if yb > ya else -1
            p0, p1 = (xa, ya + s * H / 2), (xb, yb - s * H / 2)
        else:
            p0, p1 = (xa + W / 2, ya), (xb - W / 2, yb)
        ax.add_patch(FancyArrowPatch(p0, p1, arrowstyle="-|>", mutation_scale=13, lw=1.3,
                                     color="#455a64", shrinkA=1, shrinkB=1, zorder=1.5))
    ax.set_xlim(-W / 2 - 0.2, 7 * DX + W / 2 + 0.2)
    ax.set_ylim(-2 * DY - H / 2 - 0.45, H / 2 + 0.45)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.subplots_adjust(0, 0, 1, 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="svg", metadata={"Date": None}, bbox_inches="tight", pad_inches=0.05)
    plt.close(fig)


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "docs/img/pipeline.svg"
    draw(out)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KiB)")
