"""Draw the grid of fresh scenes at the top of the docs page *Realistic scenes*.

Usage: ``PYOPENGL_PLATFORM=egl python tools/draw_scenes_grid.py [docs/concepts/img/scenes_grid.jpg]``.
Rows are the three kinds (hand-hand, hand-object, hand-chain); each row shows the first four
seeds ``dataset.sample_seed(11 + row, i)``, i = 0, 1, ..., that the generator accepts (as in
notebook 05), at 224 px. The output is committed; rerun this script whenever the generator's
images change. Same code, same bytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

import handmesh_tutorial as hmt

PER_ROW = 4
SIZE = 224


def scenes_grid() -> np.ndarray:
    """(3*SIZE, PER_ROW*SIZE, 3) uint8: the grid of the docs page."""
    rows = []
    with hmt.render.Renderer(SIZE) as renderer:
        for row, kind in enumerate(hmt.scenes.KINDS):
            images, i = [], 0
            while len(images) < PER_ROW:
                seed = hmt.data.sample_seed(11 + row, i)
                i += 1
                try:
                    sample = hmt.scenes.make_sample(seed, kind, SIZE, renderer=renderer)
                except hmt.scenes.InteractionError:
                    continue          # the generator rejects some seeds; take the next one
                images.append(sample["image"])
            rows.append(np.concatenate(images, axis=1))
    return np.concatenate(rows, axis=0)


def main(argv: list[str]) -> None:
    out = Path(argv[0] if argv else "docs/concepts/img/scenes_grid.jpg")
    tmp = out.with_name(out.name + ".tmp")
    Image.fromarray(scenes_grid()).save(tmp, format="JPEG", quality=88)
    tmp.replace(out)                          # atomic: never a half-written figure
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
