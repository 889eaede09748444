"""The maintainer's tools and the research probes live outside the package (``tools/``,
``benchmarks/``); their tests import them from there. ``toy_root``: an 8-sample INTER-SH root of
toy hands, shared by the training, output-folder and read-out tests."""

import functools
import sys
from pathlib import Path

import pytest

from handmesh_tutorial.data import generate_dataset
from handmesh_tutorial.testing import toy_sample

ROOT = Path(__file__).resolve().parents[1]
for folder in ("tools", "benchmarks"):
    if str(ROOT / folder) not in sys.path:
        sys.path.insert(0, str(ROOT / folder))


@pytest.fixture(scope="module")
def toy_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("toy_intersh")
    generate_dataset(root, functools.partial(toy_sample, image_size=64), num=8, seed=11,
                     kind="hand-hand", progress=False, durable=False)
    return root
