"""The ``handmesh`` command: ``handmesh --help`` lists the sub-commands.

Each sub-command is a thin wrapper: argument parsing here, the work in the library module that owns
the concept, so everything the command does can also be called from Python or a notebook.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _cmd_demo(args: argparse.Namespace) -> int:
    from . import viz

    out = Path(args.out)
    path = viz.save_hand_gallery(out / "open_hand_poses.png", seed=args.seed)
    print(f"handmesh demo: rendered the open hand in a few poses to {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of the ``handmesh`` command (sub-commands included)."""
    parser = argparse.ArgumentParser(
        prog="handmesh",
        description="MSMR-Net tutorial toolkit: generate INTER-SH scenes, train, evaluate, demo.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = sub.add_parser("demo", help="run the main demo job and write its outputs to --out")
    demo.add_argument("--out", default="runs/demo", help="output folder (default: runs/demo)")
    demo.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``handmesh`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
