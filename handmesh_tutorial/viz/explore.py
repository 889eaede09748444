"""Explore a figure with sliders (ipywidgets) in Jupyter, a strip of frames everywhere else.

[`explore`][handmesh_tutorial.viz.explore.explore] wraps a function that draws one matplotlib
figure from a few parameters: in Jupyter it shows sliders and redraws the figure as they move; on
a static page (the docs site, GitHub, a notebook opened without a kernel) the same output is a
strip of precomputed frames, one per value along the first parameter (or the frames you list).
Both come from one display bundle, so the notebook code is the same. Docs page "3D views";
taught in notebooks 02 (the joint angles of the local coordinate systems) and 05 (the visibility
ratio as an occluder moves).
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Callable, Sequence

import numpy as np

from .._optional import require

__all__ = ["Explorer", "explore"]


def _png(fig, dpi: int) -> bytes:
    plt = require("matplotlib.pyplot", "hmt.viz figures")
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return buf.getvalue()


def _label(values: dict) -> str:
    return ", ".join(f"{k} = {v:g}" if isinstance(v, int | float) else f"{k} = {v}"
                     for k, v in values.items())


class Explorer:
    """Sliders over a figure function, with a strip of frames as the static fallback.

    Made by [`explore`][handmesh_tutorial.viz.explore.explore]. Displaying it gives Jupyter the
    live widget and any static renderer the strip (``text/html``); the widget's entry in the
    bundle also carries the strip (key ``hmt_fallback``), for pages that keep widget outputs
    (the docs build shows that strip in place of the widget).

    Attributes:
        render: the figure function, ``render(**values) -> matplotlib Figure``.
        params: ``{name: options}`` of the sliders.
        frames: the parameter values of the strip's frames, in order.
    """

    def __init__(self, render: Callable, params: dict[str, Sequence], frames: list[dict],
                 dpi: int, title: str | None):
        self.render, self.params, self.frames = render, params, frames
        self.dpi, self.title = dpi, title
        self._strip: str | None = None
        self._widget = None

    def defaults(self) -> dict:
        """The starting value of each slider: the middle option."""
        return {k: list(v)[len(v) // 2] for k, v in self.params.items()}

    def strip_html(self) -> str:
        """The static fallback: one PNG per frame, side by side and labelled (computed once)."""
        if self._strip is None:
            cells = []
            for values in self.frames:
                data = base64.b64encode(_png(self.render(**values), self.dpi)).decode()
                label = html.escape(_label(values))
                cells.append(
                    '<figure style="margin:0;flex:0 0 auto;text-align:center">'
                    f'<img src="data:image/png;base64,{data}" alt="{label}" '
                    'style="max-height:260px;width:auto">'
                    f'<figcaption style="font-size:0.8em">{label}</figcaption></figure>')
            head = (f"<p><strong>{html.escape(self.title)}</strong></p>" if self.title else "")
            self._strip = (
                f'<div class="hmt-explore-strip">{head}<p style="font-size:0.85em;color:#666">'
                "Frames of an interactive figure (sliders when run in Jupyter).</p>"
                '<div style="display:flex;gap:6px;overflow-x:auto">' + "".join(cells)
                + "</div></div>")
        return self._strip

    @property
    def widget(self):
        """The live ipywidgets control (sliders above an image of the figure), made once."""
        if self._widget is None:
            widgets = require("ipywidgets", "hmt.viz.explore")
            image = widgets.Image(format="png")
            sliders = {k: widgets.SelectionSlider(options=list(v), value=self.defaults()[k],
                                                  description=k, continuous_update=False)
                       for k, v in self.params.items()}

            def redraw(_=None):
                image.value = _png(self.render(**{k: s.value for k, s in sliders.items()}),
                                   self.dpi)

            for s in sliders.values():
                s.observe(redraw, names="value")
            redraw()
            self._widget = widgets.VBox([*sliders.values(), image])
        return self._widget

    def _repr_mimebundle_(self, include=None, exclude=None):
        strip = self.strip_html()
        bundle = {"text/plain": f"Explorer({', '.join(self.params)}; {len(self.frames)} frames)",
                  "text/html": strip}
        try:
            data = self.widget._repr_mimebundle_()
        except Exception:  # no kernel comm (a plain script): the strip alone
            return bundle
        data = data[0] if isinstance(data, tuple) else data
        view = dict(data.get("application/vnd.jupyter.widget-view+json", {}))
        if view:
            view["hmt_fallback"] = strip
            bundle["application/vnd.jupyter.widget-view+json"] = view
        return bundle


def explore(render: Callable, params: dict[str, Sequence], *, frames: list[dict] | None = None,
            n_frames: int = 5, dpi: int = 60, title: str | None = None) -> Explorer:
    """Sliders over ``render`` in Jupyter; a strip of frames on static pages.

    ``hmt.viz.explore(lambda flex: draw(flex), {"flex": range(0, 91, 15)})``.

    Args:
        render: ``render(**values) -> matplotlib Figure``, one figure per call (it is closed
            after use).
        params: ``{name: options}``, each a sequence of values the slider steps through
            (numbers or strings); each slider starts at its middle option.
        frames: the strip's frames as ``[{name: value, ...}, ...]`` (missing names take their
            start value); by default ``n_frames`` options spread over the first parameter.
        n_frames: frames of the default strip.
        dpi: resolution of the widget's image and of the strip's frames.
        title: a line above the strip.

    Returns:
        The [`Explorer`][handmesh_tutorial.viz.explore.Explorer] (display it).

    Raises:
        ValueError: no parameter, a parameter with no option, a frame naming an unknown
            parameter or a value that is not one of its options.
    """
    if not params:
        raise ValueError("explore needs at least one parameter: {name: options}")
    params = {k: list(v) for k, v in params.items()}
    empty = [k for k, v in params.items() if not v]
    if empty:
        raise ValueError(f"parameters {empty} have no option")
    ex = Explorer(render, params, [], dpi, title)
    start = ex.defaults()
    if frames is None:
        first, options = next(iter(params.items()))
        picks = np.unique(np.linspace(0, len(options) - 1, min(n_frames, len(options))).round())
        frames = [{first: options[int(i)]} for i in picks]
    full = []
    for f in frames:
        unknown = [k for k in f if k not in params]
        if unknown:
            raise ValueError(f"frame {f} names unknown parameters {unknown}; known: {list(params)}")
        bad = [k for k, v in f.items() if v not in params[k]]
        if bad:
            raise ValueError(f"frame {f}: {bad} not among their options {[params[k] for k in bad]}")
        full.append({**start, **f})
    ex.frames = full
    return ex
