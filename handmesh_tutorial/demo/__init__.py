"""The main demo job (``handmesh demo`` / ``make demo``): data -> training -> evaluation -> report.

One call runs the whole paper pipeline at laptop scale, on CPU:

1. **Data.** Two INTER-SH sets of mixed scenes (hand-hand, hand-object and hand-chain, one kind
   drawn per sample; natural poses: the generator's default anatomical joint limits, not the paper's
   ±60°; [`handmesh_tutorial.dataset.generate_dataset`][handmesh_tutorial.dataset.generate_dataset]
   with [`handmesh_tutorial.interact.make_sample`][handmesh_tutorial.interact.make_sample]):
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
[`DemoConfig.from_budget`][handmesh_tutorial.demo.config.DemoConfig.from_budget]; the demo's own
choices, made so that the ``default`` tier finishes in about twelve minutes on a 2-core CPU:

* training scenes = 5 x ``budget.samples`` (``default``: 3,000; about 7 scenes/s with two
  workers at 128 px on a 2-core CPU) and VR-balanced test scenes = 1/2 of
  ``budget.eval_samples`` (``default``: 100; balancing rejects candidates, about 5 renders per
  kept scene). Training needs *many different* scenes far more than it needs balanced ones;
* network crop = 1/2 of ``budget.image_size`` (``default``: 64 px; images are rendered at
  ``budget.image_size``, where the target hand spans 45-75 % of the side; the network's crop is
  cut around it), batch ``budget.batch_size`` (``default``: 16), ``budget.epochs / 2`` epochs
  (``default``: 10, about 1,700 steps), learning rate ``1e-3`` (as MobRecon/HandMesh; the
  paper's ``1e-4`` is for 200 epochs with a pretrained encoder), halved once, after three
  quarters of the run;
* **ResNet-10** instead of the paper's ImageNet-pretrained ResNet-50 / HRNet, **no augmentation**
  below the ``full`` tier, and the **CPU recipe**
  ([`RECIPES`][handmesh_tutorial.demo.config.RECIPES]): a 2D keypoint head whose features are pooled
  at the joints, a global-rotation head, the skinned decoder output (the decoder's field read as
  joint rotations and shape, then skinning: smooth hand surfaces), and keypoint and aligned-joint
  losses beside the paper's L1. With the paper's recipe (``recipe="paper"``) a from-scratch network
  stays for thousands of steps on a plateau of the L1 loss (about 28 mm) where it predicts one
  average mesh for every image. The docs page "Training from scratch on a CPU" has the measurements
  behind every choice.

The ``full`` tier is the paper's scale instead: ``budget.samples`` training scenes (40,000),
``budget.epochs`` epochs (200), augmentation on.

What to expect at the ``default`` size (measured on a 2-core CPU, seed 0, 2026-11-25, 12.4 min in
all: 5.5 min generating, 6.8 min training): on the 100 held-out scenes MPJPE 37.2 mm, PA-MPJPE
10.35 mm, PA-MPVPE 9.5 mm, roughness 3.9 degrees, 1.0% flipped faces. The rest hand (the
template's open hand for every image) scores PA-MPJPE 13.1 mm, the mean training hand
([`mean_hand`][handmesh_tutorial.train.baselines.mean_hand]) 10.3 mm: the network has learnt the
hand's orientation and the data's average articulation, not yet each hand's finger pose.

Example::

    import handmesh_tutorial as hmt
    result = hmt.demo.run_demo("runs/demo", seed=0)
    print(result.report, result.scores["pa_mpjpe"])

The submodules (every name is importable from ``handmesh_tutorial.demo`` itself):

* [`config`][handmesh_tutorial.demo.config]: `DemoConfig`, `RECIPES`, `train_config`.
* [`run`][handmesh_tutorial.demo.run]: `run_demo`, `generate_data`, `generate_scenes`, `DemoResult`.
* [`report`][handmesh_tutorial.demo.report]: the headline table, ``report.md``, `parse_headline`.

The figures (`plot_overlays`, `plot_loss_curves`) live in
[`handmesh_tutorial.viz`][handmesh_tutorial.viz] and are re-exported here. Taught in notebook 00
("Quickstart").
"""

from __future__ import annotations

from ..viz import plot_loss_curves, plot_overlays
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
           "MODEL_ROW", "BASELINE_ROW", "MEAN_ROW", "RECIPES"]
