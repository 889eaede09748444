"""Every code block of the docs page "For researchers" runs, in order, in one namespace (issue 54).

The page shows eight tasks in a few lines each, from the public API only; a block that stops
working fails here. Slow (a fine-tune epoch, an ONNX export, scenes rendered): marked ``slow``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

PAGE = Path(__file__).resolve().parents[1] / "docs" / "concepts" / "researchers.md"


def blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S)


def test_the_page_has_a_block_per_task():
    text = PAGE.read_text(encoding="utf-8")
    assert len(re.findall(r"^## \d\. ", text, re.M)) == 8
    assert len(blocks()) >= 8


@pytest.mark.slow
def test_every_block_of_the_page_runs(tmp_path, monkeypatch):
    pytest.importorskip("onnxruntime", reason="task 5 needs the export extra")
    pytest.importorskip("pyrender", reason="tasks 2 and 6 render scenes (the scenes extra)")
    import torch

    torch.set_num_threads(1)
    namespace: dict = {}
    for i, code in enumerate(blocks()):
        code = code.replace("/tmp/", f"{tmp_path}/")
        exec(compile(code, f"{PAGE.name} block {i}", "exec"), namespace)  # noqa: S102
    assert namespace["loss"].item() < 0.2  # the autoencoder learned something
    assert abs(namespace["vr"] - namespace["s"]["vr"][1]) < 1e-9
