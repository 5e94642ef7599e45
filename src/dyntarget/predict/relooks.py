"""Plume-top heights measured on a pass: re-looks of the look-ahead, their cost, the estimates.

A 3D world's plumes appear displaced by their parallax in the look-ahead frames
(:mod:`dyntarget.parallax`). The pass loop (:mod:`dyntarget.fly.loop`) corrects its
NFOV aim for it with a height per plume; in ``"estimated"`` mode that height is
measured here, from the look-ahead stream itself.

Model (what is and is not modelled):

* **Plumes.** The components of a frame's denoised mask within :data:`GROUP_PX`
  pixels of each other (a fragmented envelope) are one plume when they hold at least
  :data:`MIN_PLUME_PX` WFOV pixels. It is the plume already tracked when it lies within
  :data:`MATCH_PX` pixels of the apparent footprint of a tracked plume on the strip's WFOV
  grid (the look-ahead's parallax changes by a fraction of a pixel between overlapping
  frames); otherwise it is new, and measured at once (the frame's own pointings need its
  height). A new plume whose upwind end (where its vent is) is cut by the frame's top
  edge (the side ahead) is measured again on the first frame that sees that end, and
  that estimate replaces the first (sharing its re-looks where their windows hold it).
* **Re-looks.** For a new plume of at least :data:`MIN_RELOOK_PX` pixels the
  look-ahead re-points at it when its apparent centre (as frame ``k`` saw it) is
  ``relook_km[i]`` ahead of the nadir, one re-look per distance (:data:`RELOOK_KM`: one,
  300 km ahead, by default), each preceded where needed by re-looks nearer in time
  (at most :data:`MAX_INSERTED`) whose searches still fit in
  the frame: a frame holds fewer rows than a long baseline's uncertainty asks for (the
  search spans 0.2 to 1.8 times a guessed height), and a shorter baseline narrows the
  height enough for the next. A re-look is taken at ``t_k + (along_k -
  d_i) / v``. A plume first seen already nearer than every ``relook_km[i]`` (in a frame
  taken late, catching up) is re-looked at ``relook_km[i]`` scaled by where it was seen
  over the look-ahead distance (300 km of a 500 km look, seen 280 km ahead: 168 km).
  A re-look sees a window of the frame's size on the strip, centred where
  the plumes still measured will appear by the heights known so far (each plume's own:
  the prior or guess in the first re-look, its own fit after), clipped to the strip;
  where they do not fit in one window, where the largest will. Where a plume's search
  asks more than half a frame either side of its centre (a narrowing re-look not taken,
  the look-ahead busy, or none that narrows it), the re-look is a mosaic instead: frames
  enough (at most ``relook_frames``, :data:`RELOOK_FRAMES`) to hold the envelope anywhere
  in the searches, each further down the strip (nearer the nadir) by the frame less the
  tallest envelope and two margins, each taken after the last by a pitch step on the
  slew model, a settle and an exposure (as a frame taken late); the plume is searched
  for in every frame that can hold it, nearest the search's centre first, and measured
  at the time of the frame it is found in. No re-look is taken once
  none of the frame's plumes is left to measure. It occupies the look-ahead for ``relook_s`` (the pitch
  change there and back on the agility preset's slew model, two settles and one
  exposure: :func:`relook_seconds`); a regular frame due meanwhile is taken late
  (below) or, without catching up, not at all (the loop records it dropped) - that is the
  cost. A re-look wanted while the look-ahead is on another (between that one's exposure
  and its return to the regular pitch) is taken straight after it, without going back
  in between: the look-ahead slews from the last re-look's pitch to the next's (none
  between two at the same distance: the pitch of a look a fixed distance ahead does not
  change), settles, and holds there until it is wanted; their window then ends with one
  slew back, from the last (:meth:`HeightTracker._straight_after`). Two ``slow`` re-looks
  300 km ahead 10 s apart keep the look-ahead 42.6 s instead of 65.3 s, and the second is
  taken when wanted instead of 22.6 s late. Otherwise (a re-look's duration given,
  ``relook_s``; a mosaic; a window that would run into a later one) a re-look that would
  start while the look-ahead is busy with another waits for it, at most
  :data:`RELOOK_WAIT` times its own duration and while its plumes are still ahead of the
  nadir (a ``slow`` re-look 300 km ahead lasts 32.6 s: four of them would reach past it),
  else it is not taken: a plume not re-looked
  at gets no height and is not flown, and the wait costs the look-ahead no more than the
  re-look itself does. The plumes of one frame share its re-looks, and a
  plume of a later frame shares a re-look already taken within one re-look's duration of the time it wants
  whose window holds it (a margin included); a plume never shares a re-look it has
  looked at already (before, a ``slow`` plume's nearer re-looks, within 32.6 s of its
  first, reused it: the same look counted two or three times).
* **Catching up** (:meth:`HeightTracker.take`; ``catch_up=False``: every regular frame
  due during a re-look is lost, as before). The look-ahead stares at its regular pitch,
  ``look_ahead_m`` ahead, and a frame on time costs it nothing. A frame due while it
  re-looks (or while it is still behind) is taken late, from nearer: the look-ahead pitches
  from where it last looked to that frame's ground as it is by then (the agility preset's
  slew model), settles and exposes (``dwell_s``), then goes on to the next, until a
  frame's time comes before the look-ahead is ready again: it is back on its pitch. It
  catches up only where it gains on the ground: where a frame taken late (a whole frame's
  pitch step, settling, exposure) costs less than the time the frame's ground takes to
  pass (:func:`gains_on_ground`: ``fast`` on frames of about 1.7 km or more at the default
  geometry; ``slow``, which settles for a second, only on frames of 35.8 km or more: on
  shorter ones it holds the re-look's pitch instead by default, below, or loses the frames
  due during a re-look). While behind,
  a frame whose ground the last frame seen (:meth:`HeightTracker.seen`: taken and planned)
  and the next one cover between them (frames overlap) is skipped, unless the next would
  come too late. A frame whose centre would already be within the NFOV's forward reach
  (its field of regard; the nadir without one) when taken is lost. A re-look booked later
  waits for the frame the look-ahead is taking. A late frame's plumes are seen at a smaller
  view angle: tracking looks for a tracked plume up to :data:`TRACK_HEIGHT_M`'s change of
  parallax nearer the nadir (so a new plume that near a tracked one, on its nadir side, is
  taken for it), and a new plume is measured from that look's own geometry.
* **Holding** (``hold``; by default where catching up is asked for and the look-ahead
  cannot gain on the ground, as ``slow``: :func:`holds_relooks`; ``fly --relook-hold``
  asks for it anywhere, ``--no-relook-hold`` refuses it; the look-ahead then never catches
  up). Going back from a re-look to the regular pitch loses the frames due
  meanwhile (``slow``: 32.6 s of them for a re-look 300 km ahead). Held instead, the
  look-ahead stays at a re-look's pitch, ``d`` ahead, and takes every later frame there, on
  the same cadence, ``(look_ahead_m - d) / v`` after it was due (28.3 s for 300 km): its
  ground, not yet seen, is then ``d`` ahead. Nothing is lost but lead: coming nearer, the
  look-ahead only waits while ground it has already seen passes. A one-frame re-look on
  the slew model is held when it is nearer than the pitch held then, not nearer than the
  NFOV's field of regard begins (:func:`_reach_m`: frames from there are not too late) and
  no re-look is booked after it (:meth:`HeightTracker._holds`); its window is the slew
  there, a settle and the exposure (no slew back), and a frame the look-ahead would have
  taken from the window's start on is held there, unless it was asked about already (then
  lost to the window). Each hold comes nearer (a plume's narrowing re-looks, 450 then 365
  then 300 km ahead on 2 km frames, are each held in turn), and a frame not yet taken
  where the look-ahead held before is taken where it holds now (:meth:`HeightTracker._lag_s`).
  A re-look from a held pitch slews from it and back to it; a plume seen in a held frame
  is re-looked at the asked distances scaled, as in a frame taken late (seen 300 km ahead:
  180 km, nearer than the field of regard begins, so not held: the frames due meanwhile
  are lost).
* **Measurement: the envelope.** A plume attached to its vent keeps its envelope (the
  mask's shape) at the vent while the wind blows its texture through it; so the
  envelope is measured, not the texture: the displacement between frame ``k``'s mask
  (before denoising) and each re-look's mask (the oracle's, or the pass's classifier on
  the re-look's image) is :func:`dyntarget.predict.height.envelope_disparity` (masked
  normalised correlation, sub-pixel), on the plume's upwind part (:data:`UPWIND_SHARE`
  of its length along the wind; the downwind end grows between the looks) and a margin
  of background. The looks' apparent positions (the component's centroid, moved by each
  displacement) and the nadir at each look's time go to
  :func:`~dyntarget.predict.height.fit_height` with a **zero-drift prior** (sigma
  :data:`ENVELOPE_DRIFT_SIGMA_MPS`). Where the three looks' track is curved beyond their
  noise (:data:`RISE_TEST_PX`), and re-looks at two or more distances were asked for
  (``relook_km``; not the default), the top may be rising: the fit adds a linear rise, kept
  when it is positive beyond :data:`RISE_SIGNIFICANCE` of its standard deviations and
  fits better, which gives ``rise_mps`` and the height at frame ``k``'s time (the aim
  then follows the rise). A young plume whose envelope changes its shape between the
  looks can pass that test without rising (a known limit). A top rising faster than the
  approach brings it nearer appears to move *away* from the nadir between looks, where a
  steady top's search never looks: asked to allow for a rise (``max_rise_mps``), a re-look
  that does not find the plume where a steady top would be searches again where the rise
  its last move implies puts it (:meth:`HeightTracker._following`), else anywhere a top
  rising that fast could be, and the re-look's window reaches into the room it has left
  beyond where the guessed heights put the plumes, at the expense of the steady search's
  far side (on long passes of short frames, wrong matches: ``docs/plumes-3d.md``). Positions are given a standard deviation of :data:`POSITION_SIGMA_PX` WFOV
  pixels (the fit scales its covariance up when the residuals say more). Everything is
  measured at the look-ahead's WFOV resolution.
* **When it is known.** The simulator renders a plume's re-looks as soon as its frame
  is planned (the world is known), but each estimate is usable only from its re-look's
  time + the measured compute time of the measurement and fit: the first re-look gives
  a two-look estimate (:attr:`Plume.stages`), the last the final one (from ``t_e``);
  the NFOV's pointings aim with the latest estimate usable when each is flown, earlier
  ones with the prior; without a prior they wait for the estimate
  (:meth:`HeightTracker.known_window`), and a plume with none is not flown. A plume lost by a later re-look keeps the
  estimate of the looks that saw it. The schedule is decided once at the frame's plan
  time with the aim each pointing will have when flown; a flight system would re-plan
  when an estimate arrives.
* **Failures.** A plume too small for a re-look, one whose re-looks the look-ahead
  had no time for, one whose envelope is not found in a re-look (no match above
  :data:`~dyntarget.predict.height.MIN_ENVELOPE_NCC`, or the best on the search's
  edge), a degenerate fit or one whose standard deviation exceeds :data:`MAX_SIGMA_M`
  keeps the prior (``height_source`` ``"prior"``) or nothing (``"none"``), with one
  line on stderr naming the plume and the reason. So does a plume whose later re-look
  finds its best match on the edge of the search its earlier looks' fit allows (0.7 to
  1.3 times the fitted height): the fit is contradicted (:meth:`HeightTracker._conclude`);
  a plume a later re-look does not find at all keeps the fit of the looks that saw it.
* **Known limits:** the loop does not tell a detached cloud (which drifts with the wind
  as a whole) from a vent-attached plume: it is fitted with the zero-drift prior too,
  and an along-track drift ``v`` biases its height by about ``v dt / (tan_0 - tan_2)``
  (60 m per m/s at the default geometry, ``docs/plumes-3d.md``); a cross-track drift is
  measured by the looks. A plume cut by the strip's side keeps a cut envelope.
* **Not modelled:** the plume's change of shape between looks beyond a translation (and
  the growth of its downwind end, left out of the match), re-looks planned around the
  regular frames (they are booked when a plume is seen, and the frames make way), and a
  late frame's stretched footprint (it is rendered on the regular frame's grid).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from functools import partial

import cv2
import numpy as np

from dyntarget import defaults, parallax
from dyntarget.errors import InvalidParameterError
from dyntarget.predict.height import (
    EDGE_MATCH,
    Disparity,
    HeightFit,
    Look,
    envelope_disparity,
    fit_height,
)
from dyntarget.schedule import Agility, OrbitGeometry
from dyntarget.schedule.kinematics import EARTH_RADIUS_M, angle_between_deg, look_vectors

MIN_PLUME_PX = 6
"""Fewest WFOV pixels of a plume (its components grouped, :data:`GROUP_PX`) tracked."""
MIN_RELOOK_PX = 6
"""Fewest WFOV pixels of a plume worth a re-look (its envelope is measured on its mask)."""
MATCH_PX = 4
"""A component within this many WFOV pixels of a tracked plume's footprint is that plume."""
GROUP_PX = 3
"""Components of one frame within this many WFOV pixels of each other are one plume."""
UPWIND_SHARE = 0.5
"""Share of a plume's length along the wind (from its upwind end) whose envelope is matched."""
MARGIN_PX = 6
"""Margin of background around a plume's mask compared by the envelope match, WFOV px."""
RISE_TEST_PX = 0.3
"""Root mean square residual (WFOV px) of the three looks' fit above which a rise is fitted."""
SPREAD_GUESS = 0.8
"""Relative uncertainty of a guessed height searched over (0.2 to 1.8 times the guess)."""
SPREAD_FITTED = 0.3
"""Relative uncertainty searched over once a plume's own looks have fitted a height."""
MAX_INSERTED = 3
"""Most re-looks added before an asked one so that each search fits in the frame."""
RELOOK_FRAMES = defaults.RELOOK_FRAMES
"""Most frames one re-look takes (a mosaic down the strip) where its search asks more rows
than one frame holds."""
RISE_SIGNIFICANCE = 1.5
"""A fitted rise is kept only above this many of its standard deviations (a one-sided
test at about 93 %): on the heights benchmark, smaller rises fitted to still columns
(an envelope changing its shape between the looks) cost more than they gave."""
POSITION_SIGMA_PX = 0.5
"""Standard deviation of a look's measured position, WFOV pixels."""
ENVELOPE_DRIFT_SIGMA_MPS = 1.0
"""Standard deviation of the zero-drift prior of a vent-attached plume's envelope, m/s
per axis (the envelope stays at the vent; its downwind end grows, its edges flicker)."""
MAX_SIGMA_M = 1500.0
"""A fit less certain than this (one sigma, metres) is not used: the looks disagree
(e.g. the flow followed something else than the plume in a re-look)."""
GUESS_HEIGHT_M = 8500.0
"""Height guessed for the disparity's search when no prior is given (mid-range of 2-15 km)."""
TRACK_HEIGHT_M = 20_000.0
"""Highest plume top the tracker allows for when it matches a frame taken late: such a
frame sees its plumes from nearer, displaced towards the nadir by up to this height's
change of parallax, and a plume tracked on an earlier frame is looked for that far."""
RELOOK_WAIT = 4.0
"""Longest wait for a busy look-ahead, in the waiting re-look's own durations (``fast`` 300
km ahead: 3.8 s each). A plume whose re-looks are not taken gets no height and is not
flown; where three re-looks per plume keep the look-ahead busy (2 km frames), a longer
wait measures plumes a shorter one leaves without a height; ``docs/plumes-3d.md`` compares
waits of 1, 2, 4 and 10 (``benchmarks/parallax_targets.py --relook-wait``)."""
DEFER_CUT_BELOW_M = 4000.0
"""Look-ahead frames shorter than this along track, m, hold the pointings they plan on a
plume their top edge cuts by default (:func:`defers_cut`). Measured (``docs/plumes-3d.md``):
on 2 km frames, where most plumes a frame shows are cut, holding them kept 94 % (``fast``)
and 96 % (``slow``) of the flat utility against 90 % and 90 % (48 strips); on 4 km frames
(4 short strips) 1.01 and 1.20 against 0.99 and 1.21, on 8 km frames (2 strips) 0.99 and
1.03 against 0.97 and 0.98: too few strips to change the default there."""
RELOOK_KM = (300.0,)
"""Default re-look distances ahead of the nadir, km: one re-look, 300 km ahead (from
500 km, tan(theta) falls by 0.468: the longest baseline the NFOV's lead leaves). Two
(``(400.0, 300.0)``) also measure a rise and give a two-look estimate earlier, at twice
the look-ahead time; on the targeting benchmark they kept 75 % (``fast``) and 49 %
(``slow``) of the flat utility against 92 % and 95 % with one (``docs/plumes-3d.md``): a
young plume's changing envelope is taken for a rise."""


