"""Prediction on the moving-world generator (dyntarget.synth.dynamic) and the evaluation modes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget.evaluate.dynamic import DynamicConfig, evaluate_dynamic
from dyntarget.evaluate.options import RunOptions
from dyntarget.predict import estimate_motion, predict_mask
from dyntarget.synth.dynamic import CloudSpec, VentSpec, Wind, World, WorldSpec, world_sequence

GSD = 8.0


def _world(wind, vents=(), clouds=(), size=256, seed=5):
    spec = WorldSpec(
        seed=seed, size=size, gsd=GSD, wind=wind, vents=tuple(vents), clouds=tuple(clouds)
    )
    return World(spec)


def _upwind_end(mask, u):
    ys, xs = np.nonzero(mask)
    s = xs * u[0] + ys * u[1]
    near = s <= s.min() + 1.0
    return np.array([xs[near].mean(), ys[near].mean()])


@pytest.mark.slow
def test_young_attached_plume_vent_end_predicted_within_2_px():
    # a young plume (60 s old) in 10 m/s from the west: the front advances 1.25 px/s
    vent = VentSpec(
        x=30.0, y=128.0, eruption_age_s=60.0, gustiness=0.0, meander=0.0, pulsation=0.0,
        fade_s=900.0,
    )  # fmt: skip
    world = _world(Wind(10.0, 270.0), vents=[vent])
    a, b = world.render(0.0), world.render(10.0)
    m = estimate_motion(a.image, b.image, 10.0, previous_mask=a.mask, current_mask=b.mask)
    assert m.regime == "attached", m.summary()
    assert m.velocity[0] == pytest.approx(10.0 / GSD, rel=0.1)
    lead = 60.0
    predicted = predict_mask(b.mask, m, lead)
    truth, _ = world.truth(10.0 + lead)
    u = np.array([1.0, 0.0])
    assert np.hypot(*(_upwind_end(predicted, u) - _upwind_end(truth, u))) <= 2.0
    # the front advanced with the wind; the prediction stretched with it
    far = lambda mask: np.nonzero(mask.any(axis=0))[0].max()  # noqa: E731
    assert abs(far(predicted) - far(truth)) <= 0.15 * (10.0 / GSD) * lead


@pytest.mark.slow
def test_predictive_mode_recovers_a_drifting_cloud_where_static_loses_it(tmp_path):
    # one detached volcanic cloud per scene, 5 m/s, 90 s latency: it moves 450 m = 28 WFOV px
    seqs = []
    for i, (x, y, d) in enumerate([(70, 90, 270.0), (120, 80, 180.0), (100, 120, 90.0)]):
        cloud = CloudSpec(x=float(x), y=float(y), radius_m=180.0, optical_depth=3.0)
        world = _world(Wind(5.0, d), clouds=[cloud], size=192, seed=11 + i)
        seqs.append(world_sequence(world, frames=2, interval_s=10.0))
    config = DynamicConfig(
        folds=3, classifiers=(), true_mask=True, planners=("lawnmower-transect", "track-center"),
        modes=("static", "predictive", "wind-prior"), latencies=(0.0, 90.0), factor=2,
    )  # fmt: skip
    rows = evaluate_dynamic(seqs, config, options=RunOptions(progress=False))["rows"]
    ratio = {(r["mode"], r["planner"], r["latency_s"]): r["ratio_plume"] for r in rows}
    for planner in ("lawnmower-transect", "track-center"):
        zero = ratio[("static", planner, 0.0)]
        assert ratio[("static", planner, 90.0)] < 0.5 * zero  # the cloud has left the plan
        assert ratio[("predictive", planner, 90.0)] >= 0.9 * zero
        assert ratio[("wind-prior", planner, 90.0)] >= 0.9 * zero
        # zero latency: prediction changes nothing
        assert ratio[("predictive", planner, 0.0)] == pytest.approx(zero)
    assert math.isfinite(zero)
