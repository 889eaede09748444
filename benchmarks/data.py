"""Training-crop loading: the lean target read against the full sample read, one run.

A data loader's worker spends each item on reading a scene and cutting the target's crop
(``InterSHTorchDataset[i]``). Two ways to read, timed in interleaved repeats (medians):

* ``full read``: ``read_sample``, every file of the sample (image, scene mask, one mask per body,
  every body's arrays), as before ``read_target`` existed;
* ``lean read``: ``read_target`` (the default for an on-disk root): the image, the annotation and
  the target's arrays only.

Both give identical items (checked here on every item, and in ``tests/test_dataset.py``). Prints
ms per item (augmented crop included) and the ratio. The scenes are made first, in a temporary
folder: mixed kinds at 224 px, as the pretrained model's training data.

    .venv/bin/python benchmarks/data.py [--scenes 40] [--repeats 5] [--crop 128]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from handmesh_tutorial.apps.demo import generate_scenes
from handmesh_tutorial.data import InterSHDataset
from handmesh_tutorial.data.torch_views import InterSHTorchDataset


def time_items(ds, repeats: int) -> float:
    """Median over ``repeats`` passes of the seconds per item."""
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        for i in range(len(ds)):
            ds[i]
        runs.append((time.perf_counter() - t) / len(ds))
    return float(np.median(runs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=40)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--crop", type=int, default=128)
    args = ap.parse_args()
    torch.set_num_threads(1)  # as in a data-loader worker
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "scenes"
        generate_scenes(root, args.scenes, 7, render_size=224, workers=2, progress=False)
        views = {
            "full read": InterSHTorchDataset(InterSHDataset(root, transform=lambda s: s),
                                             args.crop, train=True),
            "lean read": InterSHTorchDataset(root, args.crop, train=True),
        }
        for i in range(len(views["lean read"])):
            a, b = (v[i] for v in views.values())
            assert all(torch.equal(a[k], b[k]) for k in a), f"item {i} differs"
        times = {k: [] for k in views}
        for _ in range(args.repeats):  # interleaved, so a busy moment hits both
            for name, ds in views.items():
                times[name].append(time_items(ds, 1))
    base = np.median(times["full read"])
    print(f"# {args.scenes} mixed scenes at 224 px, {args.crop}-px augmented crops, 1 thread, "
          f"median of {args.repeats}")
    print(f"{'read':<12}{'ms/item':>10}{'ratio':>8}")
    for name, t in times.items():
        m = np.median(t)
        print(f"{name:<12}{1000 * m:>10.2f}{base / m:>7.2f}x")


if __name__ == "__main__":
    main()
