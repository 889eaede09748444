"""Training and evaluating MSMR-Net: config, loop, checkpoints, exact resume, DDP, evaluation.

A notebook trains and evaluates in a few lines::

    cfg = hmt.train.TrainConfig.from_budget(data="runs/intersh", out_dir="runs/train")
    result = hmt.train.train(cfg)                 # tqdm bar, metrics.csv, checkpoints
    report = hmt.train.evaluate(result.checkpoint, "runs/intersh_test", out_dir="runs/eval")
    print(report["table"])                        # scores per visibility-ratio bin

Every public name below is importable from ``handmesh_tutorial.train`` itself; the submodules:

* [`config`][handmesh_tutorial.train.config]: `TrainConfig` (the paper's recipe as defaults),
  which fields a resumed run may change (notebook 08, "Training").
* [`templates`][handmesh_tutorial.train.templates]: the run's mesh template, its hash, and the
  network a config describes (notebook 08).
* [`data`][handmesh_tutorial.train.data]: the seeded per-epoch batch order (`EpochBatchSampler`)
  and the train / validation datasets of a config (notebook 08).
* [`checkpoints`][handmesh_tutorial.train.checkpoints]: weights-only checkpoints and the other
  files of a run folder (notebook 08).
* [`loop`][handmesh_tutorial.train.loop]: the objective and the training loop `train`, with exact
  resume and DDP (notebook 08).
* [`evaluation`][handmesh_tutorial.train.evaluation]: `predict`, `validate` and `evaluate`
  (notebook 09, "Evaluation").
* [`baselines`][handmesh_tutorial.train.baselines]: the constant rest-hand and mean-hand baselines
  (notebooks 08 and 09).

(``hmt.train`` is this package; ``hmt.train.train`` is the training function of
[`loop`][handmesh_tutorial.train.loop].)
"""

from __future__ import annotations

from ..nn.losses import vertex_loss
from .baselines import (
    MEAN_HAND,
    REST_HAND,
    constant_hand_predictions,
    constant_hand_scores,
    mean_hand,
)
from .checkpoints import (
    CHECKPOINT_FORMAT,
    METRIC_COLUMNS,
    RUN_CHECKPOINTS,
    existing_run,
    load_checkpoint,
    remove_stale_temp_files,
    save_checkpoint,
)
from .config import RESUMABLE_KEYS, TrainConfig, changed_settings
from .data import EpochBatchSampler, make_datasets
from .evaluation import evaluate, predict, validate
from .loop import TrainResult, train, training_loss
from .templates import build_model_from_config, resolve_template, save_template, template_hash

__all__ = [
    "TrainConfig", "TrainResult", "EpochBatchSampler", "train", "evaluate", "validate", "predict",
    "load_checkpoint", "save_checkpoint", "build_model_from_config", "make_datasets",
    "resolve_template", "save_template", "template_hash", "vertex_loss", "training_loss",
    "constant_hand_predictions", "constant_hand_scores", "mean_hand", "REST_HAND", "MEAN_HAND",
    "existing_run", "remove_stale_temp_files", "changed_settings",
    "CHECKPOINT_FORMAT", "METRIC_COLUMNS", "RUN_CHECKPOINTS", "RESUMABLE_KEYS",
]
