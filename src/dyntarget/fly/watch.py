"""Live mode: plan every look-ahead frame that appears in a directory, until stopped.

For hardware-in-the-loop tests and ground replays. The rules (also in
``docs/onboard.md``, section "Live mode"):

* **Which files.** ``*.tif``/``*.tiff`` in the watched directory; names that
  start with ``.``, end in ``.part`` or ``_mask.tif`` are never read. A writer
  may write ``NAME.tif.part`` and rename it to ``NAME.tif`` when complete (the
  rename is atomic on one file system) — the safe convention.
* **When.** A frame written in place is read only once its size and
  modification time have not changed for ``settle_s`` seconds *and* it opens
  and reads completely as a 4-band GeoTIFF. A file that stays unreadable for
  ``corrupt_after_s`` is reported once (``rejected.csv``) and skipped.
* **Order.** Ready frames are planned in order of acquisition time (read by
  :func:`dyntarget.io.acquisition.read_acquisition`: sidecar, then the tags in
  its one order; else the file's modification time, said on stderr and in
  ``frames.csv``'s ``acquired_from``; the name breaks ties).
* **Output.** One plan per frame, ``OUT/<stem>.geojson``, and a line per
  frame in ``OUT/frames.csv`` (rewritten whole), each written atomically.
  Frames whose plan already exists are not planned again, so a restarted
  watcher carries on where it stopped.
* **Stopping.** ``should_stop`` (the CLI sets it on SIGINT/SIGTERM) is polled
  between frames and while idle: the frame in hand is finished and written,
  then the watcher returns.
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
from dyntarget.pipeline import PipelineConfig, plan_scene
from dyntarget.schedule import OrbitGeometry, get_agility, make_feasible

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
    source ``"file mtime"`` (the watcher says so).

    Parameters
    ----------
    path : pathlib.Path
        The frame's file.

    Returns
    -------
    tuple
        ``(POSIX seconds, source)``.
    """
    from dyntarget.io.acquisition import read_acquisition

    try:
        when, source = read_acquisition(path)
    except DynTargetError:  # an unreadable time: the frame is dated by its file, and says so
        when, source = None, None
    if when is None or source is None:
        return path.stat().st_mtime, "file mtime"
    return when.timestamp(), source


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
        self.out.mkdir(parents=True, exist_ok=True)
        self.classifier, self.config, self.clock = classifier, config, clock
        self.log = log or (lambda line: None)
        self._seen: dict[Path, _Seen] = {}
        self._rejected: dict[str, str] = {}
        self.rows: list[dict[str, str]] = []
        self.done: set[str] = {p.stem for p in self.out.glob("*.geojson")}

    def ready(self) -> list[Path]:
        """Frames complete and not yet planned, in acquisition order.

        Returns
        -------
        list of pathlib.Path
            The frames.
        """
        now = self.clock()
        ready = []
        for p in candidates(self.directory):
            if p.stem in self.done or p.name in self._rejected:
                continue
            try:
                st = p.stat()
            except FileNotFoundError:
                continue
            seen = self._seen.get(p)
            if seen is None or (seen.size, seen.mtime) != (st.st_size, st.st_mtime):
                first = seen.first if seen else now
                self._seen[p] = _Seen(st.st_size, st.st_mtime, now, first)
                continue
            if now - seen.since >= self.config.settle_s:
                ready.append(p)
        return sorted(ready, key=lambda p: (acquired_time(p)[0], p.name))

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
            try:
                scene = self._read(path)
            except (DynTargetError, OSError) as exc:
                seen = self._seen[path]
                if self.clock() - seen.first >= self.config.corrupt_after_s:
                    self._reject(path, str(exc).splitlines()[0])
                continue  # not complete yet (or corrupt): try again later
            self.plan(path, scene)
            n += 1
            if self.config.max_frames is not None and len(self.rows) >= self.config.max_frames:
                break
        return n

    def plan(self, path: Path, scene) -> Path:
        """Plan one frame and write its plan and the frames table atomically.

        Parameters
        ----------
        path : pathlib.Path
            The frame's file.
        scene : dyntarget.scene.Scene
            The frame, already read.

        Returns
        -------
        pathlib.Path
            The plan written, ``OUT/<stem>.geojson``.
        """
        cfg = self.config
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
            traj = make_feasible(traj, scene.shape, geometry, cfg.agility).trajectory
        out = traj.save(self.out / f"{path.stem}.geojson", transform=scene.transform, crs=scene.crs)
        latency = time.perf_counter() - t0
        self.done.add(path.stem)
        when, source = acquired_time(path)
        if source == "file mtime":
            self.log(
                f"{path.name}: no acquisition time in its tags or sidecar; dated by its file's mtime"
            )
        self.rows.append(
            {
                "frame": path.name,
                "acquired": datetime.fromtimestamp(when, UTC).isoformat(),
                "acquired_from": source,
                "planned_s": f"{latency:.4f}",
                "deadline_met": ""
                if result.deadline_met is None
                else str(result.deadline_met).lower(),
                "pointings": str(len(traj)),
                "path": "; ".join(result.path),
            }
        )
        write_text(self.out / FRAMES, _csv(self.rows))
        self.log(f"{path.name}: {len(traj)} pointings in {latency:.3f} s -> {out.name}")
        return out

    def _reject(self, path: Path, why: str) -> None:
        self._rejected[path.name] = why
        rows = [{"frame": k, "reason": v} for k, v in sorted(self._rejected.items())]
        write_text(self.out / REJECTED, _csv(rows))
        self.log(f"{path.name}: skipped, unreadable for {self.config.corrupt_after_s:g} s ({why})")

    def run(self, should_stop: Callable[[], bool] = lambda: False) -> int:
        """Poll until ``should_stop()`` (or the idle/max-frames limits); return frames planned.

        Parameters
        ----------
        should_stop : callable
            Polled between frames and while idle; the watcher returns once it is true.

        Returns
        -------
        int
            Frames planned in all.
        """
        cfg = self.config
        last = self.clock()
        while not should_stop():
            if self.step():
                last = self.clock()
            if cfg.max_frames is not None and len(self.rows) >= cfg.max_frames:
                break
            if cfg.idle_exit_s is not None and self.clock() - last >= cfg.idle_exit_s:
                break
            _sleep(cfg.poll_s, should_stop)
        return len(self.rows)


def _sleep(seconds: float, should_stop: Callable[[], bool]) -> None:
    end = time.monotonic() + seconds
    while not should_stop() and (left := end - time.monotonic()) > 0:
        time.sleep(min(left, 0.05))


def _csv(rows: list[dict[str, str]]) -> str:
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    return buf.getvalue()
