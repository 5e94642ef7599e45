"""Open a view in headless Chromium and read back what it drew (tests, screenshots).

Drives Debian's ``chromium`` with its ``chromedriver`` through selenium (both
optional: ``apt-get install chromium chromium-driver``, ``pip install selenium``).
What comes back is read from the page, not from our file: the browser console,
the names of the plotted traces, the pointings trace's data as plotly holds it,
and the position of every marker plotly drew (its SVG transform mapped back to
data coordinates with plotly's own axis conversion).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.view.html import DIV_ID, POINTINGS

CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-dev-shm-usage",
    "--hide-scrollbars",
)
"""Flags Chromium needs to run headless as root in a container without network."""

_READ = """
const gd = document.getElementById(arguments[0]);
if (!gd || !gd._fullLayout || !gd.querySelector('.scatterlayer')) { return null; }
const names = gd.data.map(t => t.name);
const k = names.indexOf(arguments[1]);
const xa = gd._fullLayout.xaxis, ya = gd._fullLayout.yaxis;
let data = [], drawn = [];
if (k >= 0) {
  const t = gd.data[k];
  data = (t.x || []).map((x, i) => [x, t.y[i]]);
  const traces = gd.querySelectorAll('.scatterlayer .trace');
  const fullIndex = gd._fullData.findIndex(f => f.name === arguments[1]);
  traces.forEach(tr => {
    const cd = tr.__data__;
    const trace = cd && cd[0] && cd[0].trace;
    if (!trace || trace.index !== fullIndex) { return; }
    tr.querySelectorAll('path.point').forEach(p => {
      const m = /translate\\(([-0-9.e]+),\\s*([-0-9.e]+)\\)/.exec(p.getAttribute('transform'));
      if (m) { drawn.push([xa.p2d(parseFloat(m[1])), ya.p2d(parseFloat(m[2]))]); }
    });
  });
}
return {names: names, data: data, drawn: drawn, px_per_unit: xa._m,
        images: gd.querySelectorAll('.layer-subplot image, .imagelayer image').length};
"""

_ANIMATE = """
const done = arguments[arguments.length - 1];
const gd = document.getElementById(arguments[0]);
Plotly.animate(gd, [arguments[1]], {mode: 'immediate', frame: {duration: 0, redraw: true},
                                    transition: {duration: 0}})
  .then(() => done(true), e => done(String(e)));
