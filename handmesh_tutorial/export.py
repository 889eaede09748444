"""The fast inference path: a network exported to ONNX and run by onnxruntime.

[`export_onnx`][handmesh_tutorial.export.export_onnx] writes one ``.onnx`` file (weights inside:
no ``.onnx.data`` beside it) whose batch dimension is named ``batch``, with the crop side, box
margin and faces of the network in its metadata.
[`OnnxNetwork`][handmesh_tutorial.export.OnnxNetwork] runs such a file (or the bytes of one) and
returns what the torch network returns, a dict of ``vertices``, ``joints`` (and ``uv``) tensors,
equal to eager PyTorch to 1e-5 m (``tests/test_export.py``), so
[`predict_hand`][handmesh_tutorial.inference.predict_hand] and
[`predict_hands`][handmesh_tutorial.inference.predict_hands] take it as their ``model``
(also a path ending in ``.onnx``). [`onnx_network`][handmesh_tutorial.export.onnx_network]
exports in memory and opens the session in one call::

    fast = hmt.export.onnx_network()          # the shipped network, exported once (seconds)
    hand = hmt.inference.predict_hand("photo.jpg", box, "left", K=K, model=fast)

Needs the ``export`` extra (``onnx``, ``onnxscript``, ``onnxruntime``). Speeds on a CPU
(``benchmarks/inference_backends.py``) and what bounds them: docs page "Exporting the network".
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ._optional import require

__all__ = ["BATCH_DIM", "OnnxNetwork", "export_onnx", "onnx_network"]

BATCH_DIM = "batch"
"""The name of the ONNX file's dynamic first dimension (inputs and outputs)."""

_META_KEY = "handmesh_tutorial"


def _resolve(model, image_size: int | None, box_scale: float | None):
    """``(network, image_size, box_scale)``: the shipped network (``None``/``"pretrained"``), a
    checkpoint path, or a network (then ``image_size`` is needed)."""
    if model is None or isinstance(model, str | os.PathLike):
        from .pretrained import pretrained_path
        from .train import load_checkpoint

        path = pretrained_path() if model is None or str(model) == "pretrained" else model
        net, ck = load_checkpoint(path, device="cpu")
        cfg = ck["config"]
        return (net, int(cfg["image_size"] if image_size is None else image_size),
                float(cfg.get("box_scale", 1.5) if box_scale is None else box_scale))
    if not isinstance(model, nn.Module):
        raise ValueError(f"model must be None, 'pretrained', a checkpoint path or a network, "
                         f"got {type(model).__name__}")
    if image_size is None:
        raise ValueError("give image_size, the crop side this network was trained on")
    return model, int(image_size), float(1.5 if box_scale is None else box_scale)


def _proto(net: nn.Module, image_size: int, box_scale: float):
    """The ONNX ``ModelProto`` of ``net`` with a dynamic batch named `BATCH_DIM` and metadata."""
    require("onnxscript", "ONNX export (hmt.export)")
    require("onnx", "ONNX export (hmt.export)")
    from . import __version__

    was_training = net.training
    net.eval()
    try:
        x = torch.zeros(2, 3, image_size, image_size,  # 2: a batch of 1 would fix the size
                        device=next(net.parameters()).device)
        with torch.no_grad():
            names = list(net(x))
        batch = torch.export.Dim(BATCH_DIM, min=1, max=1024)
        program = torch.onnx.export(net, (x,), dynamic_shapes=({0: batch},), dynamo=True,
                                    input_names=["images"], output_names=names,
                                    external_data=False, verbose=False)
    finally:
        net.train(was_training)
    proto = program.model_proto
    for v in [*proto.graph.input, *proto.graph.output]:  # the exporter may name it by a symbol
        d = v.type.tensor_type.shape.dim[0]
        if d.dim_param:
            d.dim_param = BATCH_DIM
    faces = getattr(net, "faces", None)
    meta = {"image_size": int(image_size), "box_scale": float(box_scale),
            "faces": None if faces is None else np.asarray(faces).tolist(),
            "library_version": __version__}
    entry = proto.metadata_props.add()
    entry.key, entry.value = _META_KEY, json.dumps(meta)
    return proto


