"""Export and compilation of the pretrained network and of each decoder (issue 32).

``torch.export`` (with a dynamic batch), ONNX run with onnxruntime, ``torch.compile(fullgraph=
True)`` and ``torch.jit.trace`` must capture the networks and give the eager outputs. The
decoders are built small (a 3-level icosphere hierarchy, a one-layer encoder) so that the tests
stay fast; the pretrained network covers the full 5-level multi-path decoder with attention.
Compile times on a CPU are in ``docs/concepts/export.md``: the tests use the ``aot_eager``
backend (the graph capture and AOT autograd that ``inductor`` compiles from) and one
``inductor`` run of the smallest decoder.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh
from torch import nn

import handmesh_tutorial as hmt
from handmesh_tutorial.nn import blocks
from handmesh_tutorial.nn import model as M
from handmesh_tutorial.nn.blocks import SparseVertexMap
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy

torch.set_num_threads(1)

ATOL = 1e-5  # metres
NAMES = ("single", "multi", "multi+attention", "pretrained")


class _TinyEncoder(nn.Sequential):
    """(B, 3, H, W) -> (B, 8): one strided convolution and a global average."""

    out_features = 8

    def __init__(self):
        super().__init__(nn.Conv2d(3, 8, 4, stride=4), nn.AdaptiveAvgPool2d(1), nn.Flatten())


@pytest.fixture(scope="module")
def nets() -> dict:
    """name -> (eval-mode network, example images (2, 3, S, S))."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(0)
    jr = rng.random((21, len(mesh.vertices)))
    jr /= jr.sum(1, keepdims=True)
    tmpl = M.MeshTemplate(np.asarray(mesh.vertices) * 0.05, np.asarray(mesh.faces), jr)
    hier = mesh_hierarchy(tmpl.vertices, tmpl.faces, factors=(2, 2), use_cache=False)
    out = {}
    for name, decoder, attention in (("single", "single", False), ("multi", "multi", False),
                                     ("multi+attention", "multi", True)):
        torch.manual_seed(0)
        net = M.build_model(_TinyEncoder(), decoder, attention, tmpl, channels=(4, 8, 8),
                            latent_channels=8, hierarchy=hier, zero_head=False)
        out[name] = (net.eval(), torch.randn(2, 3, 16, 16))
    net = hmt.pretrained.pretrained()
    size = hmt.pretrained.pretrained_info()["config"]["image_size"]
    out["pretrained"] = (net, torch.randn(2, 3, size, size))
    return out


@pytest.fixture(scope="module")
def programs(nets):
    """name -> ExportedProgram with a dynamic batch dimension, exported once per module."""
    cache = {}

    def get(name):
        if name not in cache:
            net, x = nets[name]
            batch = torch.export.Dim("batch", min=1, max=1024)
            cache[name] = torch.export.export(net, (x,), dynamic_shapes=({0: batch},))
        return cache[name]

    return get


def _assert_equal_to_eager(net, x, out):
    with torch.no_grad():
        ref = net(x)
    if not isinstance(out, dict):  # ONNX / traced outputs: the dict's values in order
        out = dict(zip(ref, out, strict=True))
    assert set(out) == set(ref)
    for k in ref:
        torch.testing.assert_close(torch.as_tensor(out[k]), ref[k], rtol=0, atol=ATOL, msg=k)


