"""Reliability round 4 (issue 42), the command line: results never lost or mixed, values
never silently wrong.

Class 2: a failing, refused or interrupted rerun of ``fly`` (and ``synth``) into an existing
``--out`` leaves the previous result byte for byte; a rerun without the picture or the view
leaves no old ``pass.png``/``pass.html``. Class 4: tiny intervals, huge angles, other grids,
silently capped clouds, strips too long or too wide, GEO settings a mode ignores: each is one
line and exit 2 before anything is written; ``fly --geo`` writes the same ``summary.json``
twice. Class 3: ``--footprint 999999``. Every input is built here, in ``tmp_path``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from affine import Affine

from dyntarget.cli import main
from dyntarget.io import write_scene
from dyntarget.scene import Scene

UTM = Affine(8.0, 0.0, 250000.0, 0.0, -8.0, 2150000.0)


def _one_line_error(capsys, *args) -> str:
    """Run the CLI; assert exit 2 and exactly one line on stderr, no traceback; return it."""
    code = main([str(a) for a in args])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dyntarget: error: "), err
    assert "Traceback" not in err
    return lines[0]


def _tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (hidden ones too) with its bytes."""
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def _scene(directory: Path, scene_id: str, *, transform=UTM, shift=0) -> Path:
    """A 64 px labelled scene with one bright plume (moved ``shift`` px to the right)."""
    image = np.full((4, 64, 64), 0.05, np.float32)
    label = np.zeros((64, 64), bool)
    label[20:40, 10 + shift : 30 + shift] = True
    image[:, label] = 0.8
    write_scene(
        Scene(image, label=label, gsd=abs(transform.a), crs="EPSG:32605", transform=transform,
              id=scene_id),
        directory,
    )  # fmt: skip
    return directory / f"{scene_id}.tif"


@pytest.fixture(scope="module")
def strip(tmp_path_factory) -> Path:
    """A short synthetic strip (64 px across, two plumes, flat): 8 frames to fly."""
    out = tmp_path_factory.mktemp("strips") / "s"
    args = ["synth", "--strip", "--scenes", "1", "--size", "64", "--plumes", "2", "--seed", "3"]
    args.append("--flat")  # the reliability cases count frames and stderr lines of a flat pass
    assert main([*args, "--out", str(out), "--quiet"]) == 0
    return out / "strip-0003.tif"


FLY = ("--truth", "--compute-budget-s", "0.05", "--quiet")


def _fly(strip: Path, out: Path, *extra: str) -> int:
    return main(["fly", "--scene", str(strip), *FLY, "--out", str(out), *extra])


@pytest.fixture
def flown(strip, tmp_path) -> Path:
    """A complete pass (picture and view included) in ``tmp_path/pass``."""
    out = tmp_path / "pass"
    assert _fly(strip, out) == 0
    assert {"pass.png", "summary.json", "timeline.csv"} <= {p.name for p in out.iterdir()}
    return out


# --------------------------------------------------------------------------- class 2: fly reruns


def _failing_fly_pass(monkeypatch, after_frames: int, exc: BaseException) -> None:
    """``fly_pass`` that raises ``exc`` after ``after_frames`` frames (progress written)."""
    import dyntarget.fly

    real = dyntarget.fly.fly_pass

    def failing(world, classifier, config, *, on_frame=None, **kw):
        seen = []

        def frame(result):
            on_frame(result)
            seen.append(1)
            if len(seen) == after_frames:
                raise exc

        return real(world, classifier, config, on_frame=frame, **kw)

    monkeypatch.setattr(dyntarget.fly, "fly_pass", failing)


def test_a_failing_rerun_leaves_the_previous_pass_byte_for_byte(strip, flown, monkeypatch, capsys):
    from dyntarget.errors import InvalidSceneError

    before = _tree(flown)
    _failing_fly_pass(monkeypatch, 2, InvalidSceneError("frame 1: hostile pixels"))
    line = _one_line_error(capsys, "fly", "--scene", strip, *FLY, "--out", flown)
    assert "hostile pixels" in line and "holds what it held before" in line
    assert _tree(flown) == before


