"""Random directions and rotations shared by the generator and the camera framing (private)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def _unit(v):
    return v / np.linalg.norm(v)


def _random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


def _random_direction(rng) -> np.ndarray:
    return _unit(rng.normal(size=3))
