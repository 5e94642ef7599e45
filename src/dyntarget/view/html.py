"""The HTML views: one plotly figure, its JavaScript inline, written atomically.

Why plotly rather than folium: ``fig.to_html(include_plotlyjs=True)`` embeds the
whole plotly.js bundle, so the file opens with no network at all; folium's maps
load Leaflet and their base-map tiles from the web, and a WFOV image in pixel
coordinates needs no web map under it. plotly draws the image in its own pixel
grid (pixel centres at integers, as our pointings), so nothing is resampled.
"""

from __future__ import annotations

import base64
import html
import itertools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.io.acquisition import iso_utc, parse_acquired
from dyntarget.io.atomic import write_text
from dyntarget.io.geojson import crs_to_lonlat, pixels_to_crs
from dyntarget.scene import check_image

DIV_ID = "dyntarget-view"
"""``id`` of the figure's ``<div>`` (the page's plotted data is ``document.getElementById(DIV_ID).data``)."""
POINTINGS = "pointings"
"""Name of the trace holding the pointings (one marker per pointing, in order)."""
MAX_HEATMAP = 256
"""Largest probability heatmap side in cells (hover shows values); larger maps are strided."""

_RGB, _FALSE, _PROBA, _POLYS, _PATH, _POINTS = range(6)


@dataclass(frozen=True, eq=False)
class PassFrame:
    """One step of a pass for :func:`write_pass_view`.

    Parameters
    ----------
    time_s : float
        Seconds after the first acquisition of the pass (the slider's label).
    image : array (4, H, W)
        The WFOV image seen at this step (R, G, B, NIR); every frame has the same shape.
    probability : array (H, W) or None
        The classifier's plume probability.
    polygons : sequence of shapely polygons
        Denoised plume polygons, pixel coordinates.
    trajectory : Trajectory or None
        The pointings to show at this step (e.g. those flown so far), with times.
    point_values : mapping name -> sequence, optional
        Per-pointing values for the hover (e.g. what each pointing observed).
    label : str
        Extra text for the slider step.
    transform : affine.Affine or None
        This frame's own pixel -> CRS transform (frames of a strip each cover
        their own ground); ``None``: the pass's ``transform``. Used for the
        hover's lon/lat.
    """

    time_s: float
    image: np.ndarray
    probability: np.ndarray | None = None
    polygons: Sequence[Any] = ()
    trajectory: Any = None
    point_values: Mapping[str, Sequence[float]] | None = None
    label: str = ""
    transform: Any = None


def require_plotly():
    """The ``plotly.graph_objects`` module, or :class:`~dyntarget.errors.MissingExtraError`
    naming the ``view`` extra to install.

    Returns
    -------
    module

    Examples
    --------
    >>> require_plotly().__name__
    'plotly.graph_objects'
    """
    try:
        import plotly.graph_objects as go
    except ImportError as exc:  # pragma: no cover - depends on the environment
        from dyntarget.errors import missing_extra

        raise (missing_extra(exc) or exc) from None
    return go


_plotly = require_plotly  # the name callers used before it was public


