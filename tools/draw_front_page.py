"""Draw the picture at the top of the docs' front page: generated scenes, then predictions on them.

Usage: ``PYOPENGL_PLATFORM=egl python tools/draw_front_page.py [docs/img/front.jpg]``.

Top row: one fresh INTER-SH scene per kind and a second hand-object scene (the first seeds
``data.sample_seed(31 + column, i)``, i = 0, 1, ..., that the generator accepts), 224 px. Bottom
row: the same images with the shipped pretrained network's mesh (``inference.predict_hand`` on
the target hand's keypoint box) in orange over the true mesh in green, each titled with its
PA-MPJPE beside the rest hand's on the same hand. The output is committed; rerun this script
whenever the generator's images or the shipped network change. Same code, same bytes.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

import handmesh_tutorial as hmt  # noqa: E402

SIZE = 224
KINDS = ("hand-hand", "hand-object", "hand-object", "hand-chain")
TRUTH = (0.25, 0.75, 0.3)
PREDICTION = (1.0, 0.55, 0.1)


def scenes(renderer) -> list[dict]:
    """One accepted scene per column of ``KINDS``."""
    out = []
    for column, kind in enumerate(KINDS):
        i = 0
        while True:
            try:
                out.append(hmt.scenes.make_sample(hmt.data.sample_seed(31 + column, i), kind,
                                                  SIZE, renderer=renderer))
                break
            except hmt.scenes.InteractionError:
                i += 1          # the generator rejects some seeds; take the next one
    return out


def pa_mpjpe_mm(pred_joints: np.ndarray, gt_joints: np.ndarray) -> float:
    """PA-MPJPE of one hand, mm: (21, 3) and (21, 3) metres."""
    scores = hmt.metrics.per_sample_scores(pred_joints=pred_joints[None], gt_joints=gt_joints[None])
    return float(np.mean(scores["joint_err_pa"][0]) * 1000)


def draw(samples: list[dict]) -> plt.Figure:
    """The 2 x 4 figure: scenes above, predictions over the truth below."""
    rest_joints = hmt.hand.HandModel()().joints[0].detach().numpy()
    fig, axes = plt.subplots(2, len(samples), figsize=(2.3 * len(samples), 5.1))
    for ax, s in zip(axes[1], samples, strict=True):
        t = s["target"]
        joints = np.asarray(s["joints"][t], dtype=float)
        uv = joints @ np.asarray(s["K"]).T
        uv = uv[:, :2] / uv[:, 2:]
        pred = hmt.inference.predict_hand(s["image"], (*uv.min(0), *uv.max(0)), s["sides"][t],
                                          K=s["K"])
        gv, gf = s["meshes"][t]
        hmt.viz.plot_mesh_on_image(ax, s["image"], gv, gf, s["K"], color=TRUTH, alpha=0.5,
                                   zoom=None)
        hmt.viz.plot_mesh_on_image(ax, None, pred.vertices, pred.faces, s["K"],
                                   color=PREDICTION, alpha=0.55, zoom=None)
        ax.set_xlim(0, SIZE)
        ax.set_ylim(SIZE, 0)
        ax.set_title(f"PA-MPJPE {pa_mpjpe_mm(pred.joints, joints):.1f} mm, "
                     f"rest hand {pa_mpjpe_mm(rest_joints, joints):.1f}", fontsize=8)
    for ax, s, kind in zip(axes[0], samples, KINDS, strict=True):
        ax.imshow(s["image"])
        ax.set_title(kind, fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout(pad=0.4, h_pad=1.4)
    return fig


def main(argv: list[str]) -> None:
    out = Path(argv[0]) if argv else Path(__file__).resolve().parents[1] / "docs/img/front.jpg"
    with hmt.render.Renderer(SIZE) as renderer:
        samples = scenes(renderer)
    fig = draw(samples)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    Image.open(buffer).convert("RGB").save(out, quality=88, optimize=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
