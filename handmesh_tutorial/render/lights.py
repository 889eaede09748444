"""Lights in the OpenCV camera frame: the `Light` record, deterministic and random lighting.

`default_lights` (a head light and a key light), `random_lights` (a few lights mostly along the
optical axis) and `scene_lights` (the generator's key / fill / rim / point lighting of random
colour temperature). Directions are the way the light *travels*, in the camera frame (x right,
y down, z forward); intensities are pyrender's (lux for directional lights, candela for point
lights).

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .color import color_temperature

__all__ = ["Light", "default_lights", "random_lights", "scene_lights"]


@dataclass(frozen=True)
class Light:
    """A light in the OpenCV camera frame.

    Attributes:
        kind: ``"directional"`` or ``"point"``.
        color: (3,) RGB in [0, 1].
        intensity: lux for directional lights, candela for point lights (pyrender units).
        direction: (3,) unit direction the light *travels* (directional lights), camera frame.
        position: (3,) position, metres, camera frame (point lights).
    """

    kind: str
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 3.0
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)


def default_lights() -> list[Light]:
    """Deterministic lighting: a head light along the view axis and a key light from top left.

    Returns:
        A list of `Light`.
    """
    key = np.array([0.4, 0.6, 1.0])
    key /= np.linalg.norm(key)
    return [Light("directional", intensity=1.0, direction=(0.0, 0.0, 1.0)),
            Light("directional", intensity=0.8, direction=tuple(key))]


def random_lights(rng: np.random.Generator | int | None, num: tuple[int, int] = (2, 4),
                  target_depth: float = 0.5) -> list[Light]:
    """Random lighting: a few directional and point lights with random intensity and direction.

    Intensities are chosen so that a surface at ``target_depth`` facing the camera receives an
    irradiance of roughly 0.5-3 (pyrender units; 1 is a well exposed single light).
    Directions come from the camera's hemisphere (lights travel roughly along +z, never from
    behind the objects towards the camera), point lights sit around the camera at
    ``0.2-0.6 * target_depth`` from the optical axis, colours are slightly warm or cool whites.

    Args:
        rng: a ``numpy.random.Generator`` or a seed.
        num: inclusive range of the number of lights.
        target_depth: typical depth of the scene, metres (sizes the point-light positions).

    Returns:
        A list of `Light` (first one always directional so the scene is never dark).
    """
    rng = np.random.default_rng(rng)
    n = int(rng.integers(num[0], num[1] + 1))
    lights = []
    for i in range(n):
        tint = np.clip(1.0 + rng.normal(0.0, 0.08, 3), 0.75, 1.0)
        kind = "directional" if i == 0 or rng.random() < 0.6 else "point"
        if kind == "directional":
            d = rng.normal(size=3)
            d[2] = abs(d[2]) + 0.8  # travel into the scene
            d /= np.linalg.norm(d)
            lights.append(Light("directional", tuple(tint), float(rng.uniform(0.4, 1.2)),
                                direction=tuple(d)))
        else:
            ang = rng.uniform(0, 2 * np.pi)
            r = rng.uniform(0.2, 0.6) * target_depth
            pos = (r * np.cos(ang), r * np.sin(ang), rng.uniform(-0.2, 0.2) * target_depth)
            lights.append(Light("point", tuple(tint),
                                float(rng.uniform(0.3, 1.0) * target_depth**2),
                                position=tuple(float(p) for p in pos)))
    return lights


def scene_lights(rng, depth: float = 0.5):
    """Random lighting of varied intensity, colour temperature and direction (camera frame).

    * a **key light** 20-75 degrees off the optical axis from a random side;
    * a weaker **fill light** from the opposite side;
    * with probability 0.3 a **rim light** from behind the bodies (it lights their silhouettes);
    * with probability 0.3 a point light near the camera.

    The key light's colour temperature is drawn log-uniformly in 2700-8000 K; the fill shares it
    half of the time, else it differs by about 60 mired (mixed light: a lamp and a window). The
    camera is white-balanced for a temperature near the key's (15 mired off), so colour casts
    stay as mild as in real photos. All intensities share an exposure factor (x0.6-1.6). A side
    key light gives the shading cues (folds, finger outlines) that real photos have;
    ``render.random_lights`` lights mostly along the optical axis.

    Args:
        rng: ``numpy.random.Generator`` or seed.
        depth: typical scene depth, metres (places the point light).

    Returns:
        A list of [`Light`][handmesh_tutorial.render.lights.Light] (camera frame).
    """
    rng = np.random.default_rng(rng)

    def direction(lo, hi, phi):
        th = np.deg2rad(rng.uniform(lo, hi))
        return (float(np.sin(th) * np.cos(phi)), float(np.sin(th) * np.sin(phi)),
                float(np.cos(th)))

    def shifted(kelvin, mired):  # colour temperatures differ evenly in mired (1e6 / K)
        return float(np.clip(1e6 / (1e6 / kelvin + mired), 2500.0, 9000.0))

    t_key = float(np.exp(rng.uniform(np.log(2700.0), np.log(8000.0))))
    t_wb = shifted(t_key, rng.normal(0.0, 15.0))  # the camera's (imperfect) white balance
    ref = np.asarray(color_temperature(t_wb))

    def colour(kelvin):
        c = np.asarray(color_temperature(kelvin)) / ref
        return tuple(float(v) for v in c / c.max())

    exposure = float(np.exp(rng.uniform(np.log(0.6), np.log(1.6))))
    phi = rng.uniform(0, 2 * np.pi)
    t_fill = t_key if rng.random() < 0.5 else shifted(t_key, rng.normal(0.0, 60.0))
    lights = [Light("directional", colour(t_key), float(rng.uniform(1.5, 3.0)) * exposure,
                    direction=direction(20, 75, phi)),
              Light("directional", colour(t_fill), float(rng.uniform(0.3, 1.0)) * exposure,
                    direction=direction(10, 50, phi + np.pi + rng.uniform(-0.8, 0.8)))]
    if rng.random() < 0.3:
        lights.append(Light("directional", colour(t_key), float(rng.uniform(1.0, 3.0)) * exposure,
                            direction=direction(110, 160, rng.uniform(0, 2 * np.pi))))
    if rng.random() < 0.3:
        ang = rng.uniform(0, 2 * np.pi)
        lights.append(Light("point", colour(t_wb), float(rng.uniform(0.2, 0.6) * depth**2)
                            * exposure, position=(float(0.3 * depth * np.cos(ang)),
                                                  float(0.3 * depth * np.sin(ang)), 0.0)))
    return lights
