"""Live mode: plan every look-ahead frame that appears in a directory, until stopped.

For hardware-in-the-loop tests and ground replays. The rules (also in
``docs/onboard.md``, section "Live mode"):

* **Which files.** ``*.tif``/``*.tiff`` in the watched directory; names that
  start with ``.``, end in ``.part`` or ``_mask.tif`` are never read. A writer
  may write ``NAME.tif.part`` and rename it to ``NAME.tif`` when complete (the
  rename is atomic on one file system) — the safe convention.
* **When.** Where inotify is available (Linux, with ``inotify_simple``: the
  ``onboard`` extra), a frame renamed into the folder (``IN_MOVED_TO``) or
  closed after writing (``IN_CLOSE_WRITE``) is read at once; otherwise, and
  for every file the events missed, a frame is read only once its size and
  modification time have not changed for ``settle_s`` seconds. Either way it
  must open and read completely as a 4-band GeoTIFF. A file that stays
  unreadable for ``corrupt_after_s`` is reported once (``rejected.csv``) and
  skipped; a frame that reads but cannot be planned (a bad time tag, absurd
  pixel size, anything) is rejected at once with the reason. A bad frame never
  stops the watcher.
* **Order.** Ready frames are planned in order of acquisition time (read by
  :func:`dyntarget.io.acquisition.read_acquisition`: sidecar, then the tags in
  its one order; else the file's modification time, said on stderr and in
  ``frames.csv``'s ``acquired_from``; the name breaks ties).
* **Output.** One plan per frame, ``OUT/<stem>.geojson`` (``OUT/<name>.geojson``,
  e.g. ``a.tiff.geojson``, when another frame already has that stem), and a line
  per frame in ``OUT/frames.csv``, each written atomically. A restarted watcher
  reads ``frames.csv`` back, keeps its rows, and does not plan the frames listed
  there again: nothing is overwritten or dropped.
* **Latency.** ``frames.csv`` gives ``waited_s`` (file seen -> read started),
  ``read_s``, ``planned_s`` (plan and write) and ``acquired_to_written_s`` (the
  acquisition time, from the tag or mtime, to the plan written, by the wall clock).
* **Stopping.** ``should_stop`` (the CLI sets it on SIGINT/SIGTERM) is polled
  between frames and while idle: the frame in hand is finished and written,
  then the watcher returns; :attr:`Watcher.stop_reason` says why it stopped
  (stop request, idle limit, frame limit). If the watched folder is removed or
  replaced by a file the watcher stops with a :class:`DataFileError` saying so.
"""

from __future__ import annotations

import csv
import io
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from dyntarget import defaults
from dyntarget.errors import DataFileError, DynTargetError, InvalidParameterError
from dyntarget.io.atomic import write_text
from dyntarget.perceive.base import Classifier
from dyntarget.pipeline import PipelineConfig, plan_scene, schedule_on_prediction
from dyntarget.schedule import OrbitGeometry, get_agility

FRAMES = "frames.csv"
REJECTED = "rejected.csv"
ACQUIRED_TAG = "DYNTARGET_ACQUIRED"
"""GeoTIFF tag holding a frame's acquisition time (ISO-8601 UTC); one of
:data:`dyntarget.io.acquisition.TAGS`, read there."""


