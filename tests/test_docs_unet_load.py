"""The U-Net-under-load tables docs/performance.md quotes are their records'.

``docs/benchmarks/unet_bound_load.json`` and ``unet_bound_spin.json``
(``benchmarks/unet_bound.py run --load N``, merged) hold every run's classify time, bound
and ratio; each row is built again here from those runs, so a rerun not copied to the
page, or a figure edited by hand, fails here.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
RECORD = json.loads((ROOT / "docs" / "benchmarks" / "unet_bound_load.json").read_text())
SPIN = json.loads((ROOT / "docs" / "benchmarks" / "unet_bound_spin.json").read_text())
FLAT = " ".join(PAGE.split())


def runs_of(record: dict, label: str) -> list[dict]:
    return [r for p in record["processes"] if p["label"] == label for r in p["runs"]]


def cells(record: dict, label: str) -> tuple[str, str, str]:
    """``load``, ``threads`` and ``classify | bound | ratio median (min–max)`` of one row."""
    parts = [p for p in record["processes"] if p["label"] == label]
    runs = runs_of(record, label)
    ratios = [r["ratio"] for r in runs]
    (load,) = {p["load_processes"] for p in parts}
    threads = "/".join(str(t) for t in sorted({r["threads"] for r in runs}))
    times = (
        f"{statistics.median(r['classify_s'] for r in runs):.3f} | "
        f"{statistics.median(r['bound_s'] for r in runs):.3f} | "
        f"**{statistics.median(ratios):.2f}** ({min(ratios):.2f}–{max(ratios):.2f})"
    )
    return f"{load}", threads, times


def medians(record: dict) -> dict[str, float]:
    """Each row's median per-run ratio, by label."""
    return {
        label: statistics.median(r["ratio"] for r in runs_of(record, label))
        for label in record["summary"]
    }


def met(record: dict, label: str) -> str:
    return "yes" if medians(record)[label] <= 3 else "no"


def rows() -> list[str]:
    """The table's rows, from the runs themselves (not the record's own summary)."""
    out = []
    for label in RECORD["summary"]:
        load, threads, times = cells(RECORD, label)
        parts = [p for p in RECORD["processes"] if p["label"] == label]
        fixed = " (fixed)" if any(p.get("threads_fixed") for p in parts) else ""
        out.append(f"| {load} | {threads}{fixed} | {times} | {met(RECORD, label)} |")
    return out


def test_every_row_of_the_unet_load_table_is_the_records():
    assert len(rows()) == 6
    for row in rows():
        assert row in PAGE, row


def test_the_quoted_summary_is_the_records():
    med = medians(RECORD)
    shared = [med[f"load-{n}"] for n in (2, 3, 4)]
    assert med["load-0"] <= 3 and med["load-1"] <= 3 and min(shared) > 3
    assert f"(2-4 load processes: {min(shared):.1f}-{max(shared):.1f}×)" in FLAT
    assert f"at the median ({med['load-2-threads-2']:.1f}×)" in FLAT
    worst = max(r["ratio"] for r in runs_of(RECORD, "load-2-threads-2"))
    assert f"their worst run is {worst:.1f}×" in FLAT


def spin_rows() -> list[str]:
    """The bounded-spin table's rows, from the runs themselves."""
    out = []
    for label in SPIN["summary"]:
        load, threads, times = cells(SPIN, label)
        ratios = [r["ratio"] for r in runs_of(SPIN, label)]
        over = f"{sum(x > 3 for x in ratios)} of {len(ratios)}"
        code = label.split("-")[0]
        out.append(f"| {load} | {code} | {threads} | {times} | {over} | {met(SPIN, label)} |")
    return out


def test_every_row_of_the_bounded_spin_table_is_the_records():
    assert len(spin_rows()) == 10
    for row in spin_rows():
        assert row in PAGE, row


def test_the_bounded_spin_summary_is_the_records():
    # the "after" processes ran with the command's setting, the "before" ones without
    for p in SPIN["processes"]:
        assert p["gomp_spincount"] == ("10000" if p["label"].startswith("after") else None)
    med = medians(SPIN)
    after = [med[f"after-load-{n}"] for n in range(5)]
    shared = [med[f"before-load-{n}"] for n in (2, 3, 4)]
    assert max(after) <= 3 < min(shared)
    assert f"the median per-run ratio is {min(after):.2f}-{max(after):.2f}×" in FLAT
    assert f"it was {min(shared):.1f}-{max(shared):.1f}× with every core shared" in FLAT
    over = [
        r["ratio"] for n in range(5) for r in runs_of(SPIN, f"after-load-{n}") if r["ratio"] > 3
    ]
    total = sum(len(runs_of(SPIN, f"after-load-{n}")) for n in range(5))
    assert f"({len(over)} of the {total} after the change, at most {max(over):.2f}×)" in FLAT
    n = {k: sum(r["ratio"] > 3 for r in runs_of(SPIN, f"after-load-{k}")) for k in (3, 4)}
    m = {k: len(runs_of(SPIN, f"after-load-{k}")) for k in (3, 4)}
    assert (
        f"({n[3]} of {m[3]} at 3 load processes, {n[4]} of {m[4]} at 4, at most {max(over):.2f}×)"
        in FLAT
    )
    now = [med[f"after-load-{n}"] for n in (2, 3, 4)]
    assert (
        f"its median ratio is {min(now):.2f}-{max(now):.2f}× against {min(shared):.2f}-{max(shared):.2f}×"
        in FLAT
    )
    secs = {
        arm: [
            statistics.median(r["classify_s"] for r in runs_of(SPIN, f"{arm}-load-{n}"))
            for n in (2, 3, 4)
        ]
        for arm in ("before", "after")
    }
    assert (
        f"takes {min(secs['after']):.2f}-{max(secs['after']):.2f} s against "
        f"{min(secs['before']):.2f}-{max(secs['before']):.2f} s before" in FLAT
    )


def test_the_readme_quotes_the_bounded_spin_record():
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    med = medians(SPIN)
    after = [med[f"after-load-{n}"] for n in (2, 3, 4)]
    before = [med[f"before-load-{n}"] for n in (2, 3, 4)]
    assert (
        f"{min(after):.1f}-{max(after):.1f}× its FLOP bound at the median, "
        f"{min(before):.1f}-{max(before):.1f}× before" in readme
    )
