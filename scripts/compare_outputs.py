"""Compare two output trees of ``scripts/identity_outputs.sh``, ignoring only measured times.

Every file must be byte-identical except what holds wall-clock times: ``stage_times.csv``, the
``*.timing.json`` files, the timing columns of ``timeline.csv``, the runtime column of Table 2
and the report's "took ... written ..." line. Figures and HTML views are skipped (their bytes
carry rendering metadata); their data is in the CSV/GeoJSON files compared.

Usage: ``python scripts/compare_outputs.py BEFORE AFTER``; exit 1 when anything else differs.
"""

from __future__ import annotations

import csv
import io
import json
import sys
from pathlib import Path

TIMING_COLUMNS = {
    "start_s", "ready_s", "latency_s", "classify_s", "denoise_s", "predict_s",
    "plan_s", "schedule_s", "loop_s",
}  # fmt: skip
SKIPPED_SUFFIXES = {".png", ".html", ".log"}


def _drop_runtime(value: object) -> object:
    """``value`` with every mapping key that names a runtime removed, recursively."""
    if isinstance(value, dict):
        return {k: _drop_runtime(v) for k, v in value.items() if "runtime" not in k.lower()}
    if isinstance(value, list):
        return [_drop_runtime(v) for v in value]
    return value


def _without_timing(rel: Path, text: str) -> object:
    """The file's content with its measured times taken out, or the text itself."""
    if rel.name == "timeline.csv":
        rows = list(csv.DictReader(io.StringIO(text)))
        return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]
    if rel.name.startswith("table2") and rel.suffix == ".csv":
        return [row[:-1] for row in csv.reader(io.StringIO(text))]
    if rel.name.startswith("table2") and rel.suffix == ".json":
        return _drop_runtime(json.loads(text))
    if rel.suffix == ".md":
        out, drop = [], None
        for line in text.splitlines():
            if " took " in line and "written" in line:
                continue  # the report's run line
            if not line.startswith("|"):
                drop = None
            else:
                cells = line.split("|")
                if drop is None and any("Runtime" in c for c in cells):
                    drop = [i for i, c in enumerate(cells) if "Runtime" in c]
                line = "|".join(c for i, c in enumerate(cells) if i not in (drop or []))
            if "runtime" in line.lower() and "|" in line and drop is None:
                continue  # the checklist's runtime claim quotes measured times
            out.append(line)
        return out
    return text


def main(before: Path, after: Path) -> int:
    bad = 0
    for fa in sorted(before.rglob("*")):
        rel = fa.relative_to(before)
        if fa.is_dir() or {"parts", "models"} & set(rel.parts):
            continue
        if (
            rel.suffix in SKIPPED_SUFFIXES
            or rel.name == "stage_times.csv"
            or ".timing." in rel.name
        ):
            continue
        fb = after / rel
        if not fb.exists():
            print(f"missing in {after}: {rel}")
            bad += 1
        elif fa.read_bytes() != fb.read_bytes():
            ta, tb = fa.read_text(), fb.read_text()
            if _without_timing(rel, ta) == _without_timing(rel, tb):
                print(f"same but for measured times: {rel}")
            else:
                print(f"DIFFERS: {rel}")
                bad += 1
    print(f"{bad} file(s) differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
