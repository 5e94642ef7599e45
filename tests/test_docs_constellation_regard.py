"""The field-of-regard table docs/constellation.md quotes is its record's.

``docs/benchmarks/constellation_regard.json`` (``benchmarks/constellation.py --parts
regard``) holds the 20-satellite targets over 200 days with ``fast`` agility's field of
regard widened; each row is built again here from the record, the "met" column from the
targets' own thresholds, and the default's row is checked against the separate 200-day
revisit run (the same days: the same ratios).
"""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "constellation.md").read_text(encoding="utf-8")
RESULTS = " ".join((ROOT / "docs" / "results.md").read_text(encoding="utf-8").split())
BENCH = ROOT / "docs" / "benchmarks"
ROWS = json.loads((BENCH / "constellation_regard.json").read_text(encoding="utf-8"))["regard"]
REVISIT = json.loads((BENCH / "constellation_revisit.json").read_text(encoding="utf-8"))["revisit"]


def _with_interval(value: float, interval: list[float]) -> str:
    return f"{value:.2f}× ({interval[0]:.2f}–{interval[1]:.2f})"


def met(row: dict) -> list[bool]:
    """The four 20-satellite targets: 3x, <= 1/3, >= 1.4x (40 % more), <= 1/2 (halves)."""
    return [
        row["per6_cross_over_none"] >= 3,
        row["cross_over_none"] <= 1 / 3,
        row["episodes_6h_geo_over_none"] >= 1.4,
        row["episode_delay_geo_over_none"] <= 0.5,
    ]


def table_rows() -> list[str]:
    out = []
    for row in ROWS:
        cells = [
            f"{row['field_of_regard_deg']:g}",
            _with_interval(row["per6_cross_over_none"], row["per6_cross_over_none_bootstrap_95"]),
            _with_interval(row["cross_over_none"], row["cross_over_none_bootstrap_95"]),
            f"{row['episodes_6h_geo_over_none']:.2f}×",
            _with_interval(
                row["episode_delay_geo_over_none"], row["episode_delay_geo_over_none_bootstrap_95"]
            ),
            " / ".join("yes" if m else "no" for m in met(row)),
        ]
        out.append("| " + " | ".join(cells) + " |")
    return out


def test_every_row_of_the_field_of_regard_table_is_the_records():
    assert [r["field_of_regard_deg"] for r in ROWS] == [30.0, 40.0, 50.0, 60.0]
    assert all(r["seeds"] == 200 for r in ROWS)
    for row in table_rows():
        assert row in PAGE, row


def test_the_default_row_is_the_revisit_runs():
    (default,) = [r for r in ROWS if r["agility"] == "fast"]
    for key in (
        "per6_cross_over_none",
        "cross_over_none",
        "episodes_6h_geo_over_none",
        "episode_delay_geo_over_none",
    ):
        assert default[key] == REVISIT[key], key


def test_the_quoted_least_field_of_regard_is_the_records():
    every = [r["field_of_regard_deg"] for r in ROWS if all(met(r))]
    assert every, "no field of regard meets every target"
    flat = " ".join(PAGE.split())
    quote = f"every 20-satellite target is met from a {min(every):g}° field of regard"
    assert quote in flat and quote in RESULTS


def test_the_results_page_quotes_the_50_degree_row_and_the_wall_time():
    (row,) = [r for r in ROWS if r["field_of_regard_deg"] == 50.0]
    assert (
        f"{row['per6_cross_over_none']:.2f}× the observations, {row['cross_over_none']:.2f}× "
        f"the revisit gap, {row['episode_delay_geo_over_none']:.2f}× the delay" in RESULTS
    )
    minutes = sum(r["wall_s"] for r in ROWS) / 60
    assert f"2,400 constellation-days, {minutes:.0f} min on the 2-core" in " ".join(PAGE.split())