@dataclass
class WatchConfig:
    """Settings of the live mode (see the module docstring).

    Parameters
    ----------
    planner : str
        Registered planner name.
    factor : int
        High-res -> WFOV downsampling factor.
    agility : str or None
        Agility preset; ``None`` writes the plans untimed.
    altitude_m, look_ahead_m : float
        Orbit geometry, metres (with ``agility``).
    deadline_s : float or None
        Time allowed per frame, seconds (the pipeline's fallbacks apply).
    poll_s : float
        Seconds between polls of the directory.
    settle_s : float
        Seconds a frame's size and time must stay unchanged before it is read.
    corrupt_after_s : float
        Seconds after which a still unreadable frame is rejected.
    idle_exit_s : float or None
        Return after this many seconds without a new frame.
    max_frames : int or None
        Return after planning this many frames.
    pipeline : dyntarget.pipeline.PipelineConfig
        Settings of the pipeline.
    events : bool
        Use inotify events where available (else, and always as well, polling).
    """

    planner: str = "lawnmower-transect"
    factor: int = 4
    agility: str | None = None
    altitude_m: float = defaults.ALTITUDE_M
    look_ahead_m: float = defaults.LOOK_AHEAD_M
    deadline_s: float | None = None
    poll_s: float = 0.2
    settle_s: float = 1.0
    corrupt_after_s: float = 10.0
    idle_exit_s: float | None = None
    max_frames: int | None = None
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    events: bool = True

    def __post_init__(self) -> None:
        if self.agility is not None:
            get_agility(self.agility)
        for name in ("poll_s", "settle_s", "corrupt_after_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0 <= v < 3600):
                raise InvalidParameterError(f"{name}: expected seconds in [0, 3600), got {v!r}")


@dataclass
class _Seen:
    size: int
    mtime: float
    since: float
    first: float


def candidates(directory: Path) -> list[Path]:
    """Frame files in ``directory`` that may be read (see the module docstring).

    Parameters
    ----------
    directory : the watched directory.

    Returns
    -------
    list of paths, sorted by name.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for n in ("b.tif", "a.tif.part", ".x.tif", "b_mask.tif", "c.tiff"): _ = (d / n).write_bytes(b"")
    >>> [p.name for p in candidates(d)]
    ['b.tif', 'c.tiff']
    """
    out = []
    for p in directory.iterdir():
        n = p.name
        if n.startswith(".") or n.endswith(".part") or not p.is_file():
            continue
        low = n.lower()
        if (low.endswith(".tif") or low.endswith(".tiff")) and not low.endswith("_mask.tif"):
            out.append(p)
    return sorted(out)


def acquired_time(path: Path) -> tuple[float, str]:
    """A frame's acquisition time as POSIX seconds, and where it came from.

    :func:`dyntarget.io.acquisition.read_acquisition` (sidecar, then the tags, in
    its one order); a frame none of them dates gets its file's modification time,
    source ``"file mtime"`` (the watcher says so on stderr and in ``frames.csv``).

    Parameters
    ----------
    path : pathlib.Path
        The frame's file.

    Returns
    -------
    tuple
        ``(POSIX seconds, source)``.

    Raises
    ------
    dyntarget.errors.DataFileError
        For a tag or sidecar holding a time that cannot be read (the frame is rejected).
    """
    from dyntarget.io.acquisition import read_acquisition

    when, source = read_acquisition(path)
    if when is None or source is None:
        return path.stat().st_mtime, "file mtime"
    return when.timestamp(), source


class _Events:
    """inotify on the watched folder (``inotify_simple``); ``None`` where unavailable."""

    def __init__(self, directory: Path) -> None:
        from inotify_simple import INotify, flags  # ImportError / OSError: polling only

        self.flags = flags
        self.inotify = INotify()
        mask = flags.CLOSE_WRITE | flags.MOVED_TO | flags.DELETE_SELF | flags.MOVE_SELF
        self.inotify.add_watch(str(directory), mask)
        self.gone = False

    def read(self, timeout_s: float) -> set[str]:
        """Names closed after writing or renamed in, waiting at most ``timeout_s``."""
        names = set()
        for ev in self.inotify.read(timeout=max(0, int(timeout_s * 1000))):
            if ev.mask & (self.flags.DELETE_SELF | self.flags.MOVE_SELF | self.flags.IGNORED):
                self.gone = True
            elif ev.name:
                names.add(ev.name)
        return names

    def close(self) -> None:
        self.inotify.close()


def _events(directory: Path, wanted: bool) -> _Events | None:
    if not wanted:
        return None
    try:
        return _Events(directory)
    except (ImportError, OSError, AttributeError):  # not Linux, no inotify_simple, no watches left
        return None


FRAME_COLUMNS = (
    "frame",
    "acquired",
    "acquired_from",
    "plan",
    "waited_s",
    "read_s",
    "planned_s",
    "acquired_to_written_s",
    "deadline_met",
    "pointings",
    "path",
)
"""Columns of ``frames.csv``."""


class Watcher:
    """Plan frames as they appear in ``directory``; write plans into ``out``.

    Parameters
    ----------
    directory : the watched directory.
    out : where plans go (created).
    classifier : a fitted classifier (an ONNX one on the onboard install).
    config : live-mode settings.
    clock : monotonic clock (tests may pass a fake one).
    log : called with one line per event.
    """

    def __init__(
        self,
        directory: str | os.PathLike[str],
        out: str | os.PathLike[str],
        classifier: Classifier,
        config: WatchConfig,
        *,
        clock: Callable[[], float] = time.monotonic,
        log: Callable[[str], None] | None = None,
    ) -> None:
        self.directory = Path(directory)
        if not self.directory.is_dir():
            raise DataFileError(f"--watch {directory}: not a directory")
        self.out = Path(out)
        if self.out.resolve() == self.directory.resolve():
            raise InvalidParameterError(f"--out {out}: the watched folder itself; give another")
        self.out.mkdir(parents=True, exist_ok=True)
        self.classifier, self.config, self.clock = classifier, config, clock
        self.log = log or (lambda line: None)
        self._seen: dict[Path, _Seen] = {}
        self._rejected: dict[str, str] = dict(_read_table(self.out / REJECTED, ("frame", "reason")))
        self._rejected_sig: dict[str, tuple[int, float]] = {}
        self.rows: list[dict[str, str]] = []
        """Rows of the frames planned by this watcher (``frames.csv`` also keeps earlier ones)."""
        self._table = [dict(r) for r in _read_rows(self.out / FRAMES)]
        self.plans: dict[str, str] = {}  # plan file name -> frame name
        for r in self._table:
            self.plans[r.get("plan") or f"{Path(r['frame']).stem}.geojson"] = r["frame"]
        self.done: set[str] = {r["frame"] for r in self._table}
        if not self._table:  # plans of a watcher older than frames.csv's "plan" column
            self._legacy = {p.stem for p in self.out.glob("*.geojson")}
        else:
            self._legacy = set()
        self._complete: set[str] = set()
        self._events = _events(self.directory, config.events)
        self.stop_reason = ""

    def close(self) -> None:
        """Release the inotify watch (:meth:`run` does so when it returns)."""
        if self._events is not None:
            self._events.close()
            self._events = None

    def __del__(self) -> None:
        events = getattr(self, "_events", None)
        if events is not None:
            events.close()

    def _check_folder(self) -> None:
        if (self._events is not None and self._events.gone) or not self.directory.is_dir():
            what = "replaced by a file" if self.directory.exists() else "removed"
            raise DataFileError(
                f"--watch {self.directory}: the watched folder was {what}; stopped after "
                f"planning {len(self.rows)} frame(s) (plans and frames.csv in {self.out} are kept)"
            )

    def _drain(self, timeout_s: float = 0.0) -> None:
        if self._events is not None:
            self._complete |= self._events.read(timeout_s)

    def _is_done(self, p: Path) -> bool:
        return p.name in self.done or (p.suffix.lower() == ".tif" and p.stem in self._legacy)

    def ready(self) -> list[Path]:
        """Frames complete and not yet planned, in acquisition order.

        Returns
        -------
        list of pathlib.Path
            The frames.
        """
        self._drain()
        now = self.clock()
        ready = []
        try:
            found = candidates(self.directory)
        except OSError:  # FileNotFoundError, NotADirectoryError: the folder went away
            self._check_folder()
            raise
        for p in found:
            if self._is_done(p):
                continue
            try:
                st = p.stat()
            except FileNotFoundError:
                continue
            if p.name in self._rejected:
                if self._rejected_sig.get(p.name, (st.st_size, st.st_mtime)) == (
                    st.st_size,
                    st.st_mtime,
                ):
                    continue  # the same bad file: reported once
                del self._rejected[p.name]  # replaced since: try again
            seen = self._seen.get(p)
            if seen is None or (seen.size, seen.mtime) != (st.st_size, st.st_mtime):
                first = seen.first if seen else now
                self._seen[p] = _Seen(st.st_size, st.st_mtime, now, first)
                if p.name not in self._complete:
                    continue
                seen = self._seen[p]
            if p.name in self._complete or now - seen.since >= self.config.settle_s:
                ready.append(p)
        keys = {}
        for p in ready:
            try:
                keys[p] = (acquired_time(p)[0], p.name)
                datetime.fromtimestamp(keys[p][0], UTC)
            except Exception as exc:  # a time the clock cannot hold (year 1 at +14:00, ...)
                keys.pop(p, None)
                self._reject(p, f"bad acquisition time ({type(exc).__name__}: {exc})")
        return sorted(keys, key=keys.__getitem__)

    def _read(self, path: Path):
        from dyntarget.io import read_scene

        return read_scene(path, factor=self.config.factor, auto_label=False)

    def step(self) -> int:
        """Plan every frame ready now; return how many were planned.

        Returns
        -------
        int
            Frames planned.
        """
        n = 0
        for path in self.ready():
            seen = self._seen[path]
            t_read = self.clock()
            try:
                scene = self._read(path)
            except (DynTargetError, OSError) as exc:
                self._complete.discard(path.name)  # the event lied (or was early): settle
                if self.clock() - seen.first >= self.config.corrupt_after_s:
                    self._reject(path, str(exc).splitlines()[0])
                continue  # not complete yet (or corrupt): try again later
            except Exception as exc:  # anything else a hostile file provokes
                self._reject(path, f"{type(exc).__name__}: {str(exc)[:200]}")
                continue
            read_s = self.clock() - t_read
            try:
                self.plan(path, scene, waited_s=t_read - seen.first, read_s=read_s)
            except Exception as exc:  # a frame that reads but cannot be planned
                first = str(exc).splitlines()[0] if str(exc) else ""
                self._reject(path, f"cannot be planned ({type(exc).__name__}: {first[:200]})")
                continue
            self._complete.discard(path.name)
            n += 1
            if self.config.max_frames is not None and len(self.rows) >= self.config.max_frames:
                break
        return n

    def _plan_name(self, path: Path) -> str:
        for name in (f"{path.stem}.geojson", f"{path.name}.geojson"):
            owner = self.plans.get(name)
            if owner in (None, path.name) and not (
                owner is None and name.removesuffix(".geojson") in self._legacy
            ):
                return name
        raise DataFileError(
            f"{path.name}: its plan names {path.stem}.geojson and {path.name}.geojson are "
            "taken by other frames; rename it"
        )

    def plan(self, path: Path, scene, *, waited_s: float = 0.0, read_s: float = 0.0) -> Path:
        """Plan one frame and write its plan and the frames table atomically.

        Parameters
        ----------
        path : pathlib.Path
            The frame's file.
        scene : dyntarget.scene.Scene
            The frame, already read.
        waited_s, read_s : float
            Seconds from the file seen to its read, and of the read (for ``frames.csv``).

        Returns
        -------
        pathlib.Path
            The plan written (see :meth:`_plan_name`).
        """
        cfg = self.config
        name = self._plan_name(path)
        acquired, acquired_from = acquired_time(path)
        if acquired_from == "file mtime":
            self.log(f"{path.name}: no acquisition time in its tags or sidecar; dated by its mtime")
        acquired_iso = datetime.fromtimestamp(acquired, UTC).isoformat()
        t0 = time.perf_counter()
        result = plan_scene(
            scene.image,
            self.classifier,
            cfg.planner,
            valid=scene.valid,
            config=cfg.pipeline,
            deadline_s=cfg.deadline_s,
        )
        traj = result.trajectory
        if cfg.agility is not None:
            geometry = OrbitGeometry(
                altitude_m=cfg.altitude_m,
                look_ahead_m=cfg.look_ahead_m,
                wfov_gsd_m=scene.gsd or OrbitGeometry().wfov_gsd_m,
                start_s=result.runtime,
            )
            flown = schedule_on_prediction(traj, scene.shape, geometry, cfg.agility, None)
            traj = flown.trajectory
        out = traj.save(self.out / name, transform=scene.transform, crs=scene.crs)
        latency = time.perf_counter() - t0
        written = time.time()
        self.done.add(path.name)
        self.plans[name] = path.name
        row = {
            "frame": path.name,
            "acquired": acquired_iso,
            "acquired_from": acquired_from,
            "plan": name,
            "waited_s": f"{max(waited_s, 0.0):.4f}",
            "read_s": f"{read_s:.4f}",
            "planned_s": f"{latency:.4f}",
            "acquired_to_written_s": f"{written - acquired:.3f}",
            "deadline_met": "" if result.deadline_met is None else str(result.deadline_met).lower(),
            "pointings": str(len(traj)),
            "path": "; ".join(result.path),
        }
        self.rows.append(row)
        self._table.append(row)
        write_text(self.out / FRAMES, _csv(self._table, FRAME_COLUMNS))
        self.log(
            f"{path.name}: {len(traj)} pointings in {latency:.3f} s "
            f"(waited {max(waited_s, 0.0):.3f} s) -> {out.name}"
        )
        return out

    def _reject(self, path: Path, why: str) -> None:
        self._rejected[path.name] = why
        try:
            st = path.stat()
            self._rejected_sig[path.name] = (st.st_size, st.st_mtime)
        except OSError:
            pass
        rows = [{"frame": k, "reason": v} for k, v in sorted(self._rejected.items())]
        write_text(self.out / REJECTED, _csv(rows, ("frame", "reason")))
        self.log(f"{path.name}: rejected ({why}); see {REJECTED}")

    def run(self, should_stop: Callable[[], bool] = lambda: False) -> int:
        """Poll until ``should_stop()`` (or the idle/max-frames limits); return frames planned.

        Parameters
        ----------
        should_stop : callable
            Polled between frames and while idle; the watcher returns once it is true.

        Returns
        -------
        int
            Frames planned by this watcher. :attr:`stop_reason` says why it returned.

        Raises
        ------
        DataFileError
            When the watched folder is removed or replaced by a file.
        """
        cfg = self.config
        last = self.clock()
        try:
            while True:
                if should_stop():
                    self.stop_reason = "stop requested"
                    break
                self._check_folder()
                if self.step():
                    last = self.clock()
                if cfg.max_frames is not None and len(self.rows) >= cfg.max_frames:
                    self.stop_reason = f"{cfg.max_frames} frame(s) planned (--max-frames)"
                    break
                if cfg.idle_exit_s is not None and self.clock() - last >= cfg.idle_exit_s:
                    self.stop_reason = f"no new frame for {cfg.idle_exit_s:g} s (--idle-exit-s)"
                    break
                if self._events is not None:
                    self._drain(min(cfg.poll_s, 0.05))  # wakes at once on a new frame
                    if not self._complete:
                        _sleep(max(cfg.poll_s - 0.05, 0.0), should_stop)
                else:
                    _sleep(cfg.poll_s, should_stop)
        finally:
            self.close()
        return len(self.rows)


def _read_rows(path: Path) -> list[dict[str, str]]:
    """The rows of an earlier ``frames.csv`` (refused unless it has a ``frame`` column)."""
    if not (path.exists() or path.is_symlink()):
        return []
    from dyntarget.io.safeopen import read_text

    text = read_text(path, max_bytes=256 * 1024 * 1024)
    rows = list(csv.DictReader(io.StringIO(text)))
    if text.strip() and (not rows or "frame" not in rows[0]):
        raise DataFileError(f"{path}: not a frames table of 'fly --watch'; move it away")
    return [{k: (v or "") for k, v in r.items() if k is not None} for r in rows]


def _read_table(path: Path, columns: tuple[str, str]) -> list[tuple[str, str]]:
    try:
        rows = _read_rows(path)
    except DataFileError:
        return []
    return [(r.get(columns[0], ""), r.get(columns[1], "")) for r in rows if r.get(columns[0])]


def _sleep(seconds: float, should_stop: Callable[[], bool]) -> None:
    end = time.monotonic() + seconds
    while not should_stop() and (left := end - time.monotonic()) > 0:
        time.sleep(min(left, 0.05))


def _csv(rows: list[dict[str, str]], columns: tuple[str, ...]) -> str:
    buf = io.StringIO()
    names = list(columns) + [k for r in rows for k in r if k not in columns]
    w = csv.DictWriter(buf, fieldnames=list(dict.fromkeys(names)), lineterminator="\n", restval="")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()