def relook_seconds(geometry: OrbitGeometry, agility: Agility, distance_m: float) -> float:
    """Look-ahead time one re-look at ``distance_m`` ahead of the nadir costs, seconds.

    The look-ahead pitches from its usual direction (``look_ahead_m`` ahead) to the
    re-look's and back, on the preset's rest-to-rest slew model
    (:meth:`~dyntarget.schedule.Agility.slew_time_one`), settling after each slew
    (``settle_s`` twice), and exposes one frame (``dwell_s``).

    Parameters
    ----------
    geometry : dyntarget.schedule.OrbitGeometry
        The orbit (altitude, look-ahead distance).
    agility : dyntarget.schedule.Agility
        The pointing preset.
    distance_m : float
        Ground distance ahead of the nadir of the re-look, metres.

    Returns
    -------
    float
        Seconds the look-ahead is busy.

    Examples
    --------
    500 km up, 500 -> 300 km ahead is a pitch change of 13.27 deg (41.61 to 28.34 deg off
    nadir); ``fast`` (10 deg/s, 20 deg/s^2) slews it in 13.27 / 10 + 10 / 20 = 1.83 s,
    twice, plus 2 x 0.05 s settling and a 0.05 s exposure (``slow``: 32.6 s):

    >>> from dyntarget.schedule import get_agility
    >>> round(relook_seconds(OrbitGeometry(), get_agility("fast"), 300e3), 2)
    3.8
    """
    if not (math.isfinite(distance_m) and distance_m > 0):
        raise InvalidParameterError(f"re-look distance: expected metres > 0, got {distance_m!r}")
    return 2.0 * _pitch_back_s(geometry, agility, distance_m) + agility.dwell_s


def _pitch_back_s(geometry: OrbitGeometry, agility: Agility, distance_m: float) -> float:
    """Seconds to slew between a look ``distance_m`` ahead and the regular pitch (either
    way: the slew model is symmetric) and settle."""
    slew = agility.slew_time_one(_pitch_deg(geometry, geometry.look_ahead_m, distance_m))
    return slew + agility.settle_s


@dataclass(frozen=True)
class HeightEstimate:
    """One plume's top height as the pass measured it (or took it from the prior).

    Parameters
    ----------
    plume_id : int
        The plume, numbered over the pass from 1 (not the truth's id).
    x_px, y_px : float
        Ground position of the plume top (parallax-corrected), strip high-resolution
        pixels (the apparent position where no height is known).
    top_height_m, top_height_sigma_m : float or None
        Top height above sea level and its standard deviation, metres (``None``: none).
    rise_mps : float or None
        Rise velocity where the looks showed one (``None``: not measured).
    height_source : str
        ``"estimated"``, ``"prior"`` or ``"none"``.
    true_height_m : float or None
        The true top height of the vent or cloud it belongs to, where the world knows it.
    frame : int
        The frame that first saw it.
    relooks : int
        Re-looks taken of it.
    ready_s : float or None
        When the estimate was usable (last re-look + compute), seconds into the pass.
    reason : str
        Why no height was estimated (empty when estimated).
    """

    plume_id: int
    x_px: float
    y_px: float
    top_height_m: float | None
    top_height_sigma_m: float | None
    rise_mps: float | None
    height_source: str
    true_height_m: float | None
    frame: int
    relooks: int
    ready_s: float | None
    reason: str = ""

    def as_dict(self) -> dict[str, object]:
        """The estimate as plain JSON values.

        Returns
        -------
        dict
            Field name to value.
        """
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class Relook:
    """A re-look the look-ahead took: when, which rows (strip WFOV), what it saw.

    Parameters
    ----------
    t_s : float
        Pass time of the re-look, seconds.
    duration_s : float
        Look-ahead time it took, seconds (one taken straight after another: the time it
        added to that one's window).
    top : int
        Its window's top strip WFOV row (the window has the frame's size).
    mask : numpy.ndarray or None
        ``(H_f, W)`` plume mask (fraction 0..1) it showed.
    frames : list of tuple
        Every frame it took, ``(t_s, top, mask)`` in order: the first is the one above; a
        mosaic adds frames further down the strip (nearer the nadir), each later.
    ahead_m : float or None
        Ground distance ahead of the nadir it looked, metres (``None``: not on record; a
        re-look is then not followed straight by another).
    held : bool
        The look-ahead stayed at its pitch after it (:meth:`HeightTracker._holds`).
    """

    t_s: float
    duration_s: float
    top: int
    mask: np.ndarray | None = None
    frames: list[tuple[float, int, np.ndarray | None]] = field(default_factory=list)
    ahead_m: float | None = None
    held: bool = False

    def __post_init__(self) -> None:
        if not self.frames:
            self.frames = [(self.t_s, self.top, self.mask)]


@dataclass
class Plume:
    """A plume tracked over the pass (apparent footprint, re-looks, estimate).

    Parameters
    ----------
    pid : int
        Its number over the pass, from 1.
    frame : int
        The frame it was measured on (the first that saw its upwind end).
    t_k : float
        That frame's acquisition time, pass seconds.
    rows, cols : numpy.ndarray
        Strip WFOV pixels of its mask in that frame.
    relooks : list of Relook
        The re-looks that saw it.
    height_m, sigma_m : float or None
        Its height and standard deviation (or the prior), metres.
    ground_xy : tuple of float or None
        Strip WFOV px of the top's ground position at the first frame's time.
    ready_s : float
        When its estimate is usable, pass seconds (``inf``: never).
    source : str
        ``"estimated"``, ``"prior"`` or ``"none"``.
    reason : str
        Why no height was estimated.
    true_id : int
        The truth's id (unused by the tracker).
    pending : bool
        Measured provisionally (its upwind end cut by the frame's edge): measured again
        on the first frame that sees that end, whose index, time and view replace
        ``frame``, ``t_k``, ``rows`` and ``cols``, and whose estimate replaces this one.
    rise_mps : float or None
        The top's measured rise, m/s (``None``: not measured).
    stages : list of tuple of float
        ``(ready_s, height_m)`` of the estimates made on the way, one per re-look whose
        looks so far fitted (the first from two looks): aimed with from ``ready_s`` until
        the final estimate is ready.
    cut : Plume or None
        With ``keep_cut``, the plume as its cut view measured it (an estimate), kept when
        it is measured again on a whole view, in case that gives none.
    """

    pid: int
    frame: int
    t_k: float
    rows: np.ndarray
    cols: np.ndarray
    relooks: list[Relook] = field(default_factory=list)
    height_m: float | None = None
    sigma_m: float | None = None
    ground_xy: tuple[float, float] | None = None
    ready_s: float = math.inf
    source: str = "none"
    reason: str = ""
    true_id: int = 0
    pending: bool = False
    rise_mps: float | None = None
    stages: list[tuple[float, float]] = field(default_factory=list)
    cut: Plume | None = None


