"""The paper's headline claims, checked on our tables with stated criteria.

Every verdict is computed from the table rows by the rules below (the same
rules applied to the paper's own numbers are reported beside them), never
written by hand.
"""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

import numpy as np

from dyntarget.plan import BASELINES

UNETS = ("unet-xception", "unet-uavsar")
ORDER_OF_MAGNITUDE = 10.0
WINDOW_S = (10.0, 100.0)


def paper_results() -> dict[str, Any]:
    """The paper's Tables 1 and 2 as stored in the package (``dyntarget/data/paper_results.json``)."""
    text = (
        resources.files("dyntarget").joinpath("data/paper_results.json").read_text(encoding="utf-8")
    )
    return json.loads(text)


def _iou(rows, name, denoised):
    for r in rows:
        if r["classifier"] == name and r["denoised"] == denoised:
            return r["IoU"]
    return None


def claim_unets_best(table1: list[dict]) -> dict[str, Any]:
    names = sorted({r["classifier"] for r in table1})
    best = {n: max(_iou(table1, n, False), _iou(table1, n, True)) for n in names}
    unets = [n for n in names if n in UNETS]
    others = [n for n in names if n not in UNETS]
    if not unets or not others:
        return {
            "claim": "U-Nets have the best IoU",
            "verdict": "not tested",
            "detail": "needs U-Nets and others",
        }
    best_other = max(others, key=best.get)
    holds = min(best[u] for u in unets) > best[best_other]
    detail = (
        ", ".join(f"{n} {best[n]:.3f}" for n in unets)
        + f"; best other: {best_other} {best[best_other]:.3f}"
    )
    return {
        "claim": "U-Nets have the best IoU (both above every other classifier)",
        "holds": holds,
        "detail": detail,
    }


def claim_denoising_helps(table1: list[dict]) -> dict[str, Any]:
    names = sorted({r["classifier"] for r in table1})
    better = [n for n in names if _iou(table1, n, True) > _iou(table1, n, False)]
    holds = len(better) > len(names) / 2
    return {
        "claim": "Denoising raises the IoU of most classifiers",
        "holds": holds,
        "detail": f"{len(better)} of {len(names)} improve"
        + (f" ({', '.join(better)})" if better else ""),
    }


def _good_classifiers(table1: list[dict], k: int = 2) -> list[str]:
    names = sorted({r["classifier"] for r in table1})
    return sorted(names, key=lambda n: -max(_iou(table1, n, False), _iou(table1, n, True)))[:k]


def claim_order_of_magnitude(table1: list[dict], table2: list[dict]) -> dict[str, Any]:
    """Rule: for the two best-IoU classifiers, the mean over look-ahead rows of ratio plume and of
    intensity is at least sqrt(10) (about 3.2) times the better baseline's, i.e. an order of
    magnitude when rounded on a log scale; whether every row reaches a strict 10x is reported too."""
    good = _good_classifiers(table1)
    base = [r for r in table2 if r["planner"] in BASELINES]
    if not base:
        return {
            "claim": "order of magnitude over baselines",
            "verdict": "not tested",
            "detail": "no baseline rows",
        }
    factors = {}
    for metric in ("Ratio Plume", "Intensity"):
        best_base = max(r[metric] for r in base)
        sel = [
            r[metric] for r in table2 if r["classifier"] in good and r["planner"] not in BASELINES
        ]
        if best_base <= 0:
            factors[metric] = (float("inf"), float("inf"))
        else:
            factors[metric] = (min(sel) / best_base, float(np.mean(sel)) / best_base)
    holds = all(f[1] >= np.sqrt(ORDER_OF_MAGNITUDE) for f in factors.values())
    strict = all(f[0] >= ORDER_OF_MAGNITUDE for f in factors.values())
    detail = "; ".join(
        f"{m}: mean {f[1]:.1f}x, worst row {f[0]:.1f}x the better baseline"
        for m, f in factors.items()
    )
    detail += f"; strict 10x on every row: {'yes' if strict else 'no'}"
    return {
        "claim": f"Look-ahead planning with the good classifiers ({', '.join(good)}) gives an order of magnitude "
        "more ratio plume and intensity than the baselines (mean over planners >= sqrt(10) = 3.2x)",
        "holds": holds,
        "detail": detail,
    }


def claim_runtime(table2: list[dict]) -> dict[str, Any]:
    """Rule: the slowest end-to-end row fits the window: below 10 s fits every window, below 100 s some."""
    worst = max(r["Runtime (s)"] for r in table2)
    low, high = WINDOW_S
    if worst <= low:
        verdict = "holds"
    elif worst <= high:
        verdict = f"holds for windows longer than {worst:.0f} s"
    else:
        verdict = "does not hold"
    return {
        "claim": f"End-to-end runtimes fit the {low:.0f}-{high:.0f} s dynamic-targeting window",
        "verdict": verdict,
        "detail": f"slowest row {worst:.3f} s",
    }


def check_claims(table1: list[dict], table2: list[dict]) -> list[dict[str, Any]]:
    """All four claims on the given rows (our tables or the paper's)."""
    return [
        claim_unets_best(table1),
        claim_denoising_helps(table1),
        claim_order_of_magnitude(table1, table2),
        claim_runtime(table2),
    ]
