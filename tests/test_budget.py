from dataclasses import fields

import pytest

import handmesh_tutorial as hmt
from handmesh_tutorial.budget import ENV_VAR, TIERS


def test_environment_selects_the_tier(monkeypatch):
    for tier in TIERS:
        monkeypatch.setenv(ENV_VAR, tier)
        assert hmt.budget().name == tier
    monkeypatch.delenv(ENV_VAR)
    assert hmt.budget().name == "default"
    monkeypatch.setenv(ENV_VAR, "  ")
    assert hmt.budget().name == "default"


def test_unknown_tier_names_the_variable(monkeypatch):
    monkeypatch.setenv(ENV_VAR, "huge")
    with pytest.raises(ValueError, match="HANDMESH_BUDGET.*smoke, default, full"):
        hmt.budget()


def test_tiers_grow_from_smoke_to_full():
    smoke, default, full = (hmt.budget(t) for t in TIERS)
    for f in fields(smoke):
        if f.name in ("name", "threads"):
            continue
        a, b, c = (getattr(x, f.name) for x in (smoke, default, full))
        assert 0 < a <= b <= c, f"{f.name}: {a}, {b}, {c}"
    assert full.image_size == 224  # the paper's input size


def test_budget_is_immutable():
    with pytest.raises(AttributeError):
        hmt.budget("smoke").epochs = 5


@pytest.mark.parametrize("tier", ["smoke", "default", "full"])
def test_printed_budget_fits_a_page_and_keeps_every_size(tier):
    b = hmt.budget(tier)
    text = str(b)
    assert max(len(line) for line in text.splitlines()) <= 96
    assert text.startswith(f"Budget {tier!r}: ")
    for key, value in b.as_dict().items():
        if key != "name":
            assert f"{key}={value}" in text.replace("\n  ", " ")
    assert "\n" not in repr(b)  # repr stays the one-line dataclass form


def test_printed_train_config_fits_a_page_and_keeps_every_field():
    cfg = hmt.train.TrainConfig(model_kwargs={"keypoints": True, "output": "skinned"},
                                out_dir="runs/a/rather/long/path/to/show/wrapping")
    text = str(cfg)
    assert max(len(line) for line in text.splitlines()) <= 96
    joined = text.replace("\n  ", " ")
    for key in cfg.to_dict():
        assert f"{key}={getattr(cfg, key)!r}" in joined, key
    assert "\n" not in repr(cfg)
