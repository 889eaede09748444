"""The main demo job (``handmesh demo`` / ``make demo``): data -> training -> evaluation -> report.

One call runs the whole paper pipeline at laptop scale, on CPU:

1. **Data.** Two INTER-SH sets of mixed scenes (hand-hand, hand-object and hand-chain, one kind
   drawn per sample; natural poses: the generator's default anatomical joint limits, not the paper's
   ±60°; [`handmesh_tutorial.data.generate_dataset`][handmesh_tutorial.data.generate_dataset]
   with [`handmesh_tutorial.scenes.make_sample`][handmesh_tutorial.scenes.make_sample]):
   ``OUT/data/train`` (seed ``seed``, the generator's natural VR distribution) and the held-out
   ``OUT/data/test`` (seed ``seed + 1``, never seen in training, ``balance_vr=True``: the target
   hands spread evenly over the paper's four VR bins, so every row of the VR table has the same
   weight).
2. **Training.** MSMR-Net (ResNet-10 encoder, multi-path decoder, coarse-mesh attention) with
   [`handmesh_tutorial.train.train`][handmesh_tutorial.train.loop.train] into ``OUT/train`` (10% of
   the training set held out for per-epoch validation; ``checkpoint_best.pt`` keeps the best
   validation PA-MPVPE).
3. **Evaluation** of the best checkpoint on the test set with
   [`handmesh_tutorial.train.evaluate`][handmesh_tutorial.train.evaluation.evaluate] into
   ``OUT/eval`` (``eval.json``, ``predictions.npz``, ``pck.png``, ``vr.png``), beside the rest
   hand and the mean training hand; the shipped pretrained network
   ([`handmesh_tutorial.pretrained`][handmesh_tutorial.pretrained]) is scored on the same scenes
   when the installation has it.
4. **Report.** ``OUT/report.md`` with the FreiHAND-style scores, the table per VR bin (the
   paper's Table 2 layout), predicted meshes drawn over held-out images next to the ground truth
   (``overlays.png``), the loss curves (``loss.png``), PCK curves and error vs VR; ``OUT/demo.json``
   holds the same numbers and the timings.

**Resumable.** Rerunning the same command skips finished work: the data generators skip samples
already on disk, training continues from ``OUT/train/checkpoint_last.pt`` (exactly, see
[`handmesh_tutorial.train`][handmesh_tutorial.train]), and a finished training is not repeated.
Evaluation and report are cheap and always redone.

**Sizes** come from the run-size tier
([`handmesh_tutorial.budget.budget`][handmesh_tutorial.budget.budget]) through
[`DemoConfig.from_budget`][handmesh_tutorial.apps.demo.config.DemoConfig.from_budget]; the demo's
own choices, made so that the ``default`` tier finishes in minutes on a 2-core CPU (wall times:
docs page "Performance"):

* training scenes = 5 x ``budget.samples`` (``default``: 3,000) and VR-balanced test scenes =
  1/2 of ``budget.eval_samples`` (``default``: 100; balancing rejects candidates, docs page
  "INTER-SH on disk", "VR-balanced sets"). Training needs *many different* scenes far more than
  it needs balanced ones;
* network crop = ``budget.image_size`` (``default``: 128 px, cut around the target hand, which
  spans 45-75 % of the rendered image), batch ``budget.batch_size`` (``default``: 16),
  ``budget.epochs / 2`` epochs (``default``: 10, about 1,700 steps), learning rate ``1e-3``,
  halved after three quarters of the run (the paper recipe: after each quarter, the shape of
  the paper's schedule);
* **the paper's protocol**: the encoder starts from the shipped pretrained hand encoder
  ([`pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder], a ResNet-10 with a
  2D keypoint head; our stand-in for ImageNet weights) and stays frozen; everything after it
  trains from random weights. Frozen, with no augmentation below the ``full`` tier, each crop's
  features are computed once ([`EncodedDataset`][handmesh_tutorial.train.features.EncodedDataset]).
  ``DemoConfig(init_encoder=None)`` (``handmesh demo --init-encoder none``) trains from random
  weights instead;
* the **CPU recipe** ([`RECIPES`][handmesh_tutorial.apps.demo.config.RECIPES]): pose pooling at the
  2D keypoints, a global-rotation head, the skinned decoder output (smooth hand surfaces), and
  keypoint and aligned-joint losses beside the paper's L1 (``recipe="paper"``: L1 only).

Why these choices, and what the run scores beside the two constant hands: docs page "Why the paper
starts from pretrained weights". The ``full`` tier is the paper's scale instead:
``budget.samples`` training scenes (40,000), ``budget.epochs`` epochs (200), augmentation on.

Example::

    import handmesh_tutorial as hmt
    result = hmt.apps.demo.run_demo("runs/demo", seed=0)
    print(result.report, result.scores["pa_mpjpe"])

The submodules (every name is importable from ``handmesh_tutorial.apps.demo`` itself):

* [`config`][handmesh_tutorial.apps.demo.config]: `DemoConfig`, `RECIPES`, `train_config`.
* [`run`][handmesh_tutorial.apps.demo.run]: `run_demo`, `generate_data`, `generate_scenes`,
`DemoResult`.
* [`report`][handmesh_tutorial.apps.demo.report]: the headline table, ``report.md``,
`parse_headline`.
* [`ablation`][handmesh_tutorial.apps.demo.ablation]: the paper's Table 3 at laptop scale;
  [`table3`][handmesh_tutorial.apps.demo.table3]: the same in two configurations, with intervals,
  power and VR bins.

The figures (`plot_overlays`, `plot_loss_curves`) live in
[`handmesh_tutorial.viz`][handmesh_tutorial.viz] and are re-exported here. Taught in notebook 00
("Quickstart").
"""

from __future__ import annotations

from ...viz import plot_loss_curves, plot_overlays
from . import ablation, table3
from .config import RECIPES, DemoConfig, train_config
from .report import (
    BASELINE_ROW,
    HEADLINE,
    MEAN_ROW,
    MODEL_ROW,
    PRETRAINED_ROW,
    headline,
    parse_headline,
    write_report,
)
from .run import DemoResult, generate_data, generate_scenes, run_demo

__all__ = ["DemoConfig", "DemoResult", "run_demo", "generate_data", "generate_scenes",
           "train_config", "plot_overlays", "plot_loss_curves", "write_report", "headline",
           "parse_headline", "HEADLINE", "PRETRAINED_ROW",
           "MODEL_ROW", "BASELINE_ROW", "MEAN_ROW", "RECIPES", "ablation", "table3"]
