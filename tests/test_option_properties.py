"""Property (issue 42): any value of a numeric option of ``plan``, ``fly``, ``synth`` and
``constellation`` gives a
result or exit 2 with one line; never exit 1 (an internal error) and never a traceback.

Values are drawn from floats (nan, inf, subnormal, huge), integers far beyond any range and
odd spellings. Valid values that would legitimately take long (a thousand scenes, a 10 000 km
strip) are left out with ``assume``; everything else runs on scenes of 32-64 px.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from affine import Affine
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from dyntarget.cli import main
from dyntarget.io import write_scene
from dyntarget.scene import Scene

VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e-6, max_value=1e-6),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.integers(min_value=-3, max_value=300),
    st.sampled_from(["nan", "-inf", "1e-300", "5e-324", "-0", "1e308", "0x10", "", " 3", "1_0"]),
).map(str)


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _check(argv: list[str], capsys, ok: tuple[int, ...] = (0, 2)) -> None:
    code = main(argv)
    err = capsys.readouterr().err
    assert code in ok, f"{argv}: exit {code}: {err}"
    assert "Traceback" not in err
    if code == 2:
        lines = [ln for ln in err.strip().splitlines() if ln.startswith("dyntarget:")]
        assert len(lines) == 1 and lines[0].startswith("dyntarget: error: "), err


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    transform = Affine(8.0, 0.0, 250000.0, 0.0, -8.0, 2150000.0)
    for name, shift in (("now", 4), ("prev", 0)):
        image = np.full((4, 64, 64), 0.05, np.float32)
        label = np.zeros((64, 64), bool)
        label[20:40, 10 + shift : 30 + shift] = True
        image[:, label] = 0.8
        scene = Scene(image, label=label, gsd=8.0, crs="EPSG:32605", transform=transform, id=name)
        write_scene(scene, d)
    args = ["synth", "--strip", "--scenes", "1", "--size", "64", "--plumes", "2", "--seed", "3"]
    assert main([*args, "--out", str(d / "strips"), "--quiet"]) == 0
    return {
        "now": d / "now.tif",
        "now_mask": d / "now_mask.tif",
        "prev": d / "prev.tif",
        "prev_mask": d / "prev_mask.tif",
        "strip": d / "strips" / "strip-0003.tif",
    }


PLAN_OPTIONS = {
    "--factor": [],
    "--step": [],
    "--width": [],
    "--scale": [],
    "--offset": [],
    "--deadline-s": [],
    "--wind-mps": ["--wind-from-deg", "90", "--lead-s", "10"],
    "--wind-from-deg": ["--wind-mps", "5", "--lead-s", "10"],
    "--lead-s": ["--wind-mps", "5", "--wind-from-deg", "90"],
    "--interval-s": ["PREVIOUS", "--lead-s", "0"],
    "--altitude-km": ["--agility", "fast"],
    "--look-ahead-km": ["--agility", "fast"],
    "--start-s": ["--agility", "fast"],
    "--wfov-gsd": ["--agility", "fast"],
    "--budget-s": ["--agility", "fast"],
    "--max-pointings": ["--agility", "fast"],
}


@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(option=st.sampled_from(sorted(PLAN_OPTIONS)), value=VALUES)
def test_plan_numeric_options_give_a_result_or_exit_2(inputs, capsys, option, value):
    extra = []
    for a in PLAN_OPTIONS[option]:
        if a == "PREVIOUS":
            extra += [
                "--previous",
                str(inputs["prev"]),
                "--previous-mask",
                str(inputs["prev_mask"]),
            ]
        else:
            extra.append(a)
    with tempfile.TemporaryDirectory() as d:
        argv = ["plan", str(inputs["now"]), "--mask", str(inputs["now_mask"])]
        argv += ["--planner", "track-center", "--out", str(Path(d) / "t.geojson")]
        _check([*argv, *extra, f"{option}={value}"], capsys, ok=(0, 2, 3))


FLY_OPTIONS = {
    "--factor": [],
    "--frame-px": [],
    "--overlap": [],
    "--compute-budget-s": [],
    "--deadline-s": [],
    "--footprint": [],
    "--altitude-km": [],
    "--look-ahead-km": [],
    "--truth-step-s": [],
    "--wind-mps": ["--predict", "wind", "--wind-from-deg", "90"],
    "--wind-from-deg": ["--predict", "wind", "--wind-mps", "5"],
    "--step": [],
    "--width": [],
}


def _slow_fly(option: str, value: str) -> bool:
    """Valid values that make a pass legitimately long (thousands of frames)."""
    v = _number(value)
    if v is None or not math.isfinite(v):
        return False
    if option == "--overlap":
        return 0.9 < v < 1
    if option == "--compute-budget-s":
        return 0 < v < 1e-3  # measured stage times still run; fine, but keep examples short
    return False


@pytest.mark.slow
@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(option=st.sampled_from(sorted(FLY_OPTIONS)), value=VALUES)
def test_fly_numeric_options_give_a_result_or_exit_2(inputs, capsys, option, value):
    assume(not _slow_fly(option, value))
    with tempfile.TemporaryDirectory() as d:
        argv = ["fly", "--scene", str(inputs["strip"]), "--truth", "--no-picture", "--no-html"]
        argv += ["--out", str(Path(d) / "o"), "--quiet"]
        budget = [] if option == "--compute-budget-s" else ["--compute-budget-s", "0.05"]
        _check([*argv, *budget, *FLY_OPTIONS[option], f"{option}={value}"], capsys)


SYNTH_OPTIONS = {
    "--scenes": [],
    "--size": [],
    "--seed": [],
    "--gsd": [],
    "--frames": ["--size", "32"],
    "--frame-interval-s": ["--frames", "2", "--size", "32"],
    "--wind-mps": ["--frames", "2", "--size", "32"],
    "--wind-from-deg": ["--frames", "2", "--size", "32"],
    "--plumes": ["--strip", "--size", "32"],
    "--length": ["--strip", "--size", "32"],
    "--length-km": ["--strip", "--size", "32"],
    "--plumes-per-100km": ["--strip", "--size", "32", "--length-km", "50"],
    "--clouds-per-100km": ["--strip", "--size", "32", "--length-km", "50"],
}


def _slow_synth(option: str, value: str) -> bool:
    """Valid values that legitimately take long: many scenes or frames, big or long strips."""
    v = _number(value)
    if v is None or not math.isfinite(v):
        return False
    limits = {"--scenes": 2, "--size": 96, "--frames": 4, "--length": 1024, "--length-km": 200}
    return option in limits and v > limits[option]


@pytest.mark.slow
@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(option=st.sampled_from(sorted(SYNTH_OPTIONS)), value=VALUES)
def test_synth_numeric_options_give_a_result_or_exit_2(capsys, option, value):
    assume(not _slow_synth(option, value))
    extra = list(SYNTH_OPTIONS[option])
    if option != "--size" and "--size" not in extra:
        extra += ["--size", "32"]
    scenes = [] if option == "--scenes" else ["--scenes", "1"]
    with tempfile.TemporaryDirectory() as d:
        argv = ["synth", *scenes, "--out", str(Path(d) / "o"), "--quiet", *extra]
        _check([*argv, f"{option}={value}"], capsys)


CONSTELLATION_OPTIONS = {
    "--altitude-km": [],
    "--inclination-deg": [],
    "--hours": [],
    "--seed": [],
    "--swath-km": [],
    "--look-ahead-km": [],
    "--eruptions-per-day": [],
}


def _slow_constellation(option: str, value: str) -> bool:
    """Valid values that legitimately take long: a simulated month, a volcano erupting per second."""
    v = _number(value)
    if v is None or not math.isfinite(v):
        return False
    return (option == "--hours" and v > 2) or (option == "--eruptions-per-day" and v > 1000)


@pytest.fixture(scope="module")
def catalog(tmp_path_factory) -> Path:
    """Three volcanoes in the GVP export's columns: Etna, Kilauea, Sakurajima."""
    p = tmp_path_factory.mktemp("catalog") / "volcanoes.csv"
    p.write_text(
        "volcano_number,volcano_name,latitude,longitude,elevation_m,last_known_eruption\n"
        "211060,Etna,37.748,14.999,3357,2025 CE\n"
        "332010,Kilauea,19.421,-155.287,1222,2025 CE\n"
        "282080,Sakurajima,31.593,130.657,1117,2025 CE\n"
    )
    return p


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(option=st.sampled_from(sorted(CONSTELLATION_OPTIONS)), value=VALUES)
def test_constellation_numeric_options_give_a_result_or_exit_2(catalog, capsys, option, value):
    assume(not _slow_constellation(option, value))
    hours = [] if option == "--hours" else ["--hours", "1"]
    with tempfile.TemporaryDirectory() as d:
        argv = ["constellation", "--walker", "2/1/0", "--volcanoes", str(catalog), *hours]
        argv += ["--out", str(Path(d) / "o"), "--quiet", "--no-picture", "--no-html"]
        _check([*argv, *CONSTELLATION_OPTIONS[option], f"{option}={value}"], capsys)


@pytest.mark.parametrize("option", ["--step", "--width"])
def test_a_spacing_whose_double_overflows_is_refused_in_one_line(inputs, capsys, option):
    # found by the property test above: --step 1e308 made the default transect width
    # (2 x step) infinite, and writing it to the GeoJSON failed with exit 1
    with tempfile.TemporaryDirectory() as d:
        argv = ["plan", str(inputs["now"]), "--mask", str(inputs["now_mask"])]
        argv += ["--planner", "lawnmower-transect", "--out", str(Path(d) / "t.geojson")]
        assert main([*argv, f"{option}=1e308"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "expected pixels in (0, 1e+06]" in err[0]
        assert not (Path(d) / "t.geojson").exists()