def test_an_internal_error_in_a_rerun_leaves_the_previous_pass(strip, flown, monkeypatch, capsys):
    before = _tree(flown)
    _failing_fly_pass(monkeypatch, 3, RuntimeError("a bug"))
    assert _fly(strip, flown) == 1
    assert "internal error" in capsys.readouterr().err
    assert _tree(flown) == before


def test_an_interrupt_while_writing_leaves_the_previous_pass(strip, flown, monkeypatch, capsys):
    import dyntarget.view.pass_report as report

    before = _tree(flown)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "summary_json", interrupted)
    assert _fly(strip, flown, "--no-html") == 130
    assert _tree(flown) == before


def test_sigint_during_a_rerun_keeps_the_previous_pass(strip, flown, monkeypatch, capsys):
    """SIGINT mid-pass: the earlier complete pass stays; the stopped one is set aside."""
    import dyntarget.fly

    before = _tree(flown)
    real = dyntarget.fly.fly_pass

    def interrupted(world, classifier, config, *, on_frame=None, **kw):
        seen = []

        def frame(result):
            on_frame(result)
            seen.append(1)
            if len(seen) == 2:
                os.kill(os.getpid(), signal.SIGINT)

        return real(world, classifier, config, on_frame=frame, **kw)

    monkeypatch.setattr(dyntarget.fly, "fly_pass", interrupted)
    assert _fly(strip, flown, "--no-picture") == 128 + signal.SIGINT
    err = capsys.readouterr().err
    assert "keeps its earlier pass" in err and "(stopped)" in err
    kept = {k: v for k, v in _tree(flown).items() if not k.startswith(".partial-")}
    assert kept == before
    partial = [p for p in flown.iterdir() if p.name.startswith(".partial-")]
    assert len(partial) == 1  # the stopped pass, named on stderr, never mixed in
    assert str(partial[0]) in err
    assert "**stopped** after 2 of 8 frames" in (partial[0] / "summary.md").read_text()


def test_a_stopped_first_pass_is_written_as_stopped(strip, tmp_path, monkeypatch, capsys):
    import dyntarget.fly

    real = dyntarget.fly.fly_pass

    def interrupted(world, classifier, config, *, on_frame=None, **kw):
        def frame(result):
            on_frame(result)
            if len(result.records) == 3:
                os.kill(os.getpid(), signal.SIGTERM)

        return real(world, classifier, config, on_frame=frame, **kw)

    monkeypatch.setattr(dyntarget.fly, "fly_pass", interrupted)
    out = tmp_path / "first"
    assert _fly(strip, out, "--no-picture", "--no-html") == 128 + signal.SIGTERM
    assert "**stopped** after 3 of 8 frames" in (out / "summary.md").read_text()
    assert not [p for p in out.iterdir() if p.name.startswith(".partial-")]


@pytest.mark.parametrize(
    ("flags", "gone"),
    [
        (["--no-picture"], {"pass.png"}),
        (["--no-html"], {"pass.html"}),
        (["--no-picture", "--no-html"], {"pass.png", "pass.html"}),
    ],
)
def test_a_rerun_without_picture_or_view_leaves_no_old_one(strip, flown, flags, gone):
    assert gone <= {p.name for p in flown.iterdir()}
    assert _fly(strip, flown, *flags) == 0
    names = {p.name for p in flown.iterdir()}
    assert not gone & names
    assert {"timeline.csv", "summary.json", "summary.md", "pointings.geojson"} <= names
    assert not [n for n in names if n.startswith(".partial-")]


def test_a_measured_rerun_leaves_no_old_stage_times(strip, flown):
    assert (flown / "stage_times.csv").is_file()  # the fixed-budget pass measured its times
    assert main(["fly", "--scene", str(strip), "--truth", "--quiet", "--out", str(flown)]) == 0
    assert not (flown / "stage_times.csv").exists()  # measured: the timeline holds them


