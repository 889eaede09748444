"""Small weight files: int8 per output channel for the weight tensors, float16 for the other
parameters, the buffers exact; and the inverse.

Used by the shipped network's export and the pretrained hand encoder's file; docs page "The
pretrained model".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch

__all__ = ["quantize_state_dict", "dequantize_state_dict"]


def quantize_state_dict(state: Mapping[str, torch.Tensor], names: Sequence[str]
                        ) -> tuple[dict, dict]:
    """Store weights small: symmetric int8 per output channel, float16 for the other parameters.

    Each tensor named in ``names`` with two or more dimensions (convolution kernels, linear and
    spiral weights) becomes int8 ``round(w / s)`` with one float32 scale ``s = max|w| / 127`` per
    output channel (row 0 of the tensor); the other floating tensors in ``names`` (biases,
    normalisation weights) become float16. Tensors not in ``names`` (buffers: the template,
    regressors, running statistics, index tables) stay exact. About a quarter of the float32
    size.

    Args:
        state: a ``state_dict``.
        names: the parameter names (``dict(model.named_parameters())``).

    Returns:
        ``(stored, scales)``: the dict to save and ``{name: (C,) float32 scale}`` of the int8
        entries.
        [`dequantize_state_dict`][handmesh_tutorial.nn.quantize.dequantize_state_dict]
        inverts it to within half a step (``s / 2``) per weight.
    """
    names = set(names)
    stored, scales = {}, {}
    for k, v in state.items():
        v = v.detach().cpu()
        if k in names and v.is_floating_point() and v.ndim >= 2:
            flat = v.float().reshape(v.shape[0], -1)
            s = flat.abs().amax(dim=1).clamp_min(1e-12) / 127.0
            stored[k] = torch.round(flat / s[:, None]).clamp(-127, 127).to(torch.int8) \
                .reshape(v.shape)
            scales[k] = s
        elif k in names and v.is_floating_point():
            stored[k] = v.to(torch.float16)
        else:
            stored[k] = v
    return stored, scales


def dequantize_state_dict(stored: Mapping[str, torch.Tensor],
                          scales: Mapping[str, torch.Tensor]) -> dict:
    """Float32 weights of a
    [`quantize_state_dict`][handmesh_tutorial.nn.quantize.quantize_state_dict] result.

    Raises:
        ValueError: a scale without its int8 tensor, or of the wrong length.
    """
    out = {}
    for k, v in stored.items():
        if k in scales:
            s = scales[k]
            if v.dtype != torch.int8 or s.shape != (v.shape[0],):
                raise ValueError(f"quantized entry {k!r}: {v.dtype} {tuple(v.shape)} with "
                                 f"scales {tuple(s.shape)}")
            out[k] = (v.float().reshape(v.shape[0], -1) * s.float()[:, None]).reshape(v.shape)
        elif v.dtype == torch.float16:
            out[k] = v.float()
        else:
            out[k] = v
    extra = sorted(set(scales) - set(stored))
    if extra:
        raise ValueError(f"scales for entries that are not stored: {extra}")
    return out
