"""The U-Net-under-load table docs/performance.md quotes is its record's.

``docs/benchmarks/unet_bound_load.json`` (``benchmarks/unet_bound.py run --load N``, merged)
holds every run's classify time, bound and ratio; each row is built again here from those
runs, so a rerun not copied to the page, or a figure edited by hand, fails here.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
RECORD = json.loads((ROOT / "docs" / "benchmarks" / "unet_bound_load.json").read_text())


def rows() -> list[str]:
    """The table's rows, from the runs themselves (not the record's own summary)."""
    out = []
    for label in RECORD["summary"]:
        parts = [p for p in RECORD["processes"] if p["label"] == label]
        runs = [r for p in parts for r in p["runs"]]
        ratios = [r["ratio"] for r in runs]
        med = statistics.median(ratios)
        (load,) = {p["load_processes"] for p in parts}
        threads = "/".join(str(t) for t in sorted({r["threads"] for r in runs}))
        fixed = " (fixed)" if any(p.get("threads_fixed") for p in parts) else ""
        out.append(
            f"| {load} | {threads}{fixed} | {statistics.median(r['classify_s'] for r in runs):.3f} | "
            f"{statistics.median(r['bound_s'] for r in runs):.3f} | **{med:.2f}** "
            f"({min(ratios):.2f}–{max(ratios):.2f}) | {'yes' if med <= 3 else 'no'} |"
        )
    return out


def test_every_row_of_the_unet_load_table_is_the_records():
    assert len(rows()) == 6
    for row in rows():
        assert row in PAGE, row


def test_the_quoted_summary_is_the_records():
    med = {
        label: statistics.median(
            r["ratio"] for p in RECORD["processes"] if p["label"] == label for r in p["runs"]
        )
        for label in RECORD["summary"]
    }
    shared = [med[f"load-{n}"] for n in (2, 3, 4)]
    assert med["load-0"] <= 3 and med["load-1"] <= 3 and min(shared) > 3
    flat = " ".join(PAGE.split())
    assert f"(2-4 load processes: {min(shared):.1f}-{max(shared):.1f}×)" in flat
    both = f"{med['load-0']:.2f}× both" if f"{med['load-0']:.2f}" == f"{med['load-1']:.2f}" else ""
    assert f"({both}), not with 2-4 single-threaded processes on the 2 cores " in flat
    assert f"({min(shared):.1f}-{max(shared):.1f}×).*" in flat
    assert f"at the median ({med['load-2-threads-2']:.1f}×)" in flat
    worst = max(
        r["ratio"]
        for p in RECORD["processes"]
        if p["label"] == "load-2-threads-2"
        for r in p["runs"]
    )
    assert f"their worst run is {worst:.1f}×" in flat
