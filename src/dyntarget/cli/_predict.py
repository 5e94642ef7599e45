"""``dyntarget plan`` prediction options: two looks (``--previous``) or a wind prior.

The plan is drawn for the plume as predicted ``--lead-s`` seconds after the
current image was taken (see ``docs/onboard.md``, "Predictive targeting").
"""

from __future__ import annotations

import argparse

from dyntarget.cli import options as o
from dyntarget.cli._common import log


def add_predict_options(p: argparse.ArgumentParser) -> None:
    """The ``prediction`` option group of ``dyntarget plan``."""
    g = p.add_argument_group(
        "prediction (plan for the plume as it will be; two looks and/or a wind prior)"
    )
    g.add_argument("--previous", help="the previous look-ahead frame (same grid and CRS)")
    g.add_argument(
        "--previous-mask", help="plume mask of --previous (with --mask; --model classifies it)"
    )
    g.add_argument(
        "--interval-s",
        type=o.float_range(o.MIN_INTERVAL_S, o.MAX_SECONDS, "seconds"),
        help="seconds from --previous to the image",
    )
    g.add_argument(
        "--lead-s",
        type=o.seconds,
        help="plan for the plume this many seconds after the image was taken "
        "(with --agility each pointing is moved on to its own scheduled time)",
    )
    o.add_wind_options(g)
    o.GROUND.add(
        g,
        help="with --previous: is the background a fixed ground (its shift is misregistration, "
        "removed) or moving itself (weather, radar, a plume over moving cloud)? auto "
        "(default) decides from the frames and says so",
    )
    g.add_argument(
        "--regime",
        choices=["detached", "attached"],
        default="detached",
        help="with the wind prior alone: how the plume moves (default detached: see docs)",
    )


def wants_prediction(args: argparse.Namespace) -> bool:
    """Whether any prediction option was given (then they are checked together)."""
    names = ("previous", "previous_mask", "interval_s", "lead_s", "wind_mps", "wind_from_deg")
    return any(getattr(args, n) is not None for n in names)


def _check_args(args: argparse.Namespace) -> None:
    from dyntarget.errors import InvalidParameterError
    from dyntarget.predict import MAX_LEAD_INTERVALS, check_interval, check_lead

    two_looks = args.previous is not None
    wind = args.wind_mps is not None or args.wind_from_deg is not None
    if args.interval_s is not None and not two_looks:
        raise InvalidParameterError(
            "--previous: missing; --interval-s is the time between --previous and the image"
        )
    if args.previous_mask is not None and not two_looks:
        raise InvalidParameterError("--previous: missing; --previous-mask is its mask")
    if wind and (args.wind_mps is None or args.wind_from_deg is None):
        raise InvalidParameterError("wind prior: give both --wind-mps and --wind-from-deg")
    if not (two_looks or wind):
        raise InvalidParameterError(
            "--lead-s: a prediction needs --previous PREVIOUS.tif --interval-s S "
            "or --wind-mps M --wind-from-deg D"
        )
    if args.lead_s is None:
        raise InvalidParameterError("--lead-s: missing; seconds after the image to plan for")
    check_lead(args.lead_s)
    if two_looks:
        if args.interval_s is None:
            raise InvalidParameterError(
                f"--interval-s: missing; seconds from {args.previous} to the image"
            )
        check_interval(args.interval_s)
        limit = MAX_LEAD_INTERVALS * args.interval_s
        if args.lead_s > limit:
            raise InvalidParameterError(
                f"--lead-s {args.lead_s:g}: two looks {args.interval_s:g} s apart support a lead "
                f"of at most {MAX_LEAD_INTERVALS} intervals ({limit:g} s)"
            )
        if args.mask is not None and args.previous_mask is None:
            raise InvalidParameterError(
                "--previous-mask: missing; with --mask give the previous frame's mask too "
                "(or use --model to classify both)"
            )


