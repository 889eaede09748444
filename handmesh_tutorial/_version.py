"""The library's version (the one source: ``pyproject.toml`` reads it from here) and the record of
the shipped weights that each version carries.

The version changes whenever behaviour or the shipped weights change; ``CHANGELOG.md`` has an entry
for each. Files the library writes (training checkpoints, the pretrained network's export, the
pose-encoder file) record the version that wrote them under ``library_version``. The shipped files
made before 0.2.0 carry no such entry: `SHIPPED_ASSETS` records them by hash, and a test fails
when a shipped file changes without a new entry here. Docs page "Changelog".
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["ASSET_DIR", "PRETRAINED_FILE", "SHIPPED_ASSETS", "__version__", "shipped_file",
           "shipped_version"]

__version__ = "0.6.0"

SHIPPED_ASSETS: dict[str, tuple[str, str]] = {
    # file in handmesh_tutorial/assets/: (sha256 of its bytes, the version that first shipped them)
    "hand_encoder_neutral.pt": (
        "069afa10e4cf433fd1b9dcce7d5289413890f811cd4608b5bd0a76486fe5aabe", "0.3.0"),
    "hand_encoder_pretrained.pt": (
        "1c2bf71bcafce790672d067784defea0d0dab7336b6e54dca8d1eb067db20637", "0.5.0"),
    "fit_sweep_results.json": (
        "cc9747770695d84c371596f37857aa4e8dd57142b07f43d45800b963ed6741f7", "0.3.0"),
    "table3_results.json": (
        "6fef0c9376dd478af175d513483320a30577d993e0762092f5d4cbff31819e07", "0.3.0"),
    "makehuman_hand.npz": (
        "7ec92e1e3c99b0d6cedef1209e2cd6ade09b5e4ce2abb04c17c1713b08e1a739", "0.2.0"),
    "msmr_net_pretrained.pt": (
        "76da223e26b8df8c7ec4ba08873cf2e0ce12a130dd98a8187ad8922a5ec9f430", "0.6.0"),
}
"""The shipped files, by hash: file name -> (sha256, the library version that shipped them).

Replacing a file (new weights, a rebuilt template) means a new version: bump `__version__`, record
the new hash with it here and add the CHANGELOG entry."""

ASSET_DIR = Path(__file__).resolve().parent / "assets"
"""The folder of the shipped files (package data)."""
PRETRAINED_FILE = "msmr_net_pretrained.pt"
"""The shipped pretrained MSMR-Net in `ASSET_DIR` (``load_checkpoint("pretrained")`` reads it)."""


def shipped_file(name: str, how_to_make: str) -> Path:
    """Path of a shipped file in `ASSET_DIR`.

    Args:
        name: its file name.
        how_to_make: what makes it (for the error), e.g. ``"make pretrained"``.

    Raises:
        FileNotFoundError: this installation does not have it.
    """
    path = ASSET_DIR / name
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not in this installation; make it with `{how_to_make}`")
    return path


def shipped_version(path: str | os.PathLike) -> str | None:
    """The library version that shipped a file, by its bytes (`SHIPPED_ASSETS`).

    Args:
        path: a file; only its name and bytes are read.

    Returns:
        The recorded version when the file's name is in `SHIPPED_ASSETS` and its sha256 equals the
        recorded one, else ``None`` (another file, or shipped files edited by hand).
    """
    path = Path(path)
    digest, version = SHIPPED_ASSETS.get(path.name, ("", None))
    if not digest or not path.is_file():
        return None
    return version if hashlib.sha256(path.read_bytes()).hexdigest() == digest else None