@pytest.mark.parametrize(
    "bad",
    [
        ["--footprint", "999999"],
        ["--footprint", "101"],  # wider than the 16 WFOV px strip
        ["--wind-from-deg", "1e300", "--wind-mps", "5", "--predict", "wind"],
        ["--geo-blind", "--geo-gsd-m", "3000"],
        ["--overlap", "nan"],
    ],
)
def test_a_refused_rerun_changes_nothing(strip, flown, capsys, bad):
    before = _tree(flown)
    _one_line_error(capsys, "fly", "--scene", strip, *FLY, "--out", flown, *bad)
    assert _tree(flown) == before


def test_the_wrote_line_names_every_file_once(strip, tmp_path, capsys):
    out = tmp_path / "o"
    assert _fly(strip, out, "--no-html") == 0
    wrote = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("wrote ")]
    assert len(wrote) == 1
    named = [Path(p).name for p in wrote[0][len("wrote ") :].split(", ")]
    assert sorted(named) == sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert named.count("stage_times.csv") == 1


@pytest.mark.slow
def test_sigint_to_a_rerun_process_never_mixes_two_passes(strip, tmp_path):
    """A real SIGINT to a separate process flying a long pass into an existing --out."""
    out = tmp_path / "out"
    assert _fly(strip, out, "--no-html") == 0
    before = _tree(out)
    rows = 8192
    image = np.full((4, rows, 64), 0.05, np.float32)
    label = np.zeros((rows, 64), bool)
    for r in range(200, rows - 200, 600):
        label[r : r + 40, 10:40] = True
    image[:, label] = 0.8
    write_scene(Scene(image, label=label, gsd=8.0, id="long"), tmp_path / "in")
    cmd = [sys.executable, "-m", "dyntarget", "fly", "--scene", str(tmp_path / "in" / "long.tif")]
    cmd += ["--truth", "--compute-budget-s", "0.01", "--out", str(out), "--quiet"]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        staged = list(out.glob(".partial-*/timeline.csv"))
        if staged and len(staged[0].read_text().splitlines()) >= 4:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the pass ended before it was interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGINT, err
    after = {k: v for k, v in _tree(out).items() if not k.startswith(".partial-")}
    assert after == before
    assert "keeps its earlier pass" in err


# --------------------------------------------------------------------------- class 2: synth reruns


