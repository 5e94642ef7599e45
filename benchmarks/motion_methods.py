"""Plume motion from two looks: OpenCV DIS and Farneback against pysteps (LK, DARTS, VET).

Accuracy on the prediction tests' analytic worlds (``tests/motion_worlds.py``:
rigidly drifting textured clouds over a fixed textured ground, an attached
plume, calm air) and wall time at 1024 x 1024 px. DIS and Farneback run inside
:func:`dyntarget.predict.estimate_motion` (ground registration, texture votes,
confidence); pysteps' motion fields are reduced the same simple way (median over
the previous mask's interior minus the median over the ground) since pysteps has
no notion of a plume. pysteps is optional: install it where it is wanted
(``pip install --no-deps --target DIR pysteps jsmin`` and ``PYTHONPATH=DIR``);
absent, its rows say so.

    PYTHONPATH=src:tests python benchmarks/motion_methods.py \\
        [--size 1024] [--vet-size 256] [--out docs/benchmarks/motion_methods.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from pathlib import Path

import cv2
import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.tables import markdown_table
from dyntarget.predict import Motion, brightness, estimate_motion, predict_mask
from motion_worlds import AttachedPlume, RigidCloud

INTERVAL = 10.0
CASES = {
    "cloud (0.3, -0.16)": lambda: RigidCloud(velocity=(0.3, -0.16)),
    "cloud (-0.5, 0)": lambda: RigidCloud(velocity=(-0.5, 0.0)),
    "cloud (0.14, 0.38)": lambda: RigidCloud(velocity=(0.14, 0.38)),
    "attached (0.4, 0.2)": lambda: AttachedPlume(velocity=(0.4, 0.2)),
    "calm": lambda: RigidCloud(velocity=(0.0, 0.0)),
    "texture-poor (0.3, -0.16)": lambda: RigidCloud(velocity=(0.3, -0.16), textured=False),
}
WORLDS = 6
"""Moving-world scenes (dyntarget.synth.dynamic, 10 m/s, WFOV 128 px at 32 m) also scored."""


class _WorldCase:
    """A moving-world scene seen at WFOV (factor 4) with the same interface as the test worlds."""

    def __init__(self, index: int) -> None:
        from dyntarget.synth.dynamic import World, sample_world, world_sequence

        spec = sample_world(0, index, size=512, gsd=8.0, wind_mps=10.0)
        seq = world_sequence(World(spec), frames=2, interval_s=INTERVAL).to_wfov(4)
        self.v = spec.wind.velocity_px(spec.gsd * 4)
        self._frames = {0.0: seq.frames[0], INTERVAL: seq.frames[1]}

    def frame(self, t: float) -> np.ndarray:
        return self._frames[t].image

    def mask(self, t: float) -> np.ndarray:
        return self._frames[t].label


def _pysteps():
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import pysteps  # noqa: F401
            from pysteps import motion
        return motion
    except ImportError:
        return None


def _pysteps_velocity(motion, name, prev, cur, pm, cm, dt):
    a, b = brightness(prev), brightness(cur)
    lo, hi = np.percentile(np.concatenate([a.ravel(), b.ravel()]), [1, 99])
    stack = np.clip((np.stack([a, b]) - lo) / (hi - lo), 0, 1).astype(np.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kwargs = {"N_t": 0} if name == "DARTS" else {}  # two frames: no temporal terms
        v = motion.get_method(name)(stack, verbose=False, **kwargs)
    inner = cv2.erode(pm.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    ground = ~(cv2.dilate((pm | cm).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0)
    vx = np.median(v[0][inner]) - (np.median(v[0][ground]) if ground.any() else 0)
    vy = np.median(v[1][inner]) - (np.median(v[1][ground]) if ground.any() else 0)
    return float(vx) / dt, float(vy) / dt


def _methods(steps, with_vet):
    out = {
        "opencv DIS": lambda p, c, pm, cm: estimate_motion(
            p, c, INTERVAL, previous_mask=pm, current_mask=cm, flow="dis"
        ),
        "opencv Farneback (default)": lambda p, c, pm, cm: estimate_motion(
            p, c, INTERVAL, previous_mask=pm, current_mask=cm, flow="farneback"
        ),
    }
    for name in ("LK", "DARTS", "VET") if with_vet else ("LK", "DARTS"):
        if steps is None:
            out[f"pysteps {name}"] = None
        else:
            out[f"pysteps {name}"] = lambda p, c, pm, cm, n=name: _pysteps_velocity(
                steps, n, p, c, pm, cm, INTERVAL
            )
    return out


def _velocity(result):
    return result.velocity if hasattr(result, "velocity") else result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024, help="image size of the timing run")
    ap.add_argument("--vet-size", type=int, default=256, help="VET is timed at this size")
    ap.add_argument(
        "--with-vet", action="store_true", help="also pysteps VET (minutes per 128-px case)"
    )
    ap.add_argument("--out", default="docs/benchmarks/motion_methods.json")
    args = ap.parse_args()
    steps = _pysteps()
    methods = _methods(steps, args.with_vet)
    rows = []
    cases = dict(CASES)
    for i in range(WORLDS):
        cases[f"moving world {i}"] = lambda i=i: _WorldCase(i)
    for case, make in cases.items():
        world = make()
        truth = np.asarray(world.v, float)
        prev, cur = world.frame(0.0), world.frame(INTERVAL)
        pm, cm = world.mask(0.0), world.mask(INTERVAL)
        for name, fn in methods.items():
            if fn is None:
                rows.append({"case": case, "method": name, "note": "pysteps not installed"})
                continue
            try:
                res = fn(prev, cur, pm, cm)
            except Exception as exc:  # a method that cannot run on two frames says why
                rows.append({"case": case, "method": name, "note": f"failed: {exc}"[:120]})
                continue
            v = np.asarray(_velocity(res))
            err = float(math.hypot(*(v - truth)))
            speed = float(math.hypot(*truth))
            rows.append(
                {
                    "case": case,
                    "method": name,
                    "vx": round(float(v[0]), 3),
                    "vy": round(float(v[1]), 3),
                    "error_px_s": round(err, 3),
                    "error_pct": round(100 * err / speed, 1) if speed else None,
                    "confidence": round(res.confidence, 2) if hasattr(res, "confidence") else None,
                    "regime": getattr(res, "regime", None),
                }
            )
            print(rows[-1], flush=True)
    timing = []
    for name, fn in methods.items():
        if fn is None:
            continue
        size = args.vet_size if name.endswith("VET") else args.size
        r = size / 1024
        world = RigidCloud(
            size=size, velocity=(0.3, -0.16), centre=(400 * r, 500 * r), radius=150 * r
        )
        prev, cur = world.frame(0.0), world.frame(INTERVAL)
        pm, cm = world.mask(0.0), world.mask(INTERVAL)
        best = math.inf
        for _ in range(1 if name.endswith("VET") else 3):
            t0 = time.perf_counter()
            fn(prev, cur, pm, cm)
            best = min(best, time.perf_counter() - t0)
        timing.append({"method": name, "size_px": size, "seconds": round(best, 3)})
        print(timing[-1], flush=True)
    # the prediction itself at the timing size: a plume mask carried 90 s ahead
    r = args.size / 1024
    world = RigidCloud(
        size=args.size, velocity=(0.3, -0.16), centre=(400 * r, 500 * r), radius=150 * r
    )
    mask = world.mask(INTERVAL)
    for regime in ("detached", "attached"):
        motion = Motion((0.3, -0.16), regime=regime)
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            predict_mask(mask, motion, 90.0)
            best = min(best, time.perf_counter() - t0)
        timing.append(
            {
                "method": f"predict_mask ({regime}, 90 s)",
                "size_px": args.size,
                "seconds": round(best, 3),
            }
        )
        print(timing[-1], flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"machine": machine(), "interval_s": INTERVAL, "accuracy": rows, "timing": timing}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    md = (
        "## Accuracy (velocity error, px/s and % of the true speed)\n\n"
        + markdown_table(
            rows,
            [
                "case",
                "method",
                "vx",
                "vy",
                "error_px_s",
                "error_pct",
                "confidence",
                "regime",
                "note",
            ],
        )
        + "\n\n## Wall time (best of 3; VET once): estimate_motion per flow, and the prediction\n\n"
        + markdown_table(timing, ["method", "size_px", "seconds"])
        + "\n"
    )
    out.with_suffix(".md").write_text(md)
    print(out, out.with_suffix(".md"))


if __name__ == "__main__":
    main()