@dataclass(frozen=True)
class Geometry3D:
    """Where the spacecraft is during a pass, on the strip's WFOV grid.

    Parameters
    ----------
    geometry : dyntarget.schedule.OrbitGeometry
        The orbit and look-ahead.
    wfov_shape : tuple of int
        The strip's WFOV shape ``(rows, cols)``.
    frame_px : int
        Frame rows.
    top0 : int
        The first frame's top strip WFOV row.
    factor : int
        High-resolution pixels per WFOV pixel.
    """

    geometry: OrbitGeometry
    wfov_shape: tuple[int, int]
    frame_px: int
    top0: int
    factor: int

    def nadir(self, t: float) -> tuple[float, float]:
        """The nadir at pass time ``t``, strip WFOV px (``docs``' formula).

        Parameters
        ----------
        t : float
            Pass seconds.

        Returns
        -------
        tuple of float
            ``(x, y)`` strip WFOV px.
        """
        g = self.geometry
        x = (self.wfov_shape[1] - 1) / 2.0
        y = (
            self.top0
            + (self.frame_px - 1) / 2.0
            + (g.look_ahead_m - g.ground_speed * t) / g.wfov_gsd_m
        )
        return x, y

    def nadir_hr(self, t: float) -> tuple[float, float]:
        """The nadir at ``t`` in strip high-resolution px.

        Parameters
        ----------
        t : float
            Pass seconds.

        Returns
        -------
        tuple of float
            ``(x, y)`` high-resolution px (WFOV px ``i`` centres at ``i f + (f-1)/2``).
        """
        x, y = self.nadir(t)
        f = self.factor
        return x * f + (f - 1) / 2.0, y * f + (f - 1) / 2.0

    def along(self, y: float, t: float) -> float:
        """Metres ahead of the nadir at ``t`` of strip WFOV row ``y``.

        Parameters
        ----------
        y : float
            Strip WFOV row.
        t : float
            Pass seconds.

        Returns
        -------
        float
            Metres.
        """
        return (self.nadir(t)[1] - y) * self.geometry.wfov_gsd_m

    def disparity_rows(self, y: float, t0: float, t1: float, height_m: float) -> float:
        """Rows a feature at ``height_m`` seen at row ``y`` at ``t0`` appears lower at ``t1``.

        Its parallax shrinks as the nadir approaches; no drift is counted.

        Parameters
        ----------
        y : float
            Strip WFOV row where it appeared at ``t0``.
        t0, t1 : float
            Pass seconds of the two looks.
        height_m : float
            The feature's height.

        Returns
        -------
        float
            WFOV rows (positive: towards the nadir).
        """
        return self.shift_rows(y, t0, t1, height_m, height_m)

    def shift_rows(self, y: float, t0: float, t1: float, h0_m: float, h1_m: float) -> float:
        """Rows a feature at ``h0_m`` seen at row ``y`` at ``t0`` appears lower at ``t1``,
        where it has risen (or sunk) to ``h1_m`` above the same ground point.

        Parameters
        ----------
        y : float
            Strip WFOV row where it appeared at ``t0``.
        t0, t1 : float
            Pass seconds of the two looks.
        h0_m, h1_m : float
            Its heights at ``t0`` and ``t1``.

        Returns
        -------
        float
            WFOV rows (positive: towards the nadir; a top rising fast enough moves away).
        """
        g = self.geometry
        true_along = float(parallax.sight_at_height(g.altitude_m, self.along(y, t0), h0_m))
        s0 = self.along(y, t0) - true_along
        d1 = true_along - g.ground_speed * (t1 - t0)
        s1 = float(parallax.parallax_shift(g.altitude_m, d1, h1_m))
        return (s0 - s1) / g.wfov_gsd_m


Search = tuple[float, float] | None
"""``(centre, half-width)``: rows a plume's envelope moved, searched (``None``: skipped)."""

Follow = Callable[["Plume", float], "tuple[float, float] | None"]
"""``follow(plume, t) -> (centre, half)``: the search (rows moved since the plume was seen) for a
top found rising, in a look at pass time ``t`` (``None``: where its guessed height puts it)."""

Render = Callable[[float, int, tuple[float, float]], np.ndarray]
"""``render(t, top, nadir_hr) -> (H_f, W)`` plume mask (fraction 0..1) that a look of the
world at pass time ``t`` from above ``nadir_hr`` (strip high-res px) shows on the frame-sized
window whose top strip WFOV row is ``top`` (the oracle's, or the pass's classifier's)."""


