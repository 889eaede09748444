"""The network: MSMR-Net's parts, from the mesh hierarchy to the assembled model.

* `hierarchy`: the mesh hierarchy (subset-preserving QSlim, down/up maps); notebook 06.
* `spiral`: spiral sequences and `SpiralConv`; notebook 06.
* `blocks`, `decoder`: residual spiral blocks, multi-resolution fusion, the transformer on the
  coarse mesh; single- and multi-path decoders; notebook 07.
* `encoder`, `keypoints`, `rotation`, `pose_encoder`: ResNet/HRNet encoders, the 2D keypoint head,
  the global-rotation head, the pretrained hand encoder's network and file.
* `outputs`, `skinned`, `smoothing`: what the decoder's field means (affine, offset, xyz,
  skinned output modules), the output smoothing; notebook 07.
* `mesh_template`, `config`, `model`: the template a network is built on, `ModelConfig` and its
  presets, `build_model` / `MSMRNet`; notebook 07.
* `losses`, `quantize`: the training losses; int8 weight files.

Submodules are imported on first attribute access (``hmt.nn.spiral``). Docs page "The pipeline".
"""

from __future__ import annotations

import importlib

_SUBMODULES = ("blocks", "config", "decoder", "encoder", "hierarchy", "keypoints", "losses",
               "mesh_template", "model", "outputs", "pose_encoder", "quantize", "rotation",
               "skinned", "smoothing", "spiral")

__all__ = list(_SUBMODULES)


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_SUBMODULES))
