"""The shipped, trained weights: the pretrained MSMR-Net and the pretrained hand encoder.

* [`pretrained`][handmesh_tutorial.pretrained.pretrained] loads the shipped network (eval mode);
  ``handmesh evaluate --checkpoint pretrained`` and ``load_checkpoint("pretrained")`` read the same
  file (``torch.load(weights_only=True)``);
  [`pretrained_info`][handmesh_tutorial.pretrained.pretrained_info] says what made it, and
  [`lineage`][handmesh_tutorial.pretrained.lineage] lists its training stages, oldest first.
* [`save_network`][handmesh_tutorial.pretrained.save_network] saves a network fine-tuned from it
  (int8 as shipped, about 8 MB; float32 about 32 MB) so that every loader reads it.
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

__all__ = ["pretrained", "pretrained_path", "pretrained_info", "lineage", "save_network",
           "pretrained_encoder", "pretrained_encoder_info", "pretrained_encoder_path"]


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


def save_network(path, model, *, weights: str = "int8", config=None,
                 info: dict | None = None) -> Path:
    """Save a network built like the shipped one (e.g. fine-tuned from ``pretrained()``).

    The file is a checkpoint: ``load_checkpoint(path)``, ``predict_hand(..., model=path)`` and
    ``handmesh evaluate --checkpoint path`` read it, as they read the shipped file. Sizes for
    the shipped architecture (7.9 million weights): ``"int8"`` about 8 MB (the shipped file's
    storage: per-channel int8,
    [`quantize_state_dict`][handmesh_tutorial.nn.quantize.quantize_state_dict]; each weight
    moves by at most half its channel's step, ``max|w| / 254``), ``"float16"`` about 16 MB,
    ``"float32"`` about 32 MB and exact. A network loaded from an int8 file and saved again as
    int8 keeps its weights (the same steps).

    Args:
        path: the ``.pt`` file to write (atomically).
        model: the network (a DDP wrapper is unwrapped).
        weights: ``"int8"``, ``"float16"`` or ``"float32"``.
        config: its [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig] (or its dict);
            default: the shipped network's (``pretrained_info()["config"]``), which is what a
            network fine-tuned from ``pretrained()`` is built from.
        info: stored as the file's ``pretrained`` entry (what made it: data, seeds, epochs).

    Returns:
        ``path`` as a ``Path``.

    Raises:
        ValueError: ``weights`` unknown, or a network that ``config`` does not build (other
            layers or sizes: pass its own config).

    Examples:
        >>> net = hmt.pretrained.pretrained()          # doctest: +SKIP
        >>> ...                                       # fine-tune it  # doctest: +SKIP
        >>> hmt.pretrained.save_network("mine.pt", net)  # doctest: +SKIP
        >>> net2, ck = hmt.train.load_checkpoint("mine.pt")  # doctest: +SKIP
    """
    import io
    import math

    import torch

    from ._io import atomic_write_bytes
    from ._version import __version__
    from .nn.quantize import quantize_state_dict
    from .train.checkpoints import CHECKPOINT_FORMAT
    from .train.config import TrainConfig
    from .train.templates import build_model_from_config, resolve_template, template_hash

    if weights not in ("int8", "float16", "float32"):
        raise ValueError(f"weights must be 'int8', 'float16' or 'float32', got {weights!r}")
    if config is None:
        config = pretrained_info()["config"]
    cfg = config if isinstance(config, TrainConfig) else TrainConfig.from_dict(config)
    tmpl = resolve_template(cfg.template)
    net = model.module if hasattr(model, "module") else model
    state = {k: v.detach().cpu() for k, v in net.state_dict().items()}
    try:
        build_model_from_config(cfg, tmpl).load_state_dict(state, strict=True)
    except RuntimeError as e:
        raise ValueError(f"this network is not the one its config builds ({e}); pass "
                         "config= the TrainConfig it was built from") from None
    names = {n for n, _ in net.named_parameters()}
    scales: dict = {}
    if weights == "int8":
        state, scales = quantize_state_dict(state, names)
    elif weights == "float16":
        state = {k: (v.half() if k in names and v.is_floating_point() else v)
                 for k, v in state.items()}
    ck = {"format": CHECKPOINT_FORMAT, "model": state, "scales": scales, "weights": weights,
          "config": cfg.to_dict(), "template_hash": template_hash(tmpl),
          "num_vertices": len(tmpl.vertices), "epoch": 0, "step": 0, "history": [],
          "best": math.inf, "optimizer": None, "scheduler": None,
          "torch_version": str(torch.__version__), "library_version": __version__,
          "pretrained": dict(info or {})}
    buf = io.BytesIO()
    torch.save(ck, buf)
    path = Path(path)
    atomic_write_bytes(path, buf.getvalue(), True)
    return path


def lineage(made: dict | None = None) -> list[dict]:
    """Every training stage that made a network file, oldest first: the stages of the encoder
    it started from (``--init-encoder``), then its own runs (``--init``), as the file records
    them.

    Args:
        made: a network file's record, ``pretrained_info()["pretrained"]`` or a checkpoint's
            ``"pretrained"``; the shipped file's when None.

    Returns:
        One dict per stage: ``part`` (``"encoder"`` or ``"network"``), ``command`` (as recorded:
        a network's full command line; an encoder's sub-command only, its options being
        ``recipe``'s fields; None when not recorded), ``recipe`` (every setting), ``start``
        (``"random weights"``, ``"the stage before"``, ``"the encoder of the stage before"`` or
        ``"unknown"``), ``train_seed``, ``val_seed``, ``train_scenes``, ``epochs`` (network) or
        ``steps`` (encoder), ``train_seconds`` (None when not recorded), ``hardware``,
        ``commit`` (the code that ran it), ``date``.

    Raises:
        ValueError: ``made`` is not a training record (no ``data``), or its recorded chain is
            deeper than 64 or holds more than `MAX_STAGES` stages (each record is walked once,
            however often it is referred to).
    """
    made = pretrained_info()["pretrained"] if made is None else made
    if not isinstance(made, dict) or "data" not in made:
        raise ValueError("lineage() takes a network file's 'pretrained' record (with 'data'), "
                         f"got {type(made).__name__} with keys {sorted(made or {})[:8]}")
    return _network_stages(made, depth=0, seen=set())


def _stage(node: dict, part: str, start: str) -> dict:
    data, recipe = node.get("data") or {}, node.get("recipe") or {}
    row = {"part": part, "command": node.get("command"), "recipe": recipe, "start": start,
           "train_seed": data.get("train_seed", recipe.get("data_seed")),
           "val_seed": data.get("val_seed"), "train_scenes": data.get("train_scenes"),
           "train_seconds": (node.get("seconds") or {}).get("train"),
           "hardware": node.get("hardware"), "commit": node.get("commit"),
           "date": node.get("date")}
    if part == "network":
        row["epochs"] = node.get("epochs_done")
    else:
        row["steps"] = node.get("steps") or node.get("stop_after") or recipe.get("max_steps")
    return row


MAX_STAGES = 256
"""Most stages `lineage` lists (the shipped file has four): a record is a tree of dicts that a
file can make share its branches, so each is walked once and the total is bounded."""


def _visit(node: dict, seen: set[int]) -> bool:
    """Whether ``node`` is new (then marked seen); raises past `MAX_STAGES` records."""
    if id(node) in seen:
        return False
    seen.add(id(node))
    if len(seen) > MAX_STAGES:
        raise ValueError(f"the recorded chain of runs holds more than {MAX_STAGES} stages "
                         "(MAX_STAGES): not a record this library wrote")
    return True


def _network_stages(node: dict, depth: int, seen: set[int]) -> list[dict]:
    if depth > 64:  # a recorded chain is never a cycle; bounded all the same
        raise ValueError("the recorded chain of runs is deeper than 64 stages")
    if not _visit(node, seen):  # a shared record: listed where first met
        return []
    parent, encoder = node.get("init_from"), node.get("init_encoder_from")
    stages: list[dict] = []
    if isinstance(parent, dict):
        stages += _network_stages(parent, depth + 1, seen)
    if isinstance(encoder, dict) and isinstance(encoder.get("made_by"), dict):
        stages += _encoder_stages(encoder["made_by"], depth + 1, seen)
    if isinstance(parent, dict):
        start = "the stage before"
    elif stages:
        start = "the encoder of the stage before"
    else:
        init = (node.get("recipe") or {}).get("init")
        start = "random weights" if init is None and parent is None else "unknown"
    return stages + [_stage(node, "network", start)]


def _encoder_stages(node: dict, depth: int, seen: set[int]) -> list[dict]:
    from .nn.pose_encoder import _encoder_runs

    nodes, origin, network = _encoder_runs(node)
    first = {"random weights": "random weights"}.get(origin, "unknown")
    before: list[dict] = []
    if isinstance(network, dict):  # began as a network's encoder: its stages come first
        before = _network_stages(network, depth + 1, seen)
        first = "the encoder of the stage before"
    return before + [_stage(n, "encoder", first if i == 0 else "the stage before")
                     for i, n in enumerate(nodes) if _visit(n, seen)]