class HeightTracker:
    """Plumes of a pass, their re-looks and height estimates (the module docstring's model).

    Parameters
    ----------
    where : Geometry3D
        The pass's geometry on the strip's WFOV grid.
    agility : dyntarget.schedule.Agility
        The preset whose slew model times a re-look.
    relook_km : tuple of float
        Re-look distances ahead of the nadir, km.
    relook_s : float or None
        Seconds per re-look (``None``: :func:`relook_seconds` per distance).
    prior_m : float or None
        The prior height (also the disparity's guess; :data:`GUESS_HEIGHT_M` without one).
    wind : tuple of float or None
        ``(east, north)`` wind, m/s: kept for a feature that drifts with the wind; the
        envelope of a vent-attached plume is fitted with a zero-drift prior instead.
    measure : bool
        Take re-looks and estimate heights (``"estimated"`` mode); otherwise only track.
    log : callable
        Where a plume's fallback line goes (stderr in the pass loop).
    catch_up : bool
        Take the regular frames due during a re-look late (:meth:`take`) instead of
        losing them.
    max_rise_mps : float
        Where a rise is fitted, the fastest rise of a top, m/s, the re-looks' windows and
        searches allow for (0, the default: a steady top's search).
    fit_s : float or None
        Seconds a height fit takes before its estimate is usable (a pass with a fixed
        compute budget passes its budget, so that the pass is reproducible); ``None``, the
        default: the fit's measured compute time.
    relook_frames : int
        Most frames one re-look takes where its search asks more rows than a frame holds
        (:data:`RELOOK_FRAMES`; 1: one frame, its search cut to it).
    hold : bool or None
        Instead of going back to its regular pitch after a re-look (nearer than the pitch
        it holds, not nearer than the NFOV's field of regard begins), the look-ahead holds
        that re-look's pitch and takes the regular frames from there, later (:meth:`take`;
        the module docstring's "Holding"). It then never catches up. ``None``, the default:
        where catching up is asked for but the look-ahead cannot gain on the ground
        (:func:`holds_relooks`).
    keep_cut : bool
        A plume measured provisionally on a cut view (:attr:`Plume.pending`) and again on
        the first view that sees it whole keeps the cut view's estimate where the whole
        view gives none (usable once that is known), instead of having none (the pass's
        ``defer_cut``, whose held pointings would otherwise not fly). ``False``, the
        default: the whole view's outcome replaces it either way.
    """

    def __init__(  # noqa: PLR0913 (the pass's height options, keyword-only after wind)
        self,
        where: Geometry3D,
        agility: Agility,
        relook_km: tuple[float, ...],
        relook_s: float | None,
        prior_m: float | None,
        wind: tuple[float, float] | None,
        *,
        measure: bool,
        log: Callable[[str], None],
        catch_up: bool = True,
        max_rise_mps: float = 0.0,
        fit_s: float | None = None,
        relook_frames: int = RELOOK_FRAMES,
        hold: bool | None = None,
        keep_cut: bool = False,
    ) -> None:
        self.where, self.agility, self.prior_m, self.wind = where, agility, prior_m, wind
        self.keep_cut = bool(keep_cut)
        self.measure, self.log, self.fit_s = measure, log, fit_s
        self.relook_frames = int(relook_frames)
        self.hold = holds_relooks(where.geometry, agility, where.frame_px, catch_up, hold)
        """Whether the look-ahead holds its re-looks' pitch (:func:`holds_relooks`)."""
        self.catch_up = (
            catch_up and not self.hold and gains_on_ground(where.geometry, agility, where.frame_px)
        )
        """Whether frames due during a re-look are taken late: asked for, not holding, and
        the look-ahead gains on the ground (:func:`gains_on_ground`)."""
        self.holds: list[tuple[float, float]] = []
        """``(from, distance)``: from pass time ``from`` on (frames due then, re-looks taken
        then), the look-ahead's regular pitch looks ``distance`` m ahead (:meth:`_home_m`)."""
        self.last_due = -math.inf
        """When the last frame :meth:`take` was asked about was due, pass seconds."""
        self.lags = (0.0, 0.0)
        """Seconds after its due time the frame taken before the last was taken, and the last
        (held frames: :meth:`frame` tracks a plume from the view the frame before had)."""
        self.free_s = 0.0
        """When the look-ahead is done with the last frame it took late, pass seconds."""
        self.pitch_m: float | None = None
        """How far ahead of the nadir it last looked while behind (``None``: on its pitch)."""
        self.last_top: int | None = None
        """The top strip WFOV row of the last regular frame taken."""
        self.reach_m = _reach_m(where.geometry, agility)
        self.distances_m = tuple(float(d) * 1e3 for d in relook_km)
        self.relook_s = relook_s
        self.fit_rise = len(self.distances_m) >= 2
        """A rise is fitted only where re-looks at two or more distances were asked for."""
        self.rise_mps = float(max_rise_mps) if self.fit_rise else 0.0
        """Fastest rise a re-look's window and search allow for (0: a steady top's)."""
        self.labels = np.zeros(where.wfov_shape, np.int32)
        """Strip WFOV px -> tracked plume (1-based; 0: none), apparent footprints."""
        self.plumes: list[Plume] = []
        self.busy: list[tuple[float, float]] = []
        """``(start, end)`` of every re-look taken, pass seconds."""
        self.taken: list[Relook] = []
        """Every re-look taken (shared by the plumes its window holds)."""
        if measure:  # loaded before the pass (as at boot), not in the first plume's time
            import scipy.optimize  # noqa: F401

    # -- the look-ahead's time -------------------------------------------------------
    def busy_at(self, t: float) -> bool:
        """Whether the look-ahead is re-looking at pass time ``t``.

        Parameters
        ----------
        t : float
            Pass seconds.

        Returns
        -------
        bool
            True inside a re-look's window.
        """
        return any(a <= t < b for a, b in self.busy)

    def take(
        self, t_due: float, top: int, nxt: tuple[int, float] | None
    ) -> tuple[float | None, str]:
        """When the look-ahead takes the regular frame due at ``t_due`` (the model's
        "catching up"), or why it does not.

        Parameters
        ----------
        t_due : float
            When the frame is due (its acquisition on the regular cadence), pass seconds.
        top : int
            Its top strip WFOV row.
        nxt : tuple or None
            The next frame's top row and due time (``None``: the pass's last frame).

        Returns
        -------
        tuple
            ``(t, "")``: taken at pass time ``t`` (``t_due`` on time, later when late or
            held: while the look-ahead holds a re-look's pitch, ``d`` ahead, every frame is
            taken when its ground is there, ``(look_ahead_m - d) / v`` after it was due);
            ``(None, why)``: not taken, ``why`` one of ``"re-looking"`` (due, or held to a
            time, during a re-look, without catching up), ``"covered"`` (its ground is seen by the last
            frame seen (:meth:`seen`) and the next, which will not come too late) or
            ``"too late"`` (its centre would be within the NFOV's reach).

        Examples
        --------
        A re-look from 1.0 to 4.8 s (``fast``, 300 km ahead): the frame due at 2.0 s is
        taken late, once the look-ahead is back and has pitched to it.

        >>> from dyntarget.schedule import get_agility
        >>> where = Geometry3D(OrbitGeometry(wfov_gsd_m=32.0), (4096, 64), 64, 4032, 4)
        >>> tr = HeightTracker(where, get_agility("fast"), (300.0,), None, None, None,
        ...                    measure=False, log=print)
        >>> tr.take(0.0, 4032, (4000, 0.145))
        (0.0, '')
        >>> tr.busy.append((1.0, 4.8))
        >>> t, why = tr.take(2.0, 3968, (3936, 2.145))
        >>> 4.8 < t < 5.5, why
        (True, '')
        """
        self.last_due = t_due
        if not self.catch_up:  # on time, or held: on the cadence, later; lost while re-looking
            lag = self._lag_s(t_due)
            t = t_due + lag
            if self.busy_at(t):
                return None, "re-looking"
            self.lags = (self.lags[1], lag)
            return t, ""
        busy = self.busy_at(t_due)
        if not busy and self.pitch_m is None and t_due >= self.free_s:  # on time
            return t_due, ""
        g, a = self.where.geometry, self.agility
        v, ahead = g.ground_speed, g.look_ahead_m
        start, prev = self.free_s, ahead if self.pitch_m is None else self.pitch_m
        fp = self.where.frame_px
        if nxt is not None and self.last_top is not None and nxt[0] + fp >= self.last_top:
            # the next frame abuts the last one seen: skip this one, unless the next will
            # come too late to see its ground
            if ahead - v * (self._when(nxt[1], start, prev) - nxt[1]) >= self.reach_m:
                return None, "covered"
        t = self._when(t_due, start, prev)
        along = ahead - v * (t - t_due)
        if along < self.reach_m:
            return None, "too late"
        on_time = t <= t_due
        self.pitch_m = None if on_time else along
        self.free_s = t if on_time else t + a.dwell_s
        return t, ""

    def seen(self, top: int) -> None:
        """Record that the regular frame whose top strip WFOV row is ``top`` was seen (taken
        and planned): catching up skips a frame only between frames seen.

        Parameters
        ----------
        top : int
            The frame's top strip WFOV row.
        """
        self.last_top = top

    def _home_m(self, t: float) -> float:
        """How far ahead of the nadir the look-ahead's regular pitch looks at pass time ``t``
        (for a frame: due at ``t``), metres: ``look_ahead_m`` until it holds a re-look's."""
        home = self.where.geometry.look_ahead_m
        for start, d in self.holds:
            if start <= t:
                home = d
        return home

    def _lag_s(self, t_due: float) -> float:
        """Seconds after its due time a frame due at ``t_due`` is taken (0 on the regular
        pitch): when its ground is as far ahead as the pitch held then. Each hold is nearer
        than the last and applies to the frames that would be taken from its start on: a
        frame the look-ahead had not taken yet where it held before is taken where it holds
        now (its ground was not seen: it lay beyond the pitch held before)."""
        g, lag = self.where.geometry, 0.0
        for start, d in self.holds:
            if t_due + lag >= start:
                lag = (g.look_ahead_m - d) / g.ground_speed
        return lag

    def _from(self, t: float) -> OrbitGeometry:
        """The geometry whose look-ahead distance is the pitch held at ``t`` (a re-look there
        slews from it and back to it)."""
        g, home = self.where.geometry, self._home_m(t)
        return g if home == g.look_ahead_m else replace(g, look_ahead_m=home)

    def _when(self, t_due: float, start: float, prev_m: float) -> float:
        """When the look-ahead, free from ``start`` looking ``prev_m`` ahead, can take the
        frame due at ``t_due``: re-looks booked first (each returns to the regular pitch)."""
        a, ahead = self.agility, self.where.geometry.look_ahead_m
        while True:
            t = self._on_frame(t_due, start, prev_m)
            clash = [b for s, b in self.busy if s < t + a.dwell_s and b > start]
            if not clash:
                return t
            start, prev_m = max(clash), ahead  # a re-look first; it returns to the pitch

    def _on_frame(self, t_due: float, start: float, prev_m: float) -> float:
        """The first time (>= ``t_due``) at which the look-ahead, free from ``start`` and
        looking ``prev_m`` ahead of the nadir, can be pitched to and settled on the regular
        frame due at ``t_due`` (the frame comes nearer meanwhile: bisection on the time)."""
        g, a = self.where.geometry, self.agility
        v, ahead = g.ground_speed, g.look_ahead_m

        def behind(t: float) -> bool:  # not yet settled on the frame at t
            step = _pitch_deg(g, prev_m, ahead - v * (t - t_due))
            return start + a.slew_time_one(step) + a.settle_s > t

        lo = max(start, t_due)
        if not behind(lo):
            return lo
        hi = lo + 1.0
        while behind(hi):
            lo, hi = hi, hi + 2.0 * (hi - lo)
        while hi - lo > 1e-9:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if behind(mid) else (lo, mid)
        return hi

    def _free_from(self, t: float, duration: float) -> float:
        """The first time at or after ``t`` (and after the frame the look-ahead is taking)
        at which ``duration`` s of look-ahead are free."""
        start = max(t, self.free_s)
        for a, b in sorted(self.busy):
            if start < b and start + duration > a:
                start = b
        return start

    # -- per frame -------------------------------------------------------------------
    def frame(
        self,
        k: int,
        t_k: float,
        top: int,
        mask: np.ndarray,
        render: Render,
        *,
        last: bool,
        raw: np.ndarray | None = None,
        due: float | None = None,
    ) -> np.ndarray:
        """Track frame ``k``'s plumes, take and measure re-looks of new ones.

        Parameters
        ----------
        k : int
            Frame index.
        t_k : float
            Its acquisition time, pass seconds.
        top : int
            Its top strip WFOV row.
        mask : numpy.ndarray
            ``(H_f, W)`` bool denoised mask the plan used.
        render : callable
            The world's look (:data:`Render`), for the re-looks.
        last : bool
            The pass's last frame (no plume waits for a next one).
        raw : numpy.ndarray or None
            ``(H_f, W)`` bool mask before denoising (``None``: ``mask``): the envelope is
            matched on it, as the re-looks' masks are not denoised either.
        due : float or None
            When the frame was due, if it was taken late (``t_k`` later, :meth:`take`):
            its plumes appear nearer the nadir than on an earlier frame, by up to the
            parallax change of :data:`TRACK_HEIGHT_M`, and are matched that far ahead.

        Returns
        -------
        numpy.ndarray
            ``(H_f, W)`` int32: the tracked plume (1-based) of each component pixel, 0 elsewhere.
        """
        m8 = mask.astype(np.uint8)
        # components within GROUP_PX of each other are one plume (a fragmented envelope)
        grow = np.ones((GROUP_PX + 1, GROUP_PX + 1), np.uint8)
        n, comp = cv2.connectedComponents(cv2.dilate(m8, grow), connectivity=8)
        comp = np.where(mask, comp, 0).astype(np.int32)
        areas = np.bincount(comp.ravel(), minlength=n)
        out = np.zeros(mask.shape, np.int32)
        new: list[tuple[int, np.ndarray, np.ndarray]] = []
        ready: list[Plume] = []
        late = 0  # rows ahead a tracked plume's footprint may lie, in a frame taken late
        ref = None if due is None else due + self.lags[0]  # the frame before's view (held)
        if ref is not None and t_k > ref:  # at the frame's far edge, where it is largest
            late = math.ceil(self.where.disparity_rows(float(top), ref, t_k, TRACK_HEIGHT_M))
        near = np.ones((2 * MATCH_PX + 1 + late, 2 * MATCH_PX + 1), np.uint8)
        for i in range(1, n):
            if areas[i] < MIN_PLUME_PX:
                continue
            on = comp == i
            rows, cols = np.nonzero(on)
            lo = int(rows.min()) - MATCH_PX - late
            r0, r1 = max(lo, -top), int(rows.max()) + MATCH_PX + 1
            c0, c1 = max(int(cols.min()) - MATCH_PX, 0), int(cols.max()) + MATCH_PX + 1
            # the box reaches past the frame's bottom on the strip: a footprint tracked in
            # an earlier frame may lie just behind it (frames skipped while catching up abut)
            r1, c1 = min(r1, self.labels.shape[0] - top), min(c1, mask.shape[1])
            box = np.zeros((r1 - r0, c1 - c0), np.uint8)
            f0, f1 = max(r0, 0), min(r1, mask.shape[0])
            box[f0 - r0 : f1 - r0, :] = on[f0:f1, c0:c1]
            grown = cv2.dilate(box, near, anchor=(MATCH_PX, MATCH_PX)) > 0
            under = self.labels[top + r0 : top + r1, c0:c1][grown]
            under = under[under > 0]
            if len(under):
                pid = int(np.bincount(under).argmax())
                out[on] = pid
                self.labels[rows + top, cols] = np.where(
                    self.labels[rows + top, cols] == 0, pid, self.labels[rows + top, cols]
                )
                p = self.plumes[pid - 1]
                if p.pending and p not in ready and (last or not self._cut_upwind(rows, cols)):
                    # its upwind end is in view now: measured again on this frame's view (the
                    # re-looks already taken shared where their windows hold it)
                    if self.keep_cut and p.source == "estimated":
                        p.cut = replace(p, relooks=list(p.relooks), stages=list(p.stages))
                    p.pending, p.frame, p.t_k, p.rows, p.cols = False, k, t_k, rows + top, cols
                    p.relooks, p.source, p.reason, p.ready_s = [], "none", "", math.inf
                    p.stages = []
                    ready.append(p)
                continue
            new.append((i, rows, cols))
        for i, rows, cols in new:
            plume = Plume(len(self.plumes) + 1, k, t_k, rows + top, cols)
            # its upwind end (the vent's) cut by the frame's top edge (the side ahead):
            # measured now (this frame's pointings need a height) and again on the first
            # frame that sees that end
            plume.pending = bool(not last and self._cut_upwind(rows, cols))
            self.plumes.append(plume)
            self.labels[rows + top, cols] = plume.pid
            out[comp == i] = plume.pid
            ready.append(plume)
        if not ready:
            return out
        fresh = ready
        if not self.measure:
            for p in fresh:
                self._fallback(p, "")
            return out
        small = [p for p in fresh if len(p.rows) < MIN_RELOOK_PX]
        for p in small:
            self._fallback(p, f"too small for a re-look: {len(p.rows)} WFOV px, fewer than "
                           f"{MIN_RELOOK_PX}")  # fmt: skip
        big = [p for p in fresh if len(p.rows) >= MIN_RELOOK_PX]
        if big:
            self._relook(big, t_k, top, comp, mask if raw is None else raw, render)
        return out

    def pending_ids(self) -> set[int]:
        """The tracked plumes measured provisionally so far (:attr:`Plume.pending`: their
        upwind end cut by the edge of the frame that saw them; measured again, with the
        rest of them, on the first frame that sees that end).

        Returns
        -------
        set of int
            Their ids (1-based).
        """
        return {p.pid for p in self.plumes if p.pending}

    def _cut_upwind(self, rows: np.ndarray, cols: np.ndarray) -> bool:
        """Whether a component (frame rows, columns) has its upwind end (the quarter of its
        length along the wind at the upwind side; all of it without a wind) on the frame's
        top row: a later frame, further north, sees more of that end."""
        on_top = rows == 0
        if not on_top.any():
            return False
        if self.wind is None or math.hypot(*self.wind) < 0.5:
            return True
        ux, uy = self.wind[0], -self.wind[1]  # east, north -> column, row
        along = cols * ux + rows * uy
        lo, hi = float(along.min()), float(along.max())
        return bool(on_top[along <= lo + 0.25 * (hi - lo) + 1.0].any())

    def _upwind(self, p: Plume, top: int, shape: tuple[int, int]) -> np.ndarray:
        """The frame's pixels on the upwind side of plume ``p`` (all without a wind): those
        whose distance along the wind is at most :data:`UPWIND_SHARE` of the plume's length
        along it (and a margin) past its upwind end. Its vent end stays where it is while the
        wind stretches the downwind end between the looks."""
        if self.wind is None or math.hypot(*self.wind) < 0.5:
            return np.ones(shape, bool)
        ux, uy = self.wind[0], -self.wind[1]  # east, north -> column, row
        norm = math.hypot(ux, uy)
        ux, uy = ux / norm, uy / norm
        along = p.cols * ux + (p.rows - top) * uy
        lo, hi = float(along.min()), float(along.max())
        cut = lo + UPWIND_SHARE * (hi - lo) + 1.0
        rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]]
        return np.asarray(cc * ux + rr * uy <= cut)

    def _window_for(
        self,
        plumes: list[Plume],
        t_k: float,
        at: float,
        guess: dict[int, float],
        tol: float,
        follow: Follow | None = None,
    ) -> Relook | None:
        """A re-look already taken within ``tol`` s of ``at`` whose window holds the plumes
        where their ``guess`` heights (or ``follow``) put them (their rows and a margin), and
        that none of them has looked at already (the same look twice is no new view), or
        ``None``."""
        for r in self.taken:
            if abs(r.t_s - at) > tol or any(r in p.relooks for p in plumes):
                continue
            a, b = self._expected_rows(plumes, t_k, r.t_s, guess, follow)
            if a - MARGIN_PX >= r.top and b + MARGIN_PX < r.frames[-1][1] + self.where.frame_px:
                return r
        return None

    def _relook(
        self,
        plumes: list[Plume],
        t_k: float,
        top: int,
        comp: np.ndarray,
        raw: np.ndarray,
        render: Render,
    ) -> None:
        """Take (or share) the re-looks in order, measure each plume's envelope on each, fit.

        Each plume is searched for around where its own height known so far puts it: the
        prior (or :data:`GUESS_HEIGHT_M`) in the first re-look, then the fit of its own
        looks so far (plumes of one frame differ in height by kilometres, which moves them
        hundreds of pixels apart between looks). A re-look's window is centred on where
        the plumes still measured will appear by those heights; a re-look already taken
        (for an earlier frame's plumes) near the wanted time whose window holds them is
        shared instead of taking another, and no re-look is taken once none of the
        frame's plumes is left to measure. After each re-look, a plume whose looks so far
        fit is given that estimate from then on (:attr:`Plume.stages`); a plume lost in a
        later re-look keeps the fit of the looks that saw it.
        """
        w = self.where
        gsd, shape = w.geometry.wfov_gsd_m, comp.shape
        prior = self.prior_m if self.prior_m is not None else GUESS_HEIGHT_M
        guess = {p.pid: prior for p in plumes}
        fitted: set[int] = set()
        nx, ny0 = w.nadir(t_k)
        alt, sig = w.geometry.altitude_m, POSITION_SIGMA_PX * gsd
        looks: dict[int, list[Look]] = {}
        failed: dict[int, str] = {}
        fits: dict[int, HeightFit] = {}  # each plume's fit of its looks so far
        moved: dict[int, list[tuple[float, float]]] = {}  # (time, rows moved) per re-look
        rising: set[int] = set()  # found only by a search that allowed a rise
        first: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        margin = np.ones((2 * MARGIN_PX + 1, 2 * MARGIN_PX + 1), np.uint8)
        near = np.ones((2 * GROUP_PX + 1, 2 * GROUP_PX + 1), np.uint8)
        raw = np.asarray(raw, bool)
        for p in plumes:
            cy, cx = float(np.mean(p.rows)), float(np.mean(p.cols))
            looks[p.pid] = [Look(t_k, cx * gsd, -cy * gsd, nx * gsd, -ny0 * gsd, alt, sig)]
            comp_p = np.zeros(shape, np.uint8)
            comp_p[p.rows - top, p.cols] = 1
            own = raw & (cv2.dilate(comp_p, near) > 0)  # its raw mask (not denoised)
            weight = (cv2.dilate(own.astype(np.uint8), margin) > 0) & (own | ~raw)
            first[p.pid] = (own, weight & self._upwind(p, top, shape))

        def follow(p: Plume, at: float) -> tuple[float, float] | None:  # a rising top's search
            if p.pid not in rising:
                return None
            return self._following(float(np.mean(p.rows)), t_k, at, moved[p.pid], prior)

        def steady(p: Plume, at: float) -> tuple[float, float]:  # its first search:
            # heights from 0.2 x to 1.8 x the guess (0.7 x to 1.3 x once fitted)
            spread = SPREAD_FITTED if p.pid in fitted else SPREAD_GUESS
            return self._search(float(np.mean(p.rows)), t_k, at, guess[p.pid], spread)

        def searches(p: Plume, at: float) -> list[Search]:  # the searches, in turn
            rise = self._rise_searches(p, t_k, at, guess[p.pid], p.pid in fitted, moved, prior)
            return [steady(p, at), *rise]

        why = ""
        main = max(plumes, key=lambda p: len(p.rows))
        for d in self._chain(float(np.mean(main.rows)), t_k, prior):
            alive = [p for p in plumes if p.pid not in failed]
            if not alive:
                break
            centre = float(np.mean(np.concatenate([p.rows for p in alive])))
            want = t_k + (w.along(centre, t_k) - d) / w.geometry.ground_speed
            if want <= t_k:
                why = why or f"already nearer than {d / 1e3:g} km when seen"
                continue
            dur = self._duration(d, want)
            shared = self._window_for(alive, t_k, want, guess, dur, follow) or self._take(
                alive, t_k, want, dur, guess, render, follow, searches, ahead_m=d
            )
            if shared is None:
                why = why or "the look-ahead was busy re-looking at other plumes"
                continue
            t0 = time.perf_counter()
            for p in alive:
                p.relooks.append(shared)
                cy, cx = float(np.mean(p.rows)), float(np.mean(p.cols))
                rows = (int(p.rows.min()) - top, int(p.rows.max()) - top)
                disp, which, why_not, at, r0 = self._seek(
                    first[p.pid], shared, top, rows, partial(searches, p)
                )
                if disp is None:
                    failed[p.pid] = why_not
                    continue
                if which > 0:  # found only where a risen top would be: follow it so
                    rising.add(p.pid)
                _, ny = w.nadir(at)
                x, y = cx + disp.dx_px, cy + disp.dy_px + (r0 - top)
                moved.setdefault(p.pid, []).append((at, disp.dy_px + (r0 - top)))
                looks[p.pid].append(Look(at, x * gsd, -y * gsd, nx * gsd, -ny * gsd, alt, sig))
                fit = fits[p.pid] = fit_height(looks[p.pid], wind_prior=(0.0, 0.0),
                                 wind_prior_sigma_mps=ENVELOPE_DRIFT_SIGMA_MPS)  # fmt: skip
                if fit.ok and 0 < fit.height_m < parallax.MAX_HEIGHT_M:
                    guess[p.pid] = fit.height_m
                    fitted.add(p.pid)
                    if fit.height_sigma_m <= MAX_SIGMA_M:  # usable from now on
                        ready = at + self._fit_time(t0)
                        p.stages.append((ready, fit.height_m))
        for p in plumes:
            self._conclude(p, looks[p.pid], fits.get(p.pid), failed.get(p.pid), why)

    def _rise_searches(
        self,
        p: Plume,
        t_k: float,
        at: float,
        guess: float,
        fitted: bool,
        moved: dict[int, list[tuple[float, float]]],
        prior: float,
    ) -> list[Search]:
        """Plume ``p``'s searches in a look at ``at`` after the steady top's, where a rise is
        allowed for (none otherwise): where the rise its last move implies puts it, else
        anywhere a top rising at up to :attr:`rise_mps` could be."""
        if self.rise_mps <= 0.0:
            return []
        cy, spread = float(np.mean(p.rows)), SPREAD_FITTED if fitted else SPREAD_GUESS
        return [
            self._following(cy, t_k, at, moved.get(p.pid, []), prior),
            self._search_risen(cy, t_k, at, guess, spread),
        ]

    def _seek(
        self,
        first: tuple[np.ndarray, np.ndarray],
        relook: Relook,
        top: int,
        rows: tuple[int, int],
        searches_at: Callable[[float], list[Search]],
    ) -> tuple[Disparity | None, int, str, float, int]:
        """A plume (``first``: its envelope, rows ``rows`` of the frame whose top strip row is
        ``top``) found in a re-look's frames: the searches ``searches_at(t)`` gives for a
        frame taken at ``t``, each in turn, in every frame that can hold the envelope
        somewhere in that search (the part it can hold, nearest the search's centre first).

        Returns the displacement, the search's index, ``""``, and the time and top row of the
        frame it was found in; or ``None``, -1, why, and the first frame's time and top."""
        if len(relook.frames) == 1:
            at, r0, mask = relook.frames[0]
            assert mask is not None
            disp, which, why = self._find(first, mask, r0 - top, searches_at(at))
            return disp, which, why, at, r0
        hf, (a, b) = self.where.frame_px, rows
        looked = [(at, r0, mask, searches_at(at)) for at, r0, mask in relook.frames]
        reason, covered = "", True
        for i in range(len(looked[0][3])):
            held: list[tuple[float, float, int, np.ndarray, tuple[float, float]]] = []
            asked: tuple[float, float] | None = None
            for at, r0, mask, searches in looked:
                search = searches[i]
                if search is None or mask is None:
                    continue
                if asked is None:
                    asked = search
                part = held_part(search, r0 - top, rows, hf)
                if part is not None:
                    held.append((abs(part[0] - search[0]), at, r0, mask, part))
            if asked is not None:
                first_top, last_top = looked[0][1] - top - a, looked[-1][1] - top + hf - 1 - b
                covered = (
                    covered
                    and first_top <= asked[0] - asked[1]
                    and (asked[0] + asked[1] <= last_top)
                )
            for _, at, r0, mask, part in sorted(held, key=lambda h: h[0]):
                disp, _, why = self._find(first, mask, r0 - top, [None] * i + [part])
                if disp is not None:
                    return disp, i, "", at, r0
                reason = why
        if not covered:
            reason = (
                f"the re-look's {len(looked)} frames ({hf} WFOV rows each) are too few to find "
                f"the plume again: its height's uncertainty asks more rows than they hold"
            )
        return None, -1, reason, relook.t_s, relook.top

    def _find(
        self,
        first: tuple[np.ndarray, np.ndarray],
        second: np.ndarray,
        offset: int,
        searches: list[tuple[float, float] | None],
    ) -> tuple[Disparity | None, int, str]:
        """A plume's envelope (``first``: its mask and the pixels compared) found in a
        re-look's mask ``second`` (window ``offset`` rows below the frame's), by the first of
        ``searches`` (``(centre, half-width)`` rows moved; ``None``: skipped) that finds it.

        Returns the displacement (rows and columns in the re-look's window), the search's
        index and ``""``; or ``None``, -1 and why the last search tried failed."""
        own, weight = first
        half_frame = second.shape[0] // 2
        reason = ""
        for i, search in enumerate(searches):
            if search is None:
                continue
            centre, span = search
            disp, reason = envelope_disparity(
                own, second, weight=weight, guess_px=(0.0, centre - offset),
                search_px=(MATCH_PX, int(min(span, half_frame))),
            )  # fmt: skip
            if disp is not None:
                return disp, i, ""
            reason = reason.split("; no height")[0]
            if span > half_frame:  # the search was cut to the frame
                reason = (
                    f"the frame ({second.shape[0]} WFOV rows) is too short to find the plume "
                    f"again: its height's uncertainty asks a search of +-{span:.0f} rows, "
                    f"the frame holds +-{half_frame}"
                    + ("" if self.relook_frames > 1 else " (re-looks of several frames, "
                       "relook_frames / --relook-frames, may hold it)")
                )  # fmt: skip
        return None, -1, reason

    def _conclude(
        self, p: Plume, looks: list[Look], fit: HeightFit | None, lost: str | None, why: str
    ) -> None:
        """Plume ``p``'s final estimate from its looks and their last fit (``lost``: why a
        later re-look did not see it; ``why``: why a re-look was not taken), or the fallback.

        A later re-look whose best match lies on the edge of its search contradicts the fit
        of the looks before it: that search spanned the heights the fit allows (0.7 to 1.3
        times it), and the envelope most likely lies beyond them; the plume gets no
        estimate (its earlier ones are used until then, as a rejected final fit's are)."""
        if len(looks) >= 2 and fit is not None:
            t0 = time.perf_counter()
            if lost is not None and lost.startswith(EDGE_MATCH):
                self._fallback(
                    p,
                    f"a later re-look found its best match on the edge of the search the fit of "
                    f"its first {len(looks) - 1} re-look(s) allows ({fit.height_m:.0f} m): the "
                    f"fit is contradicted",
                )
            else:
                self._fit(p, looks, fit)
            last = looks[-1].t_s
            known = max(last, p.stages[-1][0]) if p.stages else last
            p.ready_s = known + self._fit_time(t0)  # decided (estimate or not)
            if p.source == "estimated" and lost is not None:  # measured on the looks that saw it
                p.reason = f"{len(looks) - 1} re-look(s) used; {lost}"
        elif lost is not None:
            self._fallback(p, lost)
        else:
            self._fallback(p, f"no re-look taken ({why or 'none asked'})")

    def _fit_time(self, t0: float) -> float:
        """Seconds the fit begun at ``perf_counter()`` ``t0`` took: ``fit_s`` where given."""
        return time.perf_counter() - t0 if self.fit_s is None else self.fit_s

    def _duration(self, d: float, at: float) -> float:
        """Look-ahead seconds of a re-look ``d`` metres ahead at ``at`` (given, or the slew
        model's from the pitch held then and back)."""
        if self.relook_s is not None:
            return self.relook_s
        return relook_seconds(self._from(at), self.agility, d)

    def _span(self, y: float, t_k: float, d: float, guess: float, spread: float) -> float:
        """Half-width (rows) of the search for a plume seen at row ``y`` at ``t_k`` in a
        re-look ``d`` metres ahead, its height ``guess`` known to ``spread`` of itself."""
        w = self.where
        t = t_k + (w.along(y, t_k) - d) / w.geometry.ground_speed
        return self._search(y, t_k, t, guess, spread)[1]

    def _search(
        self, y: float, t_k: float, at: float, guess: float, spread: float
    ) -> tuple[float, float]:
        """Centre and half-width (rows) of the search, in a look at ``at``, for a steady top
        seen at row ``y`` at ``t_k``, its height ``guess`` known to ``spread`` of itself (its
        shift is about proportional to its height: ``guess``'s shift, give or take ``spread``
        of it)."""
        shift = self.where.disparity_rows(y, t_k, at, guess)
        return shift, abs(shift) * spread + MARGIN_PX

    def _search_risen(
        self, y: float, t_k: float, at: float, guess: float, spread: float
    ) -> tuple[float, float] | None:
        """:meth:`_search` widened for a top that may have risen since ``t_k`` at up to
        :attr:`rise_mps`: such a top appears up to :meth:`_rise_rows` further from the nadir
        than a steady one (``None`` where no rise is allowed for)."""
        back = self._rise_rows(y, t_k, at, guess)
        if back <= 0.0:
            return None
        shift, half = self._search(y, t_k, at, guess, spread)
        lo, hi = shift - (half - MARGIN_PX) - back, shift + (half - MARGIN_PX)
        return 0.5 * (lo + hi), 0.5 * (hi - lo) + MARGIN_PX

    def _following(
        self, y: float, t_k: float, at: float, moved: list[tuple[float, float]], prior: float
    ) -> tuple[float, float] | None:
        """Centre and half-width (rows) of the search, in a look at ``at``, for a top seen at
        row ``y`` at ``t_k`` that had moved ``moved[-1] = (t, rows)`` by an earlier re-look,
        and was not found where a steady top would be (:meth:`_relook`).

        Its height at ``t_k`` is anywhere in ``prior``'s range (:data:`SPREAD_GUESS`); for
        each such height the steady rise up to :attr:`rise_mps` that explains the move it
        made (within :data:`MARGIN_PX` rows) predicts where it is at ``at``: the search
        spans those predictions. ``None`` where no rise is allowed for, nothing was
        measured, or no height and rise explain the move."""
        if self.rise_mps <= 0.0 or not moved:
            return None
        w, (t1, d1), top_m = self.where, moved[-1], parallax.MAX_HEIGHT_M

        def move(h0: float, r: float, t: float) -> float:  # rows moved by t
            return w.shift_rows(y, t_k, t, h0, min(h0 + r * (t - t_k), top_m))

        found = []
        for h0 in np.linspace(prior * (1.0 - SPREAD_GUESS), prior * (1.0 + SPREAD_GUESS), 9):
            still, fastest = move(h0, 0.0, t1) - d1, move(h0, self.rise_mps, t1) - d1
            if still < -MARGIN_PX or fastest > MARGIN_PX:  # no rise in range explains it
                continue
            # the move is about linear in the rise: interpolate, clipped to the range
            r = self.rise_mps * min(max(still / (still - fastest), 0.0), 1.0)
            found.append(move(h0, r, at))
        if not found:
            return None
        lo, hi = min(found), max(found)
        return 0.5 * (lo + hi), 0.5 * (hi - lo) + MARGIN_PX

    def _rise_rows(self, y: float, t_k: float, at: float, guess: float) -> float:
        """Rows by which a top at ``guess`` seen at row ``y`` at ``t_k`` appears further
        from the nadir at ``at`` if it rose at :attr:`rise_mps` meanwhile (0 without)."""
        if self.rise_mps <= 0.0 or at <= t_k:
            return 0.0
        w, risen = self.where, guess + self.rise_mps * (at - t_k)
        risen = min(risen, parallax.MAX_HEIGHT_M)
        return w.disparity_rows(y, t_k, at, guess) - w.shift_rows(y, t_k, at, guess, risen)

    def _chain(self, y: float, t_k: float, guess: float) -> list[float]:
        """The re-look distances (metres ahead) for a plume seen at row ``y`` at ``t_k``:
        the asked ones, each preceded where needed by one nearer in time whose search
        still fits in the frame. The search spans 0.2 to 1.8 times the guessed height
        before a fit (0.7 to 1.3 after): a disparity growing with the baseline can ask more
        rows than a frame holds, and a first re-look at a shorter baseline narrows the
        height enough for the next.

        A plume first seen already nearer than every asked distance (in a frame taken late,
        the look-ahead catching up after a re-look) would get none: its distances are then
        scaled by where it was seen over the look-ahead distance (seen 280 km ahead, a
        re-look asked 300 km ahead of a 500 km look is taken 168 km ahead), the same
        fraction of the view the asked ones are of a frame taken on time."""
        half = self.where.frame_px // 2
        seen = self.where.along(y, t_k)
        chain: list[float] = []
        spread = SPREAD_GUESS
        asked = self.distances_m
        ahead = self.where.geometry.look_ahead_m
        if asked and (seen <= min(asked) or self._home_m(t_k) < ahead):  # late, or held
            asked = tuple(d * seen / ahead for d in asked)
        for d in asked:
            for _ in range(MAX_INSERTED):
                prev = chain[-1] if chain else seen
                if not (d < prev and self._span(y, t_k, d, guess, spread) > half):
                    break
                lo, hi = d, prev  # the span shrinks as the distance nears where it was seen
                for _ in range(40):
                    mid = 0.5 * (lo + hi)
                    far = self._span(y, t_k, mid, guess, spread) > half
                    lo, hi = (mid, hi) if far else (lo, mid)
                if hi >= prev - 1.0:  # no re-look nearer in time narrows it
                    break
                chain.append(hi)
                spread = SPREAD_FITTED
            chain.append(d)
            spread = SPREAD_FITTED
        return chain

    def _take(
        self,
        plumes: list[Plume],
        t_k: float,
        want: float,
        dur: float,
        guess: dict[int, float],
        render: Render,
        follow: Follow | None = None,
        searches: Callable[[Plume, float], list[Search]] | None = None,
        ahead_m: float | None = None,
    ) -> Relook | None:
        """Take a re-look for ``plumes`` at ``want`` (or as soon after as the look-ahead is
        free, within :data:`RELOOK_WAIT` re-look durations ``dur`` and while the plumes,
        ``ahead_m`` ahead at ``want``, are still ahead of the nadir; else ``None``), its
        window centred where their guessed heights put them (a rising top: where ``follow``
        searches for it; where they do not fit in one window, the largest); where a rise is
        allowed for, the room the window has left reaches beyond them, where a risen top
        would appear. Where a plume's searches (``searches(plume, t)``) ask more rows than
        a frame holds, the re-look is a mosaic (:meth:`_mosaic`). A one-frame re-look may
        be held (:meth:`_holds`)."""
        w = self.where
        hw, rows = w.wfov_shape[0], w.frame_px
        if hw >= rows and searches is not None:  # the frames it takes, decided at ``want``
            n, step, step_s = self._mosaic(plumes, want, searches)
        else:
            n, step, step_s = 1, 0, 0.0
        total_s = dur + (n - 1) * step_s
        free = self._free_from(want, total_s)
        for held in (True, False) if self.hold and n == 1 else (False,):
            chained = self._straight_after(want, ahead_m, held) if n == 1 else None
            if chained is None or chained[0] > free:  # not later than going back between
                at, chained = free, None
            else:
                at = chained[0]
            if not held or self._holds(at, ahead_m):
                break
        if at - want > RELOOK_WAIT * dur:
            return None
        if ahead_m is not None and ahead_m <= w.geometry.ground_speed * (at - want):
            return None  # the plumes would have passed the nadir by then
        if n > 1:
            assert searches is not None
            lo, hi = self._needed_rows(plumes, at, searches)
            total = rows + (n - 1) * step
            r0 = int(min(max(round(0.5 * (lo + hi) - (total - 1) / 2.0), 0), hw - total))
            shots = [(at + i * step_s, r0 + i * step) for i in range(n)]
            frames: list[tuple[float, int, np.ndarray | None]]
            frames = [(t, top, render(t, top, w.nadir_hr(t))) for t, top in shots]
            return self._book(Relook(at, total_s, r0, frames[0][2], frames))
        lo, hi = self._expected_rows(plumes, t_k, at, guess, follow)
        if hi - lo + 2 * MARGIN_PX > rows:  # not all in one window: the largest plume's
            plumes = [max(plumes, key=lambda p: len(p.rows))]
            lo, hi = self._expected_rows(plumes, t_k, at, guess, follow)
        back = max(self._rise_rows(float(p.rows.min()), t_k, at, guess[p.pid]) for p in plumes)
        room = rows - (hi - lo + 2 * MARGIN_PX)
        if back > 0.0 and room > 0.0:  # tops that may have risen: the room left, beyond
            lo -= min(back, room)  # (steady tops stay inside, with their margin)
        r0 = int(min(max(round(0.5 * (lo + hi) - (rows - 1) / 2.0), 0), hw - rows))
        img = render(at, r0, w.nadir_hr(at))
        if chained is not None:  # it extends a window: the time it adds
            _, i, end = chained
            relook = Relook(at, end - self.busy[i][1], r0, img, ahead_m=ahead_m, held=held)
            return self._book(relook, (i, end))
        if held:  # no slew back: its window ends at the exposure (the slew there counted)
            assert ahead_m is not None
            dur -= _pitch_back_s(self._from(at), self.agility, ahead_m)
        return self._book(Relook(at, dur, r0, img, ahead_m=ahead_m, held=held))

    def _holds(self, at: float, ahead_m: float | None) -> bool:
        """Whether a one-frame re-look at ``at``, ``ahead_m`` ahead, is held (:attr:`hold`
        asked): on the slew model, nearer than the pitch held then (the look-ahead only
        ever comes nearer: ground beyond it is not seen yet), not nearer than the NFOV's
        field of regard begins (frames taken from there are not too late), and no re-look
        booked after it (they slew back to the pitch before)."""
        return (
            self.hold
            and ahead_m is not None
            and self.relook_s is None
            and self.reach_m <= ahead_m < self._home_m(at)
            and all(s <= at for s, _ in self.busy)
        )

    def _hold(self, start: float, ahead_m: float) -> None:
        """Hold ``ahead_m`` from the window that began at ``start`` on: the frames that would
        be taken from then on (:meth:`_lag_s`), less those already asked about
        (:meth:`take`: taken, or lost to the window), are taken from there."""
        asked = self.last_due + self._lag_s(self.last_due)
        self.holds.append((max(start, math.nextafter(asked, math.inf)), ahead_m))

    def _book(self, relook: Relook, extends: tuple[int, float] | None = None) -> Relook:
        """Record a re-look taken: the look-ahead busy for its duration (a window of its own,
        or, ``extends`` = ``(i, end)``, window ``i`` of :attr:`busy` now ending at ``end``),
        the re-look, and, for a held one, the hold from its window's start (:meth:`_hold`)."""
        if extends is None:
            self.busy.append((relook.t_s, relook.t_s + relook.duration_s))
            start = relook.t_s
        else:
            i, end = extends
            start = self.busy[i][0]
            self.busy[i] = (start, end)
        if relook.held:
            assert relook.ahead_m is not None
            self._hold(start, relook.ahead_m)
        self.taken.append(relook)
        return relook

    def _straight_after(
        self, want: float, ahead_m: float | None, held: bool
    ) -> tuple[float, int, float] | None:
        """A re-look wanted at ``want``, ``ahead_m`` ahead, taken straight after the re-look
        the look-ahead is on then, without going back to its pitch in between: ``(t, i, end)``
        (its time, the index in :attr:`busy` of the window it extends, that window's new
        end), or ``None`` where it is not (no window holds ``want``; the look-ahead's time
        not on the slew model; the last re-look of that window a mosaic; the longer window
        would run into another). It is taken at ``want``, or once the look-ahead has slewed
        from the last re-look's pitch to its own and settled, if that is later.

        A window's time is counted from the first re-look's exposure, the slew there counted
        at its end (as :func:`relook_seconds`): a re-look chained after the last one ``B``
        of a window ending ``e`` ends it at ``e + (t - t_B) + back - back_B``, ``back`` the
        slew to the regular pitch (the pitch held then) and a settle; 0 for a re-look that
        is ``held`` (:meth:`_holds`: the look-ahead stays there)."""
        if ahead_m is None or self.relook_s is not None:
            return None
        on = [i for i, (s, e) in enumerate(self.busy) if s <= want < e]
        if len(on) != 1:
            return None
        i = on[0]
        s0, e0 = self.busy[i]
        last = max((r for r in self.taken if s0 <= r.t_s < e0), key=lambda r: r.t_s)
        if len(last.frames) > 1 or last.ahead_m is None:
            return None
        g, a = self.where.geometry, self.agility
        step = _pitch_deg(g, last.ahead_m, ahead_m)
        move = a.slew_time_one(step) + a.settle_s if step > 1e-9 else 0.0
        t = max(want, last.t_s + a.dwell_s + move, self.free_s)
        home = self._from(want)
        back = 0.0 if held else _pitch_back_s(home, a, ahead_m)
        back_last = 0.0 if last.held else _pitch_back_s(home, a, last.ahead_m)
        end = e0 + (t - last.t_s) + back - back_last
        if any(s < end and e > s0 for j, (s, e) in enumerate(self.busy) if j != i):
            return None
        return t, i, end

    def _needed_rows(
        self, plumes: list[Plume], at: float, searches: Callable[[Plume, float], list[Search]]
    ) -> tuple[float, float]:
        """Strip WFOV rows the envelopes of ``plumes`` may occupy in a look at ``at``, over
        their searches ``searches(plume, at)``."""
        spans = [
            (s, int(p.rows.min()), int(p.rows.max()))
            for p in plumes
            for s in searches(p, at)
            if s is not None
        ]
        return (
            min(a + c - h for (c, h), a, _ in spans),
            max(b + c + h for (c, h), _, b in spans),
        )

    def _mosaic(
        self, plumes: list[Plume], at: float, searches: Callable[[Plume, float], list[Search]]
    ) -> tuple[int, int, float]:
        """The frames a re-look at ``at`` of ``plumes`` takes: ``(n, step, step_s)``.

        One frame where each of every plume's searches (``searches``: rows moved, centre
        and half-width) fits in half a frame either side of its centre. Otherwise frames enough (at most
        :attr:`relook_frames`) to hold every envelope anywhere in its search: each frame ``step``
        rows further down the strip than the last, overlapping it by the tallest envelope
        and twice :data:`MARGIN_PX` (so that every position lies wholly in one frame, a
        margin from its edge), each taken ``step_s`` after the last (the pitch step on the
        agility preset's slew model, a settle and an exposure, as a frame taken late)."""
        rows = self.where.frame_px
        half = rows // 2
        wide = [s for p in plumes for s in searches(p, at) if s is not None and s[1] > half]
        if self.relook_frames <= 1 or not wide:
            return 1, 0, 0.0
        tallest = max(int(p.rows.max()) - int(p.rows.min()) + 1 for p in plumes)
        step = rows - tallest - 2 * MARGIN_PX
        if step < 1:  # an envelope too tall to repeat in a frame: one frame
            return 1, 0, 0.0
        lo, hi = self._needed_rows(plumes, at, searches)
        # more rows than a frame (a search wider than half a frame): two frames or more
        n = min(self.relook_frames, 1 + math.ceil((hi - lo + 1 - rows) / step))
        g, a = self.where.geometry, self.agility
        d0 = self.where.along(0.5 * (lo + hi), at)
        step_s = (
            a.slew_time_one(_pitch_deg(g, d0, d0 - step * g.wfov_gsd_m)) + a.settle_s + a.dwell_s
        )
        return n, step, step_s

    def _expected_rows(
        self,
        plumes: list[Plume],
        t_k: float,
        at: float,
        guess: dict[int, float],
        follow: Follow | None = None,
    ) -> tuple[float, float]:
        """Strip WFOV rows spanned at ``at`` by ``plumes`` (seen at ``t_k``) at their guessed
        heights, or for a plume ``follow`` gives a search for (a rising top), that search."""
        w = self.where

        def rows(p: Plume) -> tuple[float, float]:
            a, b = float(p.rows.min()), float(p.rows.max())
            found = follow(p, at) if follow is not None else None
            if found is not None:
                return a + found[0] - found[1], b + found[0] + found[1]
            g = guess[p.pid]
            return a + w.disparity_rows(a, t_k, at, g), b + w.disparity_rows(b, t_k, at, g)

        spans = [rows(p) for p in plumes]
        return min(a for a, _ in spans), max(b for _, b in spans)

    def _fit(self, p: Plume, looks: list[Look], fit: HeightFit) -> None:
        """Height and ground position of plume ``p`` from its envelope's looks, given their
        fit with a zero-drift prior (the envelope of a vent-attached plume), or the fallback."""
        gsd = self.where.geometry.wfov_gsd_m
        if self.fit_rise and len(looks) >= 3 and fit.ok and fit.rms_residual_m > RISE_TEST_PX * gsd:
            # the looks' track is curved beyond their noise: a rising top (its parallax
            # grows while the approach shrinks it); fit the rise as well
            rising = fit_height(
                looks, wind_prior=(0.0, 0.0), wind_prior_sigma_mps=ENVELOPE_DRIFT_SIGMA_MPS,
                rise=True,
            )  # fmt: skip
            # tops do not sink, and a rise within its noise is not one
            up = (
                rising.rise_mps is not None
                and rising.rise_sigma_mps is not None
                and rising.rise_mps > RISE_SIGNIFICANCE * rising.rise_sigma_mps
            )
            if rising.ok and up and rising.rms_residual_m < fit.rms_residual_m:
                fit = rising
        if not fit.ok or not math.isfinite(fit.height_m) or fit.height_m <= 0:
            self._fallback(p, fit.reason or f"the fit gave no usable height ({fit.height_m:.0f} m)")
            return
        if not fit.height_sigma_m <= MAX_SIGMA_M:
            self._fallback(
                p,
                f"too uncertain: {fit.height_m:.0f} +- {fit.height_sigma_m:.0f} m (the looks "
                f"disagree; more than {MAX_SIGMA_M:g} m)",
            )
            return
        p.height_m, p.sigma_m, p.source = fit.height_m, fit.height_sigma_m, "estimated"
        p.rise_mps = fit.rise_mps
        p.ground_xy = (fit.position_m[0] / gsd, -fit.position_m[1] / gsd)

    def _fallback(self, p: Plume, reason: str) -> None:
        """No estimate: the prior, or nothing; say so (``reason`` empty: not measured by design).

        A plume measured again on a whole view that kept its cut view's estimate
        (:attr:`Plume.cut`, ``keep_cut``) gets that back instead, usable once the whole
        view's outcome is known (its last re-look's end, or the whole view's time)."""
        if p.cut is not None:
            known = max((r.t_s + r.duration_s for r in p.relooks), default=p.t_k)
            whole, cut = p.frame, p.cut
            for f in fields(Plume):
                setattr(p, f.name, getattr(cut, f.name))
            p.pending, p.cut = False, None  # measured again: done
            p.ready_s = max(p.ready_s, known)
            self.log(
                f"plume {p.pid} (frame {whole}): no height measured on the whole view: "
                f"{reason}; keeping the estimate from its cut view on frame {p.frame} "
                f"({p.height_m:.0f} m)"
            )
            return
        p.source = "prior" if self.prior_m is not None else "none"
        p.height_m = self.prior_m
        p.sigma_m = None
        p.reason = reason
        if reason and not p.pending:
            self.log(
                f"plume {p.pid} (frame {p.frame}): no height estimated: {reason}; "
                + (f"using the prior {self.prior_m:g} m" if self.prior_m is not None else
                   "its pointings are not flown (no height to aim with; a prior, "
                   "--plume-height-km, would fly them)")
            )  # fmt: skip

    # -- what the aim reads ----------------------------------------------------------
    def height_at(self, pid: int, t: float, at: float | None = None) -> float:
        """The height plume ``pid`` is aimed with at pass time ``t``.

        The final estimate from its ``ready_s`` on (with its rise, where measured); before
        that the latest estimate made on the way (:attr:`Plume.stages`); without one (or
        once the final fit is rejected) the prior, else NaN (not corrected).

        Parameters
        ----------
        pid : int
            The plume (1-based; 0: none).
        t : float
            Pass seconds: what is known then.
        at : float or None
            The time whose top height is wanted (e.g. the look-ahead's acquisition, to
            place the top the look-ahead saw); ``None``: ``t``.

        Returns
        -------
        float
            Metres (NaN: not corrected).
        """
        prior = math.nan if self.prior_m is None else self.prior_m
        if pid <= 0 or pid > len(self.plumes):
            return prior
        p = self.plumes[pid - 1]
        if t >= p.ready_s:  # its final estimate is decided
            if p.source != "estimated" or p.height_m is None:
                return prior
            if p.rise_mps is not None:  # a rising top, up to the highest height modelled
                when = t if at is None else at
                return float(min(p.height_m + p.rise_mps * (when - p.t_k), parallax.MAX_HEIGHT_M))
            return p.height_m
        known = [h for ready, h in p.stages if ready <= t]  # the estimates made on the way
        return known[-1] if known else prior

    def known_window(self, pid: int) -> tuple[float, float]:
        """When plume ``pid`` is aimed with a height (:meth:`height_at` not NaN), pass seconds.

        With a prior every plume is: ``(-inf, inf)``. Without one, from its first estimate
        made on the way (or its final one) until its final fit is rejected, if it is;
        ``(inf, inf)`` for a plume with no estimate (yet: a plume measured again on a later
        frame gets its window then). Pointings at the plume are flown only inside it
        (:class:`~dyntarget.schedule.ParallaxAim` ``known_s``): uncorrected, they would
        look kilometres from its top.

        Parameters
        ----------
        pid : int
            The plume (1-based; 0 or unknown: no plume, ``(-inf, inf)``: its pointings are
            not held).

        Returns
        -------
        tuple of float
            ``(from, until)``, pass seconds.

        Examples
        --------
        A plume given a two-look estimate at 12 s and its final one at 20 s is aimed with
        a height from 12 s on; had its final fit been rejected, only until 20 s.

        >>> from dyntarget.schedule import OrbitGeometry, get_agility
        >>> where = Geometry3D(OrbitGeometry(wfov_gsd_m=32.0), (4096, 64), 64, 4032, 4)
        >>> tracker = HeightTracker(where, get_agility("fast"), (300.0,), None, None, None,
        ...                         measure=True, log=print)
        >>> p = Plume(1, 0, 0.0, np.zeros(1, np.int64), np.zeros(1, np.int64),
        ...           height_m=9e3, source="estimated", ready_s=20.0, stages=[(12.0, 8e3)])
        >>> tracker.plumes.append(p)
        >>> tracker.known_window(1), tracker.known_window(0)
        ((12.0, inf), (-inf, inf))
        >>> p.source = "none"
        >>> tracker.known_window(1)
        (12.0, 20.0)
        """
        if self.prior_m is not None or pid <= 0 or pid > len(self.plumes):
            return -math.inf, math.inf
        p = self.plumes[pid - 1]
        final = p.source == "estimated" and p.height_m is not None
        start = min([ready for ready, _ in p.stages] + ([p.ready_s] if final else []),
                    default=math.inf)  # fmt: skip
        if not math.isfinite(start):
            return math.inf, math.inf
        return start, math.inf if final else max(p.ready_s, start)

    def estimates(self, true_height: Callable[[Plume], float | None]) -> tuple[HeightEstimate, ...]:
        """Every tracked plume's estimate (:class:`HeightEstimate`), in the order first seen.

        Parameters
        ----------
        true_height : callable
            ``true_height(plume) -> metres or None`` (the world's truth, where known).

        Returns
        -------
        tuple of HeightEstimate
        """
        w = self.where
        f = w.factor
        out = []
        for p in self.plumes:
            cy, cx = float(np.mean(p.rows)), float(np.mean(p.cols))
            if p.ground_xy is not None:
                gx, gy = p.ground_xy
            elif p.height_m is not None:  # the prior: the true position under the apparent one
                along = float(
                    parallax.sight_at_height(w.geometry.altitude_m, w.along(cy, p.t_k), p.height_m)
                )
                gx, gy = cx, w.nadir(p.t_k)[1] - along / w.geometry.wfov_gsd_m
            else:
                gx, gy = cx, cy
            out.append(
                HeightEstimate(
                    p.pid,
                    round(gx * f + (f - 1) / 2.0, 3),
                    round(gy * f + (f - 1) / 2.0, 3),
                    None if p.height_m is None else round(float(p.height_m), 1),
                    None if p.sigma_m is None else round(float(p.sigma_m), 1),
                    None if p.rise_mps is None else round(float(p.rise_mps), 2),
                    p.source,
                    true_height(p),
                    p.frame,
                    len(p.relooks),
                    None
                    if p.source != "estimated" or not math.isfinite(p.ready_s)
                    else round(p.ready_s, 4),
                    p.reason,
                )
            )
        return tuple(out)


