"""The predict stage's entry point: the plume's motion for a plan, from a wind prior, two looks or both.

:func:`plume_motion` is what every caller asks (``plan --previous/--wind-mps``, the pass
loop's ``--predict``, ``evaluate dynamic``): two looks checked against the prior
when there are two looks (:func:`two_look_motion`), else the prior alone.
:func:`~dyntarget.predict.motion.lucas_kanade` is the one wrapper of pysteps'
Lucas-Kanade motion field (``estimate_motion(flow="lk")`` and the GEO nowcast's velocity).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.predict.motion import Motion


def two_look_motion(
    previous: np.ndarray,
    current: np.ndarray,
    interval_s: float,
    *,
    previous_mask: np.ndarray,
    current_mask: np.ndarray,
    prior: Motion | None = None,
    offset_rows: int = 0,
    **motion_options: Any,
) -> Motion:
    """The plume's motion from two looks, checked against a prior.

    :func:`dyntarget.predict.estimate_motion` on the two images and their
    (denoised) masks, then, with a ``prior`` (a wind),
    :func:`dyntarget.predict.check_against_prior`.

    Parameters
    ----------
    previous, current : numpy.ndarray
        ``(4, H, W)`` looks, ``interval_s`` apart.
    interval_s : float
        Seconds from ``previous`` to ``current``.
    previous_mask, current_mask : numpy.ndarray
        Boolean ``(H, W)`` plume masks of the looks (denoised as planned on).
    prior : dyntarget.predict.Motion or None
        A prior (e.g. :func:`~dyntarget.predict.wind_motion`) the estimate is
        checked against.
    offset_rows : int
        Consecutive frames of a pass: ``previous`` lies this many rows below
        ``current`` (image "up" is the flight direction). Only the rows both saw
        are compared (``previous``'s first ``H - offset_rows`` rows against
        ``current``'s last), and the positions found there (``vent``, the attached
        plumes) are given in ``current``'s rows.
    **motion_options
        Passed on to :func:`~dyntarget.predict.estimate_motion` (e.g. ``flow=``).

    Returns
    -------
    dyntarget.predict.Motion
        In ``current``'s pixels.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For an ``offset_rows`` that leaves no row seen twice.

    Examples
    --------
    >>> import cv2
    >>> rng = np.random.default_rng(0)
    >>> tex = cv2.GaussianBlur(rng.random((96, 96)).astype(np.float32), (0, 0), 2)
    >>> ground = np.repeat(0.1 + 0.1 * tex[None], 4, 0)
    >>> def frame(x0):
    ...     img, m = ground.copy(), np.zeros((96, 96), bool)
    ...     m[30:60, x0:x0 + 30] = True
    ...     img[:, m] = 0.6 + 0.6 * np.roll(tex, x0 - 20, axis=1)[m]
    ...     return img, m
    >>> (a, ma), (b, mb) = frame(20), frame(24)     # a cloud 4 px further east 2 s later
    >>> m = two_look_motion(a, b, 2.0, previous_mask=ma, current_mask=mb)
    >>> m.source, m.regime, round(m.velocity[0], 1)
    ('two-looks', 'detached', 2.0)
    """
    # its functions looked up at call time (patchable in tests)
    from dyntarget.predict import motion

    h = np.shape(current)[-2]
    if isinstance(offset_rows, bool) or not isinstance(offset_rows, int | np.integer):
        raise InvalidParameterError(f"offset_rows: expected an integer, got {offset_rows!r}")
    if not 0 <= offset_rows < h:
        raise InvalidParameterError(
            f"offset_rows: expected 0 <= offset < {h} rows (some rows seen twice), got {offset_rows}"
        )
    overlap = h - offset_rows
    est = motion.estimate_motion(
        np.asarray(previous)[:, :overlap],
        np.asarray(current)[:, offset_rows:],
        interval_s,
        previous_mask=np.asarray(previous_mask)[:overlap],
        current_mask=np.asarray(current_mask)[offset_rows:],
        **motion_options,
    )
    if offset_rows:  # from the overlap's rows to the current frame's
        dense = est.dense
        if dense is not None:  # its cells where they are in the current frame, on its grid
            x0, y0 = dense.origin
            dense = replace(dense, origin=(x0, y0 + offset_rows), shape=(h, dense.shape[1]))
        est = replace(
            est,
            vent=None if est.vent is None else (est.vent[0], est.vent[1] + offset_rows),
            attached=tuple((x, y + offset_rows, r) for x, y, r in est.attached),
            dense=dense,
        )
    return est if prior is None else motion.check_against_prior(est, prior)


def plume_motion(
    prior: Motion | None,
    looks: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
    interval_s: float = 0.0,
    *,
    offset_rows: int = 0,
    ground: str = "auto",
) -> Motion | None:
    """The plume's motion for a plan: two looks checked against the prior, or the prior.

    The one entry point of the predict stage: the CLI (``plan --previous``, ``--wind-mps``)
    and the pass loop (``fly --predict``) ask it.

    Parameters
    ----------
    prior : dyntarget.predict.Motion or None
        A wind prior (:func:`~dyntarget.predict.wind_motion`), or none.
    looks : tuple of numpy.ndarray or None
        ``(previous, current, previous_mask, current_mask)``: two ``(4, H, W)`` looks
        and their denoised masks; ``None``: one look only (the prior is the motion).
    interval_s : float
        Seconds from the previous look to the current one.
    offset_rows : int
        Rows the previous look lies below the current one (a pass's frames;
        :func:`two_look_motion`).
    ground : {"auto", "fixed", "moving"}
        The background (:func:`~dyntarget.predict.estimate_motion`).

    Returns
    -------
    dyntarget.predict.Motion or None
        ``None`` only without looks and without a prior.

    Examples
    --------
    >>> from dyntarget.predict import wind_motion
    >>> plume_motion(None) is None
    True
    >>> plume_motion(wind_motion(8.0, 270.0, gsd_m=8.0)).velocity   # one look: the wind
    (1.0, 0.0)
    """
    if looks is None:
        return prior
    previous, current, previous_mask, current_mask = looks
    return two_look_motion(
        previous,
        current,
        interval_s,
        previous_mask=previous_mask,
        current_mask=current_mask,
        prior=prior,
        offset_rows=offset_rows,
        ground=ground,
    )