def test_a_failing_synth_rerun_leaves_the_previous_scenes(tmp_path, monkeypatch, capsys):
    out = tmp_path / "scenes"
    assert main(["synth", "--scenes", "2", "--size", "32", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    before = _tree(out)
    import dyntarget.io

    real = dyntarget.io.write_scene
    calls = []

    def failing(scene, directory, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            from dyntarget.errors import DataFileError

            raise DataFileError("disk full (simulated)")
        return real(scene, directory, *args, **kwargs)

    monkeypatch.setattr(dyntarget.io, "write_scene", failing)
    args = ["synth", "--scenes", "2", "--size", "32", "--seed", "7", "--out", out, "--quiet"]
    assert "disk full" in _one_line_error(capsys, *args)
    assert _tree(out) == before  # the first new scene was not mixed in


# --------------------------------------------------------------------------- class 4: plan


@pytest.fixture
def looks(tmp_path) -> dict[str, Path]:
    """Two looks on one grid (the plume moved 4 px), and previous frames on other grids."""
    d = tmp_path / "looks"
    files = {"now": _scene(d, "now", shift=4), "prev": _scene(d, "prev")}
    files["coarse"] = _scene(d, "coarse", transform=Affine(16.0, 0, 250000.0, 0, -16.0, 2150000.0))
    files["rotated"] = _scene(d, "rotated", transform=UTM @ Affine.rotation(10.0))
    files["shifted"] = _scene(d, "shifted", transform=UTM @ Affine.translation(3, 0))
    return files


def _plan_two_looks(looks, out, previous, *extra):
    now, prev = looks["now"], looks[previous]
    return [
        "plan", now, "--mask", now.with_name("now_mask.tif"), "--planner", "track-center",
        "--out", out, "--previous", prev, "--previous-mask",
        prev.with_name(f"{previous}_mask.tif"), *extra,
    ]  # fmt: skip


@pytest.mark.parametrize("interval", ["1e-300", "0", "-1", "nan", "inf", "1e300", "5e-324"])
def test_a_degenerate_interval_is_refused_naming_it(looks, tmp_path, capsys, interval):
    out = tmp_path / "t.geojson"
    args = _plan_two_looks(looks, out, "prev", "--interval-s", interval, "--lead-s", "0")
    assert "--interval-s" in _one_line_error(capsys, *args)
    assert not out.exists()


def test_a_valid_interval_still_plans(looks, tmp_path, capsys):
    out = tmp_path / "t.geojson"
    args = _plan_two_looks(looks, out, "prev", "--interval-s", "2", "--lead-s", "4")
    assert main([str(a) for a in args]) == 0
    assert json.loads(out.read_text())["properties"]["prediction"]["lead_s"] == 4.0


@pytest.mark.parametrize(
    ("previous", "word"),
    [("coarse", "another grid"), ("rotated", "rotated"), ("shifted", "shifted by (+3.000")],
)
def test_a_previous_frame_on_another_grid_is_refused(looks, tmp_path, capsys, previous, word):
    out = tmp_path / "t.geojson"
    args = _plan_two_looks(looks, out, previous, "--interval-s", "2", "--lead-s", "4")
    line = _one_line_error(capsys, *args)
    assert "--previous" in line and word in line
    assert not out.exists()


@pytest.mark.parametrize("deg", ["1e300", "-1e300", "nan", "inf", "361", "-360.5"])
def test_a_wind_direction_out_of_range_is_refused_by_plan(looks, tmp_path, capsys, deg):
    now = looks["now"]
    args = ["plan", now, "--mask", now.with_name("now_mask.tif"), "--planner", "track-center"]
    args += ["--out", tmp_path / "t.geojson", "--wind-mps", "5", "--wind-from-deg", deg]
    assert "--wind-from-deg" in _one_line_error(capsys, *args, "--lead-s", "10")


@pytest.mark.parametrize("deg", ["1e300", "nan", "-inf", "400"])
def test_a_wind_direction_out_of_range_is_refused_by_fly(strip, tmp_path, capsys, deg):
    args = ["fly", "--scene", strip, *FLY, "--out", tmp_path / "o", "--predict", "wind"]
    line = _one_line_error(capsys, *args, "--wind-mps", "5", "--wind-from-deg", deg)
    assert "--wind-from-deg" in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("speed", ["-1", "nan", "1e300", "61"])
def test_a_wind_speed_out_of_range_is_refused_by_plan_fly_and_synth(strip, tmp_path, capsys, speed):
    fly = ["fly", "--scene", strip, *FLY, "--out", tmp_path / "o", "--predict", "wind"]
    assert "--wind-mps" in _one_line_error(capsys, *fly, "--wind-mps", speed)
    synth = ["synth", "--scenes", "1", "--frames", "2", "--out", tmp_path / "s"]
    assert "--wind-mps" in _one_line_error(capsys, *synth, "--wind-mps", speed)


# --------------------------------------------------------------------------- class 4: fly --geo


@pytest.mark.slow
def test_fly_geo_writes_the_same_summary_twice(strip, tmp_path):
    """Timings (targets_s, blueprint_s) go to geo.timing.json; summary.json is deterministic."""
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        assert _fly(strip, out, "--geo", "--geo-gsd-m", "100", "--no-html", "--no-picture") == 0
    first, second = ((o / "summary.json").read_bytes() for o in outs)
    assert first == second
    geo = json.loads(first)["geo"]
    assert geo["computed"] == "ground" and "targets_s" not in geo and "blueprint_s" not in geo
    times = json.loads((outs[0] / "geo.timing.json").read_text())
    assert set(times) == {"targets_s", "blueprint_s"} and times["targets_s"] >= 0


@pytest.mark.parametrize(
    ("opts", "word"),
    [
        (["--geo-omniscient", "--geo-gsd-m", "3000"], "--geo-gsd-m: has no effect with --geo-omniscient"),
        (["--geo-omniscient", "--geo-cadence-s", "60"], "--geo-cadence-s: has no effect"),
        (["--geo-omniscient", "--geo-detection", "brightness"], "--geo-detection: has no effect"),
        (["--geo-blind", "--geo-reserve", "0.2"], "--geo-reserve: has no effect with --geo-blind"),
        (["--geo-blind", "--geo-no-stage"], "--geo-no-stage: has no effect"),
        (["--geo-blind", "--geo-latency-s", "10"], "--geo-latency-s: has no effect"),
        (["--geo", "--geo-blind"], "exclude each other"),
        (["--geo", "--geo-omniscient"], "exclude each other"),
    ],
)  # fmt: skip
def test_geo_settings_a_mode_ignores_are_refused(strip, tmp_path, capsys, opts, word):
    line = _one_line_error(capsys, "fly", "--scene", strip, *FLY, "--out", tmp_path / "o", *opts)
    assert word in line
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- class 4: synth


def test_length_km_at_the_default_density_is_refused_naming_the_way_out(tmp_path, capsys):
    out = tmp_path / "x"
    args = ["synth", "--strip", "--length-km", "10000", "--out", out, "--quiet"]
    line = _one_line_error(capsys, *args)
    assert "--length-km 10000" in line and "100 vents" in line and "64" in line
    assert "--plumes-per-100km 0.64 or less" in line
    assert not out.exists()


def test_the_help_states_the_vent_limit_it_enforces(capsys):
    from dyntarget.cli import build_parser

    parser = build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["synth", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "10-10000 km" in help_text
    assert "beyond 6400 km give a lower --plumes-per-100km" in help_text


def test_the_cli_limits_are_the_renderers(capsys):
    """The limits written out in cli/synth.py (for a light --help) are the library's."""
    import math

    from dyntarget.cli import synth as cli_synth
    from dyntarget.synth import dynamic
    from dyntarget.synth import strip as fly_strip

    assert cli_synth.MAX_VENTS == dynamic.MAX_VENTS == 64
    assert cli_synth.MAX_CLOUDS == dynamic.MAX_CLOUDS == 256
    assert cli_synth.MAX_WINDOW_PIXELS == dynamic.MAX_WINDOW_PIXELS
    assert cli_synth.MAX_WINDOW_SIDE == dynamic.MAX_WINDOW_SIDE
    assert (cli_synth.MIN_LENGTH_KM, cli_synth.MAX_LENGTH_KM) == (
        fly_strip.MIN_LENGTH_KM,
        fly_strip.MAX_LENGTH_KM,
    )
    assert cli_synth.MAX_LONG_WIDTH == math.isqrt(dynamic.MAX_WINDOW_PIXELS) == 2896


def test_clouds_beyond_the_cap_are_refused_not_capped(tmp_path, capsys):
    out = tmp_path / "x"
    args = ["synth", "--strip", "--length-km", "1000", "--clouds-per-100km", "30", "--out", out]
    line = _one_line_error(capsys, *args, "--quiet")
    assert "--clouds-per-100km 30" in line and "300 clouds" in line and "256" in line
    assert not out.exists()


def test_a_cloud_draw_beyond_the_cap_is_refused_by_the_library():
    from dyntarget.errors import InvalidParameterError
    from dyntarget.synth.strip import long_strip_spec

    # a mean of 255.9 clouds: draws above 256 are refused, never silently cut to 256
    outcomes = set()
    for seed in range(12):
        try:
            spec, _ = long_strip_spec(seed, 1000.0, clouds_per_100km=25.59, plumes=1)
            assert len(spec.clouds) <= 256
            outcomes.add("kept")
        except InvalidParameterError as exc:
            assert "more than the 256" in str(exc) and "--clouds-per-100km" in str(exc)
            outcomes.add("refused")
    assert outcomes == {"kept", "refused"}


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (["--size", "4096"], "--size 4096 --length 18432"),
        (["--size", "512", "--length", "65536"], "--size 512 --length 65536"),
        (["--size", "4096", "--length-km", "1000"], "--size 4096: a pass-length strip is 32 to 2896"),
    ],
)  # fmt: skip
def test_a_strip_too_large_to_render_is_refused_early_naming_the_option(
    tmp_path, capsys, args, word
):
    out = tmp_path / "x"
    line = _one_line_error(capsys, "synth", "--strip", "--scenes", "1", *args, "--out", out)
    assert word in line
    assert not out.exists()


# --------------------------------------------------------------------------- class 3: footprint


@pytest.mark.parametrize("footprint", ["999999", "256", "2", "0", "-1", "1e3", "nan"])
def test_a_footprint_beyond_its_limit_is_refused(strip, tmp_path, capsys, footprint):
    line = _one_line_error(
        capsys, "fly", "--scene", strip, *FLY, "--out", tmp_path / "o", "--footprint", footprint
    )
    assert "--footprint" in line
    assert not (tmp_path / "o").exists()


def test_a_footprint_wider_than_the_strip_is_refused(strip, tmp_path, capsys):
    line = _one_line_error(
        capsys, "fly", "--scene", strip, *FLY, "--out", tmp_path / "o", "--footprint", "17"
    )
    assert "17 WFOV px is wider than the strip's 16 WFOV px (--footprint)" in line
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- export-onnx


@pytest.mark.parametrize("size", ["999999", "8", "0", "nan"])
def test_export_onnx_refuses_a_check_size_before_touching_the_model(tmp_path, capsys, size):
    model = tmp_path / "model"
    model.mkdir()
    (model / "forest-kernel-x86-64.so").write_bytes(b"\x7fELF...")
    before = _tree(model)
    line = _one_line_error(capsys, "export-onnx", model, "--check-size", size)
    assert "--check-size" in line
    assert _tree(model) == before


def test_a_refusal_leaves_an_empty_out_folder_empty(strip, tmp_path, capsys):
    out = tmp_path / "empty"
    out.mkdir()
    line = _one_line_error(capsys, "fly", "--scene", strip, *FLY, "--out", out, "--footprint", "17")
    assert "--footprint" in line
    assert list(out.iterdir()) == []


def test_a_failing_campaign_rerun_leaves_each_earlier_pass_whole(
    strip, tmp_path, monkeypatch, capsys
):
    import dyntarget.view.pass_report as report

    out = tmp_path / "campaign"
    args = ["fly", "--campaign", str(strip.parent), "--truth", "--quiet", "--out", str(out)]
    assert main([*args, "--compute-budget-s", "0.05"]) == 0
    passes = out / "passes"
    before = _tree(passes)
    real = report.write_pass

    def failing(result, world, where, **kw):
        real(result, world, where, **kw)  # every file written, then the disk fills
        from dyntarget.errors import DataFileError

        raise DataFileError("disk full (simulated)")

    monkeypatch.setattr(report, "write_pass", failing)
    capsys.readouterr()
    assert "disk full" in _one_line_error(capsys, *args, "--compute-budget-s", "0.06")
    assert _tree(passes) == before  # other settings flew again; nothing of them was mixed in


def test_an_evaluation_table_moves_in_whole(tmp_path, monkeypatch):
    import dyntarget.evaluate.tables as tables
    from dyntarget.cli._common import show_result

    out = tmp_path / "eval"
    out.mkdir()
    result = {"rows": [{"a": 1, "b": 2.0}], "timing": {"seconds": 1.0}}
    show_result(str(out), "t", result, ["a", "b"])
    before = _tree(out)
    real = tables.write_table

    def failing(out_dir, stem, rows, columns, **kw):
        real(out_dir, stem, rows, columns, **kw)
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(tables, "write_table", failing)
    with pytest.raises(OSError):
        show_result(str(out), "t", {"rows": [{"a": 9, "b": 9.0}]}, ["a", "b"])
    assert _tree(out) == before