def _read_previous(args: argparse.Namespace, wfov):
    from dyntarget.errors import InvalidSceneError
    from dyntarget.io.sensors import read_any

    options = dict(
        bands=args.bands, preset=args.preset, scale=args.scale, offset=args.offset,
        factor=args.factor,
    )  # fmt: skip
    # The frames are checked against each other before the previous mask is read onto
    # the previous frame's grid, so a mismatch is named as such.
    _check_previous_header(args, wfov)
    prev = read_any([args.previous], **options)
    if prev.shape != wfov.shape:
        raise InvalidSceneError(
            f"--previous {args.previous}: {prev.shape[0]} x {prev.shape[1]} px does not match "
            f"the image's {wfov.shape[0]} x {wfov.shape[1]} px (frames must share a grid)"
        )
    if _crs_key(prev.crs) != _crs_key(wfov.crs):
        raise InvalidSceneError(
            f"--previous {args.previous}: CRS {prev.crs} does not match the image's {wfov.crs}"
        )
    _check_same_grid(args.previous, prev.transform, wfov.transform)
    if args.previous_mask is not None:
        prev = read_any([args.previous], label=args.previous_mask, **options)
    return prev


def _check_previous_header(args: argparse.Namespace, wfov) -> None:
    """Size and acquisition time of ``--previous`` checked before a pixel of it is read."""
    from dyntarget.errors import InvalidParameterError, InvalidSceneError
    from dyntarget.io.acquisition import read_acquired
    from dyntarget.io.safeopen import check_regular, raster_size

    check_regular(args.previous, what="--previous")
    size = raster_size(args.previous) if args.previous.lower().endswith((".tif", ".tiff")) else None
    if size is not None:
        h, w = size[0] // args.factor, size[1] // args.factor
        if (h, w) != tuple(wfov.shape):
            raise InvalidSceneError(
                f"--previous {args.previous}: {h} x {w} px at factor {args.factor} does not "
                f"match the image's {wfov.shape[0]} x {wfov.shape[1]} px (frames must share a grid)"
            )
    then, now = read_acquired(args.previous), read_acquired(args.image[0])
    if then is None or now is None:
        return
    dt = (now - then).total_seconds()
    if dt <= 0:
        raise InvalidParameterError(
            f"--previous {args.previous}: acquired {then.isoformat()}, {-dt:g} s after the "
            f"image ({now.isoformat()}); expected the earlier frame"
        )
    if abs(dt - args.interval_s) > max(1.0, 0.1 * args.interval_s):
        raise InvalidParameterError(
            f"--interval-s {args.interval_s:g}: the files' times are {dt:g} s apart "
            f"({then.isoformat()} -> {now.isoformat()}); give --interval-s {dt:g}"
        )


def _check_same_grid(previous: str, then, now) -> None:
    """Refuse a previous frame on another grid: other pixel size, rotation or origin.

    Two looks are differenced pixel by pixel, so both must map pixel ``(col, row)`` to the
    same ground point (to a thousandth of a pixel).
    """
    from dyntarget.errors import InvalidSceneError

    if then is None and now is None:
        return
    if then is None or now is None:
        which = "it has no georeferencing" if then is None else "the image has none"
        raise InvalidSceneError(
            f"--previous {previous}: {which} and the other has; frames must share a grid"
        )
    scale = max(abs(now.a), abs(now.b), abs(now.d), abs(now.e)) or 1.0
    if (
        max(abs(then.a - now.a), abs(then.b - now.b), abs(then.d - now.d), abs(then.e - now.e))
        > 1e-6 * scale
    ):
        if abs(then.b) + abs(then.d) > 1e-9 * scale or abs(now.b) + abs(now.d) > 1e-9 * scale:
            what = "rotated or sheared against the image's"
        else:
            what = f"{abs(then.a):g} x {abs(then.e):g} pixels, the image's {abs(now.a):g} x {abs(now.e):g}"
        raise InvalidSceneError(
            f"--previous {previous}: another grid ({what}); frames must share a grid"
        )
    inv = ~now
    dx = inv.a * then.c + inv.b * then.f + inv.c  # the previous origin in the image's pixels
    dy = inv.d * then.c + inv.e * then.f + inv.f
    if max(abs(dx), abs(dy)) > 1e-3:
        raise InvalidSceneError(
            f"--previous {previous}: its grid is shifted by ({dx:+.3f}, {dy:+.3f}) px from the "
            "image's; frames must share a grid"
        )


