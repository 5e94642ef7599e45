"""bench: scaling only when two sizes measure it; the forest path and the CPU recorded."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from dyntarget.evaluate.bench import FOREST_CPU_FLAGS, cpu_summary, summary_tables


def _result(sizes, seconds):
    """A bench result by hand: one classifier, one planner, classify taking ``seconds``."""
    recs = []
    for size, t in zip(sizes, seconds, strict=True):
        base = {"size": size, "classifier": "band-threshold"}
        recs += [
            base | {"stage": "classify", "planner": None, "median_s": t, "peak_mib": 1.0},
            base | {"stage": "denoise", "planner": None, "median_s": 0.0},
            base | {"stage": "plan", "planner": "lawnmower-transect", "median_s": 0.0},
            base | {"stage": "observe", "planner": "lawnmower-transect", "median_s": 0.0},
        ]
    return {"sizes": list(sizes), "records": recs}


def test_one_size_reports_no_scaling_and_no_nan():
    text = summary_tables(_result([256], [0.5]))
    assert "scaling" not in text
    assert "nan" not in text.lower()


def test_two_sizes_report_the_scaling_exponent_worked_by_hand():
    # 4x the pixels (256 -> 512 px) and 4x the time: exponent 1 (linear in pixels)
    text = summary_tables(_result([256, 512], [0.5, 2.0]))
    header = next(ln for ln in text.splitlines() if "scaling exponent" in ln)
    row = next(ln for ln in text.splitlines() if ln.startswith("| band-threshold"))
    col = [c.strip() for c in header.split("|")].index("scaling exponent")
    assert float(row.split("|")[col]) == pytest.approx(1.0, abs=1e-3)


def test_cpu_summary_names_the_forest_flags_this_cpu_has():
    c = cpu_summary()
    with open("/proc/cpuinfo") as fh:
        flags = set()
        for line in fh:
            if line.startswith(("flags", "Features")):
                flags.update(line.split(":", 1)[1].split())
    assert c["flags"] == [f for f in FOREST_CPU_FLAGS if f in flags]
    assert c["model"]


@pytest.mark.slow
@pytest.mark.parametrize("isa", ["off", "portable"])
def test_bench_json_records_the_forced_forest_path(tmp_path, isa):
    """DYNTARGET_FOREST_ISA forces a path: bench.json says which one ran (off: no kernel,
    so ONNX Runtime's tree ensemble where onnxruntime is installed, else scikit-learn)."""
    env = {**os.environ, "DYNTARGET_FOREST_ISA": isa}
    done = subprocess.run(
        [sys.executable, "-m", "dyntarget.cli", "bench", "--sizes", "64", "--classifiers",
         "random-forest", "--planners", "lawnmower-transect", "--repeats", "1", "--out",
         str(tmp_path / "bench.json"), "--markdown", str(tmp_path / "bench.md"), "--quiet"],
        capture_output=True, text=True, env=env, timeout=600, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    doc = json.loads((tmp_path / "bench.json").read_text())
    import importlib.util

    portable = "onnxruntime" if importlib.util.find_spec("onnxruntime") else "sklearn"
    assert doc["forest_path"] == (portable if isa == "off" else "portable")
    assert doc["cpu"]["model"] == cpu_summary()["model"]
    md = (tmp_path / "bench.md").read_text()
    assert "nan" not in md.lower() and "scaling" not in md