def export_onnx(path: str | os.PathLike, model=None, *, image_size: int | None = None,
                box_scale: float | None = None) -> Path:
    """Write a network as one ONNX file, batch dimension named ``batch``.

    The weights sit in the file (``external_data=False``): no ``.onnx.data`` file beside it
    (``torch.onnx.export``'s default writes one for a model this size). The shipped network's
    file is about 34 MB: its int8 weights are dequantised to float32 on loading, and ONNX stores
    what the network computes with.

    Args:
        path: the ``.onnx`` file to write.
        model: ``None`` or ``"pretrained"`` (the shipped network), a checkpoint path, or a
            network (then give ``image_size``).
        image_size: crop side of the network (default: the checkpoint's).
        box_scale: crop margin recorded for `OnnxNetwork` (default: the checkpoint's, 1.5).

    Returns:
        ``path``.

    Raises:
        ModuleNotFoundError: the ``export`` extra is not installed.
    """
    net, size, scale = _resolve(model, image_size, box_scale)
    proto = _proto(net, size, scale)
    path = Path(path)
    path.write_bytes(proto.SerializeToString())
    return path


class OnnxNetwork:
    """An exported network run by onnxruntime, called as the torch network is.

    ``OnnxNetwork("msmr.onnx")(images)`` with ``images`` ``(B, 3, S, S)`` float32 (tensor or
    array) -> dict of float32 tensors ``vertices`` ``(B, V, 3)``, ``joints`` ``(B, 21, 3)``
    (and ``uv`` ``(B, 21, 2)``), metres.

    Attributes:
        image_size: the crop side ``S`` recorded by `export_onnx` (``None`` for another file).
        box_scale: the crop margin recorded (1.5 when none).
        faces: ``(F, 3)`` faces of the output mesh, or ``None``.
        session: the ``onnxruntime.InferenceSession``.
    """

    def __init__(self, model: str | os.PathLike | bytes, *, threads: int | None = None):
        """Open a session.

        Args:
            model: an ``.onnx`` file or its bytes.
            threads: onnxruntime's intra-op threads (``None``: ``torch.get_num_threads()``,
                so ``torch.set_num_threads`` governs both backends).

        Raises:
            ModuleNotFoundError: ``onnxruntime`` (the ``export`` extra) is not installed.
        """
        ort = require("onnxruntime", "hmt.export.OnnxNetwork")
        options = ort.SessionOptions()
        options.intra_op_num_threads = int(threads or torch.get_num_threads())
        options.inter_op_num_threads = 1
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        src = model if isinstance(model, bytes) else str(Path(model))
        self.session = ort.InferenceSession(src, options, providers=["CPUExecutionProvider"])
        meta = json.loads(self.session.get_modelmeta().custom_metadata_map.get(_META_KEY, "{}"))
        self.image_size = meta.get("image_size")
        self.box_scale = float(meta.get("box_scale", 1.5))
        self.faces = None if meta.get("faces") is None else np.asarray(meta["faces"], np.int64)
        self.input_name = self.session.get_inputs()[0].name
        self.output_names = [o.name for o in self.session.get_outputs()]

    def __call__(self, images) -> dict[str, torch.Tensor]:
        x = images.detach().cpu().numpy() if isinstance(images, torch.Tensor) else images
        out = self.session.run(None, {self.input_name: np.ascontiguousarray(x, np.float32)})
        return {k: torch.from_numpy(v) for k, v in zip(self.output_names, out, strict=True)}

    def __repr__(self) -> str:
        return f"OnnxNetwork(image_size={self.image_size}, outputs={self.output_names})"


@functools.lru_cache(maxsize=2)
def _shipped_bytes() -> bytes:
    net, size, scale = _resolve(None, None, None)
    return _proto(net, size, scale).SerializeToString()


def onnx_network(model=None, *, image_size: int | None = None, box_scale: float | None = None,
                 threads: int | None = None) -> OnnxNetwork:
    """Export a network in memory and open it in onnxruntime (the fast path of one call).

    The export takes seconds (docs page "Exporting the network"); the shipped network's is
    made once per process. To skip it in later processes, write the file
    once with [`export_onnx`][handmesh_tutorial.export.export_onnx] and open
    ``OnnxNetwork(path)``.

    Args:
        model: ``None`` or ``"pretrained"`` (the shipped network), a checkpoint path, a network
            (then give ``image_size``), or an ``.onnx`` path (opened as it is).
        image_size: crop side of a network object.
        box_scale: crop margin recorded (default: the checkpoint's, 1.5).
        threads: see [`OnnxNetwork`][handmesh_tutorial.export.OnnxNetwork].

    Returns:
        The [`OnnxNetwork`][handmesh_tutorial.export.OnnxNetwork].
    """
    if isinstance(model, str | os.PathLike) and str(model).endswith(".onnx"):
        return OnnxNetwork(model, threads=threads)
    if (model is None or str(model) == "pretrained") and image_size is None \
            and box_scale is None:
        return OnnxNetwork(_shipped_bytes(), threads=threads)
    net, size, scale = _resolve(model, image_size, box_scale)
    return OnnxNetwork(_proto(net, size, scale).SerializeToString(), threads=threads)
