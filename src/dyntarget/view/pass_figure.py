"""Pictures of a pass (PNG, matplotlib): a short pass's whole strip, a long pass's overview.

The pass's report (:mod:`dyntarget.view.pass_report`) hands over what to draw as plain arrays
(:class:`PassPicture`, :class:`PassOverview`): nothing here knows of frames, worlds
or pass results. matplotlib is optional (the lean onboard install has none): it is
imported inside the drawing functions, which return ``None`` without it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.io.atomic import atomic_path

LANE_KM = 300.0
"""Along-track kilometres per lane of a long pass's overview picture (up to 5 % more; at most
12 lanes)."""


@dataclass(frozen=True, eq=False)
class PassPicture:
    """A short pass drawn whole (:func:`draw_pass_picture`), on the strip's WFOV grid.

    Parameters
    ----------
    rgb : array (H, W, 3)
        The strip's reflectance (R, G, B) per WFOV pixel; row 0 is the strip's first
        row (the flight runs from its last row to its first).
    plume : array (H, W)
        The true plume fraction per WFOV pixel (outlined at 0.5).
    frame_px : int
        Frame height, WFOV rows.
    tops : sequence of int
        First strip row of each frame flown, in pass order.
    dropped : sequence of bool
        Whether each frame was dropped (late); as long as ``tops``.
    pointings : (x, y, t)
        The flown pointings: column and row on the WFOV grid, seconds into the pass.
    title : str
        The picture's title.

    Raises
    ------
    InvalidParameterError
        ``rgb`` and ``plume`` of other shapes, or ``tops`` and ``dropped`` of other lengths.
    """

    rgb: np.ndarray
    plume: np.ndarray
    frame_px: int
    tops: Sequence[int]
    dropped: Sequence[bool]
    pointings: tuple[Sequence[float], Sequence[float], Sequence[float]]
    title: str = ""

    def __post_init__(self) -> None:
        rgb, plume = np.shape(self.rgb), np.shape(self.plume)
        if len(rgb) != 3 or rgb[2] != 3 or rgb[:2] != plume:
            raise InvalidParameterError(
                f"rgb {rgb} and plume {plume}: expected (H, W, 3) and (H, W)"
            )
        if len(self.tops) != len(self.dropped):
            raise InvalidParameterError(
                f"tops ({len(self.tops)}) and dropped ({len(self.dropped)}): one per frame"
            )


@dataclass(frozen=True, eq=False)
class PassOverview:
    """A long pass decimated along-track, in kilometres (:func:`draw_pass_overview`).

    Parameters
    ----------
    rgb : array (n, W, 3)
        The decimated strip's reflectance, along-track increasing (NaN: not seen).
    plume : array (n, W)
        The plume fraction each cell was planned on (NaN: not seen).
    extent : (along_0, along_1, across_0, across_1)
        What the image covers, km.
    pointings : (along_km, across_km, time_s)
        The flown pointings.
    targets : (along_km, across_km) or None
        GEO targets.
    dropped : array
        Along-track km of the frames dropped (late).
    rows_per_cell : int
        WFOV rows averaged into each along-track cell.
    km_per_cell : float
        Along-track km per cell.
    title : str
        The pass, in one line.
    """

    rgb: np.ndarray
    plume: np.ndarray
    extent: tuple[float, float, float, float]
    pointings: tuple[np.ndarray, np.ndarray, np.ndarray]
    targets: tuple[np.ndarray, np.ndarray] | None
    dropped: np.ndarray
    rows_per_cell: int
    km_per_cell: float
    title: str = ""


def _pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (ImportError without matplotlib)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _save(plt: Any, fig: Any, path: str | os.PathLike[str], **kwargs: Any) -> Path:
    """Write ``fig`` to the PNG ``path`` atomically and close it."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", **kwargs)
    plt.close(fig)
    return Path(path)


