"""The GEO imager seen from a stated GEO view: raised plumes displaced by their parallax.

The flat images are pinned by SHA-256 digests computed with the code before the view
existed (commit 0308e10): a flat world, and a 3D world without a view, give those bytes.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.synth.dynamic import VentSpec, Wind, WorldSpec, with_heights
from dyntarget.synth.geoimager import DEFAULT_VIEW, GEO_ALTITUDE_M, GeoStream, GeoView
from dyntarget.synth.strip import strip_spec

R = 6_371_008.7714  # WGS 84 mean radius, typed in

# digests of image(-600) + image(0) + background(), before this change
BEFORE_1KM = {
    0.0: "534ce8b3c5035c1de59531f013dad0d06d73365b7a6ec6ba9f0eaf6f7cb9fa65",
    0.01: "e3a24256e3c2096e92dcc387d5f7b3f8bf87b55e7c92de004e65c1bb8a6545bb",
}
# strip_spec(3, 128 x 512, 3 plumes, 12 m/s), 2 km, noise 0.005: images at -900, -300, 0
BEFORE_2KM = "9581e1daee4a4191488c46054e9195e7a5e89cfc5daa978a92b058a1bd9ab4ed"


def _digest(stream: GeoStream, times) -> str:
    h = hashlib.sha256()
    for t in times:
        h.update(stream.image(t).tobytes())
    h.update(stream.background().tobytes())
    return h.hexdigest()


def test_flat_worlds_and_no_view_give_the_bytes_of_before():
    spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    spec3 = with_heights(spec)
    for noise, want in BEFORE_1KM.items():
        assert _digest(GeoStream(spec, window, 1000.0, noise), (-600.0, 0.0)) == want
        # a flat world seen from a view: the same bytes (nothing is raised)
        flat_view = GeoStream(spec, window, 1000.0, noise, view=DEFAULT_VIEW)
        assert _digest(flat_view, (-600.0, 0.0)) == want
        # a 3D world without a view (what fly --geo builds): the same bytes
        assert _digest(GeoStream(spec3, window, 1000.0, noise), (-600.0, 0.0)) == want
    spec, window = strip_spec(3, width=128, length=512, plumes=3, wind_mps=12.0)
    s = GeoStream(with_heights(spec), window, 2000.0, 0.005)
    assert _digest(s, (-900.0, -300.0, 0.0)) == BEFORE_2KM


def test_the_view_of_a_strip_by_hand():
    # 35 deg N under the GEO: 35 deg of arc (3,891.8 km), the GEO due south, and
    # tan(zenith) = (R + H) sin g / ((R + H) cos g - R)
    v = GeoView()
    g = math.radians(35.0)
    rs = R + GEO_ALTITUDE_M
    assert v.distance_m == pytest.approx(R * g, abs=1e-3)
    assert v.zenith_deg == pytest.approx(
        math.degrees(math.atan2(rs * math.sin(g), rs * math.cos(g) - R)), abs=1e-9
    )
    assert round(v.zenith_deg, 2) == 40.65 and v.azimuth_deg == 180.0
    assert GeoView(-35.0, 0.0).azimuth_deg == 0.0  # south of the equator: the GEO is north
    # 30 deg east of the sub-satellite longitude at 35 N: the GEO to the south-west,
    # atan2(sin(-30), -sin(35) cos(30)) = -134.81 deg
    assert GeoView(35.0, 30.0).azimuth_deg == pytest.approx(225.19, abs=0.01)
    assert GeoView(35.0, 30.0).distance_m == pytest.approx(
        R * math.acos(math.cos(math.radians(35.0)) * math.cos(math.radians(30.0))), abs=1e-3
    )
    x, y = v.nadir_px((100.0, 200.0), 500.0)  # 3,891.8 km south on a north-up grid
    assert x == pytest.approx(100.0, abs=1e-9) and y == pytest.approx(200.0 + R * g / 500.0)


def _ray_sphere(zenith_deg: float, height_m: float) -> float:
    """Ground arc from an apparent point to the one under a feature at ``height_m`` seen
    at ``zenith_deg`` there: the line of sight from ``(0, R)`` meeting radius ``R + h``."""
    th = math.radians(zenith_deg)
    p, d = np.array([0.0, R]), np.array([-math.sin(th), math.cos(th)])
    b = float(p @ d)
    f = p + (-b + math.sqrt(b * b - (R * R - (R + height_m) ** 2))) * d
    return R * math.atan2(-f[0], f[1])


def _one_top(height_m: float) -> tuple[WorldSpec, tuple[int, int, int, int]]:
    """A steady plume without texture, rise or noise, a light wind, its top at ``height_m``,
    on a 62.5 m grid (what 500 m GEO cells render at), 20 x 30 km about the vent."""
    vent = VentSpec(0.0, 0.0, eruption_age_s=3000.0, top_height_m=height_m)
    spec = WorldSpec(5, 256, 62.5, Wind(0.5, 0.0), (vent,), plume_texture=0.0,
                     noise_sigma=0.0)  # fmt: skip
    return spec, (-160, -320, 320, 480)


def _anomaly_centroid(s: GeoStream, t: float) -> tuple[float, float]:
    a = np.clip((s.image(t) - s.background()).mean(axis=0), 0.0, None)
    rows, cols = np.mgrid[0 : a.shape[0], 0 : a.shape[1]]
    return float((a * cols).sum() / a.sum()), float((a * rows).sum() / a.sum())


def test_a_10_km_top_is_drawn_8_6_km_from_its_ground_position_away_from_the_geo():
    spec, window = _one_top(10_000.0)
    base = GeoStream(spec, window, 500.0, 0.0)
    cx, cy = _anomaly_centroid(base, 0.0)
    # by hand: 10 km x tan(40.65 deg) = 8,586 m on flat ground; on the sphere (the line of
    # sight from the apparent point, at its zenith angle, meeting R + 10 km) 8,568 m
    assert 10_000.0 * math.tan(math.radians(40.65)) == pytest.approx(8586.2, abs=0.1)
    want = _ray_sphere(40.65, 10_000.0)
    assert want == pytest.approx(8567.8, abs=0.1)
    # measured on the images within 80 m (a sixth of a 500 m cell): the brightness
    # centroid is weighted by the ground under the plume, which changes with the shift
    for view, sign in ((DEFAULT_VIEW, -1.0), (GeoView(-35.0, 0.0), 1.0)):
        x, y = _anomaly_centroid(base.seen_from(view), 0.0)
        assert abs(x - cx) * 500.0 < 20.0
        assert (y - cy) * 500.0 == pytest.approx(sign * want, abs=80.0)  # north: rows up
    # a lower top moves less: 2 km -> 1,716 m
    low, window = _one_top(2_000.0)
    s = GeoStream(low, window, 500.0, 0.0)
    _, y0 = _anomaly_centroid(s, 0.0)
    _, y1 = _anomaly_centroid(s.seen_from(DEFAULT_VIEW), 0.0)
    assert (y0 - y1) * 500.0 == pytest.approx(_ray_sphere(40.65, 2_000.0), abs=80.0)


def test_a_bad_view_is_refused_in_one_line():
    for kw, match in (
        ({"lat_deg": float("nan")}, "lat_deg"),
        ({"lat_deg": 85.0}, "lat_deg"),
        ({"dlon_deg": "east"}, "dlon_deg"),
        ({"lat_deg": 70.0, "dlon_deg": 70.0}, "above the horizon"),
    ):
        with pytest.raises(InvalidParameterError, match=match) as e:
            GeoView(**kw)
        assert "\n" not in str(e.value)
    spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    with pytest.raises(InvalidParameterError, match="view"):
        GeoStream(spec, window, 1000.0, 0.0, view=(35.0, 0.0))  # type: ignore[arg-type]
    with pytest.raises(InvalidParameterError, match="view"):
        GeoStream(replace(spec), window, 1000.0, 0.0).seen_from("north")  # type: ignore[arg-type]
