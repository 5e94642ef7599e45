"""The HTML pages of a pass: the slider view, a long pass's overview and its segment pages.

Each function writes what :mod:`dyntarget.view.html` draws, and returns ``None`` (or no
links) when plotly is not installed (the lean onboard install), so a pass written
without it still completes. The pass's report (:mod:`dyntarget.view.pass_report`) hands over
the frames as :class:`~dyntarget.view.html.PassFrame` s and the overview as a
:class:`~dyntarget.view.pass_figure.PassOverview`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from dyntarget.io.atomic import write_text
from dyntarget.view.html import PassFrame
from dyntarget.view.pass_figure import PassOverview


def _has_plotly() -> bool:
    """Whether plotly can be imported (the lean onboard install has none)."""
    try:
        import plotly.graph_objects  # noqa: F401
    except ImportError:
        return False
    return True


def write_pass_page(
    frames: Sequence[PassFrame],
    path: str | os.PathLike[str],
    *,
    title: str,
    crs: object | None = None,
    plotlyjs: bool | str = True,
) -> Path | None:
    """The interactive HTML view of a pass: one slider step per frame (plotly, inline).

    Parameters
    ----------
    frames : sequence of PassFrame
        The frames to show, in pass order.
    path : str or os.PathLike
        The HTML file to write.
    title : str
        The page's title.
    crs : object or None
        The strip's CRS, named on the page (the frames are drawn in their own pixels).
    plotlyjs : bool or str
        plotly.js inline (``True``) or the name of a shared copy beside the page.

    Returns
    -------
    pathlib.Path or None
        The page written; ``None`` without plotly or without frames.

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> img = np.full((4, 8, 8), 0.2, np.float32)
    >>> folder = Path(tempfile.mkdtemp())
    >>> write_pass_page([PassFrame(0.0, img)], folder / "pass.html", title="a pass").name
    'pass.html'
    >>> write_pass_page([], folder / "none.html", title="no frames") is None
    True
    """
    if not frames or not _has_plotly():
        return None
    from dyntarget.view.html import write_pass_view

    return write_pass_view(path, frames, title=title, crs=crs, plotlyjs=plotlyjs)


def write_overview_page(
    overview: PassOverview,
    path: str | os.PathLike[str],
    *,
    segments: Sequence[tuple[str, str]] = (),
) -> Path | None:
    """A long pass's ``pass.html``: the zoomable overview and links to its segment pages.

    Parameters
    ----------
    overview : PassOverview
        The pass decimated along-track.
    path : str or os.PathLike
        The page to write.
    segments : sequence of (href, text)
        The per-segment pages to link.

    Returns
    -------
    pathlib.Path or None
        The page written; ``None`` without plotly.

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> ov = PassOverview(np.full((40, 8, 3), 0.1), np.zeros((40, 8)), (0.0, 400.0, 0.0, 2.0),
    ...                   (np.array([10.0]), np.array([1.0]), np.array([0.0])), None,
    ...                   np.array([]), 4, 10.0, "a pass")
    >>> page = write_overview_page(ov, Path(tempfile.mkdtemp()) / "pass.html",
    ...                            segments=[("s/segment-0000.html", "frames 0-63")])
    >>> "10.00 km per column (4 WFOV rows)" in page.read_text()
    True
    """
    if not _has_plotly():
        return None
    from dyntarget.view.html import overview_html

    note = (
        f"decimated: {overview.km_per_cell:.2f} km per column ({overview.rows_per_cell} WFOV "
        "rows); zoom in, or open a segment below at full resolution"
    )
    page = overview_html(
        overview.rgb,
        overview.extent,
        plume=overview.plume,
        pointings=overview.pointings,
        targets=overview.targets,
        dropped=overview.dropped,
        links=segments,
        title=overview.title,
        note=note,
    )
    return write_text(path, page)


def write_segment_pages(
    segments: Iterable[tuple[str, Sequence[PassFrame], str]],
    folder: str | os.PathLike[str],
    *,
    crs: object | None = None,
) -> list[tuple[str, str]]:
    """Write one slider page per segment of a long pass into ``folder``, one at a time.

    The pages share one ``plotly.min.js`` in ``folder``; ``segments`` may be a
    generator, so only one segment's frames need be in memory.

    Parameters
    ----------
    segments : iterable of (title, frames, text)
        Each segment's page title, its frames and the text of its link.
    folder : str or os.PathLike
        Where the pages go (``segment-0000.html``, ...).
    crs : object or None
        The strip's CRS, named on the pages.

    Returns
    -------
    list of (str, str)
        ``(href relative to the folder's parent, text)`` per page written (empty
        without plotly).

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> img = np.full((4, 8, 8), 0.2, np.float32)
    >>> folder = Path(tempfile.mkdtemp()) / "pass-segments"
    >>> write_segment_pages([("frames 0-0", [PassFrame(0.0, img)], "frames 0-0")], folder)
    [('pass-segments/segment-0000.html', 'frames 0-0')]
    """
    if not _has_plotly():
        return []
    from dyntarget.view.html import PLOTLYJS, write_plotlyjs

    write_plotlyjs(folder)
    folder = Path(folder)
    links = []
    for i, (title, frames, text) in enumerate(segments):
        name = f"segment-{i:04d}.html"
        page = write_pass_page(frames, folder / name, title=title, crs=crs, plotlyjs=PLOTLYJS)
        if page is not None:
            links.append((f"{folder.name}/{name}", text))
    return links