def draw_pass_picture(picture: PassPicture, path: str | os.PathLike[str]) -> Path | None:
    """Draw the strip with its frames, true plumes and flown pointings to a PNG.

    The strip lies on its side, flight to the right: the image, the true plumes
    (orange outline), the frames as numbered bars under the strip in two lanes
    (red: dropped) and the flown pointings coloured by time.

    Parameters
    ----------
    picture : PassPicture
        What to draw.
    path : str or os.PathLike
        The PNG to write.

    Returns
    -------
    pathlib.Path or None
        The PNG written, or ``None`` without matplotlib (the lean onboard install).

    Examples
    --------
    >>> import tempfile
    >>> rgb = np.full((64, 16, 3), 0.1, np.float32); plume = np.zeros((64, 16))
    >>> pic = PassPicture(rgb, plume, 16, [48, 40], [False, True], ([8.0], [50.0], [1.5]))
    >>> draw_pass_picture(pic, Path(tempfile.mkdtemp()) / "pass.png").read_bytes()[:4]
    b'\\x89PNG'
    """
    try:
        plt = _pyplot()
    except ImportError:
        return None
    hw, ww = picture.plume.shape
    rgb = np.clip(picture.rgb * 2.5, 0, 1)
    fig, ax = plt.subplots(figsize=(min(16.0, 2.0 + hw / ww * 2.4), 4.6), dpi=110)
    ax.imshow(np.rot90(rgb, -1), origin="upper", interpolation="nearest")
    ax.contour(np.rot90(picture.plume, -1), levels=[0.5], colors="orange", linewidths=0.8)
    _frame_bars(ax, picture, hw, ww)
    ax.set_ylim(ww + 1.5 + 0.22 * ww, -0.5)
    x, y, t = picture.pointings
    if len(x):
        sc = ax.scatter(hw - 1 - np.asarray(y), x, c=t, s=6, cmap="viridis", edgecolors="none")
        fig.colorbar(sc, ax=ax, label="pointing time (s)", fraction=0.03, pad=0.01)
    ax.set_title(picture.title, fontsize=9)
    _picture_legend(ax)
    ax.set_xlabel("along track (WFOV px)")
    ax.set_ylabel("across (px)")
    fig.tight_layout()
    return _save(plt, fig, path)


def _frame_bars(ax: Any, picture: PassPicture, hw: int, ww: int) -> None:
    """The frames as numbered bars under the rotated strip, alternating between two lanes."""
    from matplotlib.patches import Rectangle

    fh = picture.frame_px
    for k, (top, dropped) in enumerate(zip(picture.tops, picture.dropped, strict=True)):
        # rotated: strip row r -> x = hw - 1 - r
        lane = ww + 1.0 + (k % 2) * 0.11 * ww
        ax.add_patch(
            Rectangle(
                (hw - (top + fh) - 0.5, lane),
                fh,
                0.1 * ww,
                facecolor="red" if dropped else "tab:blue",
                edgecolor="white",
                linewidth=0.6,
            )
        )
        ax.text(hw - top - fh / 2 - 0.5, lane + 0.05 * ww, str(k), fontsize=8,
                color="w", fontweight="bold", ha="center", va="center")  # fmt: skip


