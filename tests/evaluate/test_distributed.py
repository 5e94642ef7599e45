"""run_tasks and the evaluation commands on Dask: same results as one-by-one, resumable."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.cli import main
from dyntarget.evaluate.distributed import Interrupted, run_tasks, task_key
from helpers import synth_dir

# distributed leaves a listening socket to the garbage collector at cluster teardown (its own
# internals, not ours); with warnings as errors that would fail unrelated tests.
pytestmark = [
    pytest.mark.filterwarnings("ignore::ResourceWarning"),
    pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning"),
]

CALLS: list[int] = []


def _square(x: int, *, offset: int) -> dict:
    CALLS.append(x)
    return {"x": x, "y": x * x + offset}


def test_task_key_is_stable_and_content_sensitive():
    a = np.arange(6, dtype=np.float32)
    assert task_key("e2e", {"b": 1, "a": 2}, a) == task_key("e2e", {"a": 2, "b": 1}, a.copy())
    assert task_key("e2e", a) != task_key("e2e", a + 1)
    assert task_key("e2e", a) != task_key("e2e", a.astype(np.float64))


@pytest.mark.parametrize("where", ["here", "cluster"])
def test_run_tasks_resumes_without_redoing(where, cluster, tmp_path):
    scheduler = cluster if where == "cluster" else None
    kw = dict(key=lambda x: f"t{x}", parts=tmp_path, scheduler=scheduler, progress=False)
    CALLS.clear()
    with pytest.raises(Interrupted):
        run_tasks(_square, range(10), shared={"offset": 1}, stop_after=4, **kw)
    first = set(CALLS)
    assert len(list(tmp_path.glob("*.json"))) >= 4
    CALLS.clear()
    results = run_tasks(_square, range(10), shared={"offset": 1}, **kw)
    assert results == [{"x": x, "y": x * x + 1} for x in range(10)]  # in task order
    done_before = {int(p.stem[1:]) for p in tmp_path.glob("*.json")} - set(CALLS)
    assert done_before and not done_before & set(CALLS)  # finished tasks not run again
    assert len(first) >= 4


def test_unreadable_part_is_recomputed(tmp_path):
    run_tasks(_square, [1, 2], key=str, parts=tmp_path, shared={"offset": 0}, progress=False)
    (tmp_path / "2.json").write_text("{not json")
    CALLS.clear()
    assert run_tasks(
        _square, [1, 2], key=str, parts=tmp_path, shared={"offset": 0}, progress=False
    ) == [{"x": 1, "y": 1}, {"x": 2, "y": 4}]
    assert CALLS == [2]


def test_run_tasks_refuses_bad_input(tmp_path):
    with pytest.raises(ValueError, match="share a key"):
        run_tasks(_square, [1, 1], key=str, shared={"offset": 0}, progress=False)
    with pytest.raises(InvalidParameterError, match="scheduler"):
        run_tasks(_square, [1], key=str, scheduler="nowhere", shared={"offset": 0})


@pytest.fixture(scope="module")
def scenes_dir(tmp_path_factory):
    return synth_dir(tmp_path_factory, "dist-data", scenes=6, size=64, seed=5)


def _table(path):
    rows = json.loads(path.read_text())["rows"]
    return [{k: v for k, v in r.items() if "untime" not in k and "(ms)" not in k} for r in rows]


@pytest.mark.parametrize(
    "evaluation, table",
    [
        ("classification", "table1_classification.json"),
        ("end-to-end", "table2_end_to_end.json"),
        ("planning", "planning_true_masks.json"),
    ],
)
@pytest.mark.slow
def test_evaluations_on_a_cluster_match_and_resume(
    evaluation, table, scenes_dir, cluster, tmp_path
):
    args = ["evaluate", evaluation, "--data", str(scenes_dir), "--quiet"]
    if evaluation != "planning":
        args += ["--folds", "2", "--classifiers", "band-threshold,decision-tree"]
    assert main([*args, "--out", str(tmp_path / "here")]) == 0
    reference = _table(tmp_path / "here" / table)
    assert main([*args, "--out", str(tmp_path / "dask"), "--scheduler", cluster]) == 0
    assert _table(tmp_path / "dask" / table) == reference
    # an interrupted run: half its finished parts survive; the rerun completes the same table
    parts = sorted((tmp_path / "dask" / "parts" / evaluation).glob("*.json"))
    assert len(parts) >= 2
    for p in parts[::2]:
        p.unlink()
    (tmp_path / "dask" / table).unlink()
    assert main([*args, "--out", str(tmp_path / "dask"), "--scheduler", cluster]) == 0
    assert _table(tmp_path / "dask" / table) == reference


def test_bad_scheduler_is_refused_before_any_work(scenes_dir, tmp_path, capsys):
    code = main(
        ["evaluate", "end-to-end", "--data", str(scenes_dir), "--out", str(tmp_path / "o"),
         "--folds", "2", "--scheduler", "cluster-please"]
    )  # fmt: skip
    assert code == 2 and "scheduler" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
