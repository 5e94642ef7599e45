"""Interactive, self-contained HTML views of a plan or a pass (plotly, JavaScript inline).

:func:`write_scene_view` draws one WFOV image (RGB and false colour, switchable),
the classifier's probability, the denoised plume polygons and the pointings
coloured by time (or order), with hover showing each pointing's order, time
and, when the truth is known, what it observed. :func:`write_pass_view` does the
same for a sequence of :class:`PassFrame` with a time slider. The files open
offline: plotly.js is embedded (``include_plotlyjs=True``), nothing is fetched.

plotly is an optional dependency (``pip install dyntarget[view]``); it is
imported inside the functions.

A pass's pictures and pages (:mod:`~dyntarget.view.pass_figure`,
:mod:`~dyntarget.view.pass_html`) are drawn here too, and its report
(:mod:`~dyntarget.view.pass_report`) writes every file a pass leaves.
"""

from dyntarget.view.html import (
    PassFrame,
    pass_view_html,
    require_plotly,
    scene_view_html,
    write_pass_view,
    write_scene_view,
)

__all__ = [
    "PassFrame",
    "pass_view_html",
    "require_plotly",
    "scene_view_html",
    "write_pass_view",
    "write_scene_view",
]
