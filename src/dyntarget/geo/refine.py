"""Onboard refinement within a GEO blueprint, and staging of the idle sensor.

:class:`BlueprintGate` pools the look-ahead's pointings under the blueprint's targets
(or targets of its own), releases each target's most valuable pointings once it is
seen whole or its window opens, caps a target only where the next chosen one needs the
time, and sends the idle sensor ahead to the next chosen target the look-ahead would see
too late (:meth:`BlueprintGate.route`). Deciding which pointings are flown and when is
scheduling; it uses the loop's own kinematics (:class:`dyntarget.schedule.Timer`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dyntarget.geo.blueprint import Blueprint, step_s
from dyntarget.geo.seams import PassFrames
from dyntarget.geo.targets import along_of_row
from dyntarget.schedule import Agility, Timer, visibility_windows

MERGE_ROWS = 16
"""Pooled pointings closer than this many WFOV rows (1 km at 64 m) make one look-ahead target."""
RELEASE_LEAD_S = 2.0
"""A target not yet seen whole is released this long before its window opens."""
STAGE_SLACK_S = 5.0
"""The idle sensor is sent ahead to a blueprint target only when waiting for the look-ahead
to see it would lose more than this much of its window, seconds."""


class BlueprintGate:
    """Onboard refinement within a blueprint: pool each target's pointings, fly its best ones.

    Every pointing the look-ahead plans on a plume is *pooled* with its value
    (the look-ahead's red reflectance at the pixel: the intensity utility's own
    proxy) under the blueprint target holding its row, or under a target of the
    look-ahead's own (rows within :data:`MERGE_ROWS` of each other) when no
    chosen blueprint target holds it. A target is *released* once the
    look-ahead has seen all of it (the frame's top row has passed its first
    row) or its field-of-regard window opens within :data:`RELEASE_LEAD_S`,
    whichever is first: its ``k`` most valuable pooled pointings are flown, in
    along-track serpentine order (short slews). ``k`` fills the time from when
    the sensor is free (or the window opens) to the window's end, at the
    target's :func:`~dyntarget.geo.blueprint.step_s`; the blueprint's budgets
    bind only as caps where the next chosen target's planned start needs the
    time (a chosen target keeps at least its budget), and a released target
    gets at least one pointing (the plume is observed). Pointings pooled
    after a release join it at once when at least as valuable as its worst
    released one.

    Parameters
    ----------
    blueprint : dyntarget.geo.Blueprint
        Its targets' ``span`` are strip WFOV rows.
    frames : PassFrames
        The pass's frame plan (rows -> ground, windows).
    agility : dyntarget.schedule.Agility
        The preset.
    stage : send the idle sensor ahead to blueprint targets the look-ahead would see too
        late (:meth:`route`; ``GeoSettings.stage``).
    """

    def __init__(
        self, blueprint: Blueprint, frames: PassFrames, agility: Agility, stage: bool = True
    ) -> None:
        self.blueprint, self.frames, self.agility = blueprint, frames, agility
        self.geometry = replace(frames.geometry, start_s=0.0)
        n = len(blueprint.targets)
        spans = np.array([t.span for t in blueprint.targets], np.float64).reshape(-1, 2)
        self.lo, self.hi = spans[:, 0], spans[:, 1]
        self.mid = spans.mean(axis=1) if n else np.zeros(0)
        self.chosen = blueprint.budget > 0
        # targets: the blueprint's, then the look-ahead's own, appended as found
        self.t_lo: list[float] = [float(v) for v in self.lo]
        self.t_hi: list[float] = [float(v) for v in self.hi]
        self.budget: list[int] = [int(b) for b in blueprint.budget]
        self.planned_start: list[float] = [
            float(s) if b > 0 else math.inf
            for s, b in zip(blueprint.start_s, blueprint.budget, strict=True)
        ]
        self.pool: list[dict[tuple[int, int], float]] = [{} for _ in range(n)]
        self.released: list[float | None] = [None] * n  # the worst value released
        self.done_keys: set[tuple[int, int]] = set()
        self.booked_s = 0.0
        self.booked_at: tuple[float, float] | None = None  # what the sensor tracks then
        self.top = frames.wfov_shape[0]
        self.stats = {
            "targets_released": 0,
            "targets_released_blueprint": 0,
            "look_ahead_targets": 0,
            "pointings_released": 0,
            "pointings_pooled": 0,
            "releases_capped_by_blueprint": 0,
            "caps_lifted": 0,
        }
        self.cap_by: dict[int, int] = {}
        self.stage = stage
        self.staged = np.zeros(n, bool)
        self.frame_tops = np.asarray(frames.tops)  # each frame's top row (when a row is seen)
        self.staged_at = np.full(n, math.inf)  # when the sensor is at a staged target's anchor
        self.stats["staged"] = 0

    def target_of(self, rows: np.ndarray) -> np.ndarray:
        """The chosen blueprint target holding each strip WFOV row (nearest centre; -1: none).

        Parameters
        ----------
        rows : numpy.ndarray
            Strip WFOV rows.

        Returns
        -------
        numpy.ndarray
            Target index per row, -1 outside every chosen target.
        """
        rows = np.asarray(rows, np.float64)
        if not self.chosen.any():
            return np.full(len(rows), -1, np.int64)
        inside = (rows[:, None] >= self.lo[None]) & (rows[:, None] <= self.hi[None])
        inside &= self.chosen[None]
        d = np.where(inside, np.abs(rows[:, None] - self.mid[None]), np.inf)
        best = d.argmin(axis=1)
        return np.where(np.isfinite(d.min(axis=1)), best, -1)

    def _own_target(self, r: int) -> int:
        """The look-ahead's own target for row ``r`` (merged when close), created if none."""
        nb = len(self.blueprint.targets)
        for i in range(len(self.t_lo) - 1, nb - 1, -1):
            if self.t_lo[i] - MERGE_ROWS <= r <= self.t_hi[i] + MERGE_ROWS:
                self.t_lo[i], self.t_hi[i] = min(self.t_lo[i], r), max(self.t_hi[i], r)
                return i
        self.t_lo.append(float(r))
        self.t_hi.append(float(r))
        self.budget.append(0)
        self.planned_start.append(math.inf)
        self.pool.append({})
        self.released.append(None)
        self.stats["look_ahead_targets"] += 1
        return len(self.t_lo) - 1

    def route(
        self,
        t_k: float,
        top: int,
        rows: np.ndarray,
        cols: np.ndarray,
        values: np.ndarray,
        free_s: float,
    ) -> np.ndarray:
        """Pool a frame's pointings and return those to fly now (strip rows and columns).

        Parameters
        ----------
        t_k : the frame's acquisition time, pass seconds.
        top : its top strip WFOV row.
        rows, cols : strip WFOV row and column of each planned pointing (not covered).
        values : each one's value (the look-ahead's red reflectance there).
        free_s : when the sensor is free of what it has committed, pass seconds.

        Returns
        -------
        numpy.ndarray
            ``(m, 2)`` strip ``(row, col)`` of the pointings to fly, in order.
        """
        out: list[tuple[int, int]] = []
        self.top = top
        tgt = self.target_of(rows)
        for r, c, v, i in zip(
            rows.tolist(), cols.tolist(), values.tolist(), tgt.tolist(), strict=True
        ):
            key = (int(r), int(c))
            if key in self.done_keys:
                continue
            j = i if i >= 0 else self._own_target(int(r))
            if key not in self.pool[j]:
                self.stats["pointings_pooled"] += 1
            self.pool[j][key] = float(v)
            worst = self.released[j]
            if worst is not None and v >= worst:  # a late find on a released target
                out.append(key)
                self.done_keys.add(key)
                del self.pool[j][key]
        self.booked_s = max(self.booked_s, free_s)
        out.extend(self._uncap())
        for j in self._due(t_k, top):
            out.extend(self._release(j))
        out.extend(self._stage(t_k))
        return np.array(out, np.int64).reshape(-1, 2)

    def _stage(self, t_k: float) -> list[tuple[int, int]]:  # noqa: PLR0911  (one test a return)
        """Send the idle sensor ahead to the next chosen target the look-ahead has not seen.

        The sensor is idle when nothing pooled waits for release. The next chosen
        blueprint target (earliest planned start) the look-ahead has found nothing on
        yet, and not refuted, gets one pointing at its centre, queued at the last
        frame from which the sensor would still be there when its window opens
        (waiting one more frame would make it late): the slew starts before the
        look-ahead can see the plume, and the pointing holds the sensor there.
        """
        if not self.stage or not self.chosen.any():
            return []
        if any(p and self.released[j] is None for j, p in enumerate(self.pool)):
            return []  # pooled pointings wait for their release: not idle
        t_next = t_k + self.frames.cadence_s
        if self.booked_s > t_next:
            return []  # busy beyond the next frame: decide then
        nb = len(self.blueprint.targets)
        open_ = [(self.planned_start[i], i) for i in range(nb)
                 if self.chosen[i] and self.released[i] is None and not self._refuted(i)]  # fmt: skip
        if not open_:
            return []
        i = min(open_)[1]  # the next one the blueprint visits, not yet observed nor refuted
        if self.staged[i] or self.pool[i]:
            return []  # already staged, or the look-ahead has found it: its release comes
        hw, ww = self.frames.wfov_shape
        row = int(np.clip(round((self.t_lo[i] + self.t_hi[i]) / 2.0), 0, hw - 1))
        t = self.blueprint.targets[i]
        col = int(np.clip(round(t.cross_m / self.geometry.wfov_gsd_m + (ww - 1) / 2.0), 0, ww - 1))
        t_in, t_out, along, cross = self._window(i, np.array([[row, col]], np.float64))
        if not t_in < t_out or t_out <= t_next:
            self.staged[i] = True  # never or no longer reachable: not staged
            return []
        timer = Timer(self.geometry, self.agility)
        timer.t, timer.target = max(self.booked_s, t_next), self.booked_at
        if timer.arrival_one(along, cross, t_in) <= t_in:
            return []  # still in time from the next frame: wait
        # would the look-ahead itself be in time? its release comes when it has seen the
        # target whole, or its window opens: if the sensor can still be there then with
        # no more than STAGE_SLACK_S of the window lost, wait for the look-ahead's word
        whole = np.flatnonzero(self.frame_tops <= self.t_lo[i] - MERGE_ROWS)
        first = np.flatnonzero(self.frame_tops <= self.t_hi[i])
        if len(whole) and len(first):
            t_whole = self.frames.acquired_s(int(whole[0]))
            t_first = self.frames.acquired_s(int(first[0]))
            t_rel = min(t_whole, max(t_first, t_in - RELEASE_LEAD_S))
            timer.t = max(self.booked_s, t_rel + self.frames.cadence_s)
            if timer.arrival_one(along, cross, t_in) <= t_in + STAGE_SLACK_S:
                return []
        timer.t = self.booked_s
        start = timer.arrival_one(along, cross, t_in)
        self.staged[i] = True
        key = (row, col)
        if key in self.done_keys or start >= t_out:
            return []
        self.done_keys.add(key)
        self.staged_at[i] = start
        self.booked_s = start + self.agility.dwell_s
        self.booked_at = (along, cross)
        self.stats["staged"] += 1
        return [key]

    def _window(self, j: int, keys: np.ndarray | None = None) -> tuple[float, float, float, float]:
        """``(t_in, t_out, along, cross)`` of target ``j``'s pooled pointings' centre.

        ``keys``: these strip ``(row, col)`` instead of the pooled ones.
        """
        if keys is None:
            keys = np.array(list(self.pool[j].keys()), np.float64).reshape(-1, 2)
        if len(keys) == 0:
            r = (self.t_lo[j] + self.t_hi[j]) / 2.0
            keys = np.array([[r, (self.frames.wfov_shape[1] - 1) / 2.0]])
        along = along_of_row(self.frames, keys[:, 0])
        cross = (keys[:, 1] - (self.frames.wfov_shape[1] - 1) / 2.0) * self.geometry.wfov_gsd_m
        t_in, t_out = visibility_windows(self.geometry, self.agility, along, cross)
        return float(t_in.max()), float(t_out.min()), float(along.mean()), float(cross.mean())

    def _due(self, t_k: float, top: int) -> list[int]:
        due = []
        for j in range(len(self.t_lo)):
            if self.released[j] is not None or not self.pool[j]:
                continue
            # the look-ahead is past its first row, or this is the pass's last frame
            seen = top <= self.t_lo[j] - MERGE_ROWS or top <= int(self.frame_tops[-1])
            if seen or self._window(j)[0] - t_k <= RELEASE_LEAD_S:
                due.append(j)
        return sorted(due, key=lambda j: -self.t_hi[j])  # nearest to nadir first

    def _refuted(self, i: int) -> bool:
        """Whether the look-ahead has seen all of target ``i`` and found nothing on it."""
        return (
            self.released[i] is None and not self.pool[i] and self.top <= self.t_lo[i] - MERGE_ROWS
        )

    def _release(self, j: int, more: bool = False) -> list[tuple[int, int]]:
        t_in, t_out, along, cross = self._window(j)
        timer = Timer(self.geometry, self.agility)  # the loop's kinematics
        timer.t, timer.target = self.booked_s, self.booked_at
        start = timer.arrival_one(along, cross, t_in)  # the slew there included
        step = float(step_s(self.geometry, self.agility, np.array([along]),
                                np.array([cross]), np.array([start]), 1.0)[0])  # fmt: skip
        limit = t_out
        # the next chosen blueprint target (not this one) that needs the time: not yet
        # started, and not seen whole by the look-ahead with nothing on it
        # a target the sensor was sent ahead to (staged) needs it from its anchor on, and
        # keeps it: nothing else is flown that would make the sensor leave it
        nxt = [(s, i) for i, s in enumerate(self.planned_start)
               if i != j and self.released[i] is None and not self._refuted(i)
               and (start < s < limit or self._anchor(i) < limit)]  # fmt: skip
        held = False
        if nxt:
            own = start + (0 if more else self.budget[j]) * step  # a chosen target keeps its budget
            s_next, i_next = min((min(s, self._anchor(i)), i) for s, i in nxt)
            held = math.isfinite(self._anchor(i_next))
            capped = max(s_next, own)
            if capped < limit:
                limit = capped
                self.cap_by[j] = i_next
                self.stats["releases_capped_by_blueprint"] += 1
        if step <= 0.0:  # unlimited agility: a pointing takes no time, the whole pool fits
            k = len(self.pool[j])
        else:
            k = int((limit - start) / step) if limit > start else 0
        k = k if more or held else max(1, k)  # a new target gets at least one pointing
        pool = self.pool[j]
        best = sorted(pool.items(), key=lambda kv: -kv[1])[:k]
        if not more or best:
            self.released[j] = best[-1][1] if best else -math.inf
        keys = sorted(
            (kv[0] for kv in best), key=lambda rc: (-rc[0], rc[1] if rc[0] % 2 else -rc[1])
        )
        for key in keys:
            del pool[key]
            self.done_keys.add(key)
        if keys:
            self.booked_s = start + len(keys) * step
            self.booked_at = (along, cross)
        self.stats["targets_released"] += int(not more)
        self.stats["targets_released_blueprint"] += int(
            not more and j < len(self.blueprint.targets)
        )
        self.stats["pointings_released"] += len(keys)
        return keys

    def _anchor(self, i: int) -> float:
        """When the sensor is at target ``i``'s anchor (``inf``: not staged)."""
        return float(self.staged_at[i]) if i < len(self.staged_at) else math.inf

    def _uncap(self) -> list[tuple[int, int]]:
        """More pointings for targets capped by a blueprint target the look-ahead refuted since."""
        out: list[tuple[int, int]] = []
        for j, i in list(self.cap_by.items()):
            if self._refuted(i):
                del self.cap_by[j]
                self.stats["caps_lifted"] += 1
                out.extend(self._release(j, more=True))
        return out

    def report(self) -> dict[str, int]:
        """What the refinement did (for summary.json).

        Returns
        -------
        dict
            Targets released (all, the blueprint's), the look-ahead's own targets,
            pointings pooled and released, releases capped by the blueprint.
        """
        return dict(self.stats)
