"""The day on a world map: ground tracks, eruptions, cues and observations (PNG and HTML).

The PNG is drawn with matplotlib (plate carrée longitude/latitude axes, no base-map
download: the volcano catalog itself outlines the volcanic world); the HTML view is a
plotly figure with its JavaScript inline (as :mod:`dyntarget.view.html` writes views), so
it opens with no network. Both are written atomically and carry no time stamp (the same
day gives the same bytes).
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.io.atomic import write_bytes, write_text

MAX_TRACKS = 60
"""Most ground tracks drawn (the first ones; a 500-satellite day would be a smear)."""
ORBIT_POINTS = 95
"""Track points (one a minute) drawn per satellite on the PNG: about one orbit (the whole
day's tracks cover the map; the HTML view has them all)."""


def _segments(track: list[list[float]]) -> tuple[np.ndarray, np.ndarray]:
    """Longitudes and latitudes with NaN breaks where the track crosses the antimeridian."""
    if not track:
        return np.zeros(0), np.zeros(0)
    a = np.asarray(track, np.float64)
    lon, lat = a[:, 0], a[:, 1]
    jump = np.flatnonzero(np.abs(np.diff(lon)) > 180.0) + 1
    return np.insert(lon, jump, np.nan), np.insert(lat, jump, np.nan)


def world_map(day: Any, path: str | Path, *, title: str = "") -> Path:
    """Draw the day (``constellation.png``).

    Parameters
    ----------
    day : dyntarget.constellation.simulate.Day
        The simulated day.
    path : str or pathlib.Path
        PNG to write.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    cat, er = day.catalog, day.eruptions
    fig, ax = plt.subplots(figsize=(13, 6.8), dpi=100)
    ax.scatter(cat.lon, cat.lat, s=2, c="0.75", label=f"Holocene volcanoes ({len(cat)})", zorder=1)
    for k, track in enumerate(day.tracks[:MAX_TRACKS]):
        lon, lat = _segments(track[:ORBIT_POINTS])
        ax.plot(
            lon,
            lat,
            lw=0.4,
            color="tab:blue",
            alpha=0.35,
            zorder=2,
            label="ground tracks (first orbit)" if k == 0 else None,
        )
    vlon, vlat = cat.lon[er.volcano], cat.lat[er.volcano]
    observed = np.array([r["observations"] > 0 for r in day.table], bool)
    ax.scatter(
        vlon[~observed],
        vlat[~observed],
        s=40,
        marker="^",
        facecolors="none",
        edgecolors="tab:red",
        label="eruption, not observed",
        zorder=4,
    )
    ax.scatter(
        vlon[observed],
        vlat[observed],
        s=50,
        marker="^",
        c="tab:red",
        label="eruption, observed",
        zorder=4,
    )
    if day.cues:
        ce = np.array([c["eruption"] for c in day.cues])
        geo = np.array(
            [c["source"] in {"GOES-East", "GOES-West", "Meteosat", "Himawari"} for c in day.cues]
        )
        for mask, colour, label in (
            (~geo, "tab:orange", "look-ahead cue"),
            (geo, "tab:purple", "GEO cue"),
        ):
            if mask.any():
                ax.scatter(
                    vlon[ce[mask]],
                    vlat[ce[mask]],
                    s=110,
                    marker="o",
                    facecolors="none",
                    edgecolors=colour,
                    lw=1.2,
                    label=label,
                    zorder=3,
                )
    if day.observations:
        oe = np.array([o["eruption"] for o in day.observations])
        counts = np.bincount(oe, minlength=len(er))
        hit = counts > 0
        ax.scatter(
            vlon[hit],
            vlat[hit],
            s=12 + 14 * counts[hit],
            marker="*",
            c="gold",
            edgecolors="k",
            lw=0.4,
            label="pinpoint observations (size: count)",
            zorder=5,
        )
    from dyntarget.constellation.simulate import GEO_IMAGERS

    for name, glon, _ in GEO_IMAGERS:  # where the geostationary imagers sit
        ax.axvline(glon, color="tab:purple", lw=0.6, ls=":", zorder=1)
        ax.text(glon + 1, 84, name, color="tab:purple", fontsize=7, va="top")
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_xlabel("longitude (°)")
    ax.set_ylabel("latitude (°)")
    ax.set_aspect("equal")
    ax.grid(lw=0.3, color="0.85")
    s = day.summary
    ax.set_title(
        title
        or (
            f"{s['satellites']} satellites: {s['eruptions_observed']}/{s['eruptions']} eruptions "
            f"observed, {s['observations']} observations"
        )
    )
    ax.legend(loc="lower left", fontsize=7, framealpha=0.85)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    plt.close(fig)
    return write_bytes(path, buf.getvalue())


def html_view(day: Any, path: str | Path, *, start: str, title: str = "") -> Path:
    """Write the interactive view of the day (``constellation.html``, plotly, offline).

    Parameters
    ----------
    day : dyntarget.constellation.simulate.Day
        The simulated day.
    path : str or pathlib.Path
        HTML to write.
    start : str
        ISO start (hover times).
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import plotly.graph_objects as go

    from dyntarget.io.acquisition import iso_utc, parse_acquired

    t0 = parse_acquired(start)
    cat, er = day.catalog, day.eruptions
    fig = go.Figure()
    fig.add_trace(
        go.Scatter(
            x=cat.lon,
            y=cat.lat,
            mode="markers",
            name="volcanoes",
            marker={"size": 2, "color": "#bbbbbb"},
            hoverinfo="skip",
        )
    )
    for k, track in enumerate(day.tracks[:MAX_TRACKS]):
        lon, lat = _segments(track)
        fig.add_trace(
            go.Scatter(
                x=[None if math.isnan(x) else x for x in lon.tolist()],
                y=[None if math.isnan(x) else x for x in lat.tolist()],
                mode="lines",
                name="ground tracks (click to show or hide)" if k == 0 else day.names[k],
                line={"width": 0.6, "color": "rgba(31,119,180,0.4)"},
                legendgroup="tracks",
                showlegend=k == 0,
                hoverinfo="text",
                hovertext=day.names[k],
            )
        )
    if day.cues:
        ce = np.array([c["eruption"] for c in day.cues], np.int64)
        fig.add_trace(
            go.Scatter(
                x=cat.lon[er.volcano[ce]],
                y=cat.lat[er.volcano[ce]],
                mode="markers",
                name="cues (detections on the board)",
                hoverinfo="text",
                text=[f"cue by {c['source']} at {iso_utc(t0, c['time_s'])}" for c in day.cues],
                marker={"symbol": "circle-open", "size": 16, "color": "purple"},
            )
        )
    text = [
        f"volcano {r['volcano_number']}<br>onset {iso_utc(t0, r['onset_s'])}<br>"
        f"observations {r['observations']}"
        for r in day.table
    ]
    fig.add_trace(
        go.Scatter(
            x=cat.lon[er.volcano],
            y=cat.lat[er.volcano],
            mode="markers",
            name="eruptions",
            text=text,
            hoverinfo="text",
            marker={"symbol": "triangle-up", "size": 9, "color": "red"},
        )
    )
    if day.observations:
        oe = np.array([o["eruption"] for o in day.observations], np.int64)
        fig.add_trace(
            go.Scatter(
                x=cat.lon[er.volcano[oe]],
                y=cat.lat[er.volcano[oe]],
                mode="markers",
                name="observations",
                hoverinfo="text",
                text=[
                    f"{o['satellite']} {iso_utc(t0, o['time_s'])} off-nadir {o['off_nadir_deg']:.1f}°"
                    for o in day.observations
                ],
                marker={"symbol": "star", "size": 11, "color": "gold", "line": {"width": 0.5}},
            )
        )
    fig.update_layout(
        title=title or "constellation day",
        height=700,
        xaxis={"range": [-180, 180], "title": "longitude (°)", "zeroline": False},
        yaxis={"range": [-90, 90], "title": "latitude (°)", "scaleanchor": "x", "zeroline": False},
        plot_bgcolor="white",
    )
    html = fig.to_html(include_plotlyjs=True, full_html=True, div_id="dyntarget-constellation")
    return write_text(path, html)
