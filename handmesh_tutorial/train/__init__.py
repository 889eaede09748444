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
  and the frozen encoder's linear read-out (notebooks 08 and 09).
* [`fit_probe`][handmesh_tutorial.train.fit_probe]: the decoder fit probe, an auto-decoder on
  known hands with no image and no encoder (notebook 07); its names stay in the submodule
  (``hmt.train.fit_probe.fit_decoder``).

(``hmt.train`` is this package; ``hmt.train.train`` is the training function of
[`loop`][handmesh_tutorial.train.loop].)
"""

from __future__ import annotations

# EpochBatchSampler, template_hash, vertex_loss (nn.losses), existing_run, changed_settings,
# CHECKPOINT_FORMAT, RUN_CHECKPOINTS: not public, importable from here as in 0.1
from ..nn.losses import vertex_loss  # noqa: F401
from . import fit_probe  # noqa: F401 - hmt.train.fit_probe (notebook 07); its names stay there
from .baselines import (
    LINEAR_READOUT,
    MEAN_HAND,
    REST_HAND,
    constant_hand_predictions,
    constant_hand_scores,
    fit_linear_readout,
    linear_readout,
    mean_hand,
)
from .checkpoints import (  # noqa: F401
    CHECKPOINT_FORMAT,
    METRIC_COLUMNS,
    RUN_CHECKPOINTS,
    existing_run,
    load_checkpoint,
    save_checkpoint,
)
from .config import RESUMABLE_KEYS, TrainConfig, changed_settings  # noqa: F401
from .data import EpochBatchSampler, make_datasets  # noqa: F401
from .evaluation import evaluate, predict, validate
from .loop import TrainResult, train, training_loss
from .templates import (  # noqa: F401
    build_model_from_config,
    resolve_template,
    save_template,
    template_hash,
)

__all__ = [
    "TrainConfig", "TrainResult", "train", "evaluate", "validate", "predict", "load_checkpoint",
    "save_checkpoint", "build_model_from_config", "make_datasets", "resolve_template",
    "save_template", "training_loss", "constant_hand_predictions", "constant_hand_scores",
    "mean_hand", "REST_HAND", "MEAN_HAND", "METRIC_COLUMNS", "RESUMABLE_KEYS",
    "linear_readout", "fit_linear_readout", "LINEAR_READOUT",
]
