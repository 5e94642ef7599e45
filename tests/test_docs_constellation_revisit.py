"""The revisit figures docs/constellation.md and docs/results.md quote are their record's.

``docs/benchmarks/constellation_revisit.json`` (``benchmarks/constellation.py --parts
revisit``) holds every gap between successive observations of an eruption at 20
satellites; each figure the pages quote is worked out again here from those gaps (counts,
pooled medians in minutes, their ratio and its bootstrap interval), so a rerun that is not
copied to the pages, or a number edited by hand, fails here.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "constellation.md").read_text(encoding="utf-8")
RESULTS = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
RECORD = json.loads(
    (ROOT / "docs" / "benchmarks" / "constellation_revisit.json").read_text(encoding="utf-8")
)["revisit"]


def _mode(m: str) -> tuple[int, int, float]:
    gaps = RECORD["modes"][m]["gaps_s"]
    days = sum(1 for s in RECORD["modes"][m]["per_seed_median_s"] if s is not None)
    return len(gaps), days, statistics.median(gaps) / 60.0


def test_the_quoted_revisit_figures_are_the_records():
    (nc, dc, mc), (nn, dn, mn) = _mode("cross"), _mode("none")
    lo, hi = RECORD["cross_over_none_bootstrap_95"]
    ratio = f"{mc / mn:.2f}×"
    assert RECORD["seeds"] == 200 and f"over {RECORD['seeds']} seeds" in PAGE
    assert f"`none` revisits an eruption {nn} times, in {dn} of the 200 days" in PAGE
    assert f"median gap of {mn:.0f} min" in PAGE
    assert f"`cross` {nc:,} times (in {dc} days), median {mc:.0f} min: {ratio}" in PAGE
    assert f"interval\n{lo:.2f}–{hi:.2f}" in PAGE or f"interval {lo:.2f}–{hi:.2f}" in PAGE
    row = f"`cross` {mc:.0f} min ({nc:,} gaps), `none` {mn:.0f} min ({nn} gaps, in {dn} of"
    assert row in PAGE and f"{ratio} (bootstrap 95 %: {lo:.2f}–{hi:.2f})" in PAGE
    assert f"{ratio} `none`'s ({mc:.0f} against {mn:.0f} min" in RESULTS.replace("\n", " ")


def test_the_quoted_shares_of_short_and_long_gaps_are_the_records():
    cross = [g / 60.0 for g in RECORD["modes"]["cross"]["gaps_s"]]
    none = [g / 60.0 for g in RECORD["modes"]["none"]["gaps_s"]]
    short = sum(10 <= g < 25 for g in cross)
    assert f"({short} of {len(cross):,}:" in PAGE
    assert f"{sum(g > 600 for g in none)} of\n`none`'s {len(none)} are over 10 h" in PAGE


def test_the_quoted_observations_per_eruption_are_the_records():
    c, n = (RECORD["modes"][m]["per6"] for m in ("cross", "none"))
    assert len(c) == len(n) == RECORD["modes"]["cross"]["detected_eruptions"]
    mc, mn = statistics.fmean(c), statistics.fmean(n)
    lo, hi = RECORD["per6_cross_over_none_bootstrap_95"]
    ratio = f"{mc / mn:.2f}×, bootstrap 95 %: {lo:.2f}–{hi:.2f}"
    assert f"over {len(c):,} detected eruptions in each" in PAGE
    assert f"`cross` observes one {mc:.2f} times" in PAGE and f"`none` {mn:.2f}\ntimes" in PAGE
    assert f"{mc:.2f} against {mn:.2f} ({ratio})" in PAGE.replace("\n", " ")
    assert f"over 200 days, {ratio};" in RESULTS.replace("\n", " ")


def test_the_quoted_episode_figures_of_cross_and_geo_are_the_records():
    g, n = RECORD["modes"]["cross+geo"], RECORD["modes"]["none"]
    assert g["episodes_started"] == n["episodes_started"]  # the same worlds
    share = {k: 100 * v["episodes_observed_within_6h"] / v["episodes_started"] for k, v in
             (("g", g), ("n", n))}  # fmt: skip
    hours = {k: statistics.median(v["episode_delays_s"]) / 3600 for k, v in (("g", g), ("n", n))}
    lo, hi = RECORD["episode_delay_geo_over_none_bootstrap_95"]
    text = PAGE.replace("\n", " ")
    assert f"of the {g['episodes_started']:,} plume episodes starting in the 200 days" in text
    assert (
        f"observes {share['g']:.1f} % within 6 h of their onset, `none` {share['n']:.1f} %" in text
    )
    assert f"({share['g'] / share['n']:.2f}×: the ≥ 40 % target is met)" in text
    delay = f"{hours['g']:.2f} h against {hours['n']:.2f} h"
    r = f"{hours['g'] / hours['n']:.2f}×"
    boot = f"bootstrap 95 %: {lo:.2f}–{hi:.2f}"
    assert f"{delay}, {r} ({boot})" in text and f"{delay} ({r}, {boot})" in text
    assert f"{r} over 200 days ({delay};" in RESULTS.replace("\n", " ")
    assert f"{share['g']:.1f} % against {share['n']:.1f} %" in RESULTS.replace("\n", " ")