def _stretch(bands: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """3 bands -> uint8 (H, W, 3) with one 2–98 % stretch over all three (keeps the colour balance)."""
    vals = bands[:, valid] if valid is not None and valid.any() else bands
    finite = vals[np.isfinite(vals)]
    lo, hi = np.percentile(finite, [2, 98]) if finite.size else (0.0, 1.0)
    if not hi > lo:
        hi = lo + 1e-6
    out = np.clip((np.nan_to_num(bands) - lo) / (hi - lo), 0, 1)
    return np.ascontiguousarray((out * 255 + 0.5).astype(np.uint8).transpose(1, 2, 0))


def _png_uri(rgb: np.ndarray) -> str:
    import cv2

    ok, buf = cv2.imencode(".png", rgb[..., ::-1])  # OpenCV writes BGR
    if not ok:  # pragma: no cover - OpenCV failure
        raise InvalidParameterError("image: could not be encoded as PNG")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def _layers(image: np.ndarray) -> tuple[str, str]:
    """PNG data URIs of the RGB and the false-colour (NIR, R, G) composites."""
    return _png_uri(_stretch(image[[0, 1, 2]])), _png_uri(_stretch(image[[3, 0, 1]]))


def _check_probability(probability, shape) -> np.ndarray | None:
    if probability is None:
        return None
    p = np.asarray(probability, np.float32)
    if p.shape != tuple(shape):
        raise InvalidParameterError(
            f"probability: shape {p.shape} does not match the image's {tuple(shape)}"
        )
    return p


def _heatmap_data(probability: np.ndarray | None) -> dict[str, Any]:
    if probability is None:
        return {"z": [[None]], "x": [0], "y": [0]}
    h, w = probability.shape
    s = max(1, math.ceil(max(h, w) / MAX_HEATMAP))
    z = np.round(probability[::s, ::s].astype(np.float64), 3)
    return {"z": z.tolist(), "x": list(range(0, w, s)), "y": list(range(0, h, s))}


def _polygon_data(polygons: Sequence[Any]) -> dict[str, Any]:
    import shapely

    xs: list[float | None] = []
    ys: list[float | None] = []
    text: list[str | None] = []
    for i, poly in enumerate(polygons):
        if not isinstance(poly, shapely.Geometry) or poly.geom_type not in (
            "Polygon",
            "MultiPolygon",
        ):
            raise InvalidParameterError(
                f"polygons[{i}]: expected a shapely Polygon or MultiPolygon, got {type(poly).__name__}"
            )
        for part in getattr(poly, "geoms", [poly]):
            for ring in [part.exterior, *part.interiors]:
                c = np.asarray(ring.coords)
                label = f"plume polygon {i}<br>area {poly.area:.0f} px"
                xs += [*c[:, 0].round(3).tolist(), None]
                ys += [*c[:, 1].round(3).tolist(), None]
                text += [label] * len(c) + [None]
    return {"x": xs, "y": ys, "text": text}


def _check_values(point_values, n: int) -> dict[str, np.ndarray]:
    out = {}
    for key, values in dict(point_values or {}).items():
        arr = np.asarray(values, np.float64).reshape(-1)
        if len(arr) != n:
            raise InvalidParameterError(
                f"point_values[{key!r}]: expected {n} values (one per pointing), got {len(arr)}"
            )
        out[key] = arr
    return out


def _pointing_data(traj, transform, crs, acquired, point_values) -> dict[str, Any]:
    if traj is None or len(traj.points) == 0:
        return {"x": [], "y": [], "text": [], "color": []}
    pts = np.asarray(traj.points, np.float64).reshape(-1, 2)
    n = len(pts)
    values = _check_values(point_values, n)
    lonlat = None
    if transform is not None and crs is not None:
        lonlat = crs_to_lonlat(pixels_to_crs(pts, transform), crs)
    times = traj.times
    text = []
    for i in range(n):
        lines = [f"<b>pointing {i}</b> (part {int(traj.part[i])})"]
        if times is not None:
            t = f"t = {float(times[i]):.3f} s"
            if acquired is not None:
                t += f" ({iso_utc(acquired, float(times[i]))})"
            lines.append(t)
        lines.append(f"pixel x = {pts[i, 0]:.2f}, y = {pts[i, 1]:.2f}")
        if lonlat is not None:
            lines.append(f"lon {lonlat[i, 0]:.7f}, lat {lonlat[i, 1]:.7f}")
        for key, arr in values.items():
            lines.append(
                f"{html.escape(key)}: {arr[i]:.3f}" if np.isfinite(arr[i]) else f"{key}: –"
            )
        text.append("<br>".join(lines))
    color = np.asarray(times if times is not None else np.arange(n), np.float64)
    return {
        "x": pts[:, 0].round(3).tolist(),
        "y": pts[:, 1].round(3).tolist(),
        "text": text,
        "color": color.round(3).tolist(),
    }


def _traces(go, image, probability, polygons, traj, values, transform, crs, acquired, crange):
    """The six traces: RGB, false colour, probability, polygons, path, pointings."""
    rgb, false = _layers(image)
    heat = _heatmap_data(probability)
    poly = _polygon_data(polygons)
    pts = _pointing_data(traj, transform, crs, acquired, values)
    timed = traj is not None and traj.times is not None
    return [
        go.Image(source=rgb, name="RGB", hoverinfo="skip"),
        go.Image(source=false, name="false colour (NIR, R, G)", hoverinfo="skip", visible=False),
        go.Heatmap(
            **heat,
            name="plume probability",
            zmin=0,
            zmax=1,
            colorscale="Magma",
            visible=False,
            colorbar={"title": {"text": "probability"}, "x": 1.13, "len": 0.5, "y": 0.25},
            hovertemplate="x %{x}, y %{y}<br>probability %{z:.3f}<extra></extra>",
        ),
        go.Scatter(
            x=poly["x"],
            y=poly["y"],
            text=poly["text"],
            name="plume polygons (denoised)",
            mode="lines",
            fill="toself",
            fillcolor="rgba(0, 220, 255, 0.15)",
            line={"color": "rgb(0, 220, 255)", "width": 2},
            hoverinfo="text",
        ),
        go.Scatter(
            x=pts["x"],
            y=pts["y"],
            name="path",
            mode="lines",
            line={"color": "rgba(255, 255, 255, 0.7)", "width": 1},
            hoverinfo="skip",
        ),
        go.Scatter(
            x=pts["x"],
            y=pts["y"],
            text=pts["text"],
            name=POINTINGS,
            mode="markers",
            hoverinfo="text",
            marker={
                "color": pts["color"],
                "cmin": crange[0],
                "cmax": crange[1],
                "colorscale": "Viridis",
                "size": 8,
                "line": {"color": "black", "width": 1},
                "showscale": True,
                "colorbar": {
                    "title": {"text": "time (s)<br>after acquisition" if timed else "order"},
                    "x": 1.02,
                    "len": 0.5,
                    "y": 0.75,
                },
            },
        ),
    ]


def _layout(go, shape, title: str, note: str) -> Any:
    h, w = shape
    visible = {
        "RGB": [True, False, False],
        "false colour": [False, True, False],
        "probability": [False, False, True],
    }
    buttons = [
        {"label": k, "method": "restyle", "args": [{"visible": v + [True] * 3}]}
        for k, v in visible.items()
    ]
    aspect = h / w
    width = 900
    return go.Layout(
        title={
            "text": html.escape(title),
            "subtitle": {"text": html.escape(note)},
            "x": 0.02,
            "xanchor": "left",
            "y": 0.985,
            "yref": "container",
            "yanchor": "top",
        },
        xaxis={
            "range": [-0.5, w - 0.5],
            "title": {"text": "column (WFOV px)"},
            "constrain": "domain",
        },
        yaxis={
            "range": [h - 0.5, -0.5],
            "title": {"text": "row (WFOV px)"},
            "scaleanchor": "x",
            "constrain": "domain",
        },
        autosize=True,  # the page fills the window (responsive config); height from the aspect
        height=int(min(1000, max(420, 140 + (width - 260) * aspect))),
        legend={"orientation": "h", "y": -0.12},
        margin={"l": 60, "r": 170, "t": 120, "b": 110},
        updatemenus=[
            {
                "type": "buttons",
                "direction": "right",
                "x": 0.0,
                "y": 1.01,
                "xanchor": "left",
                "yanchor": "bottom",
                "buttons": buttons,
                "showactive": True,
            }
        ],
        plot_bgcolor="black",
        modebar={"orientation": "v"},
    )


def _note(traj, transform, crs, acquired) -> str:
    parts = []
    if transform is not None and crs is not None:
        from rasterio.crs import CRS

        parts.append(f"image CRS {CRS.from_user_input(crs).to_string()}; hover gives WGS 84")
    elif crs is not None:  # a pass: frames in their own pixels, cut from a georeferenced strip
        from rasterio.crs import CRS

        parts.append(
            f"frame pixel coordinates of a strip in {CRS.from_user_input(crs).to_string()}; "
            "pointings.geojson holds WGS 84 lon/lat"
        )
    else:
        parts.append("pixel coordinates (no CRS)")
    if acquired is not None:
        parts.append(f"acquired {iso_utc(acquired, 0.0)}")
    return "; ".join(parts)


def _to_html(fig, title: str, *, animated: bool = False, plotlyjs: bool | str = True) -> str:
    text = fig.to_html(
        include_plotlyjs=plotlyjs,
        full_html=True,
        div_id=DIV_ID,
        auto_play=False,
        config={"displaylogo": False, "scrollZoom": True, "responsive": True},
        default_width="100%",
        animation_opts={"frame": {"duration": 0, "redraw": True}} if animated else None,
    )
    # The generator tag lets a rerun recognise its own file (dyntarget.io.outputs.is_ours).
    head = f'<head>\n    <title>{html.escape(title)}</title>\n    <meta name="generator" content="dyntarget">'
    return text.replace("<head>", head, 1)


def _check_common(transform, crs, acquired):
    when = None if acquired is None else parse_acquired(acquired)
    return when


def scene_view_html(
    image: np.ndarray,
    *,
    probability: np.ndarray | None = None,
    polygons: Sequence[Any] = (),
    trajectory: Any = None,
    point_values: Mapping[str, Sequence[float]] | None = None,
    transform: Any = None,
    crs: object | None = None,
    acquired: datetime | str | None = None,
    title: str = "dyntarget plan",
) -> str:
    """The HTML page of one plan: image layers, probability, polygons, pointings.

    Parameters
    ----------
    image : array (4, H, W)
        WFOV image, R, G, B, NIR.
    probability : array (H, W), optional
        The classifier's plume probability (a layer, with hover values).
    polygons : sequence of shapely polygons
        Denoised plume polygons in pixel coordinates.
    trajectory : Trajectory, optional
        The pointings; coloured by ``times`` when timed, else by order.
    point_values : mapping name -> sequence, optional
        Per-pointing values shown on hover, e.g. :func:`dyntarget.observe.pointing_truth`'s.
    transform, crs : optional
        Georeferencing; the hover then shows WGS 84 lon/lat of each pointing.
    acquired : datetime or ISO-8601 str, optional
        Acquisition instant; the hover then shows each pointing's UTC time.
    title : str

    Returns
    -------
    str
        A complete HTML document with plotly.js inline.

    Examples
    --------
    >>> from dyntarget.trajectory import Trajectory
    >>> img = np.random.default_rng(0).uniform(0, 1, (4, 16, 16)).astype(np.float32)
    >>> t = Trajectory(np.array([[2.0, 3.0], [5.0, 3.0]]), np.array([0, 0]), "demo")
    >>> page = scene_view_html(img, trajectory=t)
    >>> page.startswith("<!doctype html>"), "<title>dyntarget plan</title>" in page
    (True, True)
    """
    go = require_plotly()
    image = check_image(image)
    shape = image.shape[1:]
    probability = _check_probability(probability, shape)
    when = _check_common(transform, crs, acquired)
    n = 0 if trajectory is None else len(trajectory.points)
    color = (
        np.asarray(trajectory.times)
        if trajectory is not None and trajectory.times is not None
        else np.arange(max(n, 1))
    )
    crange = (float(color.min()), float(color.max()) if len(color) else 1.0) if n else (0.0, 1.0)
    traces = _traces(
        go, image, probability, polygons, trajectory, point_values, transform, crs, when, crange
    )
    fig = go.Figure(
        data=traces, layout=_layout(go, shape, title, _note(trajectory, transform, crs, when))
    )
    return _to_html(fig, title)


def write_scene_view(path: str | os.PathLike[str], image: np.ndarray, **kwargs: Any) -> Path:
    """Write :func:`scene_view_html` to ``path`` (``.html``) atomically.

    Parameters
    ----------
    path : path-like
        Must end in ``.html`` or ``.htm``.
    image : array (4, H, W)
    **kwargs
        As for :func:`scene_view_html`.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> img = np.random.default_rng(0).uniform(0, 1, (4, 8, 8)).astype(np.float32)
    >>> out = write_scene_view(pathlib.Path(tempfile.mkdtemp()) / "v.html", img, title="demo")
    >>> "<title>demo</title>" in out.read_text()
    True
    """
    path = _check_html_path(path)
    return write_text(path, scene_view_html(image, **kwargs))


def _check_html_path(path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise InvalidParameterError(
            f"{path}: the interactive view is an HTML file; give a path ending in .html"
        )
    return path


def pass_view_html(
    frames: Sequence[PassFrame],
    *,
    transform: Any = None,
    crs: object | None = None,
    acquired: datetime | str | None = None,
    title: str = "dyntarget pass",
    plotlyjs: bool | str = True,
) -> str:
    """The HTML page of a pass: one step per frame, a time slider and play/pause.

    Parameters
    ----------
    frames : sequence of PassFrame
        In time order; all images the same shape. Each step shows its frame's
        image, probability, polygons and pointings as given (pass the pointings
        flown so far to see the trail grow). Pointing colours share one time scale.
    transform, crs, acquired, title
        As for :func:`scene_view_html` (``acquired`` is the first frame's instant).
    plotlyjs : bool or str
        ``True``: plotly.js inline (the page opens alone, offline); a file name such
        as ``"plotly.min.js"``: the page loads it from beside itself (many pages
        sharing one copy, see :func:`write_plotlyjs`).

    Returns
    -------
    str

    Examples
    --------
    >>> img = np.random.default_rng(0).uniform(0, 1, (4, 16, 16)).astype(np.float32)
    >>> page = pass_view_html([PassFrame(0.0, img), PassFrame(5.0, img)])
    >>> page.count('"t = 5 s"') >= 1
    True
    """
    go = require_plotly()
    frames = list(frames)
    if not frames:
        raise InvalidParameterError("frames: expected at least one PassFrame, got none")
    shape = None
    times = []
    for i, f in enumerate(frames):
        if not isinstance(f, PassFrame):
            raise InvalidParameterError(
                f"frames[{i}]: expected a PassFrame, got {type(f).__name__}"
            )
        img = check_image(f.image, name=f"frames[{i}].image")
        if shape is None:
            shape = img.shape[1:]
        elif img.shape[1:] != shape:
            raise InvalidParameterError(
                f"frames[{i}].image: shape {img.shape[1:]} differs from the first frame's {shape}"
            )
        if not math.isfinite(float(f.time_s)):
            raise InvalidParameterError(
                f"frames[{i}].time_s: expected a finite number, got {f.time_s!r}"
            )
        times.append(float(f.time_s))
    if any(b < a for a, b in itertools.pairwise(times)):
        raise InvalidParameterError(f"frames: time_s must not decrease, got {times}")
    when = _check_common(transform, crs, acquired)
    colour = [
        np.asarray(
            f.trajectory.times if f.trajectory.times is not None else np.arange(len(f.trajectory))
        )
        for f in frames
        if f.trajectory is not None and len(f.trajectory.points)
    ]
    allc = np.concatenate(colour) if colour else np.zeros(0)
    crange = (float(allc.min()), float(allc.max())) if allc.size else (0.0, 1.0)
    per_frame = []
    for i, f in enumerate(frames):
        prob = _check_probability(f.probability, shape)
        per_frame.append(
            _traces(
                go,
                check_image(f.image, name=f"frames[{i}].image"),
                prob,
                f.polygons,
                f.trajectory,
                f.point_values,
                f.transform if f.transform is not None else transform,
                crs,
                when,
                crange,
            )
        )
    names = [
        f"t = {t:g} s" + (f" · {f.label}" if f.label else "")
        for t, f in zip(times, frames, strict=True)
    ]
    plot_frames = [
        go.Frame(data=tr, name=str(i), traces=list(range(6))) for i, tr in enumerate(per_frame)
    ]
    layout = _layout(go, shape, title, _note(None, transform, crs, when))
    step = {
        "frame": {"duration": 0, "redraw": True},
        "mode": "immediate",
        "transition": {"duration": 0},
    }
    layout.sliders = [
        {
            "active": 0,
            "currentvalue": {"prefix": "pass: "},
            "pad": {"t": 60},
            "steps": [
                {"label": name, "method": "animate", "args": [[str(i)], step]}
                for i, name in enumerate(names)
            ],
        }
    ]
    layout.updatemenus = [
        *layout.updatemenus,
        {
            "type": "buttons",
            "direction": "left",
            "x": 0.0,
            "y": -0.02,
            "xanchor": "right",
            "yanchor": "top",
            "pad": {"t": 60, "r": 10},
            "buttons": [
                {
                    "label": "▶",
                    "method": "animate",
                    "args": [
                        None,
                        {**step, "frame": {"duration": 700, "redraw": True}, "fromcurrent": True},
                    ],
                },
                {"label": "❚❚", "method": "animate", "args": [[None], step]},
            ],
        },
    ]
    layout.height = layout.height + 80
    layout.legend = {
        "orientation": "h",
        "x": 1.0,
        "xanchor": "right",
        "y": 1.01,
        "yanchor": "bottom",
    }
    fig = go.Figure(data=per_frame[0], layout=layout, frames=plot_frames)
    return _to_html(fig, title, animated=True, plotlyjs=plotlyjs)


def write_pass_view(
    path: str | os.PathLike[str], frames: Sequence[PassFrame], **kwargs: Any
) -> Path:
    """Write :func:`pass_view_html` to ``path`` (``.html``) atomically.

    Parameters
    ----------
    path : path-like
        Must end in ``.html`` or ``.htm``.
    frames : sequence of PassFrame
    **kwargs
        As for :func:`pass_view_html`.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> img = np.random.default_rng(0).uniform(0, 1, (4, 8, 8)).astype(np.float32)
    >>> frames = [PassFrame(0.0, img), PassFrame(2.5, img, label="second look")]
    >>> out = write_pass_view(pathlib.Path(tempfile.mkdtemp()) / "pass.html", frames)
    >>> "t = 2.5 s" in out.read_text() and "second look" in out.read_text()  # plotly may write · as \\u00b7
    True
    """
    path = _check_html_path(path)
    return write_text(path, pass_view_html(frames, **kwargs))


PLOTLYJS = "plotly.min.js"
"""File name of the shared plotly.js that pages written with ``plotlyjs=PLOTLYJS`` load."""


def write_plotlyjs(folder: str | os.PathLike[str]) -> Path:
    """Write plotly.js into ``folder`` as :data:`PLOTLYJS`, for pages that share one copy.

    Parameters
    ----------
    folder : path-like
        The folder of the pages (created if missing).

    Returns
    -------
    Path
        The file written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> js = write_plotlyjs(pathlib.Path(tempfile.mkdtemp()))
    >>> js.name, js.stat().st_size > 1_000_000
    ('plotly.min.js', True)
    """
    require_plotly()
    from plotly.offline import get_plotlyjs

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return write_text(folder / PLOTLYJS, get_plotlyjs())


def overview_html(
    rgb: np.ndarray,
    extent: tuple[float, float, float, float],
    *,
    plume: np.ndarray | None = None,
    pointings: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    targets: tuple[np.ndarray, np.ndarray] | None = None,
    dropped: np.ndarray | None = None,
    links: Sequence[tuple[str, str]] = (),
    title: str = "dyntarget pass: overview",
    note: str = "",
) -> str:
    """An overview page of a long pass: the strip decimated, along-track to the right.

    One plotly figure (zoom and pan) of the decimated strip in kilometres along and
    across track, with the plume (shaded), the flown pointings (coloured by time),
    GEO targets and dropped frames; below it, links to the full-resolution pages
    (e.g. one per segment of frames).

    Parameters
    ----------
    rgb : array (n_along, n_across, 3)
        The decimated strip, reflectance (stretched here), along-track first.
    extent : (along_0, along_1, across_0, across_1)
        What the image covers, km.
    plume : array (n_along, n_across) or None
        Plume fraction per cell (0..1), shown where above 0.
    pointings : (along_km, across_km, time_s) or None
        The flown pointings.
    targets : (along_km, across_km) or None
        GEO targets.
    dropped : array or None
        Along-track km of frames dropped (late).
    links : sequence of (href, text)
        Listed under the figure.
    title, note : str
        Page title and a subtitle line.

    Returns
    -------
    str
        The page (plotly.js inline: it opens offline).

    Examples
    --------
    >>> rgb = np.random.default_rng(0).uniform(0, 0.3, (50, 4, 3))
    >>> page = overview_html(rgb, (0.0, 100.0, 0.0, 2.0), links=[("s/0.html", "frames 0-63")])
    >>> "frames 0-63" in page and DIV_ID in page
    True
    """
    go = require_plotly()
    rgb = np.asarray(rgb, np.float64)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise InvalidParameterError(f"rgb: expected (n_along, n_across, 3), got {rgb.shape}")
    a0, a1, c0, c1 = (float(v) for v in extent)
    na, nc = rgb.shape[:2]
    da, dc = (a1 - a0) / na, (c1 - c0) / nc
    img = _stretch(np.nan_to_num(rgb).transpose(2, 1, 0))  # (across, along, 3)
    # the strip as a layout image stretched over its extent: an Image trace would force one
    # scale on both axes, and a strip thousands of times longer than wide would be a line
    strip = {
        "source": _png_uri(img), "xref": "x", "yref": "y", "x": a0, "y": c0,
        "sizex": a1 - a0, "sizey": c1 - c0, "sizing": "stretch", "layer": "below",
        "xanchor": "left", "yanchor": "top",
    }  # fmt: skip
    traces: list[Any] = []
    if plume is not None and np.any(np.asarray(plume) > 0):
        z = np.where(np.asarray(plume, np.float64) > 0, plume, np.nan).T
        traces.append(
            go.Heatmap(
                z=z, x0=a0 + da / 2, dx=da, y0=c0 + dc / 2, dy=dc, zmin=0, zmax=1,
                colorscale=[[0, "rgba(255,0,255,0.35)"], [1, "rgba(255,0,255,0.95)"]],
                showscale=False, name="plume fraction",
                hovertemplate="plume fraction %{z:.2f}<extra></extra>",
            )
        )  # fmt: skip
    if pointings is not None and len(pointings[0]):
        x, y, t = (np.asarray(v, np.float64) for v in pointings)
        traces.append(
            go.Scatter(
                x=x.round(4).tolist(), y=y.round(4).tolist(), mode="markers", name=POINTINGS,
                marker={"size": 4, "color": t.round(2).tolist(), "colorscale": "Viridis",
                        "showscale": True,
                        "colorbar": {"title": {"text": "time (s)"}}},
                hovertemplate="%{x:.2f} km along, %{y:.3f} km across<br>t = %{marker.color:.1f} s"
                "<extra></extra>",
            )
        )  # fmt: skip
    if targets is not None and len(targets[0]):
        traces.append(
            go.Scatter(
                x=np.asarray(targets[0]).tolist(), y=np.asarray(targets[1]).tolist(), mode="markers",
                name=f"GEO targets ({len(targets[0])})",
                marker={"symbol": "x-thin", "size": 10, "line": {"width": 2, "color": "red"}},
            )
        )  # fmt: skip
    if dropped is not None and len(dropped):
        traces.append(
            go.Scatter(
                x=np.asarray(dropped).tolist(), y=[c1 + 0.04 * (c1 - c0)] * len(dropped),
                mode="markers", name=f"frames dropped ({len(dropped)})",
                marker={"symbol": "triangle-down", "size": 8, "color": "red"},
            )
        )  # fmt: skip
    layout = go.Layout(
        title={"text": html.escape(title), "subtitle": {"text": html.escape(note)}, "x": 0.02},
        xaxis={"title": {"text": "along track (km), flight to the right"}, "range": [a0, a1]},
        yaxis={"title": {"text": "across (km)"}, "range": [c1 + 0.08 * (c1 - c0), c0]},
        images=[strip],
        height=460,
        legend={"orientation": "h", "y": -0.3},
        margin={"l": 60, "r": 40, "t": 90, "b": 120},
        plot_bgcolor="black",
    )
    fig = go.Figure(data=traces, layout=layout)
    page = _to_html(fig, title)
    if links:
        items = "\n".join(
            f'<li><a href="{html.escape(h, quote=True)}">{html.escape(t)}</a></li>'
            for h, t in links
        )
        page = page.replace(
            "</body>",
            "<h3 style='font-family:sans-serif'>Full resolution, frame by frame</h3>\n"
            f"<ul style='font-family:sans-serif'>\n{items}\n</ul>\n</body>",
            1,
        )
    return page
