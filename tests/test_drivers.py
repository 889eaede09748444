"""One driver and one config per concept (issue 35): the scene-generation driver and the
`TrainConfig` presets give what the three drivers and three configs gave before.

The ``_before_*`` functions are the code of the entry points as they were before the merge (kept
here verbatim as the reference): the demo's and the pretraining's training configs, and the demo's
scene generator.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from dataclasses import asdict

import pytest

import handmesh_tutorial as hmt
from handmesh_tutorial.apps import demo
from handmesh_tutorial.apps import pretrain_network as P
from handmesh_tutorial.budget import TIERS

_CPU = {"model_kwargs": {"keypoints": True, "global_rotation": True, "output": "skinned"},
        "keypoint_weight": 0.5, "aligned_weight": 1.0}
# 0.3.0 changed the paper recipe on purpose: its decoder regresses the coordinates (xyz)
_BEFORE_RECIPES = {"paper": {"model_kwargs": {"output": "xyz", "smoothing_length": 0.0}},
                   "cpu": _CPU}


def _before_lr_step(config):
    if config.lr_step is not None:
        return config.lr_step
    if config.recipe == "paper":  # 0.4.0 on purpose: halved after each quarter (paper's shape)
        return max(1, math.ceil(config.epochs / 4))
    return max(1, round(0.75 * config.epochs))


def _before_demo_train_config(config, data, out_dir, seed=0, progress=True, **overrides):
    from handmesh_tutorial.train import TrainConfig

    kw = dict(data=str(data), out_dir=str(out_dir), val_fraction=0.1,
              image_size=config.image_size, epochs=config.epochs, batch_size=config.batch_size,
              lr=config.lr, lr_step=_before_lr_step(config), augment=config.augment,
              encoder=config.encoder, decoder=config.decoder, attention=config.attention,
              seed=seed, device="cpu", threads=config.threads, cache_data=True,
              progress=progress, init_encoder=config.init_encoder,
              freeze_encoder=config.freeze_encoder if config.init_encoder else 0,
              encoder_lr_scale=config.encoder_lr_scale if config.init_encoder else 1.0,
              **_BEFORE_RECIPES[config.recipe])
    if config.recipe == "paper" and config.init_encoder:  # 0.3.0: read as the encoder was trained
        kw["model_kwargs"] = {**kw["model_kwargs"], "keypoints": True}
    kw.update(overrides)
    return TrainConfig(**kw)


def _before_pretrained_train_config(r, data, val_data, out_dir, progress=True):
    from handmesh_tutorial.train import TrainConfig

    cpus = os.cpu_count() or 1
    return TrainConfig(
        data=str(data), val_data=str(val_data), val_fraction=0.0,
        image_size=r.image_size, epochs=r.epochs, batch_size=r.batch_size,
        lr=r.lr, lr_step=max(1, math.ceil(r.epochs / 3)), lr_gamma=r.lr_gamma,
        augment=r.augment, encoder=r.encoder, decoder="multi", attention=True,
        seed=r.seed, device=r.device, threads=None,
        num_workers=r.loader_workers or max(0, cpus - 1), cache_data=False,
        val_batch_size=256, precision=r.precision, out_dir=str(out_dir),
        progress=progress, init=r.init, **_BEFORE_RECIPES[r.recipe])


@pytest.mark.parametrize("tier", TIERS)
@pytest.mark.parametrize("recipe", ["cpu", "paper"])
@pytest.mark.parametrize("init_encoder", ["pretrained", None])
def test_the_demo_trains_with_the_same_config_as_before_at_every_tier(tier, recipe, init_encoder):
    cfg = demo.DemoConfig.from_budget(hmt.budget(tier), recipe=recipe, init_encoder=init_encoder)
    for seed, over in ((0, {}), (3, {"decoder": "single", "attention": False})):
        got = demo.train_config(cfg, "d", "o", seed=seed, progress=False, **over)
        want = _before_demo_train_config(cfg, "d", "o", seed=seed, progress=False, **over)
        assert got.to_dict() == want.to_dict()


@pytest.mark.parametrize("kw", [{}, {"recipe": "paper", "epochs": 9, "loader_workers": 3},
                                {"init": "pretrained", "precision": "float32", "lr": 3e-4},
                                {"epochs": 1, "batch_size": 8, "augment": False,
                                 "device": "cpu", "seed": 4, "image_size": 96}])
def test_the_pretraining_recipe_trains_with_the_same_config_as_before(kw):
    r = P.PretrainedRecipe(**kw)
    got = r.train_config("tr", "va", "out", progress=False)
    assert got.to_dict() == _before_pretrained_train_config(r, "tr", "va", "out", False).to_dict()


def test_the_recipes_of_the_demo_are_the_same_as_before():
    from handmesh_tutorial.apps.demo.config import RECIPES

    assert RECIPES == _BEFORE_RECIPES


def _before_demo_scenes(root, num, seed, *, render_size, workers, progress=True, balance=False,
                        shard=None):
    from handmesh_tutorial.data import generate_dataset
    from handmesh_tutorial.scenes import KINDS, InteractionConfig, init_worker, make_sample

    fn = functools.partial(make_sample, kind="mixed", image_size=render_size)
    config = {k: (list(v) if isinstance(v, tuple) else v)
              for k, v in asdict(InteractionConfig()).items()}
    params = {"generator": "handmesh_tutorial.scenes.make_sample", "kind": "mixed",
              "limits": config["limits"], "config": config}
    return generate_dataset(root, fn, num, seed, list(KINDS), workers=workers,
                            progress=progress, params=params, shard=shard,
                            image_size=render_size, balance_vr=balance,
                            worker_init=functools.partial(init_worker, render_size))


def _hashes(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and not p.name.startswith(".")}


def test_one_driver_writes_the_demos_scenes_byte_for_byte_and_resumes_its_roots(tmp_path):
    """The demo's and the pretraining's scenes come from `scenes.generate_interactions` now: the
    same sample bytes as the demo's generator wrote, in whole or in time-bounded shards, and a root
    that the old generator wrote resumes (nothing rewritten)."""
    from handmesh_tutorial.scenes import generate_interactions

    old = tmp_path / "old"
    _before_demo_scenes(old, 2, 5, render_size=32, workers=1, progress=False)
    before = _hashes(old)
    # the driver in two shards within an unbounded time budget, merged into one root
    new = tmp_path / "new"
    s = generate_interactions(new, "mixed", 2, 5, image_size=32, progress=False,
                              max_seconds=math.inf, parts=2)
    assert s.written == 2 and s.shards == 2 and s.indices == [[0, 2]]
    got = _hashes(new)
    samples = {k: v for k, v in before.items() if k.startswith("samples/")}
    assert {k: v for k, v in got.items() if k.startswith("samples/")} == samples
    meta_old = json.loads((old / "meta.json").read_text())
    meta_new = json.loads((new / "meta.json").read_text())
    assert meta_new["params"].pop("generator") == "handmesh_tutorial.scenes"
    assert meta_old["params"].pop("generator") == "handmesh_tutorial.scenes.make_sample"
    assert meta_new == meta_old  # shards merged = one unsharded run
    # the old generator's root resumes through the driver and the demo's wrapper
    s = generate_interactions(old, "mixed", 2, 5, image_size=32, progress=False)
    assert (s.written, s.skipped) == (0, 2)
    s = demo.generate_scenes(old, 2, 5, render_size=32, workers=1, progress=False)
    assert (s.written, s.skipped) == (0, 2)
    assert _hashes(old) == before


def test_parts_and_a_time_budget_are_checked_before_anything_is_written(tmp_path):
    from handmesh_tutorial.data import generate_dataset
    from handmesh_tutorial.testing import toy_sample

    for kw, match in (({"parts": 0}, r"parts must be an integer in \[1, num=4\], got 0"),
                      ({"parts": 5}, "parts must be"),
                      ({"max_seconds": 10.0}, "max_seconds .* with parts > 1"),
                      ({"parts": 2, "max_seconds": -1.0}, "max_seconds must be"),
                      ({"parts": 2, "shard": (0, 2)}, "shard and parts exclude each other")):
        with pytest.raises(ValueError, match=match):
            generate_dataset(tmp_path / "r", toy_sample, 4, 0, "hand-hand", progress=False, **kw)
    assert not (tmp_path / "r").exists() and not (tmp_path / ".r-shards").exists()


def test_every_preset_is_a_valid_config_of_known_fields_and_copies_its_values():
    from handmesh_tutorial.train import TrainConfig
    from handmesh_tutorial.train.config import PRESETS

    assert set(PRESETS) == {"paper", "cpu", "demo", "pretraining"}
    # the paper: the defaults, with the decoder regressing the vertex coordinates
    paper, default = TrainConfig.preset("paper").to_dict(), TrainConfig().to_dict()
    assert paper.pop("model_kwargs") == {"output": "xyz", "smoothing_length": 0.0}
    default.pop("model_kwargs")
    assert paper == default
    fields = set(TrainConfig().to_dict())
    for name, values in PRESETS.items():
        assert set(values) <= fields, name
        cfg = TrainConfig.preset(name, data="d", epochs=3)
        assert cfg.data == "d" and cfg.epochs == 3
        assert {k: getattr(cfg, k) for k in values if k != "epochs"} == \
            {k: v for k, v in values.items() if k != "epochs"}
    cfg = TrainConfig.preset("cpu")
    cfg.model_kwargs["keypoints"] = False  # a config's dicts are its own
    assert PRESETS["cpu"]["model_kwargs"]["keypoints"] is True
    assert PRESETS["demo"]["model_kwargs"]["keypoints"] is True
    with pytest.raises(ValueError, match=r"unknown TrainConfig preset 'gpu'; the presets are "
                                         r"\['cpu', 'demo', 'paper', 'pretraining'\]"):
        TrainConfig.preset("gpu")
    with pytest.raises(ValueError, match=r"unknown TrainConfig fields \['epoch'\] given to "
                                         r"preset 'demo'"):
        TrainConfig.preset("demo", epoch=3)


def test_the_table_of_the_presets_says_what_each_sets():
    """The docstring table of `TrainConfig.preset` (rendered on the API page) is the presets."""
    import ast

    from handmesh_tutorial.train import TrainConfig
    from handmesh_tutorial.train.config import PRESETS

    rows = [ln.strip().strip("|").split("|") for ln in TrainConfig.preset.__doc__.splitlines()
            if ln.strip().startswith("| `")]
    names = ["paper", "cpu", "demo", "pretraining"]
    heads = PRESETS["cpu"]["model_kwargs"]
    table = {}
    for field, *cells in rows:
        field = field.strip().strip("`")
        named = {"cpu_heads": heads, "xyz": PRESETS["paper"]["model_kwargs"]}
        table[field] = [named[c.strip()] if c.strip() in named else ast.literal_eval(c.strip())
                        for c in cells]
    assert set(table) == {k for v in PRESETS.values() for k in v}  # every field a preset sets
    for k, name in enumerate(names):
        cfg = TrainConfig.preset(name)
        assert {f: getattr(cfg, f) for f in table} == {f: v[k] for f, v in table.items()}, name


def test_the_demo_and_the_pretraining_recipe_default_to_their_presets():
    """DemoConfig and PretrainedRecipe keep their own defaults (read before the scene generator
    forks, without torch); these must be the presets' numbers."""
    from handmesh_tutorial.train import TrainConfig

    for cfg in (demo.DemoConfig(), demo.DemoConfig.from_budget(hmt.budget("default"))):
        got = demo.train_config(cfg, "d", "o")
        assert got.to_dict() == TrainConfig.preset("demo", data="d", out_dir="o").to_dict()
    got = P.PretrainedRecipe(loader_workers=3).train_config("tr", "va", "o")
    want = TrainConfig.preset("pretraining", data="tr", val_data="va", out_dir="o", num_workers=3)
    assert got.to_dict() == want.to_dict()


def test_the_recipe_names_are_checked_without_importing_torch():
    import subprocess
    import sys

    code = ("import sys; from handmesh_tutorial.apps.pretrain_network import PretrainedRecipe; "
            "from handmesh_tutorial.apps.demo.config import DemoConfig, RECIPES; "
            "PretrainedRecipe(recipe='paper'); DemoConfig.from_budget(recipe='paper'); "
            "assert 'paper' in RECIPES and 'gpu' not in RECIPES and len(RECIPES) == 2; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'torch')[:3])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert out.stdout.strip() == "[]"