def gains_on_ground(geometry: OrbitGeometry, agility: Agility, frame_px: int) -> bool:
    """Whether a look-ahead behind its frames catches up: a frame taken late (a whole
    frame's pitch step, settling and exposure) costs less than the time its ground takes to
    pass.

    Parameters
    ----------
    geometry : OrbitGeometry
        The pass's geometry (its look-ahead distance, WFOV pixel size and ground speed).
    agility : Agility
        The preset whose slew model, settle and dwell time a frame taken late.
    frame_px : int
        Frame height, WFOV rows.

    Returns
    -------
    bool
        True where the look-ahead gains on the ground.

    Examples
    --------
    At the default geometry an 8 km frame (256 rows of 32 m) passes in 1.16 s: ``fast``
    (0.1 s of settling) gains on it, ``slow`` (a second of settling and a slower slew)
    does not.

    >>> from dyntarget.schedule import get_agility
    >>> g = OrbitGeometry(wfov_gsd_m=32.0)
    >>> gains_on_ground(g, get_agility("fast"), 256), gains_on_ground(g, get_agility("slow"), 256)
    (True, False)
    """
    frame_m = frame_px * geometry.wfov_gsd_m
    step = _pitch_deg(geometry, geometry.look_ahead_m, geometry.look_ahead_m - frame_m)
    late_frame_s = agility.slew_time_one(step) + agility.settle_s + agility.dwell_s
    return late_frame_s < frame_m / geometry.ground_speed


