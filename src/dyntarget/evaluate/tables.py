"""Result tables as Markdown, CSV and JSON (written atomically)."""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dyntarget.io.atomic import write_text

DISPLAY_NAMES = {
    "band-threshold": "Band Threshold",
    "naive-bayes": "Naive Bayes",
    "logistic-regression": "Logistic Regression",
    "decision-tree": "Decision Tree",
    "random-forest": "Random Forest",
    "mlp": "Multilayer Perceptron",
    "unet-xception": "UNET-Xception",
    "unet-uavsar": "UNET-Uavsar",
    "straight-nadir": "Straight Nadir",
    "naive-transect": "Naive Transect",
    "trace-outline": "Trace Outline",
    "track-center": "Track Center",
    "diagonal-transect": "Diagonal Transect",
    "lawnmower-transect": "Lawnmower Transect",
}


def display(name: str) -> str:
    """The display name of a planner or classifier (:data:`DISPLAY_NAMES`, else the name).

    Parameters
    ----------
    name : str
        Registered name.

    Returns
    -------
    str
        The name as the paper's tables write it.
    """
    return DISPLAY_NAMES.get(name, name)


def _fmt(value: Any, digits: int) -> str:
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def markdown_table(
    rows: Sequence[dict[str, Any]], columns: Sequence[str], *, digits: int = 3
) -> str:
    """A GitHub Markdown table of ``rows`` (dicts) over ``columns``.

    Parameters
    ----------
    rows : sequence of dict
        The rows.
    columns : sequence of str
        The columns, in order.
    digits : int
        Decimals of floats.

    Returns
    -------
    str
        The table.
    """
    head = "| " + " | ".join(columns) + " |"
    sep = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(_fmt(r.get(c, ""), digits) for c in columns) + " |" for r in rows]
    return "\n".join([head, sep, *body]) + "\n"


def csv_text(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    """CSV of ``rows`` (dicts) over ``columns``; missing values are empty, extra keys ignored.

    Parameters
    ----------
    rows : sequence of dict
        The rows.
    columns : sequence of str
        The columns, in order.

    Returns
    -------
    str
        The CSV text, header first.
    """
    buf = io.StringIO()
    writer = csv.DictWriter(
        buf, fieldnames=list(columns), extrasaction="ignore", lineterminator="\n"
    )
    writer.writeheader()
    for r in rows:
        writer.writerow({c: r.get(c, "") for c in columns})
    return buf.getvalue()


def write_result(
    out_dir: str | os.PathLike[str], stem: str, result: dict[str, Any], columns: Sequence[str]
) -> dict[str, Path]:
    """Write an evaluation result: its ``rows`` as the table, ``timing`` apart, the rest as context.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Output folder.
    stem : str
        File stem.
    result : dict
        ``rows``, optional ``timing`` and any context.
    columns : sequence of str
        Table columns.

    Returns
    -------
    dict of str to pathlib.Path
        See :func:`write_table`.
    """
    extra = {k: v for k, v in result.items() if k not in ("rows", "timing")}
    return write_table(
        out_dir, stem, result["rows"], columns, extra=extra, timing=result.get("timing")
    )


def write_table(
    out_dir: str | os.PathLike[str],
    stem: str,
    rows: Sequence[dict[str, Any]],
    columns: Sequence[str],
    *,
    extra: dict[str, Any] | None = None,
    timing: dict[str, Any] | None = None,
    digits: int = 3,
) -> dict[str, Path]:
    """Write ``<stem>.md``, ``<stem>.csv`` and ``<stem>.json`` into ``out_dir``.

    Wall-clock measurements go to ``<stem>.timing.json`` (when ``timing`` is
    given), so the three table files are byte-identical between runs with the
    same seed.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Output folder.
    stem : str
        File stem.
    rows : sequence of dict
        The rows.
    columns : sequence of str
        Columns of the Markdown and CSV tables.
    extra : dict or None
        Context stored in the JSON file beside the rows.
    timing : dict or None
        Wall-clock measurements.
    digits : int
        Decimals of floats in the Markdown table.

    Returns
    -------
    dict of str to pathlib.Path
        ``md``, ``csv``, ``json`` and, with ``timing``, ``timing``.
    """
    out = Path(out_dir)
    paths = {
        "md": write_text(out / f"{stem}.md", markdown_table(rows, columns, digits=digits)),
        "csv": write_text(out / f"{stem}.csv", csv_text(rows, columns)),
        "json": write_text(
            out / f"{stem}.json",
            json.dumps({"columns": list(columns), "rows": list(rows), **(extra or {})}, indent=2)
            + "\n",
        ),
    }
    if timing is not None:
        paths["timing"] = write_text(
            out / f"{stem}.timing.json", json.dumps(timing, indent=2) + "\n"
        )
    return paths
