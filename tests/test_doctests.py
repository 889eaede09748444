"""The liftable ops' ``Examples:`` sections run, and print what they claim (issue 35).

A researcher who lifts one op reads its example first, so each example is executed here with
``doctest`` on exactly the modules that hold the liftable ops. The examples are small, seeded and
fast; an example whose printed output no longer matches fails here, naming the op and the line.
"""

from __future__ import annotations

import doctest
import importlib
import types

import pytest

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE

# (module, names in it whose docstrings must carry an executed example)
LIFTABLE = {
    "handmesh_tutorial.nn.spiral": ("spiral_indices", "SpiralConv"),
    "handmesh_tutorial.nn.hierarchy.hierarchy": ("mesh_hierarchy",),
    "handmesh_tutorial.nn.hierarchy.matrices": ("to_torch_sparse",),
    "handmesh_tutorial.nn.blocks": ("Pool",),
    "handmesh_tutorial.collision.exact": ("cylinders_intersect", "capsules_intersect"),
    "handmesh_tutorial.collision.skin": ("triangles_intersect",),
    "handmesh_tutorial.visibility": ("visibility_ratio",),
    "handmesh_tutorial.metrics.scores": ("freihand_scores",),
    "handmesh_tutorial.metrics.procrustes": ("procrustes_align",),
    "handmesh_tutorial.lcs.angles": ("rotation_from_lcs_angles",),
    "handmesh_tutorial.hand.model": ("HandModel",),
}


def run_doctests(module) -> doctest.TestResults:
    """``doctest.testmod`` on one module; a failing example's report goes to stdout (pytest
    shows it under "Captured stdout")."""
    return doctest.testmod(module, optionflags=FLAGS, report=True)


@pytest.mark.parametrize("name", sorted(LIFTABLE))
def test_examples_of_the_liftable_ops_pass(name):
    module = importlib.import_module(name)
    results = run_doctests(module)
    assert results.failed == 0, f"{name}: {results.failed} failing example(s), report above"
    assert results.attempted > 0, f"{name}: no example ran"


@pytest.mark.parametrize("name, op", [(m, op) for m, ops in sorted(LIFTABLE.items()) for op in ops])
def test_each_liftable_op_has_an_examples_section(name, op):
    doc = getattr(importlib.import_module(name), op).__doc__ or ""
    tests = doctest.DocTestParser().get_examples(doc)
    assert "\n    Examples:\n" in doc, f"{name}.{op}: no Google-style 'Examples:' section"
    assert len(tests) >= 2, f"{name}.{op}: the example should show at least two steps"


def test_griffe_renders_the_examples_as_an_examples_section():
    """mkdocstrings (griffe's Google parser) reads 'Examples:' as code, 'Example:' as prose."""
    griffe = pytest.importorskip("griffe")
    for name, ops in LIFTABLE.items():
        module = importlib.import_module(name)
        for op in ops:
            doc = griffe.Docstring(getattr(module, op).__doc__ or "", lineno=1)
            kinds = [s.kind.value for s in doc.parse("google")]
            assert "examples" in kinds, f"{name}.{op}: sections {kinds}"


def test_a_wrong_example_fails(capsys):
    """The runner above counts a wrong printed output as a failure and reports it."""
    module = types.ModuleType("wrong_example")
    module.__doc__ = """A module whose example prints the wrong number.

    >>> 1 + 1
    3
    """
    assert run_doctests(module) == (1, 1)  # (failed, attempted)
    assert "Expected:\n    3\nGot:\n    2" in capsys.readouterr().out
