"""Every benchmark result under docs/benchmarks/ says where it was measured (issue 25, item 6).

docs/benchmarks/README.md defines the ``machine`` block: a run written by
``dyntarget.evaluate.bench.machine()`` names its commit, CPU, cores and library versions; a file
written before the block existed says so (``commit: null``, ``written_by_commit``, ``note``).
A file with several runs keeps one block per run.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs" / "benchmarks"
RECORDS = sorted(DOCS.glob("*.json"))
SHA = re.compile(r"^[0-9a-f]{40}(\+dirty)?$")


def _blocks(doc: object) -> list[dict]:
    """The machine blocks of one result file: top level, else one per run (top-level value)."""
    if isinstance(doc, dict) and isinstance(doc.get("machine"), dict):
        return [doc["machine"]]
    if isinstance(doc, dict) and doc and all(isinstance(v, dict) for v in doc.values()):
        runs = list(doc.values())
        if all(isinstance(r.get("machine"), dict) for r in runs):
            return [r["machine"] for r in runs]
    return []


def test_the_benchmark_folder_holds_results():
    assert len(RECORDS) >= 10, DOCS


@pytest.mark.parametrize("path", RECORDS, ids=[p.name for p in RECORDS])
def test_each_benchmark_result_names_its_machine_and_commit(path: Path):
    _check(path.name, json.loads(path.read_text()))


def _check(name: str, doc: object) -> None:
    blocks = _blocks(doc)
    assert blocks, f"{name}: no machine block (write it with dyntarget.evaluate.bench.machine())"
    for m in blocks:
        if m.get("commit") is None:  # older than the block: must say which commit wrote it
            assert SHA.match(m.get("written_by_commit", "")), f"{name}: no written_by_commit"
            assert m.get("note"), f"{name}: an old record must say so in a note"
            continue  # and keeps whatever that run recorded (README: "The machine block")
        assert SHA.match(m["commit"]), f"{name}: commit {m['commit']!r} is not a SHA-1"
        assert isinstance(m.get("cpu"), str) and m["cpu"], f"{name}: no CPU model"
        assert isinstance(m.get("cpus"), int) and m["cpus"] >= 1, f"{name}: no core count"
        assert "platform" in m, f"{name}: no platform"
        assert isinstance(m.get("cpu_flags"), list), f"{name}: no CPU flags"
        assert isinstance(m.get("versions"), dict) and "numpy" in m["versions"], name


def test_an_unrecorded_result_is_caught():
    # the check itself: a result without a block, or with a block lacking the CPU, fails
    assert _blocks({"wall_s": 1.0}) == []
    assert _blocks({"a": {"wall_s": 1.0}, "b": {"wall_s": 2.0, "machine": {"cpu": "x"}}}) == []
    assert _blocks({"a": {"machine": {"cpu": "x"}}}) == [{"cpu": "x"}]
    with pytest.raises(AssertionError, match="not a SHA-1"):
        _check("x.json", {"machine": {"commit": "HEAD", "cpu": "x", "cpus": 2}})
    with pytest.raises(AssertionError, match="no CPU model"):
        _check("x.json", {"machine": {"commit": "0" * 40, "cpus": 2, "platform": "p"}})
