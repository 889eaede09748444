"""The decoder fit probe, now in the package: ``handmesh_tutorial.train.fit_probe``.

A thin wrapper kept so that ``import fit_probe`` in the benchmarks (``decoder_fit.py``) keeps
working; new code imports ``from handmesh_tutorial.train import fit_probe``.
"""

from handmesh_tutorial.train.fit_probe import *  # noqa: F403
from handmesh_tutorial.train.fit_probe import __all__  # noqa: F401
