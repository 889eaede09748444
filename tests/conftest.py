"""The maintainer's tools and the research probes live outside the package (``tools/``,
``benchmarks/``); their tests import them from there."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for folder in ("tools", "benchmarks"):
    if str(ROOT / folder) not in sys.path:
        sys.path.insert(0, str(ROOT / folder))
