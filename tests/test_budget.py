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