def test_sparse_vertex_map_is_captured_without_sparse_tensors(monkeypatch):
    # eager runs the CSR product; a traced graph holds the gather path, with equal values
    rng = np.random.default_rng(1)
    m = sp.random(7, 5, density=0.5, random_state=1) + sp.eye(7, 5)
    vmap = SparseVertexMap(m)
    assert vmap.method == "csr" and not vmap.is_selection
    x = torch.from_numpy(rng.standard_normal((2, 5, 3)).astype(np.float32))
    want = torch.einsum("ij,bjc->bic", torch.from_numpy(m.toarray()).float(), x)
    calls = []
    apply = blocks._VertexMatmul.apply
    monkeypatch.setattr(blocks._VertexMatmul, "apply", lambda *a: calls.append(1) or apply(*a))
    torch.testing.assert_close(vmap(x), want)
    assert len(calls) == 1  # eager: the CSR product
    ep = torch.export.export(vmap, (x,))
    assert "sparse" not in str(ep.graph)
    torch.testing.assert_close(ep.module()(x), want)
    torch.testing.assert_close(torch.jit.trace(vmap, (x,), check_trace=False)(x), want)
    assert len(calls) == 1
    torch.testing.assert_close(torch.compile(vmap, fullgraph=True, backend="aot_eager")(x), want)
    assert len(calls) == 1 and vmap.method == "csr"


@pytest.mark.parametrize("name", NAMES)
def test_torch_export_equals_eager_at_any_batch(nets, programs, name):
    net, x = nets[name]
    ep = programs(name)
    assert "sparse" not in str(ep.graph)
    _assert_equal_to_eager(net, x, ep.module()(x))
    x3 = torch.cat([x, x[:1].flip(-1)])  # other batch sizes than the example's
    _assert_equal_to_eager(net, x3, ep.module()(x3))
    _assert_equal_to_eager(net, x3[2:], ep.module()(x3[2:]))


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "pretrained"
                                  else n for n in NAMES])
def test_onnx_export_runs_in_onnxruntime_equal_to_eager(nets, programs, name, tmp_path):
    pytest.importorskip("onnxscript", reason="ONNX export needs onnxscript (the dev extra)")
    ort = pytest.importorskip("onnxruntime", reason="running ONNX needs onnxruntime (dev extra)")
    net, x = nets[name]
    path = tmp_path / "net.onnx"
    torch.onnx.export(programs(name), f=path, verbose=False, input_names=["images"],
                      output_names=list(net(x[:1])))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [o.name for o in session.get_outputs()] == list(net(x[:1]))
    x3 = torch.cat([x, x[:1].flip(-1)])
    _assert_equal_to_eager(net, x3, session.run(None, {"images": x3.numpy()}))


@pytest.mark.parametrize("name", NAMES)
def test_compile_fullgraph_equals_eager(nets, name):
    net, x = nets[name]
    torch._dynamo.reset()
    with torch.no_grad():
        out = torch.compile(net, fullgraph=True, backend="aot_eager")(x)
    _assert_equal_to_eager(net, x, out)


def test_compiled_training_gives_the_eager_gradients(nets):
    # what torch.compile is used for in training: the captured backward equals eager's
    net, x = nets["single"]
    torch._dynamo.reset()
    compiled = torch.compile(net, fullgraph=True, backend="aot_eager")
    grads = []
    for fn in (net, compiled):
        net.zero_grad()
        out = fn(x)
        (out["vertices"].square().sum() + out["joints"].sum()).backward()
        grads.append({n: p.grad.clone() for n, p in net.named_parameters()})
    for n, g in grads[0].items():
        torch.testing.assert_close(grads[1][n], g, rtol=1e-4, atol=1e-6, msg=n)


@pytest.mark.slow
def test_inductor_compiles_the_smallest_decoder(nets, tmp_path):
    # inductor's fixed cost (C++ kernels) is tens of seconds on 2 CPUs even for one map: one run.
    # Its own kernel cache, not the shared one in /tmp: this test aborted the process twice in
    # a full suite while other processes (other checkouts) compiled into that cache at the same
    # time, and never alone; a private cache rules that cause out.
    from torch._inductor.runtime.cache_dir_utils import temporary_cache_dir

    net, x = nets["single"]
    torch._dynamo.reset()
    with temporary_cache_dir(str(tmp_path / "inductor")), torch.no_grad():
        out = torch.compile(net, fullgraph=True)(x)  # inductor, the default backend
    _assert_equal_to_eager(net, x, out)


