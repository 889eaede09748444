"""Frozen-encoder features, computed once (the paper's protocol made cheap on a CPU).

With the paper's protocol a pretrained encoder may stay frozen while the decoder learns
([`TrainConfig.freeze_encoder`][handmesh_tutorial.train.config.TrainConfig]). When, in addition, the
crops are not augmented, every epoch would feed the encoder the same images and get the same
features back: [`train`][handmesh_tutorial.train.loop.train] then encodes each crop once and trains
on the stored features. The result is the same network (the frozen encoder runs in eval mode
either way); only the encoder's repeated forward passes are saved. The features are kept in memory
per process, keyed by the encoder's weights and the crops' settings, so several runs on the same
data (notebook 10's ablation) encode it once.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Mapping

import torch
from torch import nn

from .._progress import progress_bar

__all__ = ["EncodedDataset", "clear_feature_cache"]

_MEMO: OrderedDict = OrderedDict()  # (encoder digest, crops) -> {source, items by raw index}
_MEMO_SIZE = 4


def clear_feature_cache() -> None:
    """Forget the features this process has stored."""
    _MEMO.clear()


def encoder_digest(encoder: nn.Module) -> str:
    """SHA-256 of an encoder's weights and buffers (names, shapes, bytes)."""
    h = hashlib.sha256()
    for k, v in sorted(encoder.state_dict().items()):
        t = v.detach().cpu().contiguous()
        h.update(k.encode())
        h.update(str(tuple(t.shape)).encode())
        h.update(t.numpy().tobytes() if t.dtype != torch.bfloat16 else t.float().numpy().tobytes())
    return h.hexdigest()


def is_deterministic(dataset) -> bool:
    """Whether a [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] gives
    the same crop for an index in every epoch (no augmentation)."""
    from ..data.augment import AugmentConfig

    aug = getattr(dataset, "augment", None)
    return isinstance(aug, AugmentConfig) and (not getattr(dataset, "train", True)
                                               or aug == AugmentConfig.none())


def _crop_key(dataset) -> tuple:
    src = getattr(dataset, "source", None)
    where = getattr(src, "root", None)
    return (type(dataset).__name__, str(where) if where is not None else id(src),
            dataset.image_size, dataset.crop, dataset.box_scale, dataset.mirror_left)


class EncodedDataset(torch.utils.data.Dataset):
    """A crop dataset whose images are replaced by a frozen encoder's outputs.

    Items are the wrapped dataset's without ``image``, plus ``features`` ``(D,)`` and, for a
    [`KeypointEncoder`][handmesh_tutorial.nn.keypoints.KeypointEncoder], ``uv`` ``(J, 2)``;
    [`MSMRNet.decode`][handmesh_tutorial.nn.model.MSMRNet.decode] takes ``features`` where the model
    would take ``image``.

    Args:
        dataset: a deterministic crop dataset (see
            [`is_deterministic`][handmesh_tutorial.train.features.is_deterministic]).
        encoder: the frozen encoder (run in eval mode, without gradients).
        batch_size: encoding batch size.
        progress: tqdm bar while encoding.

    Raises:
        ValueError: the dataset augments its crops (its features would differ per epoch).
    """

    def __init__(self, dataset, encoder: nn.Module, batch_size: int = 64,
                 progress: bool = False):
        if not is_deterministic(dataset):
            raise ValueError(f"{type(dataset).__name__} augments its crops: an encoder's features "
                             "of it change every epoch and cannot be stored")
        self.dataset = dataset
        self.raw = list(dataset.indices)
        key = (encoder_digest(encoder), _crop_key(dataset))
        entry = _MEMO.pop(key, None)
        src = getattr(dataset, "source", None)
        on_disk = getattr(src, "root", None) is not None
        # an in-memory set is keyed by id(), which a new object may reuse: check it is the same
        if entry is None or not (on_disk or entry["source"] is src):
            entry = {"source": src, "items": {}}
        _MEMO[key] = entry
        store = entry["items"]
        while len(_MEMO) > _MEMO_SIZE:
            _MEMO.popitem(last=False)
        todo = [i for i, r in enumerate(self.raw) if r not in store]
        if todo:
            self._encode(encoder, todo, store, batch_size, progress)
        self.items = [store[r] for r in self.raw]

    def _encode(self, encoder, todo, store, batch_size, progress) -> None:
        dev = next(encoder.parameters()).device
        was = encoder.training
        encoder.eval()
        sub = torch.utils.data.Subset(self.dataset, todo)
        loader = torch.utils.data.DataLoader(sub, batch_size=batch_size, shuffle=False)
        try:
            with torch.no_grad():
                for batch in progress_bar(loader, desc="encoding crops", disable=not progress,
                                          leave=False):
                    out = encoder(batch["image"].to(dev))
                    if not isinstance(out, dict):
                        out = {"features": out}
                    for j in range(len(batch["image"])):
                        item = {k: v[j] for k, v in batch.items() if k != "image"}
                        item.update({k: v[j].float().cpu() for k, v in out.items()})
                        store[int(batch["index"][j])] = item
        finally:
            encoder.train(was)

    @property
    def indices(self) -> list[int]:
        """Positions in the underlying reader (as the wrapped dataset's)."""
        return self.raw

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict:
        return self.items[i]

    def __getattr__(self, name):  # target_shape, vr_values, source...: the wrapped dataset's
        if name in ("dataset", "items", "raw"):
            raise AttributeError(name)
        return getattr(self.dataset, name)


def model_outputs(model: nn.Module, batch: Mapping, device: torch.device,
                  rows: slice = slice(None)) -> dict:
    """The network's output for a batch of crops, or of stored encoder features.

    Args:
        model: an [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] (or DDP around one, for images).
        batch: items with ``image`` ``(B, 3, S, S)``, or with ``features`` ``(B, D)`` (and
            ``uv``) of an [`EncodedDataset`][handmesh_tutorial.train.features.EncodedDataset].
        device: where to compute.
        rows: the micro-batch.
    """
    if "features" in batch:
        out = model.decode(batch["features"][rows].to(device, non_blocking=True))
        if "uv" in batch:
            out["uv"] = batch["uv"][rows].to(device, non_blocking=True)
        return out
    return model(batch["image"][rows].to(device, non_blocking=True))