"""

_HOVER = """
const gd = document.getElementById(arguments[0]);
const k = gd.data.map(t => t.name).indexOf(arguments[1]);
Plotly.Fx.hover(gd, [{curveNumber: k, pointNumber: arguments[2]}]);
"""


@dataclass(frozen=True)
class Rendered:
    """What Chromium showed for a view page.

    Parameters
    ----------
    console : list of dict
        Browser console entries.
    traces : list of str
        Names of the plotted traces.
    pointings : numpy.ndarray
        ``(N, 2)`` pointings as plotly holds them.
    drawn : numpy.ndarray
        ``(M, 2)`` data coordinates of the drawn pointing markers.
    px_per_unit : float
        Screen pixels per WFOV pixel on the x axis.
    images : int
        Number of ``<image>`` elements drawn.
    """

    console: list[dict]
    """Browser console entries (``level``, ``message``), errors and warnings included."""
    traces: list[str]
    """Names of the plotted traces, in drawing order."""
    pointings: np.ndarray
    """(N, 2) ``x, y`` of the pointings trace as plotly holds it in the page."""
    drawn: np.ndarray
    """(M, 2) data coordinates of the markers plotly drew for that trace."""
    px_per_unit: float
    """Screen pixels per WFOV pixel on the x axis (to turn screen tolerances into data)."""
    images: int
    """Number of ``<image>`` elements drawn (the image layers)."""

    @property
    def errors(self) -> list[dict]:
        """Console entries at level SEVERE (errors)."""
        return [e for e in self.console if e.get("level") == "SEVERE"]


def find_chromium() -> tuple[str, str] | None:
    """Paths of ``chromium`` and ``chromedriver``, or ``None`` when either is missing.

    Returns
    -------
    tuple of str or None

    Examples
    --------
    >>> r = find_chromium()
    >>> r is None or all(os.path.isabs(p) for p in r)
    True
    """
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None


def render(
    path: str | os.PathLike[str],
    *,
    screenshot: str | os.PathLike[str] | None = None,
    window: tuple[int, int] = (1000, 900),
    timeout_s: float = 60.0,
    frame: int | None = None,
    hover: int | None = None,
) -> Rendered:
    """Open ``path`` in headless Chromium, wait for the plot, read it back.

    Parameters
    ----------
    path : path-like
        An HTML view written by :func:`dyntarget.view.write_scene_view` or
        :func:`dyntarget.view.write_pass_view`.
    screenshot : path-like, optional
        Where to save a PNG of the window.
    window : (width, height)
        Window size in screen pixels.
    timeout_s : float
        How long to wait for the figure to be drawn.
    frame : int, optional
        For a pass view: move the time slider to this step (0-based) before reading.
    hover : int, optional
        Show the hover label of this pointing (0-based) before the screenshot.

    Returns
    -------
    Rendered

    Raises
    ------
    DataFileError
        When Chromium/chromedriver/selenium are missing, or the page never draws the figure.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from dyntarget.trajectory import Trajectory
    >>> from dyntarget.view import write_scene_view
    >>> img = np.random.default_rng(0).uniform(0, 1, (4, 8, 8)).astype(np.float32)
    >>> t = Trajectory(np.array([[1.0, 2.0], [5.0, 6.0]]), np.zeros(2, int), "demo")
    >>> page = write_scene_view(pathlib.Path(tempfile.mkdtemp()) / "v.html", img, trajectory=t)
    >>> shown = render(page) if find_chromium() else None  # needs Debian's chromium
    >>> shown is None or (shown.errors == [] and shown.pointings.tolist() == t.points.tolist())
    True
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise DataFileError(f"{path}: no such file")
    if timeout_s <= 0:
        raise InvalidParameterError(f"timeout_s: expected a positive number, got {timeout_s!r}")
    found = find_chromium()
    if found is None:
        raise DataFileError(
            "chromium: not installed (Debian: apt-get install -y chromium chromium-driver)"
        )
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        raise DataFileError("selenium: not installed (pip install selenium)") from None
    browser, driver_path = found
    with tempfile.TemporaryDirectory(prefix="dyntarget-chromium-") as profile:
        options = webdriver.ChromeOptions()
        options.binary_location = browser
        for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}"):
            options.add_argument(flag)
        options.add_argument(f"--window-size={int(window[0])},{int(window[1])}")
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        driver = webdriver.Chrome(service=Service(driver_path), options=options)
        try:
            driver.set_page_load_timeout(timeout_s)
            driver.get(path.as_uri())
            deadline = time.monotonic() + timeout_s
            got = None
            while got is None and time.monotonic() < deadline:
                got = driver.execute_script(_READ, DIV_ID, POINTINGS)
                if got is None:
                    time.sleep(0.2)
            if got is None:
                raise DataFileError(f"{path}: the figure was not drawn within {timeout_s:g} s")
            if frame is not None:
                driver.set_script_timeout(timeout_s)
                driver.execute_async_script(_ANIMATE, DIV_ID, str(int(frame)))
                got = driver.execute_script(_READ, DIV_ID, POINTINGS)
            if hover is not None:
                driver.execute_script(_HOVER, DIV_ID, POINTINGS, int(hover))
            if screenshot is not None:
                time.sleep(0.5)  # let the image layers decode before the picture
                driver.save_screenshot(str(screenshot))
            console = driver.get_log("browser")
        finally:
            driver.quit()
    return Rendered(
        console=[{"level": e.get("level"), "message": e.get("message")} for e in console],
        traces=list(got["names"]),
        pointings=np.asarray(got["data"], np.float64).reshape(-1, 2),
        drawn=np.asarray(got["drawn"], np.float64).reshape(-1, 2),
        px_per_unit=float(got["px_per_unit"]),
        images=int(got["images"]),
    )
