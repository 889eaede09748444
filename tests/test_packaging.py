"""Packaging: the core install without extras, the errors that name an extra, one version.

The core-install test runs in a subprocess where the extras' packages are absent
(``sys.modules[name] = None``: ``import`` raises ``ModuleNotFoundError`` and
``importlib.util.find_spec`` returns ``None``, as for a package that is not installed).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import handmesh_tutorial as hmt
from handmesh_tutorial import _optional, _version

ROOT = Path(hmt.__file__).resolve().parent.parent
tomllib = pytest.importorskip("tomllib")  # Python 3.11+
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
# every optional package, plus what they drag in (a component must not import these either)
ABSENT = sorted({*_optional.EXTRAS, "IPython", "ipykernel", "zmq", "tornado", "llvmlite",
                 "pyngrok", "mpl_toolkits", "pyglet"})


def _dist(requirement: str) -> str:
    """The normalised distribution name of a requirement string (PEP 503)."""
    name = re.match(r"[A-Za-z0-9._-]+", requirement).group(0)
    return re.sub(r"[-_.]+", "-", name).lower()


# the compiled kernels need numba (the [scenes] extra); their numpy references need nothing more
NEEDS_AN_EXTRA = ["handmesh_tutorial.collision._numba", "handmesh_tutorial.scenes._contact_numba"]


@pytest.mark.slow  # a fresh interpreter: torch's import, the network's load, one evaluation
def test_core_components_and_the_pretrained_network_work_without_any_extra(tmp_path):
    """Every module imports without the extras (their import at the top of any file fails
    here), and the components a researcher lifts run (their imports inside functions too)."""
    code = textwrap.dedent(f"""
        import importlib, json, pkgutil, sys
        for name in {ABSENT!r}:
            sys.modules[name] = None  # as if not installed
        import numpy as np, torch
        import handmesh_tutorial as hmt
        failed = {{}}
        for m in pkgutil.walk_packages(hmt.__path__, "handmesh_tutorial."):
            if m.name not in {NEEDS_AN_EXTRA!r} and not m.name.startswith("handmesh_tutorial._al"):
                try:
                    importlib.import_module(m.name)
                except Exception as err:
                    failed[m.name] = repr(err)
        from handmesh_tutorial import collision, hand, lcs, metrics, visibility
        from handmesh_tutorial.data import freihand
        from handmesh_tutorial.hand import mano
        from handmesh_tutorial.nn import blocks, decoder, encoder, hierarchy, model, spiral
        net = hmt.pretrained.pretrained()
        s = hmt.pretrained.pretrained_info()["config"]["image_size"]
        with torch.no_grad():
            out = net(torch.zeros(1, 3, s, s))
        assert out["joints"].shape == (1, 21, 3) and torch.isfinite(out["vertices"]).all()
        hm = hmt.hand.HandModel("right")
        idx = hmt.nn.spiral.spiral_indices(hm.faces, 9)
        y = hmt.nn.spiral.SpiralConv(3, 4, idx)(hm().vertices)
        levels = hierarchy.mesh_hierarchy(hm().vertices[0], hm.faces, (2, 2), use_cache=False)
        a0, a1 = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
        hit = hmt.collision.cylinders_intersect(a0, a1, np.array([0.1]), a0 + [0.15, 0, 0],
                                                a1 + [0.15, 0, 0], np.array([0.1]))
        j = out["joints"].numpy().astype(float)
        sc = hmt.metrics.freihand_scores(pred_joints=j, gt_joints=j + 0.001)
        art = hmt.lcs.hand_lcs(hm)
        ok = art.within_limits(art.from_pose(art.random_pose(0)))
        m = np.zeros((4, 4), int); m[1:3, 1:3] = 1
        vr = hmt.visibility.visibility_ratio(m, m, 1)
        image = np.random.default_rng(0).integers(0, 256, (96, 128, 3), dtype=np.uint8)
        K = np.array([[150.0, 0, 64], [0, 150, 48], [0, 0, 1]])
        p = hmt.inference.predict_hand(image, (30, 20, 90, 80), "left", K=K)
        root = hmt.testing.write_freihand_root(sys.argv[1], 2)
        from handmesh_tutorial.apps.cli import main
        code = main(["evaluate", "--checkpoint", "pretrained", "--data", str(root),
                     "--dataset", "freihand", "--no-progress", "--threads", "1"])
        bad = sorted(n for n in {ABSENT!r} if sys.modules.get(n) is not None)
        print(json.dumps({{"failed": failed, "spiral": list(y.shape), "hit": bool(hit[0]),
                          "mpjpe": round(sc["mpjpe"], 3), "limits": bool(ok), "vr": vr,
                          "levels": [len(v) for v in levels.vertices], "frame": p.frame,
                          "predicted": [list(p.vertices.shape), list(p.joints.shape)],
                          "evaluate": code, "extras_imported": bad}}))
    """)
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path / "freihand")],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    hand_v = hmt.hand.HandModel("right").num_vertices
    assert got == {"failed": {}, "spiral": [1, hand_v, 4], "hit": True, "mpjpe": 1.732,
                   "limits": True, "vr": 1.0, "levels": [hand_v, -(-hand_v // 2),
                                                         -(-hand_v // 4)],
                   "frame": "camera", "predicted": [[hand_v, 3], [21, 3]], "evaluate": 0,
                   "extras_imported": []}


def test_the_modules_that_need_an_extra_are_the_compiled_kernels():
    for name in NEEDS_AN_EXTRA:  # an import of numba at their top, nothing else optional
        path = ROOT / (name.replace(".", "/") + ".py")
        source = path.read_text()
        assert re.search(r"^import numba|^from numba import", source, re.M), path


def test_a_missing_extra_is_named_in_the_error(monkeypatch):
    from handmesh_tutorial.collision import _common
    from handmesh_tutorial.render import backend, backgrounds

    for top in ("matplotlib", "pyrender", "OpenGL", "skimage", "numba"):  # as if not installed
        for name in [m for m in sys.modules if m.startswith(top + ".")]:
            monkeypatch.delitem(sys.modules, name)
        monkeypatch.setitem(sys.modules, top, None)
    monkeypatch.setattr(backend, "_PYRENDER", None)
    monkeypatch.setattr(_common, "_NUMBA_STATE", [])
    # the numba kernels of an earlier test: as if never imported (module and package attribute)
    monkeypatch.delitem(sys.modules, "handmesh_tutorial.collision._numba", raising=False)
    monkeypatch.delattr(hmt.collision, "_numba", raising=False)
    with pytest.raises(ImportError, match=r'hmt.viz figures needs matplotlib.*pip install '
                                          r'"handmesh_tutorial\[notebooks\]"'):
        hmt.viz.plot_loss_curves([1.0, 0.5], [{"epoch": 1, "val_loss": 0.4}])
    with pytest.raises(ImportError, match=r'PyOpenGL.*"handmesh_tutorial\[scenes\]"'):
        backend.import_pyrender()
    with pytest.raises(ImportError, match=r'scikit-image.*"handmesh_tutorial\[scenes\]"'):
        backgrounds._skimage_data_dir()
    a = np.zeros((1, 3))
    with pytest.raises(ImportError, match=r'numba.*"handmesh_tutorial\[scenes\]"'):
        hmt.collision.cylinders_intersect(a, a + 1, [0.1], a, a + 1, [0.1], backend="numba")
    assert hmt.collision.cylinders_intersect(a, a + 1, [0.1], a, a + 1, [0.1],
                                             backend="auto")[0]  # numpy fallback without numba


def test_require_names_the_extra_only_when_the_package_itself_is_missing(tmp_path, monkeypatch):
    pkg = tmp_path / "hmt_fake_extra"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("import hmt_fake_missing_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(_optional.EXTRAS, "hmt_fake_extra", ("fake-extra", "scenes"))
    monkeypatch.setitem(_optional.EXTRAS, "hmt_fake_absent", ("fake-absent", "notebooks"))
    with pytest.raises(ModuleNotFoundError, match="hmt_fake_missing_dependency") as err:
        _optional.require("hmt_fake_extra", "a test")  # installed, but broken inside
    assert "handmesh_tutorial[" not in str(err.value)
    with pytest.raises(ModuleNotFoundError, match=r'^a test needs fake-absent, which the core '
                                                  r'install leaves out: pip install '
                                                  r'"handmesh_tutorial\[notebooks\]"'):
        _optional.require("hmt_fake_absent.sub", "a test")
    with pytest.raises(KeyError):
        _optional.missing_extra_message("torch", "core")


def test_extras_in_pyproject_match_the_library_and_the_core_install_leaves_them_out():
    project = PYPROJECT["project"]
    core = {_dist(r) for r in project["dependencies"]}
    extras = {k: {_dist(r) for r in v} for k, v in project["optional-dependencies"].items()}
    assert core == {"torch", "numpy", "scipy", "trimesh", "tqdm", "pillow"}, core
    for module, (dist, extra) in _optional.EXTRAS.items():
        assert _dist(dist) in extras[extra], f"{module}: {dist} is not in the [{extra}] extra"
        assert _dist(dist) not in core, f"{dist} ({module}) is in the core install"
    for heavy in ("jupyterlab", "ipywidgets", "meshcat", "matplotlib", "scikit-image"):
        assert heavy not in core
    assert (ROOT / "handmesh_tutorial" / "py.typed").is_file()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["handmesh_tutorial"]
    setup = (ROOT / "Makefile").read_text()
    installed = re.search(r'pip install -e "\.\[([a-z,]+)\]"', setup).group(1).split(",")
    assert sorted(installed) == sorted(extras), "make setup must install every extra"


def test_one_version_in_the_package_pyproject_and_changelog():
    assert hmt.__version__ == _version.__version__
    assert "version" in PYPROJECT["project"]["dynamic"] and "version" not in PYPROJECT["project"]
    attr = PYPROJECT["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "handmesh_tutorial._version.__version__"
    changelog = (ROOT / "CHANGELOG.md").read_text()
    heads = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - \d{4}-\d{2}-\d{2}$", changelog, re.M)
    assert heads and heads[0] == hmt.__version__, f"CHANGELOG's newest entry is {heads[:1]}"
    licence = (ROOT / "LICENSE").read_text()
    assert "MIT License" in licence and "CC0 1.0" in licence and "Apache License 2.0" in licence


def test_the_installed_metadata_has_the_package_version():
    dist = importlib.metadata.distribution("handmesh_tutorial")
    url = json.loads(dist.read_text("direct_url.json") or "{}").get("url", "")
    if url.startswith("file://") and Path(url[7:]).resolve() != ROOT:
        pytest.skip(f"the installed distribution is another tree's ({url}), not {ROOT}")
    installed = dist.version
    assert installed == hmt.__version__, (
        f"the installed metadata says {installed}, the package {hmt.__version__}: the install "
        "is stale (rerun make setup / pip install -e .)")


def test_shipped_files_are_recorded_with_the_version_that_shipped_them():
    assets = ROOT / "handmesh_tutorial" / "assets"
    shipped = sorted(p.name for p in assets.iterdir() if p.is_file())
    assert shipped == sorted(_version.SHIPPED_ASSETS)
    changelog = (ROOT / "CHANGELOG.md").read_text()
    entries = dict(re.findall(r"^## \[([\d.]+)\][^\n]*\n(.*?)(?=^## \[|\Z)", changelog,
                              re.M | re.S))
    for name, (digest, version) in _version.SHIPPED_ASSETS.items():
        got = hashlib.sha256((assets / name).read_bytes()).hexdigest()
        assert got == digest, (
            f"{name} changed (sha256 {got[:12]}...): a new shipped file is a new version; bump "
            "handmesh_tutorial/_version.py, record the hash there and add a CHANGELOG entry")
        assert version in entries and name in entries[version], (
            f"CHANGELOG's {version} entry does not name {name}")
        assert _version.shipped_version(assets / name) == version
    assert hmt.pretrained.pretrained_info()["library_version"] == (
        _version.SHIPPED_ASSETS["msmr_net_pretrained.pt"][1])


def test_onnx_export_has_its_own_extra_and_a_missing_package_names_it():
    """Issue 43 item 16: ONNX export needed the whole ``dev`` extra (jupyterlab, pytest...)."""
    extras = PYPROJECT["project"]["optional-dependencies"]
    export = {_dist(r) for r in extras["export"]}
    assert export == {"onnx", "onnxscript", "onnxruntime"}, export
    dev = {_dist(r) for r in extras["dev"]}
    assert export <= dev or any(r.replace(" ", "").startswith("handmesh_tutorial[") and
                                "export" in r for r in extras["dev"]), extras["dev"]
    for module in ("onnx", "onnxscript", "onnxruntime"):
        message = _optional.missing_extra_message(module, "ONNX export")
        assert 'pip install "handmesh_tutorial[export]"' in message, message
    page = (ROOT / "docs" / "concepts" / "export.md").read_text()
    assert 'pip install "handmesh_tutorial[export]"' in page
