"""Frame sequences with acquisition times, and the truth at any time.

A :class:`FrameSequence` holds look-ahead frames (:class:`~dyntarget.scene.Scene`
objects on one grid) taken at ``times`` (seconds after ``epoch``, the
acquisition time of ``t = 0`` as ISO-8601 UTC), and optionally a *truth
provider*: a callable ``t -> Scene`` giving the labelled high-resolution scene
at any time ``t`` (for synthetic worlds it renders the world; see
:class:`dyntarget.synth.dynamic.TruthCache`). Without one, the truth at ``t``
is the labelled frame last acquired at or before ``t``.

Time inside the library is seconds from ``t = 0``; ISO-8601 UTC at the edges
(files), see :func:`parse_time` and :func:`format_time`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.scene import Scene

TruthProvider = Callable[[float], Scene]
"""``t`` (s after the epoch) -> the labelled high-resolution scene at that time."""


def parse_time(text: str) -> datetime:
    """Parse ISO-8601 (``2026-01-01T00:00:00Z``) or TIFF ``YYYY:MM:DD HH:MM:SS``; naive = UTC.

    Parameters
    ----------
    text : str
        The time.

    Returns
    -------
    datetime.datetime
        Timezone-aware, in UTC.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For anything else.

    Examples
    --------
    >>> parse_time("2026-01-01T00:01:30Z").isoformat()
    '2026-01-01T00:01:30+00:00'
    >>> parse_time("2026:01:01 00:01:30").minute
    1
    """
    if not isinstance(text, str):
        raise InvalidParameterError(f"time: expected an ISO-8601 string, got {text!r}")
    s = text.strip()
    try:
        if len(s) >= 19 and s[4] == ":" and s[7] == ":":  # TIFF DateTime
            dt = datetime.strptime(s[:19], "%Y:%m:%d %H:%M:%S")
        else:
            dt = datetime.fromisoformat(s)
    except ValueError:
        raise InvalidParameterError(
            f"time: expected ISO-8601 UTC such as 2026-01-01T00:00:00Z, got {text!r}"
        ) from None
    return dt.replace(tzinfo=UTC) if dt.tzinfo is None else dt.astimezone(UTC)


def format_time(epoch: str | datetime, seconds: float = 0.0) -> str:
    """ISO-8601 UTC (``...Z``, millisecond precision) of ``epoch + seconds``.

    Parameters
    ----------
    epoch : str or datetime.datetime
        The reference time (a string as :func:`parse_time` reads).
    seconds : float
        Seconds after ``epoch``.

    Returns
    -------
    str
        ``YYYY-MM-DDTHH:MM:SS.sssZ``.

    Examples
    --------
    >>> format_time("2026-01-01T00:00:00Z", 90.5)
    '2026-01-01T00:01:30.500Z'
    """
    dt = parse_time(epoch) if isinstance(epoch, str) else epoch
    dt = dt + timedelta(seconds=float(seconds))
    return dt.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def seconds_between(epoch: str | datetime, when: str | datetime) -> float:
    """Seconds from ``epoch`` to ``when``.

    Parameters
    ----------
    epoch, when : str or datetime.datetime
        The two times (strings as :func:`parse_time` reads).

    Returns
    -------
    float
        Seconds, negative when ``when`` is before ``epoch``.

    Examples
    --------
    >>> seconds_between("2026-01-01T00:00:00Z", "2026-01-01T00:00:30Z")
    30.0
    """
    a = parse_time(epoch) if isinstance(epoch, str) else epoch
    b = parse_time(when) if isinstance(when, str) else when
    return (b - a).total_seconds()


@dataclass(frozen=True, eq=False)
class FrameSequence:
    """Look-ahead frames on one grid with their acquisition times.

    Parameters
    ----------
    frames : sequence of Scene
        Frames of the same shape, GSD and georeferencing, in time order.
    times : array of float
        Acquisition times, seconds after ``epoch``, strictly increasing.
    epoch : str or None
        ISO-8601 UTC time of ``t = 0`` (``None``: times are relative only).
    id : str
        Sequence identifier (the directory name on disk).
    truth : callable or None
        Truth provider ``t -> Scene`` (labelled, high resolution).
    meta : dict
        Free JSON-able metadata (e.g. ``{"world": spec, "wind": {...}}``).

    Examples
    --------
    >>> f = [Scene(np.zeros((4, 8, 8), np.float32), label=np.eye(8, dtype=bool), id=f"f{i}")
    ...      for i in range(2)]
    >>> seq = FrameSequence(f, [0.0, 10.0], epoch="2026-01-01T00:00:00Z", id="s")
    >>> len(seq), seq.shape, seq.truth_at(12.0).id
    (2, (8, 8), 'f1')
    """

    frames: Sequence[Scene]
    times: Any
    epoch: str | None = None
    id: str = "sequence"
    truth: TruthProvider | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        frames = tuple(self.frames)
        if not frames:
            raise InvalidSceneError(f"sequence {self.id!r}: no frames")
        if not all(isinstance(f, Scene) for f in frames):
            raise InvalidParameterError(f"sequence {self.id!r}: frames must be Scene objects")
        times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        if len(times) != len(frames):
            raise InvalidSceneError(
                f"sequence {self.id!r}: {len(times)} time(s) for {len(frames)} frame(s)"
            )
        if not np.isfinite(times).all():
            raise InvalidSceneError(f"sequence {self.id!r}: times must be finite seconds")
        if len(times) > 1 and not (np.diff(times) > 0).all():
            raise InvalidSceneError(
                f"sequence {self.id!r}: times must be strictly increasing, got {times.tolist()}"
            )
        first = frames[0]
        for f in frames[1:]:
            if f.shape != first.shape:
                raise InvalidSceneError(
                    f"sequence {self.id!r}: frame {f.id!r} has shape {f.shape}, "
                    f"expected {first.shape} like frame {first.id!r}"
                )
            if f.gsd != first.gsd or f.crs != first.crs or f.transform != first.transform:
                raise InvalidSceneError(
                    f"sequence {self.id!r}: frame {f.id!r} is not on the grid of frame "
                    f"{first.id!r} (GSD, CRS and transform must match)"
                )
        if self.epoch is not None:
            object.__setattr__(self, "epoch", format_time(self.epoch))
        if self.truth is not None and not callable(self.truth):
            raise InvalidParameterError("truth: expected a callable t -> Scene")
        times.setflags(write=False)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "times", times)

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of every frame."""
        return self.frames[0].shape

    @property
    def gsd(self) -> float | None:
        """Ground sample distance of the frames, metres per pixel (the first frame's; ``None`` if unknown)."""
        return self.frames[0].gsd

    def frame_at(self, t: float) -> Scene:
        """The frame last acquired at or before ``t`` (the first frame before it).

        Parameters
        ----------
        t : float
            Time, seconds after the sequence's epoch.

        Returns
        -------
        dyntarget.scene.Scene
            The frame.

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For a time that is not finite.
        """
        if not math.isfinite(t):
            raise InvalidParameterError(f"t: expected finite seconds, got {t!r}")
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        return self.frames[max(i, 0)]

    def truth_at(self, t: float) -> Scene:
        """The labelled scene at time ``t``: the truth provider's, else :meth:`frame_at`'s.

        Parameters
        ----------
        t : float
            Time, seconds after the sequence's epoch.

        Returns
        -------
        dyntarget.scene.Scene
            A labelled scene.

        Raises
        ------
        dyntarget.errors.InvalidSceneError
            Without a truth provider, when the frame has no label.
        """
        if self.truth is not None:
            return self.truth(float(t))
        scene = self.frame_at(t)
        if scene.label is None:
            raise InvalidSceneError(
                f"sequence {self.id!r}: no truth provider and frame {scene.id!r} has no label"
            )
        return scene

    def up_to(self, t: float) -> FrameSequence:
        """The frames acquired at or before ``t`` (at least the first).

        Parameters
        ----------
        t : float
            Time, seconds after the sequence's epoch.

        Returns
        -------
        FrameSequence
            A copy holding those frames and their times.
        """
        n = max(int(np.searchsorted(self.times, t, side="right")), 1)
        return replace(self, frames=self.frames[:n], times=self.times[:n])

    def to_wfov(self, factor: int) -> FrameSequence:
        """Every frame downsampled to the WFOV grid (the truth provider stays high-res).

        Parameters
        ----------
        factor : int
            High-resolution pixels per WFOV pixel along each axis.

        Returns
        -------
        FrameSequence
            A copy with the downsampled frames.
        """
        return replace(self, frames=tuple(f.to_wfov(factor) for f in self.frames))

    def time_iso(self, i: int) -> str | None:
        """ISO-8601 UTC acquisition time of frame ``i`` (``None`` without an epoch).

        Parameters
        ----------
        i : int
            Frame index.

        Returns
        -------
        str or None
            ``YYYY-MM-DDTHH:MM:SS.sssZ``.
        """
        return None if self.epoch is None else format_time(self.epoch, float(self.times[i]))