def _crs_key(crs) -> str | None:
    if crs is None:
        return None
    from rasterio.crs import CRS

    return CRS.from_user_input(crs).to_wkt()


def _mask_of(scene, classifier, threshold: float):
    """``(raw, denoised)`` plume mask of a look: its label, or the classifier's (the pipeline's
    segment stage, so the motion sees the masks the plan is drawn on)."""
    from dyntarget.pipeline import PipelineConfig, segment

    seg = segment(
        scene.image, classifier, mask=scene.label, valid=scene.valid,
        config=PipelineConfig(threshold=threshold),
    )  # fmt: skip
    return seg.raw_mask, seg.mask


def prediction_for(args: argparse.Namespace, wfov, classifier, threshold: float):
    """``(Prediction, current raw mask or None)`` from the options; logs the motion seen.

    With ``--model`` the current image is classified here (once) and its raw
    mask returned, so the pipeline plans on it without classifying again.
    """
    from dyntarget.errors import InvalidParameterError
    from dyntarget.predict import LOW_CONFIDENCE, Prediction, plume_motion, wind_motion

    _check_args(args)
    prior = None
    if args.wind_mps is not None:
        gsd = args.wfov_gsd or wfov.gsd
        transform = wfov.transform
        if wfov.crs is not None and transform is not None:
            from rasterio.crs import CRS

            if CRS.from_user_input(wfov.crs).is_geographic:
                transform = None  # degrees: use the GSD and assume north-up
                if gsd is None:
                    raise InvalidParameterError(
                        f"{args.image[0]}: CRS {wfov.crs} is in degrees; give --wfov-gsd METRES"
                    )
        prior = wind_motion(
            args.wind_mps, args.wind_from_deg, transform=transform, gsd_m=gsd,
            regime=args.regime,
        )  # fmt: skip
    current_raw, looks = None, None
    if args.previous is not None:
        prev = _read_previous(args, wfov)
        _, prev_mask = _mask_of(prev, classifier, threshold)
        current_raw, cur_mask = _mask_of(wfov, classifier, threshold)
        looks = (prev.image, wfov.image, prev_mask, cur_mask)
    motion = plume_motion(
        prior, looks, args.interval_s or 0.0, ground=getattr(args, "ground", "auto")
    )
    if motion is None:  # _check_args asks for --previous or --wind-mps
        raise InvalidParameterError("--predict: give --previous or --wind-mps")
    log(f"motion: {motion.summary()}")
    if motion.fallback:
        log(
            f"motion: FALLBACK to {motion.fallback} (confidence {motion.confidence:.2f} < "
            f"{LOW_CONFIDENCE}): the plan is drawn on the plume where it is now"
        )
    elif not motion.reliable:
        log("motion: LOW CONFIDENCE; the prediction may be wrong (see docs/onboard.md)")
    if wfov.label is not None:
        current_raw = None  # the pipeline reads the given mask itself
    return Prediction(motion, args.lead_s), current_raw


def prediction_record(prediction) -> dict:
    """What the GeoJSON outputs say about the prediction the plan was drawn on: the lead,
    the motion (:meth:`dyntarget.predict.Motion.to_dict`, with ``fallback`` set when the
    estimate was too unsure and the plume was not moved) and one line of it."""
    return {
        "lead_s": float(prediction.lead_s),
        "summary": prediction.motion.summary(),
        **prediction.motion.to_dict(),
    }
