"""The portable-forest table docs/performance.md quotes is its record's.

``docs/benchmarks/portable_forest.json`` (``benchmarks/portable_forest.py``) holds every
run's wall time; each table row is built again here from those runs (median, range, ratio
to the AVX2 row's median), so a rerun not copied to the page, or a figure edited by hand,
fails here.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
RELIABILITY = (ROOT / "docs" / "reliability.md").read_text(encoding="utf-8")
RECORD = json.loads((ROOT / "docs" / "benchmarks" / "portable_forest.json").read_text())


def _row(r: dict, base: float) -> str:
    isa = r["command"].split()[0].split("=")[1]
    extra = " `--onnx`" if " --onnx " in r["command"] else ""
    wall = statistics.median(r["wall_s"])
    return (
        f"| {r['row']} | `{isa}`{extra} | {wall:.3f} ({min(r['wall_s']):.3f}–"
        f"{max(r['wall_s']):.3f}) | {wall / base:.2f}× | {r['classify_median_s']:.3f} | "
        f"{r['peak_mib_median']:.0f} | {'yes' if r['plan_equals_avx2'] else 'no'} |"
    )


BY = {r["row"]: r for r in RECORD["rows"]}


def _wall(row: str) -> float:
    """A row's median wall seconds, from its runs."""
    return statistics.median(BY[row]["wall_s"])


def test_every_row_of_the_portable_forest_table_is_the_records():
    rows = RECORD["rows"]
    assert rows[0]["row"] == "avx2" and len(RECORD["rows"][0]["wall_s"]) == RECORD["runs"]
    base = statistics.median(rows[0]["wall_s"])
    for r in rows:
        assert _row(r, base) in PAGE, _row(r, base)
    assert f"{RECORD['runs']} rounds after a warm-up" in PAGE


def test_the_quoted_ratios_are_the_records():
    base = _wall("avx2")
    after, before = _wall("portable, after") / base, _wall("portable, before") / base
    assert f"**{after:.2f}× the AVX2 kernel**" in PAGE
    assert f"bit-identical and {after:.2f}×\nthe AVX2 kernel whole-process" in RELIABILITY
    assert f"(target ≤ 2×; before: {before:.2f}×)" in PAGE
    assert after <= 2.0 and BY["portable, after"]["plan_equals_avx2"]  # what "met" says
    cold = _wall("portable, after, first run")
    flat = " ".join(PAGE.split())
    assert f"row): {cold:.2f} s, {cold / base:.2f}×, once per forest." in flat
    oa, ob = _wall("--onnx, no kernel, after"), _wall("--onnx, no kernel, before")
    assert f"`plan --onnx` with no kernel takes {oa:.2f} s after and {ob:.2f} s before" in flat


def test_the_quoted_classify_times_and_load_are_the_records():
    after, avx2 = BY["portable, after"]["classify_median_s"], BY["avx2"]["classify_median_s"]
    assert f"({after:.2f} s against {avx2:.2f} s)" in PAGE
    assert f"about {after / avx2:.0f}× the AVX2 kernel's" in PAGE
    lo, hi = sorted((RECORD["load_1min_start"], RECORD["load_1min_end"]))
    assert f"(load {lo:.1f}-{hi:.1f})" in PAGE


def test_the_readme_quotes_the_records_ratios():
    readme = (ROOT / "README.md").read_text(encoding="utf-8").replace("\n", " ")
    base = _wall("avx2")
    after, before = _wall("portable, after") / base, _wall("portable, before") / base
    assert f"({after:.2f}× the AVX2 kernel's whole-process time" in readme
    assert f"against {before:.1f}× for scikit-learn" in readme
    cold = _wall("portable, after, first run") / base
    assert f"once per forest, {cold:.1f}× in that first process" in readme
