"""bench: each U-Net classification set against a bound measured around it (issue 43)."""

from __future__ import annotations

import pytest

from dyntarget.evaluate.bench import matmul_rate, measure, per_run_bound, summary_tables


def test_measure_brackets_each_timed_run_with_two_probe_readings():
    events = []
    readings = iter(range(100))

    def probe():
        events.append("probe")
        return float(next(readings))

    rec = measure(lambda: events.append("run"), repeats=2, probe=probe)
    # warm-up, then (probe, run, probe) per timed run, then the memory run
    assert events == ["run", "probe", "run", "probe", "probe", "run", "probe", "run"]
    assert [(r["probe_before"], r["probe_after"]) for r in rec["runs"]] == [(0.0, 1.0), (2.0, 3.0)]
    assert all(r["load_1min"] >= 0 for r in rec["runs"])


def test_measure_without_probe_keeps_its_former_record():
    assert "runs" not in measure(lambda: None, repeats=1)


def test_each_run_is_set_against_the_higher_rate_measured_around_it():
    # 2e9 FLOP: 1 s at 2 GFLOP/s (the higher of 1 and 2), run of 3 s -> ratio 3;
    # second run: 4 GFLOP/s -> bound 0.5 s, run of 2 s -> ratio 4; median 3.5
    rec = {
        "runs": [
            {"s": 3.0, "probe_before": 1e9, "probe_after": 2e9, "load_1min": 7.5},
            {"s": 2.0, "probe_before": 4e9, "probe_after": 3e9, "load_1min": 8.0},
        ]
    }
    out = per_run_bound(rec, 2e9, threads=1)
    assert out["ratios"] == [3.0, 4.0]
    assert out["ratio_median"] == pytest.approx(3.5)
    assert [r["bound_s"] for r in out["runs"]] == pytest.approx([1.0, 0.5])
    assert out["load_1min"] == [7.5, 8.0] and {r["threads"] for r in out["runs"]} == {1}


def test_matmul_rate_takes_the_best_thread_count_and_restores_torch_threads():
    import torch

    from dyntarget.perceive.resources import available_cores

    before = torch.get_num_threads()
    r = matmul_rate(n=128, repeats=2)
    assert torch.get_num_threads() == before
    assert set(r["by_threads"]) == {"1", str(available_cores())}
    assert r["flop_per_s"] == max(r["by_threads"].values())
    # 2 * 128**3 FLOP in no less than 1 ns per 1000 FLOP would be 4.2 ms: a sane rate
    assert 1e8 < r["flop_per_s"] < 1e13


def test_bounds_table_shows_the_per_run_ratios():
    base = {"size": 256, "classifier": "unet-xception"}
    recs = [
        base | {"stage": "classify", "planner": None, "median_s": 0.3, "peak_mib": 1.0,
                "ratios": [2.0, 3.0, 2.5]},
        base | {"stage": "denoise", "planner": None, "median_s": 0.0},
        base | {"stage": "plan", "planner": "lawnmower-transect", "median_s": 0.0},
        base | {"stage": "observe", "planner": "lawnmower-transect", "median_s": 0.0},
    ]  # fmt: skip
    bounds = {
        "rates": {"copy_bytes_per_s": 1e10, "matmul_flop_per_s": 1e11},
        "sizes": {"256": {"read_image_s": 1e-4, "unet-xception": {
            "one_pass": 1e10, "tiled": 1e10, "one_pass_s": 0.1, "tiled_s": 0.1}}},
    }  # fmt: skip
    text = summary_tables({"sizes": [256], "records": recs, "bounds": bounds})
    row = next(ln for ln in text.splitlines() if ln.startswith("| unet-xception") and "GFLOP" in ln)
    assert "2.50; 2.00, 3.00, 2.50" in row  # median of the three, then each run
    assert "| 3.0 |" in row  # 300 ms over the 100 ms bound measured at the start


@pytest.mark.slow
def test_bench_records_a_ratio_per_unet_run():
    from dyntarget.evaluate.bench import run_bench

    result = run_bench(
        sizes=[32], classifiers=["unet-xception", "band-threshold"],
        planners=["straight-nadir"], repeats=2, epochs=1, progress=False,
    )  # fmt: skip
    unet = next(
        r for r in result["records"]
        if r["stage"] == "classify" and r["classifier"] == "unet-xception"
    )  # fmt: skip
    assert len(unet["runs"]) == 2 and len(unet["ratios"]) == 2
    for run, ratio in zip(unet["runs"], unet["ratios"], strict=True):
        rate = max(run["probe_before"], run["probe_after"])
        flops = result["bounds"]["sizes"]["32"]["unet-xception"]["one_pass"]
        assert ratio == pytest.approx(run["s"] * rate / flops, rel=1e-3)
        assert run["threads"] >= 1
    forest = next(
        r for r in result["records"]
        if r["stage"] == "classify" and r["classifier"] == "band-threshold"
    )  # fmt: skip
    assert "ratios" not in forest
