"""Two fidelities, one physics: the target level's overflight against the pass loop (``fly``).

For overflights of a simulated 20-satellite day, the target level's pinpoint observation
(SGP4 + WGS 84 geometry, timed by ``schedule.make_feasible``, worth ``cos(off-nadir)``) is
compared with what ``fly`` does on a synthetic strip holding the same plume at the same
cross-track offset (``benchmarks/constellation.py``: :func:`fly_overflight`): the
off-nadir angle of its first pointing on the plume, in the pass loop's own geometry. The
two are computed by different code from different models (an ellipsoid and SGP4 on one
side; a rendered plume, the frame loop and a spherical Earth on the other).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

from dyntarget.constellation.fidelity import overflight_cases
from dyntarget.constellation.world import read_catalog

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "constellation.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("constellation_benchmark", BENCH)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _compare(bench, cases):
    out = []
    for i, case in enumerate(cases):
        px = bench.fly_overflight(case, index=i)
        assert px["observed"], (
            f"fly never pointed at the plume {case['cross_m'] / 1e3:.0f} km off track"
        )
        out.append((case, px))
    return out


def test_fly_takes_its_first_pointing_where_the_target_level_observes(gvp, bench):
    # two overflights near the track (narrow strips: seconds): the target level says the
    # NFOV observes as the summit enters the 30 deg field of regard; fly agrees in angle
    cases = overflight_cases(read_catalog(gvp), 12)[:2]
    assert len(cases) == 2
    for case, px in _compare(bench, cases):
        assert abs(case["cross_m"]) < 60e3
        assert abs(px["utility"] - case["utility"]) <= bench.FIDELITY_TOLERANCE
        # fly points at the plume within a few seconds of its vent entering the field of regard
        assert abs(px["after_vent_enters_s"]) < 5.0
        # the old placement (end of the window, near nadir) is what fly does not do
        old = math.cos(math.radians(case["off_nadir_window_end_deg"]))
        assert old - px["utility"] > 0.1


@pytest.mark.slow
def test_target_and_pixel_level_agree_on_36_overflights(gvp, bench):
    cases = overflight_cases(read_catalog(gvp), 36)
    assert len(cases) == 36
    crosses = [abs(c["cross_m"]) for c in cases]
    assert min(crosses) < 10e3 and max(crosses) > 250e3  # across the whole field of regard
    diffs = [px["utility"] - case["utility"] for case, px in _compare(bench, cases)]
    assert max(abs(d) for d in diffs) <= bench.FIDELITY_TOLERANCE
