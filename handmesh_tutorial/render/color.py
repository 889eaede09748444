"""Colour spaces of the renderer: sRGB -> linear RGB, and the colour of black-body lights.

The library's colours (skin tones, object palettes, backgrounds) are sRGB in [0, 1]; pyrender
lights and shades in linear RGB and gamma-encodes its output, so vertex colours pass through
`srgb_to_linear` and light colours come linear from `color_temperature`.

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import numpy as np

__all__ = ["color_temperature", "srgb_to_linear"]


def srgb_to_linear(colors) -> np.ndarray:
    """sRGB colours in [0, 1] -> linear RGB (the IEC 61966-2-1 transfer function), same shape.

    pyrender multiplies the lit colour by the vertex colour and gamma-encodes the result
    (``shaders/mesh.frag``), so it expects *linear* vertex colours; the library's colours (skin
    tones, object palettes) are sRGB, and `Renderer.render` converts them with this function.
    """
    c = np.clip(np.asarray(colors, float), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)



def color_temperature(kelvin: float) -> tuple[float, float, float]:
    """The colour of a black-body light source, as linear RGB with its largest channel 1.

    Tanner Helland's fit of the Planckian locus in sRGB (valid 1000-40000 K), converted to linear
    RGB for pyrender: about ``(1, 0.42, 0.13)`` at 2700 K (a tungsten bulb), ``(1, 0.86, 0.76)``
    at 5000 K, white at 6600 K, and blue above (``(0.71, 0.79, 1)`` at 10000 K, shade).

    Args:
        kelvin: colour temperature, kelvin.

    Returns:
        ``(r, g, b)`` in [0, 1].
    """
    t = float(np.clip(kelvin, 1000.0, 40000.0)) / 100.0
    if t <= 66:
        r = 255.0
        g = 99.4708025861 * np.log(t) - 161.1195681661
        b = 0.0 if t <= 19 else 138.5177312231 * np.log(t - 10) - 305.0447927307
    else:
        r = 329.698727446 * (t - 60) ** -0.1332047592
        g = 288.1221695283 * (t - 60) ** -0.0755148492
        b = 255.0
    rgb = srgb_to_linear(np.clip(np.array([r, g, b]) / 255.0, 0.0, 1.0))
    rgb = rgb / rgb.max()
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))
