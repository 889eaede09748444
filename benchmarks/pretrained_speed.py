"""The shipped network's CPU cost beside the previous shipped file's, measured in the same run.

Times one forward pass of one 128-px crop (batch 1, as ``predict_hand`` runs a photo) on one
thread, for the shipped ``msmr_net_pretrained.pt`` and for the previous version of that file in
git history (the newest committed version whose bytes differ from the file now in the package),
or for ``--previous FILE``. Round-robin repeats, the fastest of each is printed with the ratio
new / previous (below 1: the new file is cheaper). Also prints each file's parameters, its
storage and its training stages (``hmt.pretrained.lineage``).

Run: ``python benchmarks/pretrained_speed.py [--previous FILE] [--repeats 7] [--threads 1]``.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import torch

from handmesh_tutorial.pretrained import lineage, pretrained_path
from handmesh_tutorial.train import load_checkpoint

ASSET = "handmesh_tutorial/assets/msmr_net_pretrained.pt"


def previous_file(current: Path, out: Path) -> tuple[Path, str] | None:
    """The newest committed version of the shipped file whose bytes differ from ``current``,
    written to ``out``; ``None`` when git or such a version is missing."""
    root = Path(__file__).resolve().parents[1]
    now = current.read_bytes()
    try:
        revs = subprocess.run(["git", "log", "--format=%h", "--", ASSET], cwd=root, check=True,
                              capture_output=True, text=True).stdout.split()
        for rev in revs:
            blob = subprocess.run(["git", "show", f"{rev}:{ASSET}"], cwd=root, check=True,
                                  capture_output=True).stdout
            if blob != now:
                out.write_bytes(blob)
                return out, f"git {rev}"
    except (OSError, subprocess.CalledProcessError):
        return None
    return None


def _stages(made: dict | None) -> str:
    """What made a file, in a few words: its training stages and where the first started."""
    if not made:
        return "(no training record)"
    stages = lineage(made)
    parts = sorted({s["part"] for s in stages})
    return (f"{len(stages)} training stage(s) ({', '.join(parts)}), the first from "
            f"{stages[0]['start']}")


def time_forward(net: torch.nn.Module, size: int, repeats: int) -> list[float]:
    x = torch.randn(1, 3, size, size)
    with torch.inference_mode():
        for _ in range(3):  # warm-up: allocations, oneDNN kernels
            net(x)
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            net(x)
            times.append(time.perf_counter() - t)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--previous", type=Path, help="the file to compare with (default: the "
                    "previous shipped version from git history)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        files = {"shipped": (pretrained_path(), "package")}
        prev = (args.previous, "--previous") if args.previous else \
            previous_file(pretrained_path(), Path(tmp) / "previous.pt")
        if prev is None:
            print("no previous version of the shipped file in git history: timing it alone")
        else:
            files["previous"] = prev
        nets = {}
        for name, (path, where) in files.items():
            net, ck = load_checkpoint(path)
            nets[name] = (net.eval(), int(ck["config"]["image_size"]))
            params = sum(p.numel() for p in net.parameters())
            made = _stages(ck.get("pretrained"))
            print(f"{name:9s} {where}: {params / 1e6:.2f} M parameters, "
                  f"{ck.get('weights', 'float32')} storage, {nets[name][1]}-px input; {made}")
        best = {k: float("inf") for k in nets}
        for _ in range(args.rounds):  # round-robin: a busy machine slows both alike
            for name, (net, size) in nets.items():
                best[name] = min(best[name], min(time_forward(net, size, args.repeats)))
    print(f"\none {nets['shipped'][1]}-px crop, batch 1, {args.threads} thread(s), fastest of "
          f"{args.rounds} x {args.repeats}:")
    for name, t in best.items():
        print(f"  {name:9s} {1000 * t:7.1f} ms")
    if "previous" in best:
        print(f"  ratio shipped / previous: {best['shipped'] / best['previous']:.2f}")


if __name__ == "__main__":
    main()
