"""A 3D strip inside a pass: the oblique look-ahead frame (``look_at``), plume heights per id
(``heights_at``) and the flat world unchanged.

Expected displacements come from plain 3D vector algebra (a ray from the spacecraft
through the plume top meets the sphere), not from :mod:`dyntarget.parallax`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.observe import Sight, score_pointings
from dyntarget.scene import Scene, block_mean
from dyntarget.synth.dynamic import CloudSpec, VentSpec, Wind, WorldSpec
from dyntarget.synth.strip import long_strip_spec, strip_spec
from dyntarget.synth.strip_world import LongStrip, MovingStrip
from dyntarget.synth.worlds import StaticWorld, wfov_truth

R = 6_371_008.7714  # WGS 84 mean radius (2a + b) / 3
ALT = 500e3
GSD = 30.0
VENT = (64.0, 500.0)  # world = strip pixels (the window starts at the origin)
AHEAD, ASIDE = 500e3, 100e3  # the vent's ground position from the nadir: along, cross (m)


def _apparent(along: float, cross: float, h: float) -> tuple[float, float]:
    """Where the ray from the spacecraft through a feature ``h`` above (along, cross) meets
    the ground: (along, cross) of that point, metres (azimuthal equidistant about the nadir)."""
    d, phi = math.hypot(along, cross), math.atan2(cross, along)
    g = d / R
    top = (R + h) * np.array(
        [math.sin(g) * math.cos(phi), math.sin(g) * math.sin(phi), math.cos(g)]
    )
    s = np.array([0.0, 0.0, R + ALT])
    u = (top - s) / np.linalg.norm(top - s)
    b, c = float(s @ u), float(s @ s) - R**2
    hit = s + (-b - math.sqrt(b * b - c)) * u
    arc = R * math.atan2(math.hypot(hit[0], hit[1]), hit[2])
    return arc * math.cos(phi), arc * math.sin(phi)


def _strip(height_m: float | None) -> MovingStrip:
    vent = VentSpec(*VENT, source_sigma_m=90.0, eruption_age_s=300.0, top_height_m=height_m)
    spec = WorldSpec(7, 600, GSD, Wind(0.0, 0.0), (vent,), plume_texture=0.0, noise_sigma=0.0)
    return MovingStrip(spec, (0, 0, 256, 600), truth_step_s=0.0)


# the spacecraft's nadir (strip high-res px): the vent 500 km ahead and 100 km to the right
NADIR = (VENT[0] - ASIDE / GSD, VENT[1] + AHEAD / GSD)


def _centroid(mask: np.ndarray) -> np.ndarray:
    r, c = np.nonzero(mask)
    return np.array([c.mean(), r.mean()])


def test_a_flat_strip_is_seen_as_image_at_and_label_rows_byte_for_byte():
    spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    s = MovingStrip(spec, window)
    assert not s.is_3d and s.heights_at(0.0) is None
    im, mask = s.look_at(3.3, 40, 120, nadir_xy=(32.0, 9e4), altitude_m=ALT)
    assert im.tobytes() == s.image_at(3.3, 40, 120).tobytes()
    assert mask.tobytes() == s.label_rows(3.3, 40, 120).tobytes() and mask.any()
    lab = np.zeros((8, 6), bool)
    lab[2:4, 1:3] = True
    w = StaticWorld(Scene(np.full((4, 8, 6), 0.2, np.float32), label=lab, gsd=8.0))
    im, mask = w.look_at(5.0, 1, 5, nadir_xy=(0.0, 0.0), altitude_m=ALT)
    assert not w.is_3d and w.heights_at(5.0) is None
    assert im.tobytes() == w.image_at(5.0, 1, 5).tobytes()
    assert mask.tobytes() == lab[1:5].tobytes()


def test_a_flat_long_strip_is_seen_as_its_own_rendering():
    s = LongStrip(*long_strip_spec(0, 100.0, plumes=2, wind_mps=5.0))
    assert not s.is_3d and s.heights_at(0.0) is None
    im, mask = s.look_at(0.0, 100, 164, nadir_xy=(128.0, 9e4), altitude_m=ALT)
    assert im.tobytes() == s.image_at(0.0, 100, 164).tobytes()
    assert mask.tobytes() == s.label_rows(0.0, 100, 164).tobytes()


def test_a_3d_plume_is_seen_displaced_by_its_parallax():
    flat, raised = _strip(None), _strip(10_000.0)
    assert raised.is_3d
    ground = flat.label_rows(0.0, 0, 600)
    # the truth stays on the ground: the same label as the flat world's
    assert np.array_equal(raised.label_rows(0.0, 0, 600), ground)
    _, seen = raised.look_at(0.0, 0, 600, nadir_xy=NADIR, altitude_m=ALT)
    a, c = _apparent(AHEAD, ASIDE, 10_000.0)
    # by hand: 509.9 km from the nadir, tan(theta) = 1.149 (48.97 deg): 10 km x 1.149 plus
    # 2.2 % for the curvature (as at 45 deg, docs/plumes-3d.md) is 11.75 km, radial
    expect = np.array([(c - ASIDE) / GSD, -(a - AHEAD) / GSD])  # (dx, dy) px
    assert math.hypot(*expect) * GSD == pytest.approx(11_750, rel=0.005)
    assert expect[0] / -expect[1] == pytest.approx(ASIDE / AHEAD)
    moved = _centroid(seen) - _centroid(ground)
    assert moved == pytest.approx(expect, abs=1.5)
    # the same plume, moved (its edge resampled bilinearly: a 13 px blob gains a few px)
    assert abs(seen.sum() - ground.sum()) < 0.15 * ground.sum()
    # the flat strip from the same nadir: exactly its label
    _, flat_seen = flat.look_at(0.0, 0, 600, nadir_xy=NADIR, altitude_m=ALT)
    assert np.array_equal(flat_seen, ground)


def test_a_3d_long_strip_is_seen_displaced_too():
    spec, window = long_strip_spec(0, 100.0, plumes=1, wind_mps=5.0)
    v = spec.vents[0]
    s = LongStrip(replace(spec, vents=(replace(v, top_height_m=10_000.0),)), window)
    vx, vy = v.x - window[0], v.y - window[1]
    nadir = (vx, vy + AHEAD / s.gsd)
    a, _ = _apparent(AHEAD, 0.0, 10_000.0)
    dy = (a - AHEAD) / s.gsd  # rows towards row 0
    top = int(vy - dy) - 64
    _, seen = s.look_at(0.0, top, top + 128, nadir_xy=nadir, altitude_m=ALT)
    ground = s.label_rows(0.0, int(vy) - 64, int(vy) + 64)
    assert seen.any() and ground.any()
    moved = (_centroid(seen)[1] + top) - (_centroid(ground)[1] + int(vy) - 64)
    # the plume drifts downwind, so its centroid is not the vent's: compare the two views
    assert moved == pytest.approx(-dy, abs=2.0)


def test_heights_per_plume_id_follow_the_rising_column():
    rising = VentSpec(100.0, 100.0, eruption_age_s=100.0, top_height_m=9000.0, rise_mps=30.0)
    ground = VentSpec(300.0, 100.0)
    clouds = (
        CloudSpec(200.0, 400.0, volcanic=False, height_m=2000.0),  # meteorological: no id
        CloudSpec(250.0, 300.0, radius_m=1500.0, height_m=4000.0),
    )
    spec = WorldSpec(3, 512, 30.0, Wind(0.0, 0.0), (rising, ground), clouds)
    s = MovingStrip(spec, (0, 0, 512, 512))
    # by hand: the top rises 30 m/s from the onset 100 s before t = 0, up to 9 km
    assert s.heights_at(0.0).tolist() == [0.0, 3000.0, 0.0, 4000.0]
    assert s.heights_at(-40.0)[1] == pytest.approx(1800.0)
    assert s.heights_at(-150.0)[1] == 0.0
    assert s.heights_at(500.0)[1] == 9000.0
    # id 3 is the volcanic cloud in the truth too
    ids = s.truth_at(0.0).ids
    assert ids[300, 250] == 3 and ids[100, 100] == 1
    with pytest.raises(InvalidParameterError, match="t: expected finite seconds"):
        s.heights_at(float("nan"))


def test_a_pointing_scores_where_its_line_of_sight_meets_the_plume():
    # the strip end to end: truth -> WFOV maps; the frame's displaced plume -> the aim
    s = _strip(10_000.0)
    f = 4
    truth = wfov_truth(s.truth_at(0.0), f)
    _, seen = s.look_at(0.0, 0, 600, nadir_xy=NADIR, altitude_m=ALT)
    seen_w = block_mean(seen[None].astype(np.float32), f)[0]
    ground_w = truth.plume
    # nadir in WFOV px: a high-res pixel centre c maps to (c - (f - 1) / 2) / f
    nadir_w = ((NADIR[0] - 1.5) / f, (NADIR[1] - 1.5) / f)
    sight = Sight(lambda t: nadir_w, GSD * f, ALT, s.heights_at)
    aim = np.array(np.unravel_index(seen_w.argmax(), seen_w.shape))[::-1].astype(float)
    under = np.array(np.unravel_index(ground_w.argmax(), ground_w.shape))[::-1].astype(float)
    pts = np.array([aim, under])
    got = score_pointings(pts, [0.0, 0.0], 0, truth.plume.shape, lambda t, r: (truth, 0), sight)
    assert got.plume_id == [1, 0] and got.plume[0] > 0.5 and got.plume[1] == 0.0
    flat = score_pointings(pts, [0.0, 0.0], 0, truth.plume.shape, lambda t, r: (truth, 0))
    assert flat.plume_id == [0, 1]  # without a sight: the truth under the aim