def defers_cut(geometry: OrbitGeometry, frame_px: int, defer: bool | None) -> bool:
    """Whether a pass holds the pointings a frame plans on a plume its top edge cuts, for
    the first frame that sees the plume whole (``PassConfig.defer_cut``).

    Parameters
    ----------
    geometry : OrbitGeometry
        The pass's geometry (its WFOV pixel size).
    frame_px : int
        Frame height, WFOV rows.
    defer : bool or None
        Asked for (``True``), refused (``False``) or ``None``: held where a frame is
        shorter along track than :data:`DEFER_CUT_BELOW_M` (most plumes it shows are cut).

    Returns
    -------
    bool
        True where the pass holds them.

    Examples
    --------
    With 32 m WFOV pixels a 2 km frame (64 rows) holds them, a 4 km frame (128 rows) does
    not, unless asked.

    >>> g = OrbitGeometry(wfov_gsd_m=32.0)
    >>> defers_cut(g, 64, None), defers_cut(g, 128, None), defers_cut(g, 128, True)
    (True, False, True)
    >>> defers_cut(g, 64, False)
    False
    """
    if defer is not None:
        return bool(defer)
    return frame_px * geometry.wfov_gsd_m < DEFER_CUT_BELOW_M


def holds_relooks(
    geometry: OrbitGeometry, agility: Agility, frame_px: int, catch_up: bool, hold: bool | None
) -> bool:
    """Whether a pass's look-ahead holds its re-looks' pitch (the module docstring's
    "Holding").

    Parameters
    ----------
    geometry, agility, frame_px
        As :func:`gains_on_ground`.
    catch_up : bool
        Whether catching up is asked for.
    hold : bool or None
        Asked for (``True``), refused (``False``) or ``None``: held where catching up is
        asked for and the look-ahead cannot gain on the ground (the frames due during a
        re-look would otherwise be lost); with ``catch_up=False`` they are lost, as asked.

    Returns
    -------
    bool
        True where it holds.

    Examples
    --------
    >>> from dyntarget.schedule import get_agility
    >>> g, slow, fast = OrbitGeometry(wfov_gsd_m=32.0), get_agility("slow"), get_agility("fast")
    >>> holds_relooks(g, slow, 256, True, None), holds_relooks(g, fast, 256, True, None)
    (True, False)
    >>> holds_relooks(g, slow, 256, False, None), holds_relooks(g, fast, 256, True, True)
    (False, True)
    """
    if hold is not None:
        return bool(hold)
    return catch_up and not gains_on_ground(geometry, agility, frame_px)


