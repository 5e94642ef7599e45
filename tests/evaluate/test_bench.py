from __future__ import annotations

import json

import pytest

from dyntarget.cli import main
from dyntarget.evaluate.bench import measure, scaling_exponent


def test_scaling_exponent_by_hand():
    assert scaling_exponent([100, 200, 400], [1.0, 4.0, 16.0]) == pytest.approx(
        1.0
    )  # linear in pixels
    assert scaling_exponent([100, 200], [1.0, 2.0]) == pytest.approx(0.5)


def test_measure_reports_median_and_peak():
    calls = []
    m = measure(lambda: calls.append(1), repeats=3)
    assert len(calls) == 5  # warm-up, 3 timed, 1 for memory
    assert m["median_s"] >= 0 and m["min_s"] <= m["median_s"]


@pytest.mark.slow
def test_bench_cli_small(tmp_path, capsys):
    code = main(
        [
            "bench",
            "--sizes",
            "32,48",
            "--classifiers",
            "decision-tree,band-threshold",
            "--planners",
            "trace-outline,straight-nadir",
            "--repeats",
            "1",
            "--out",
            str(tmp_path / "b.json"),
            "--markdown",
            str(tmp_path / "b.md"),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    result = json.loads((tmp_path / "b.json").read_text())
    stages = {(r["stage"], r["size"], r["classifier"], r["planner"]) for r in result["records"]}
    assert ("classify", 48, "decision-tree", None) in stages
    assert ("observe", 32, "band-threshold", "trace-outline") in stages
    assert len(result["records"]) == 2 * 2 * (2 + 2 * 2)
    assert (
        "versions" in result["machine"]
        and "Pipeline (classify + denoise + plan" in (tmp_path / "b.md").read_text()
    )


def test_bench_bad_size(tmp_path, capsys):
    assert main(["bench", "--sizes", "8", "--out", str(tmp_path / "b.json")]) == 2
    assert "at least 32 px" in capsys.readouterr().err


@pytest.mark.slow
def test_unet_flops_scale_with_area_and_tiling_costs_more(tiny_scenes):
    from dyntarget.evaluate.bench import unet_flops
    from dyntarget.perceive import make_classifier
    from helpers import FAST_KWARGS

    model = make_classifier("unet-uavsar", **FAST_KWARGS["unet-uavsar"]).fit(tiny_scenes[:2])
    small, large = unet_flops(model, 64), unet_flops(model, 128)
    assert small["one_pass"] > 0 and large["one_pass"] == pytest.approx(4 * small["one_pass"])
    # halo stitching: the whole 128 px image in one pass, no redundancy
    assert large["tiled"] == pytest.approx(large["one_pass"])
    # the former overlapping tiles (stride tile/2) compute most pixels several times:
    # 32 px tiles at stride 16 over 128 px -> 7 x 7 tiles of 32² px = 49/16 of one pass
    blend = unet_flops(model.set_stitching("blend"), 128)
    assert blend["tiled"] == pytest.approx(49 / 16 * large["one_pass"])


@pytest.mark.slow
def test_bounds_table_in_bench_output(tmp_path, capsys):
    code = main(
        [
            "bench",
            "--sizes",
            "32",
            "--classifiers",
            "band-threshold",
            "--planners",
            "straight-nadir",
            "--repeats",
            "1",
            "--out",
            str(tmp_path / "b.json"),
            "--markdown",
            str(tmp_path / "b.md"),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    rates = json.loads((tmp_path / "b.json").read_text())["bounds"]["rates"]
    assert rates["copy_bytes_per_s"] > 0 and rates["matmul_flop_per_s"] > 0
    assert "read the image once" in (tmp_path / "b.md").read_text()


def test_machine_records_the_commit_and_the_cpu_flags_that_pick_a_code_path():
    import re
    import subprocess
    from pathlib import Path

    from dyntarget.evaluate.bench import MACHINE_FLAGS, machine

    m = machine()
    text = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    found = set()
    for line in re.findall(r"^(?:flags|Features)\s*:(.*)$", text, flags=re.M):
        found.update(line.split())
    assert m["cpu_flags"] == [f for f in MACHINE_FLAGS if f in found]
    head = subprocess.run(
        ["git", "-C", str(Path(__file__).parent), "rev-parse", "HEAD"],
        capture_output=True,
        text=True,
    )
    if head.returncode == 0 and m["commit"] is not None:  # a checkout: the same commit
        assert m["commit"].removesuffix("+dirty") == head.stdout.strip()
    assert m["cpus"] >= 1 and m["load_1min"] >= 0


def test_machine_records_the_openmp_spin_that_picks_a_unet_pass_s_threads(monkeypatch):
    from dyntarget.evaluate.bench import machine

    monkeypatch.setenv("GOMP_SPINCOUNT", "7k")  # 7,000 spins, as libgomp reads it
    assert machine()["openmp_spin_count"] == 7000
    monkeypatch.delenv("GOMP_SPINCOUNT")
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    assert machine()["openmp_spin_count"] == 0
