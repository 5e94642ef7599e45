"""The pass loop: frames, latency, one shared NFOV, no plume covered twice."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.fly import PassConfig, fly_pass, frame_plan
from dyntarget.scene import Scene
from dyntarget.synth.worlds import StaticWorld, WorldBase
from dyntarget.view.pass_report import TIMELINE, timeline_csv, write_pass

GSD = 8.0  # high-res m/px; WFOV (factor 4) 32 m/px


def _strip(plumes, *, rows=1024, cols=128) -> StaticWorld:
    """Dark ground with bright rectangular plumes ``(row0, row1, col0, col1)`` (high-res px)."""
    image = np.full((4, rows, cols), 0.05, np.float32)
    label = np.zeros((rows, cols), bool)
    for r0, r1, c0, c1 in plumes:
        label[r0:r1, c0:c1] = True
    image[:, label] = 0.8
    return StaticWorld(Scene(image, label=label, gsd=GSD, id="strip"))


def _ground_speed(altitude_m: float) -> float:
    # circular orbit, spherical Earth: v_ground = sqrt(GM / r) * R / r
    r_earth, gm = 6_371_000.0, 3.986004418e14
    r = r_earth + altitude_m
    return math.sqrt(gm / r) * r_earth / r


def test_frames_cut_bottom_first_at_the_cadence():
    world = _strip([])
    fp = frame_plan(world, PassConfig(factor=4, overlap=0.5))
    # 1024/4 = 256 WFOV rows, frames 32 px high (strip width), step 16 rows
    assert fp.frame_px == 32 and fp.step == 16
    assert fp.tops[0] == 256 - 32 and fp.tops[-1] == 0 and len(fp.tops) == 15
    # 16 rows x 32 m at the ground speed from 500 km (about 7.06 km/s)
    assert fp.cadence_s == pytest.approx(16 * 32.0 / _ground_speed(500e3), rel=1e-9)
    assert fp.cadence_s == pytest.approx(512.0 / 7060.0, rel=1e-3)


def test_timeline_is_deterministic_with_a_compute_budget(tmp_path):
    world = _strip([(600, 680, 20, 80), (200, 260, 40, 100)])
    config = PassConfig(agility="fast", compute_budget_s=0.1, planner="lawnmower-transect")
    a = fly_pass(world, None, config)
    b = fly_pass(world, None, config)
    assert timeline_csv(a) == timeline_csv(b)
    write_pass(a, world, tmp_path / "a", picture=False)
    write_pass(b, world, tmp_path / "b", picture=False)
    for name in (TIMELINE, "pointings.geojson", "summary.md"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    # latency: the budget is longer than the cadence, so frame k waits for frame k-1:
    # ready_k = (k + 1) * budget, latency_k = ready_k - k * cadence (worked by hand)
    cadence = a.frames.cadence_s
    for rec in a.records:
        k = rec.frame
        assert rec.acquired_s == pytest.approx(k * cadence)
        assert rec.ready_s == pytest.approx((k + 1) * 0.1)
        assert rec.latency_s == pytest.approx((k + 1) * 0.1 - k * cadence)
    # stage columns are left empty with a fixed budget (measured times are not reproducible)
    row = timeline_csv(a).splitlines()[1].split(",")
    header = timeline_csv(a).splitlines()[0].split(",")
    assert row[header.index("classify_s")] == ""


def test_a_plume_seen_by_two_frames_is_covered_once():
    # WFOV rows 226..238 lie in frame 0 (rows 224..256) and frame 1 (rows 208..240)
    world = _strip([(904, 952, 40, 80)])
    config = PassConfig(agility="unlimited", compute_budget_s=0.01)
    result = fly_pass(world, None, config)
    r0, r1 = result.records[0], result.records[1]
    assert r0.planned > 0 and r1.planned > 0  # both frames saw it and planned on it
    assert r0.flown == r0.planned
    assert r1.flown == 0 and r1.skipped_covered == r1.planned
    # every flown pointing on a distinct strip pixel, all from frame 0
    # the pixel holding a point (centres on integers; x.5 goes up, not to the even side)
    px = {
        (math.floor(x + 0.5), math.floor(y + 0.5))
        for x, y in zip(result.flown.x, result.flown.y, strict=True)
    }
    assert len(px) == len(result.flown.x) == r0.flown
    assert set(result.flown.frame) == {0}
    # a lone pass over the same plume (one frame holding it) flies the same number
    assert result.totals()["pointings_flown"] == r0.flown
    assert result.totals()["plumes_observed"] == 1


def test_one_nfov_is_shared_across_frames():
    # slow agility: the sensor is busy with the first plume when the others come in view
    world = _strip([(880, 920, 20, 60), (200, 240, 60, 100)])
    slow = fly_pass(world, None, PassConfig(agility="slow", compute_budget_s=0.01))
    times = np.asarray(slow.flown.t)
    assert len(times) > 0
    assert (np.diff(times) >= 1.0 + 0.1 - 1e-9).all()  # settle 1 s + dwell 0.1 s between looks
    unlimited = fly_pass(world, None, PassConfig(agility="unlimited", compute_budget_s=0.01))
    assert unlimited.totals()["plumes_observed"] == 2
    assert slow.totals()["pointings_flown"] < unlimited.totals()["pointings_flown"]


def test_scores_count_plume_pixels_against_the_truth():
    # a 40 x 40 high-res plume = WFOV rows 100..110, columns 10..20, all plume; each
    # pointing on a fully-plume WFOV pixel scores 1, any other 0
    world = _strip([(400, 440, 40, 80)])
    result = fly_pass(world, None, PassConfig(agility="unlimited", compute_budget_s=0.01))
    fl = result.flown
    assert len(fl.x) > 0
    assert result.totals()["plume_px"] == pytest.approx(sum(fl.plume))
    for x, y, p in zip(fl.x, fl.y, fl.plume, strict=True):
        r, c = round(y), round(x)
        inside = 100 <= r < 110 and 10 <= c < 20
        assert p == (1.0 if inside else 0.0)


def test_deadline_drops_frames_when_the_loop_falls_behind():
    world = _strip([(600, 680, 20, 80)])
    cadence = frame_plan(world, PassConfig()).cadence_s
    result = fly_pass(
        world, None, PassConfig(compute_budget_s=3 * cadence, deadline_s=3.5 * cadence)
    )
    dropped = [r.frame for r in result.records if r.dropped]
    assert dropped  # waits grow by 2 cadences per frame: frame 2 waits 4 > 3.5
    assert dropped[0] == 2
    assert all(r.deadline_met is False for r in result.records if r.dropped)


def test_stop_request_ends_the_pass_after_the_frame_in_hand():
    world = _strip([])
    seen = []
    result = fly_pass(
        world,
        None,
        PassConfig(compute_budget_s=0.01),
        on_frame=lambda r: seen.append(len(r.records)),
        should_stop=lambda: len(seen) >= 3,
    )
    assert result.stopped and len(result.records) == 3


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"overlap": 1.0}, "overlap"),
        ({"compute_budget_s": 0.0}, "compute_budget_s"),
        ({"deadline_s": float("nan")}, "deadline_s"),
        ({"footprint": 2}, "footprint"),
        ({"agility": "warp"}, "agility"),
        ({"frame_px": 4}, "frame_px"),
    ],
)
def test_bad_settings_name_the_argument(kwargs, word):
    with pytest.raises(InvalidParameterError, match=word):
        PassConfig(**kwargs)


def test_frames_larger_than_the_strip_are_refused():
    with pytest.raises(InvalidParameterError, match="frame_px"):
        frame_plan(_strip([]), PassConfig(frame_px=300))


def test_a_strip_without_label_is_refused():
    with pytest.raises(InvalidSceneError, match="label"):
        StaticWorld(Scene(np.zeros((4, 64, 16), np.float32), gsd=8.0))


class DriftingCloud(WorldBase):
    """A bright square cloud drifting east at ``speed`` m/s over dark ground (a test world)."""

    def __init__(self, speed: float, *, rows=1024, cols=128, box=(880, 920, 16, 56)) -> None:
        self.shape, self.gsd, self.speed, self.box = (rows, cols), GSD, speed, box
        self.crs = self.transform = self.valid = self.acquired = None
        self.id = "drift"
        self._cache: dict[float, object] = {}

    def _label(self, t: float) -> np.ndarray:
        r0, r1, c0, c1 = self.box
        dx = round(self.speed * t / self.gsd)
        label = np.zeros(self.shape, bool)
        label[r0:r1, max(c0 + dx, 0) : max(c1 + dx, 0)] = True
        return label

    def _image(self, label: np.ndarray) -> np.ndarray:
        image = np.full((4, *self.shape), 0.05, np.float32)
        image[:, label] = 0.8
        return image

    def image_at(self, t, top, bottom):
        return self._image(self._label(t))[:, top:bottom]

    def truth_at(self, t):
        from dyntarget.synth.worlds import Truth
        from dyntarget.utility import UtilityMaps

        t = float(round(t))
        if t not in self._cache:
            label = self._label(t)
            scene = Scene(self._image(label), label=label, gsd=GSD)
            self._cache[t] = Truth(UtilityMaps.from_scene(scene), label.astype(np.int32))
        return self._cache[t]


def test_a_wind_prior_keeps_pointings_on_a_drifting_cloud():
    # 8 m/s east = 0.25 WFOV px/s: in the ~30-70 s before the NFOV gets there the cloud
    # (10 WFOV px wide) moves 7-17 px, so a plan on the look misses most of it
    world = DriftingCloud(8.0)
    common = dict(agility="fast", compute_budget_s=0.05)
    static = fly_pass(world, None, PassConfig(**common)).totals()
    wind = PassConfig(**common, predict="wind", wind_mps=8.0, wind_from_deg=270.0)
    predicted = fly_pass(world, None, wind).totals()
    assert static["ratio_plume"] < 0.5
    assert predicted["ratio_plume"] >= 0.9
    assert predicted["plume_px"] > 2 * static["plume_px"]


def test_a_wind_prediction_needs_a_wind():
    with pytest.raises(InvalidParameterError, match="wind"):
        fly_pass(DriftingCloud(8.0), None, PassConfig(predict="wind", compute_budget_s=0.1))


def _mixed_stub(calls):
    """A stand-in for ``estimate_motion``: plumes west of column 15 attached, the rest detached.

    The vent is the attached plume's westmost column and mean row *in the rows it was
    given* (the overlap of two frames), so the caller must move it into the frame's rows.
    """
    from dyntarget.predict import Motion

    def estimate(previous, current, interval_s, *, previous_mask, current_mask, **kw):
        calls.append(current_mask.shape)
        rows, cols = np.nonzero(current_mask[:, :15])
        if len(rows) == 0:
            return Motion((-0.5, 0.0), regime="detached", source="two-looks", method="stub")
        vent = (float(cols.min()), float(rows.mean()))
        return Motion(
            (-0.5, 0.0),
            regime="mixed",
            source="two-looks",
            method="stub",
            vent=vent,
            attached=((*vent, 0.5),),
            interval_s=interval_s,
        )

    return estimate


def test_two_look_motion_moves_vent_and_attached_plumes_into_the_current_rows(monkeypatch):
    import dyntarget.predict.motion as predict
    from dyntarget.pipeline import two_look_motion

    calls = []
    monkeypatch.setattr(predict, "estimate_motion", _mixed_stub(calls))
    current = np.zeros((4, 32, 32), np.float32)
    mask = np.zeros((32, 32), bool)
    mask[18:23, 2:11] = True  # frame rows 18..22 = overlap rows 2..6 when offset is 16
    motion = two_look_motion(
        current, current, 0.07, previous_mask=mask, current_mask=mask, offset_rows=16
    )
    assert calls == [(16, 32)]  # only the 16 rows both frames saw were compared
    # the stub found the vent at overlap (2, 4); in the frame's rows that is (2, 20)
    assert motion.vent == (2.0, 20.0)
    assert motion.attached == ((2.0, 20.0, 0.5),)


def test_the_pass_loop_keeps_attached_plumes_of_a_mixed_scene_at_their_vent(monkeypatch):
    # two plumes side by side in WFOV rows 226..229: A (cols 2..9) attached, B (cols 20..29)
    # detached. Frame 1 (top 208) sees them at rows 18..21; its overlap with frame 0 is its
    # rows 16..31, where the stub finds A's vent at row 3.5 -> frame row 19.5, on A.
    import dyntarget.fly.loop as loop
    import dyntarget.predict.motion as predict

    monkeypatch.setattr(predict, "estimate_motion", _mixed_stub([]))
    seen = {}
    real = loop.schedule_on_prediction

    def record(todo, shape, geometry, agility, prediction, **kw):
        if prediction is not None:
            seen[len(seen)] = (prediction.motion, kw.get("attached"))
        return real(todo, shape, geometry, agility, prediction, **kw)

    monkeypatch.setattr(loop, "schedule_on_prediction", record)
    world = _strip([(904, 920, 8, 40), (904, 920, 80, 120)])
    config = PassConfig(agility="unlimited", compute_budget_s=0.01, predict="two-looks")
    fly_pass(world, None, config)
    mixed = [(m, a) for m, a in seen.values() if m.regime == "mixed"]
    assert mixed, "no frame planned on the mixed motion"
    motion, attached = mixed[0]
    assert motion.vent == (2.0, 19.5)
    assert attached is not None and attached.any()
    rows, cols = np.nonzero(attached)
    # A only (it stretches west, downwind, from its vent), never B, in A's rows
    assert cols.max() <= 9
    assert rows.min() >= 18 and rows.max() <= 21


@pytest.mark.parametrize("ground", ["fixed", "moving"])
def test_the_pass_asks_two_look_motion_for_the_ground_it_was_given(monkeypatch, ground):
    from dyntarget.predict import forecast

    asked = []
    real = forecast.two_look_motion

    def record(*args, **kw):
        asked.append(kw.get("ground"))
        return real(*args, **kw)

    monkeypatch.setattr(forecast, "two_look_motion", record)
    world = _strip([(904, 920, 8, 40)])
    config = PassConfig(
        agility="unlimited", compute_budget_s=0.01, predict="two-looks", ground=ground
    )
    fly_pass(world, None, config)
    assert asked and set(asked) == {ground}
    assert config.as_dict()["ground"] == ground  # recorded with the flown trajectory


def test_an_unknown_ground_is_refused():
    with pytest.raises(InvalidParameterError, match="ground: expected one of auto, fixed"):
        PassConfig(ground="sea")


@pytest.mark.parametrize("budget", [0.01, None])
@pytest.mark.parametrize("predict", ["none", "two-looks"])
def test_each_frame_runs_the_pipeline_once_and_schedules_once(monkeypatch, budget, predict):
    # issue 39: a predictive frame no longer plans twice, and a measured frame no longer
    # schedules once only to time the scheduling: one plan_scene, one schedule per frame
    from dyntarget.fly import loop

    calls = {"plan_scene": 0, "schedule": 0}
    real_plan, real_schedule = loop.plan_scene, loop.schedule_on_prediction

    def plan(*a, **kw):
        calls["plan_scene"] += 1
        return real_plan(*a, **kw)

    def schedule(*a, **kw):
        calls["schedule"] += 1
        return real_schedule(*a, **kw)

    monkeypatch.setattr(loop, "plan_scene", plan)
    monkeypatch.setattr(loop, "schedule_on_prediction", schedule)
    world = _strip([(600, 680, 20, 80)])
    config = PassConfig(agility="fast", compute_budget_s=budget, predict=predict)
    result = fly_pass(world, None, config)
    assert len(result.records) == 15  # 256 WFOV rows, 32-row frames every 16 rows
    assert calls == {"plan_scene": 15, "schedule": 15}


def test_a_predictive_frame_says_what_it_planned_on():
    # the path of a two-looks frame: classify, the motion (or none for the first frame),
    # the planner; the plan is drawn on the prediction from the same segmentation
    world = _strip([(600, 680, 20, 80)])
    config = PassConfig(agility="unlimited", compute_budget_s=0.01, predict="two-looks")
    paths = [r.path.split("; ") for r in fly_pass(world, None, config).records]
    assert paths[0] == [
        "classify: given mask",
        "predict: no motion known (planned on the look as it is)",
        "plan: lawnmower-transect",
    ]
    later = [p for p in paths[1:] if p[1] != paths[0][1]]
    assert later, "no frame planned on a motion"
    assert all(
        p[0] == "classify: given mask" and p[-1] == "plan: lawnmower-transect" for p in later
    )
    assert all(p[1].startswith("predict: ") and " s ahead (" in p[1] for p in later)


def test_the_agility_preset_is_looked_up_once_per_settings(monkeypatch):
    from dyntarget.passes import record

    asked = []
    real = record.get_agility
    monkeypatch.setattr(record, "get_agility", lambda name: asked.append(name) or real(name))
    config = PassConfig(agility="slow", compute_budget_s=0.01)
    fly_pass(_strip([(600, 680, 20, 80)]), None, config, upper_bound=True)
    assert asked == ["slow"]
    assert config.limits.name == "slow"
