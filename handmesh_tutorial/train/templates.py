"""The mesh template of a run and the network a config describes.

A run's template is the library's open right hand unless ``TrainConfig.template`` names a ``.npz``
written by [`save_template`][handmesh_tutorial.train.templates.save_template] or a user's MANO
pickle (``MANO_RIGHT.pkl``, read by the restricted loader of
[`handmesh_tutorial.hand.mano`][handmesh_tutorial.hand.mano]); checkpoints store only its
[`template_hash`][handmesh_tutorial.train.templates.template_hash]. Vertices in metres, (V, 3);
faces (F, 3); joint regressor (21, V).

Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import hashlib
import os
import zipfile
from pathlib import Path

import numpy as np
from torch import nn

from .._io import atomic_savez
from .._untrusted import read_npz
from ..nn.model import as_template, build_model
from .config import TrainConfig

__all__ = ["resolve_template", "save_template", "build_model_from_config"]


MAX_TEMPLATE_EXTENT_M = 1.0
"""Largest distance of a template file's vertex from the origin, metres (a hand is about 0.2 m
long)."""


def resolve_template(spec=None):
    """The mesh template of a run.

    Args:
        spec: ``None`` (the open right hand); a path to a ``.npz`` with ``vertices``, ``faces``,
            ``joint_regressor`` (see
            [`save_template`][handmesh_tutorial.train.templates.save_template]); a path to a
            right-hand MANO pickle (``.pkl``: the flat rest hand of
            [`load_mano`][handmesh_tutorial.hand.mano.load_mano], its 21-keypoint regressor with
            MANO's fingertip vertices in the ``"smplx"`` convention); or anything
            [`as_template`][handmesh_tutorial.nn.model.as_template] accepts.

    Returns:
        A [`MeshTemplate`][handmesh_tutorial.nn.model.MeshTemplate].

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: the file is neither a ``.npz`` nor a ``.pkl``; the ``.npz`` is damaged,
            lacks a key, has bad shapes or face ids, NaN, or vertices beyond
            `MAX_TEMPLATE_EXTENT_M` (the message names the file); the
            ``.pkl`` is not a MANO-format file or is a left hand (the network predicts right
            hands, left ones mirrored: give ``MANO_RIGHT.pkl``).
        UnsafePickleError: the ``.pkl`` names a class outside the MANO loader's whitelist.
    """
    if isinstance(spec, str | os.PathLike):
        path = Path(spec)
        if not path.is_file():
            raise FileNotFoundError(f"template file not found: {path}")
        if path.suffix.lower() == ".pkl":
            return as_template(_mano_template(path))
        if not zipfile.is_zipfile(path):  # numpy's own message would suggest allow_pickle
            raise ValueError(f"{path}: not a template file: give a .npz written by "
                             "train.save_template (vertices, faces, joint_regressor) or a "
                             "MANO_RIGHT.pkl")
        spec = read_npz(path, ("vertices", "faces", "joint_regressor"))
        missing = {"vertices", "faces", "joint_regressor"} - set(spec)
        if missing:
            raise ValueError(f"{path}: template lacks keys {sorted(missing)}")
        try:
            t = as_template(spec)
        except ValueError as e:  # the checks name no file
            raise ValueError(f"{path}: {e}") from None
        v, r = np.asarray(t.vertices, np.float64), np.asarray(t.joint_regressor, np.float64)
        if not (np.isfinite(v).all() and np.isfinite(r).all()):
            raise ValueError(f"{path}: template vertices or joint_regressor hold NaN or infinity")
        far = float(np.abs(v).max(initial=0.0))
        if far > MAX_TEMPLATE_EXTENT_M:
            raise ValueError(f"{path}: a template vertex lies {far:.3g} m from the origin, beyond "
                             f"{MAX_TEMPLATE_EXTENT_M:g} m: templates are in metres (a file in "
                             "millimetres?)")
        return t
    return as_template(spec)


def _mano_template(path: Path):
    """A right-hand MANO model from a pickle, refused by name when it is a left hand."""
    from ..hand.mano import load_mano

    if "left" in path.name.lower():  # load_mano's rule for the side
        raise ValueError(f"{path}: a left-hand MANO file cannot be the template: the network "
                         "predicts right hands (left ones are mirrored); give MANO_RIGHT.pkl")
    return load_mano(path, side="right")


def save_template(path: str | os.PathLike, template) -> Path:
    """Write a template as ``.npz`` (``vertices`` (V,3) m, ``faces`` (F,3), ``joint_regressor``
    (21,V)) atomically, for ``TrainConfig(template=path)``.

    Args:
        path: output file.
        template: anything [`resolve_template`][handmesh_tutorial.train.templates.resolve_template]
            accepts.

    Returns:
        The path.
    """
    t = resolve_template(template)
    path = Path(path)
    atomic_savez(path, compressed=False, vertices=t.vertices, faces=t.faces,
                 joint_regressor=t.joint_regressor)
    return path


def template_hash(template) -> str:
    """Short SHA-256 of a template's vertices, faces and joint regressor (float64/int64 bytes)."""
    t = resolve_template(template)
    h = hashlib.sha256()
    for a, dt in ((t.vertices, np.float64), (t.faces, np.int64), (t.joint_regressor, np.float64)):
        a = np.ascontiguousarray(a, dtype=dt)
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def build_model_from_config(config: TrainConfig, template=None) -> nn.Module:
    """The network described by a config (weights freshly initialised from torch's global RNG).

    Args:
        config: the run's [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig].
        template: overrides ``config.template`` (a template object or path).

    Returns:
        An [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet] on the CPU.

    Raises:
        ValueError: a template file that cannot be read, or a template whose mesh builds no
            mesh hierarchy or spirals (the message names ``config.template``'s file).
    """
    spec = config.template if template is None else template
    tmpl = resolve_template(spec)
    try:
        return build_model(encoder=config.encoder, decoder=config.decoder,
                           attention=config.attention, template=tmpl, channels=config.channels,
                           latent_channels=config.latent_channels, **config.model_kwargs)
    except (RuntimeError, ValueError, IndexError) as e:
        # a template whose mesh cannot be decimated into the network's hierarchy (the file
        # named: `train` passes the template it resolved from ``config.template``)
        where = next((str(p) for p in (spec, config.template) if isinstance(p, str | os.PathLike)),
                     "the template")
        raise ValueError(f"{where}: this template builds no network ({type(e).__name__}: "
                         f"{e}); give a manifold, consistently oriented hand mesh in metres") \
            from e
