"""Does predictive planning recover the zero-latency ratio plume? Static vs predictive vs wind prior.

Reads the per-scene records of ``dyntarget evaluate dynamic ... --modes
static,predictive,wind-prior`` (``OUT/dynamic.json``) and writes, per classifier
and look-ahead planner, the ratio plume at each latency and the share of the
zero-latency value each mode keeps at ``--latency`` (default 90 s), plus a
figure of ratio plume against latency with one curve per mode.

    python benchmarks/predictive_recovery.py --dynamic OUT/dynamic.json \\
        [--latency 90] [--out docs/benchmarks/predictive_recovery.json] \\
        [--figure docs/img/predictive-vs-static.png] [--compare OTHER/dynamic.json]

``--compare`` puts another run on the same scenes beside this one (the mean ratio plume at
``--latency`` per classifier, planner and mode both have), e.g. the same evaluation with
another version of ``dyntarget.predict``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.tables import markdown_table

MODES = ("static", "predictive", "wind-prior")
STYLE = {"static": "--", "predictive": "-", "wind-prior": ":"}


def recovery(records: list[dict], latency: float) -> list[dict]:
    """Mean ratio plume at 0 s and at ``latency`` per classifier x planner x mode, and their ratio."""
    rows = []
    keys = dict.fromkeys(
        (r["classifier"], r["planner"]) for r in records if r["classifier"] != "N/A"
    )
    for cname, pname in keys:
        for mode in MODES:
            sel = [
                r
                for r in records
                if r["classifier"] == cname and r["planner"] == pname and r["mode"] == mode
            ]
            if not sel:
                continue
            at = {
                lat: float(np.mean([r["ratio_plume"] for r in sel if r["latency_s"] == lat]))
                for lat in sorted({r["latency_s"] for r in sel})
            }
            if 0.0 not in at or latency not in at:
                continue
            rows.append(
                {
                    "classifier": cname,
                    "planner": pname,
                    "mode": mode,
                    "scenes": len({r["scene"] for r in sel}),
                    "ratio_0s": round(at[0.0], 4),
                    f"ratio_{latency:g}s": round(at[latency], 4),
                    "kept": round(at[latency] / at[0.0], 4) if at[0.0] > 0 else None,
                }
            )
    return rows


def compare(records: list[dict], other: list[dict], latency: float) -> list[dict]:
    """Mean ratio plume at ``latency`` per classifier x planner x mode found in both runs
    (over their common scenes): this run's, the other's and the difference."""
    rows = []

    def at(recs, key):
        return {
            r["scene"]: r["ratio_plume"]
            for r in recs
            if (r["classifier"], r["planner"], r["mode"]) == key and r["latency_s"] == latency
        }

    keys = dict.fromkeys(
        (r["classifier"], r["planner"], r["mode"]) for r in other if r["classifier"] != "N/A"
    )
    for key in keys:
        mine, theirs = at(records, key), at(other, key)
        common = sorted(set(mine) & set(theirs))
        if not common:
            continue
        a = float(np.mean([mine[s] for s in common]))
        b = float(np.mean([theirs[s] for s in common]))
        rows.append(
            {
                "classifier": key[0],
                "planner": key[1],
                "mode": key[2],
                "scenes": len(common),
                f"this run {latency:g}s": round(a, 4),
                f"other run {latency:g}s": round(b, 4),
                "difference": round(a - b, 4),
            }
        )
    return rows


def figure(records: list[dict], path: Path) -> Path:
    from matplotlib import colormaps

    from dyntarget.evaluate.figures import save, subplots

    classifiers = [c for c in dict.fromkeys(r["classifier"] for r in records) if c != "N/A"]
    fig, axes = subplots(
        1, len(classifiers), figsize=(5.4 * len(classifiers), 4.0), squeeze=False, sharey=True
    )
    cmap = colormaps["tab10"]
    for ci, cname in enumerate(classifiers):
        ax = axes[0, ci]
        mine = [r for r in records if r["classifier"] == cname]
        planners = list(dict.fromkeys(r["planner"] for r in mine))
        for pi, pname in enumerate(planners):
            for mode in MODES:
                sel = [r for r in mine if r["planner"] == pname and r["mode"] == mode]
                if not sel:
                    continue
                lats = sorted({r["latency_s"] for r in sel})
                vals = [
                    np.mean([r["ratio_plume"] for r in sel if r["latency_s"] == t]) for t in lats
                ]
                ax.plot(
                    lats, vals, STYLE[mode], marker="o", ms=3, color=cmap(pi % 10),
                    label=f"{pname} ({mode})",
                )  # fmt: skip
        n = len({r["scene"] for r in mine})
        ax.set_title(f"{cname}: {n} held-out scenes", fontsize=9)
        ax.set_xlabel("latency (s)", fontsize=8)
        ax.grid(alpha=0.3)
        if ci == 0:
            ax.set_ylabel("ratio plume", fontsize=8)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, ncol=3, loc="lower center", frameon=False)
    fig.tight_layout(rect=(0, 0.22, 1, 1))
    return save(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dynamic", required=True, help="dynamic.json of 'dyntarget evaluate dynamic'")
    ap.add_argument("--latency", type=float, default=90.0)
    ap.add_argument("--out", default="docs/benchmarks/predictive_recovery.json")
    ap.add_argument("--figure", default="docs/img/predictive-vs-static.png")
    ap.add_argument(
        "--compare",
        metavar="OTHER/dynamic.json",
        help="another run on the same scenes (e.g. other code): means at --latency side by side",
    )
    ap.add_argument(
        "--note", default="", help="free text kept in the JSON (e.g. the evaluation's command)"
    )
    args = ap.parse_args()
    records = json.loads(Path(args.dynamic).read_text())["records"]
    rows = recovery(records, args.latency)
    doc: dict = {"machine": machine(), "latency_s": args.latency, "rows": rows}
    if args.note:
        doc["note"] = args.note
    if args.compare:
        other = json.loads(Path(args.compare).read_text())["records"]
        doc["compare"] = {"other": args.compare, "rows": compare(records, other, args.latency)}
        print(markdown_table(doc["compare"]["rows"], list(doc["compare"]["rows"][0])))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    cols = [
        "classifier",
        "planner",
        "mode",
        "scenes",
        "ratio_0s",
        f"ratio_{args.latency:g}s",
        "kept",
    ]
    out.with_suffix(".md").write_text(markdown_table(rows, cols))
    print(markdown_table(rows, cols))
    print(figure(records, Path(args.figure)))


if __name__ == "__main__":
    main()