def _reach_m(geometry: OrbitGeometry, agility: Agility) -> float:
    """Ground distance ahead of the nadir at which the NFOV's field of regard begins, m
    (0 without one): ``R (asin((R + H) sin(a) / R) - a)`` for an off-nadir angle ``a``."""
    if agility.field_of_regard_deg is None:
        return 0.0
    a, r = math.radians(agility.field_of_regard_deg), EARTH_RADIUS_M
    return r * (math.asin((r + geometry.altitude_m) * math.sin(a) / r) - a)


def held_part(
    search: tuple[float, float], offset: int, rows: tuple[int, int], frame_px: int
) -> tuple[float, float] | None:
    """The part of a search a frame of a mosaic holds, to search it there.

    Parameters
    ----------
    search : tuple of float
        ``(centre, half-width)``: rows an envelope moved since the first look, searched.
    offset : int
        The frame's top row less the first look's frame's top row.
    rows : tuple of int
        The envelope's first and last rows in the first look's frame.
    frame_px : int
        Frame rows.

    Returns
    -------
    tuple of float or None
        ``(centre, half-width)`` of the rows moved at which the envelope lies wholly in the
        frame, within the search, searched 2 rows past (a peak on its edge is then seen);
        ``None`` where there are none.

    Examples
    --------
    An envelope on rows 10-15, searched 120 +- 100 rows on, in a 128-row frame 100 rows
    further down (it holds the envelope from 90 to 212 rows on):

    >>> held_part((120.0, 100.0), 100, (10, 15), 128)
    (151.0, 63.0)
    >>> held_part((120.0, 100.0), 400, (10, 15), 128) is None
    True
    """
    centre, half = search
    lo = max(centre - half, offset - rows[0])
    hi = min(centre + half, offset + frame_px - 1 - rows[1])
    if lo > hi:
        return None
    return 0.5 * (lo + hi), 0.5 * (hi - lo) + 2.0


def _pitch_deg(geometry: OrbitGeometry, from_m: float, to_m: float) -> float:
    """Degrees between the look-ahead's lines of sight to ground ``from_m`` and ``to_m``
    ahead of the nadir (the pitch change between two looks; exactly 0 between two looks at
    the same distance, where the arccosine of the unit vectors' dot product gives about
    1e-6 degrees of rounding, and with it a slew and a settle)."""
    if from_m == to_m:
        return 0.0
    a = look_vectors(geometry, np.array([from_m, to_m]), np.zeros(2), 0.0)
    return float(angle_between_deg(a[0], a[1]))