def test_jit_trace_of_the_pretrained_network_saves_and_equals_eager(nets, tmp_path):
    net, x = nets["pretrained"]
    traced = torch.jit.trace(net, (x,), strict=False, check_trace=False)
    torch.jit.save(traced, tmp_path / "net.pt")  # a graph with no Python calls left in it
    _assert_equal_to_eager(net, x, torch.jit.load(tmp_path / "net.pt")(x))


def _onnx_or_skip():
    pytest.importorskip("onnxscript", reason="ONNX export needs onnxscript (the export extra)")
    pytest.importorskip("onnxruntime", reason="running ONNX needs onnxruntime (the export extra)")


def test_export_onnx_writes_one_file_with_a_named_batch(nets, tmp_path):
    """Issue 54: no ``.onnx.data`` beside the file; the batch dimension is called ``batch``."""
    _onnx_or_skip()
    import onnx

    net, _ = nets["multi"]
    path = hmt.export.export_onnx(tmp_path / "net.onnx", net, image_size=32)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.onnx"]
    proto = onnx.load(path)
    for v in [*proto.graph.input, *proto.graph.output]:
        assert v.type.tensor_type.shape.dim[0].dim_param == hmt.export.BATCH_DIM == "batch"
    fast = hmt.export.OnnxNetwork(path, threads=1)
    assert fast.image_size == 32 and fast.box_scale == 1.5
    np.testing.assert_array_equal(fast.faces, net.faces)
    x = torch.randn(3, 3, 32, 32)
    _assert_equal_to_eager(net, x, fast(x))


def test_predict_hands_in_onnxruntime_equals_torch(nets, tmp_path):
    """The fast path of ``predict_hands``/``predict_hand``: the same outputs as eager torch."""
    _onnx_or_skip()
    net, _ = nets["multi"]
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    boxes, sides = [(10, 5, 40, 38), (30, 20, 70, 55)], ["left", "right"]
    want = hmt.inference.predict_hands(image, boxes, sides, model=net, image_size=32)
    path = hmt.export.export_onnx(tmp_path / "net.onnx", net, image_size=32)
    for model in (hmt.export.OnnxNetwork(path), str(path)):
        got = hmt.inference.predict_hands(image, boxes, sides, model=model, batch_size=1)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g.vertices, w.vertices, rtol=0, atol=ATOL)
            np.testing.assert_allclose(g.joints, w.joints, rtol=0, atol=ATOL)
            np.testing.assert_array_equal(g.faces, w.faces)  # mirrored for the left hand
            assert g.side == w.side and g.frame == w.frame == "root-relative"
    one = hmt.inference.predict_hand(image, boxes[0], "left", model=str(path))
    np.testing.assert_allclose(one.vertices, want[0].vertices, rtol=0, atol=ATOL)
    with pytest.raises(ValueError, match="exported for 32-px crops"):
        hmt.inference.predict_hand(image, boxes[0], "left", model=str(path), image_size=64)


@pytest.mark.slow
def test_the_shipped_network_in_onnxruntime_places_the_hand_as_torch(nets):
    _onnx_or_skip()
    net, _ = nets["pretrained"]
    fast = hmt.export.onnx_network(threads=1)
    assert fast.image_size == hmt.pretrained.pretrained_info()["config"]["image_size"]
    rng = np.random.default_rng(4)
    image = rng.integers(0, 256, (240, 320, 3), dtype=np.uint8)
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    box = (100, 60, 200, 170)
    want = hmt.inference.predict_hand(image, box, "left", K=K, model=net, image_size=128)
    got = hmt.inference.predict_hand(image, box, "left", K=K, model=fast)
    np.testing.assert_allclose(got.joints - got.root, want.joints - want.root, rtol=0, atol=ATOL)
    np.testing.assert_allclose(got.keypoints_2d, want.keypoints_2d, rtol=0, atol=1e-3)  # px
    np.testing.assert_allclose(got.root, want.root, rtol=1e-4)
