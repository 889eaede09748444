"""The shipped, trained weights: the pretrained MSMR-Net and the pretrained hand encoder.

* [`pretrained`][handmesh_tutorial.pretrained.pretrained] loads the shipped network (eval mode);
  ``handmesh evaluate --checkpoint pretrained`` and ``load_checkpoint("pretrained")`` read the same
  file (``torch.load(weights_only=True)``);
  [`pretrained_info`][handmesh_tutorial.pretrained.pretrained_info] says what made it.
* [`pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder] and its info: the
  hand encoder that training runs start from (``TrainConfig.init_encoder="pretrained"``).

A loader only: the recipes that make these files are the apps' (``handmesh pretrain``,
``handmesh pretrain-encoder``; [`apps.pretrain_network`][handmesh_tutorial.apps.pretrain_network]).
How the shipped weights were made: docs pages "The pretrained model" and "Why the paper starts from
pretrained weights". Taught in notebook 00 ("Quickstart") and notebook 09 ("Evaluation").
"""

from __future__ import annotations

from pathlib import Path

from ._version import PRETRAINED_FILE, shipped_file, shipped_version
from .nn.pose_encoder import (  # noqa: F401 - ENCODER_FILE: not public, importable as in 0.1
    ENCODER_FILE,
    pretrained_encoder,
    pretrained_encoder_info,
    pretrained_encoder_path,
)

__all__ = ["pretrained", "pretrained_path", "pretrained_info", "pretrained_encoder",
           "pretrained_encoder_info", "pretrained_encoder_path"]


def pretrained_path() -> Path:
    """Path of the shipped pretrained checkpoint.

    Raises:
        FileNotFoundError: this installation has no pretrained file (make one with
            ``make pretrained``).
    """
    return shipped_file(PRETRAINED_FILE, "make pretrained")


def pretrained(device: str = "cpu"):
    """The shipped pretrained MSMR-Net, in eval mode.

    Args:
        device: ``"cpu"``, ``"cuda"`` or ``"auto"``.

    Returns:
        The [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet]; its input is a crop of
        ``pretrained_info()["config"]["image_size"]`` pixels around one hand, normalised as the
        training crops are
        ([`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset]);
        [`predict_hand`][handmesh_tutorial.inference.predict_hand] prepares one's own image so.
    """
    from .train import load_checkpoint

    net, _ = load_checkpoint(pretrained_path(), device=device)
    return net


def pretrained_info() -> dict:
    """What made the shipped weights: ``config`` (the training run's), ``pretrained`` (recipe,
    data seeds and counts, seconds, hardware, commit, date), ``history`` (one row per epoch),
    ``weights`` (storage: ``"int8"`` or ``"float16"``) and ``library_version`` (the version that
    wrote the file, or for a shipped file of before 0.2.0 the version that shipped it, recorded
    by hash in ``handmesh_tutorial/_version.py``)."""
    from .train.checkpoints import _read_checkpoint

    path = pretrained_path()
    ck = _read_checkpoint(path)
    info = {k: ck.get(k) for k in ("config", "pretrained", "history", "weights", "epoch",
                                   "step", "template_hash", "torch_version")}
    info["library_version"] = ck.get("library_version") or shipped_version(path)
    return info


def __getattr__(name: str):
    # the recipe's names moved to the apps layer in 0.2: the old path works until 0.4
    from ._aliases import moved_attribute

    return moved_attribute(__name__, name)
