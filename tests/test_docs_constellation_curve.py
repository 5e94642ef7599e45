"""The constellation curve's table in docs/constellation.md is its record's.

``docs/benchmarks/constellation.json`` (``benchmarks/constellation.py --parts curve``)
holds every constellation-day's ``summary.json``; each row of the table (distributed
allocation, one row per satellites x cueing mode) is built again here from those
summaries, so a rerun not copied to the page, or a figure edited by hand, fails here.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "constellation.md").read_text(encoding="utf-8")
RECORD = json.loads((ROOT / "docs" / "benchmarks" / "constellation.json").read_text())


def _mean_of_those_with(values: list, scale: float, digits: int) -> str:
    """The mean over the seeds that have a value, and how many have one."""
    have = [v / scale for v in values if v is not None]
    if not have:
        return f"— (0/{len(values)})"
    return f"{statistics.fmean(have):.{digits}f} ({len(have)}/{len(values)})"


def rows() -> list[str]:
    groups: dict[tuple[int, str], list[dict]] = {}
    for day in RECORD["curve"]:
        if day["options"]["allocation"] == "distributed":
            groups.setdefault((day["satellites"], day["options"]["cueing"]), []).append(day)
    out = []
    for (n, mode), days in groups.items():
        per6 = [d["observations_per_eruption_6h"] for d in days]
        per6 = [p for p in per6 if p is not None]
        observations = sum(d["observations"] for d in days)
        cells = [
            str(n),
            mode,
            str(len(days)),
            f"{statistics.fmean(d['eruptions'] for d in days):.1f}",
            f"{statistics.fmean(100 * d['eruptions_observed'] / d['eruptions'] for d in days):.1f}",
            f"{statistics.fmean(per6):.2f}" if per6 else "—",
            _mean_of_those_with([d["median_revisit_s"] for d in days], 60, 1),
            f"{statistics.fmean(100 * d['episodes_observed_within_6h'] / d['episodes_started'] for d in days):.1f}",
            _mean_of_those_with([d["median_episode_onset_to_first_obs_s"] for d in days], 3600, 2),
            str(sum(d["eruptions_started"] for d in days)),
            str(sum(d["observed_within_6h"] for d in days)),
            f"{100 * sum(d['duplicates'] for d in days) / observations:.1f}"
            if observations
            else "—",
            f"{statistics.fmean(d['wasted_pointings'] for d in days):.1f}",
        ]
        out.append("| " + " | ".join(cells) + " |")
    return out


def test_every_row_of_the_curve_table_is_the_records():
    assert len(rows()) == 24  # 1, 7, 20, 60, 200 and 500 satellites x four modes
    for row in rows():
        assert row in PAGE, row


def test_the_quoted_duplicates_are_the_records():
    def share(n: int, mode: str) -> float:
        days = [
            d
            for d in RECORD["curve"]
            if d["satellites"] == n
            and d["options"]["cueing"] == mode
            and d["options"]["allocation"] == "distributed"
        ]
        return 100 * sum(d["duplicates"] for d in days) / sum(d["observations"] for d in days)

    flat = " ".join(PAGE.split())
    board_less = [share(n, m) for n in (200, 500) for m in ("none", "self")]
    assert max(board_less) <= 5
    assert f"{min(board_less):.1f}–{max(board_less):.1f} % at 200–500 in `none`/`self`" in flat