def _picture_legend(ax: Any) -> None:
    """The short pass picture's legend, under the axes."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    handles = [
        Line2D([], [], color="orange", lw=1.2, label="true plumes at t = 0"),
        Rectangle((0, 0), 1, 1, facecolor="tab:blue", label="frame k (planned)"),
        Rectangle((0, 0), 1, 1, facecolor="red", label="frame k (dropped: late)"),
        Line2D([], [], color="tab:green", lw=0, marker="o", ms=4,
               label="pointing flown (colour: time)"),
    ]  # fmt: skip
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(0, -0.22), ncol=4, fontsize=8,
              frameon=False)  # fmt: skip


def draw_pass_overview(overview: PassOverview, path: str | os.PathLike[str]) -> Path | None:
    """Draw a long pass's overview to a PNG: the strip in lanes of :data:`LANE_KM`.

    Each lane is a stretch of the pass, flight to the right, across-track
    stretched to be seen: the decimated strip (RGB), the plume each frame planned
    on (magenta: the fraction of each decimated cell), the flown pointings
    (coloured by time), GEO targets (red crosses) and dropped frames (red marks).

    Parameters
    ----------
    overview : PassOverview
        What to draw.
    path : str or os.PathLike
        The PNG to write.

    Returns
    -------
    pathlib.Path or None
        The PNG written, or ``None`` without matplotlib (the lean onboard install).

    Examples
    --------
    >>> import tempfile
    >>> ov = PassOverview(np.full((40, 8, 3), 0.1), np.zeros((40, 8)), (0.0, 400.0, 0.0, 2.0),
    ...                   (np.array([10.0, 350.0]), np.array([1.0, 1.5]), np.array([0.0, 9.0])),
    ...                   None, np.array([]), 4, 10.0, "a pass")
    >>> draw_pass_overview(ov, Path(tempfile.mkdtemp()) / "pass.png").read_bytes()[:4]
    b'\\x89PNG'
    """
    try:
        plt = _pyplot()
    except ImportError:
        return None
    a0, a1, _, _ = overview.extent
    n_lanes = int(min(12, max(1, math.ceil((a1 - a0) / LANE_KM - 0.05))))  # lanes <= 1.05 x
    lane = (a1 - a0) / n_lanes
    rgb = np.clip(np.nan_to_num(overview.rgb) * 2.0, 0, 1)
    plume = np.nan_to_num(overview.plume)
    t = overview.pointings[2]
    fig, axes = plt.subplots(n_lanes, 1, figsize=(16, 1.2 + 1.1 * n_lanes), dpi=110, squeeze=False)
    fig.subplots_adjust(hspace=0.55)
    tmax = float(t.max()) if len(t) else 1.0
    sc = None
    for i, ax in enumerate(axes[:, 0]):
        drawn = _draw_lane(ax, overview, rgb, plume, (a0 + i * lane, a0 + (i + 1) * lane), tmax)
        sc = drawn if drawn is not None else sc
    axes[-1, 0].set_xlabel(
        "along track (km), flight to the right; each lane continues the one above"
    )
    if sc is not None:
        fig.colorbar(sc, ax=axes[:, 0].tolist(), label="pointing time (s)", fraction=0.02, pad=0.01)
    fig.suptitle(
        overview.title
        + f" (overview: {overview.km_per_cell:.2f} km per column, across-track stretched)",
        fontsize=10,
        y=0.9 + 0.5 / fig.get_figheight(),  # above the legend, which sits above the lanes
    )
    _overview_legend(fig)
    return _save(plt, fig, path, bbox_inches="tight")


def _draw_lane(
    ax: Any,
    overview: PassOverview,
    rgb: np.ndarray,
    plume: np.ndarray,
    span: tuple[float, float],
    tmax: float,
) -> Any:
    """One lane of the overview, along-track ``span`` (km); the pointings' scatter or None."""
    a0, a1, c0, c1 = overview.extent
    lo, hi = span
    na = rgb.shape[0]
    j0 = int(np.floor((lo - a0) / (a1 - a0) * na))
    j1 = int(np.ceil((hi - a0) / (a1 - a0) * na))
    e0, e1 = a0 + j0 * (a1 - a0) / na, a0 + j1 * (a1 - a0) / na
    ext = (e0, e1, c1, c0)  # across: 0 at the top
    ax.imshow(rgb[j0:j1].transpose(1, 0, 2), extent=ext, aspect="auto", interpolation="nearest")
    overlay = np.zeros((*plume[j0:j1].T.shape, 4))
    overlay[..., 0], overlay[..., 1], overlay[..., 2] = 1.0, 0.0, 1.0  # magenta
    overlay[..., 3] = np.where(plume[j0:j1].T > 0, 0.35 + 0.6 * plume[j0:j1].T, 0.0)
    ax.imshow(overlay, extent=ext, aspect="auto", interpolation="nearest")
    along, across, t = overview.pointings
    sc = None
    sel = (along >= lo) & (along < hi)
    if sel.any():
        sc = ax.scatter(along[sel], across[sel], c=t[sel], s=3, cmap="viridis", vmin=0,
                        vmax=tmax, edgecolors="none")  # fmt: skip
    if overview.targets is not None:
        ta, tc = overview.targets
        tsel = (ta >= lo) & (ta < hi)
        ax.scatter(ta[tsel], tc[tsel], marker="x", s=30, c="red", linewidths=1.2)
    dr = overview.dropped
    if len(dr):
        dsel = (dr >= lo) & (dr < hi)
        ax.scatter(dr[dsel], np.full(int(dsel.sum()), c1), marker="v", s=25, c="red")
    ax.set_xlim(lo, hi)
    ax.set_ylim(c1, c0)
    ax.set_yticks([c0, c1])
    ax.tick_params(labelsize=7)
    ax.set_ylabel("km", fontsize=7)
    return sc


def _overview_legend(fig: Any) -> None:
    """The overview's legend, above the lanes."""
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color="magenta", lw=4, alpha=0.7, label="plume planned on (opacity: fraction)"),
        Line2D([], [], color="tab:green", lw=0, marker="o", ms=4,
               label="pointing flown (colour: time)"),
        Line2D([], [], color="red", lw=0, marker="x", ms=6, label="GEO target"),
        Line2D([], [], color="red", lw=0, marker="v", ms=6, label="frame dropped (late)"),
    ]  # fmt: skip
    fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.45, 0.9), ncol=4,
               fontsize=8, frameon=False, bbox_transform=fig.transFigure)  # fmt: skip
