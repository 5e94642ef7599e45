"""Reliability round 4 (issue 42, class 2): ``demo``, ``reproduce``, ``sweep`` and ``datasets
prepare`` stage their result.

A failing, interrupted or refused rerun into an existing ``--out`` leaves every file of the
previous result byte for byte (hidden files included) and no staging folder; the resume state
(``parts/``, ``models/``) stays in ``--out`` and a rerun resumes from it without recomputing
a finished part; files of an earlier result that a new one does not write (a smaller scene
set, a sweep without figure, a preparation without negatives) go only when the new result
moves in. Every input is built here, in ``tmp_path``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dyntarget.cli import main
from helpers import synth_dir

# distributed leaves a listening socket to the garbage collector at cluster teardown
pytestmark = [
    pytest.mark.filterwarnings("ignore::ResourceWarning"),
    pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning"),
]

RESUME = ("parts/", "models/")


def _run(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def _tree(d: Path) -> dict[str, bytes]:
    """Every file under ``d`` (hidden ones included): relative path -> bytes."""
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in d.rglob("*") if p.is_file()}


def _stamps(d: Path, prefix: str = "parts/") -> dict[str, int]:
    """Modification times of the resume parts (unchanged = not written again)."""
    return {
        p.relative_to(d).as_posix(): p.stat().st_mtime_ns
        for p in (d / prefix).rglob("*")
        if p.is_file()
    }


def _no_stage(d: Path) -> bool:
    return not list(d.glob(".partial-*"))


def _results(tree: dict[str, bytes]) -> dict[str, bytes]:
    return {k: v for k, v in tree.items() if not k.startswith(RESUME)}


def _fail_figures(exc: BaseException):
    """A ``make_figures`` that starts writing a figure into its folder, then fails."""

    def fail(out, *args, **kwargs):
        (Path(out) / "fig3_trajectories.png").write_bytes(b"half a figure")
        raise exc

    return fail


# ---------------------------------------------------------------------------------- demo


@pytest.mark.slow
def test_demo_failure_interrupt_refusal_keep_the_result_and_resume(tmp_path, capsys, monkeypatch):
    from dyntarget.evaluate import report

    out = tmp_path / "out"
    demo = ("demo", "--out", out, "--size", 48, "--quiet")
    real = report.make_figures
    # 1. a first run failing late (after both tables): no result file, the parts are kept
    monkeypatch.setattr(report, "make_figures", _fail_figures(RuntimeError("disk full")))
    code, err = _run(capsys, *demo, "--scenes", 4)
    assert code == 1, err
    names = {p.name for p in out.iterdir()}
    assert names == {".dyntarget-output", "parts", "models"}, names
    parts = _stamps(out)
    assert len(parts) > 0
    # 2. the rerun resumes: every part reused (none written again), the result moves in
    monkeypatch.setattr(report, "make_figures", real)
    code, err = _run(capsys, *demo, "--scenes", 4)
    assert code == 0, err
    assert _stamps(out) == parts
    before = _tree(out)
    assert {"report.md", "table1_classification.csv", "scenes.png"} <= set(before)
    assert len([k for k in before if k.startswith("scenes/") and k.endswith(".tif")]) == 8
    # 3. an interrupted rerun (Ctrl-C while the figures are written): nothing changes
    monkeypatch.setattr(report, "make_figures", _fail_figures(KeyboardInterrupt()))
    code, err = _run(capsys, *demo, "--scenes", 4)
    assert code == 130, err
    assert _tree(out) == before and _no_stage(out)
    # 4. a refusal: nothing changes
    monkeypatch.setattr(report, "make_figures", real)
    code, err = _run(capsys, "demo", "--out", out, "--scenes", 0, "--quiet")
    assert code == 2 and "Traceback" not in err
    assert _tree(out) == before
    # 5. a smaller rerun: its 3 scenes replace the 4 (none of the earlier run left beside them)
    code, err = _run(capsys, *demo, "--scenes", 3)
    assert code == 0, err
    scenes = sorted(p.name for p in (out / "scenes").iterdir())
    assert scenes == [f"synth-0000-{i:04d}{s}" for i in range(3) for s in (".tif", "_mask.tif")], (
        scenes
    )
    assert "Data: 3 synthetic scenes" in (out / "report.md").read_text()
    assert _no_stage(out)


# ----------------------------------------------------------------------------- reproduce


@pytest.fixture
def fast_classifiers(monkeypatch):
    """``reproduce`` runs every classifier; two quick ones stand for them here."""
    from dyntarget.perceive import CLASSIFIERS

    monkeypatch.setattr(CLASSIFIERS, "available", lambda: ["band-threshold", "naive-bayes"])


def test_reproduce_failing_rerun_keeps_the_result(
    tmp_path_factory, tmp_path, capsys, monkeypatch, fast_classifiers
):
    from dyntarget.evaluate import report

    data = synth_dir(tmp_path_factory, "repro-data", scenes=4, size=48, seed=3)
    out = tmp_path / "out"
    args = ("reproduce", "--data", data, "--out", out, "--folds", 2, "--quiet")
    code, err = _run(capsys, *args)
    assert code == 0, err
    before = _tree(out)
    assert {"report.md", "table2_end_to_end.md", "fig_utilities.png"} <= set(before)
    parts = _stamps(out)
    # a rerun failing after both tables were written: the earlier result, byte for byte
    monkeypatch.setattr(report, "make_figures", _fail_figures(RuntimeError("disk full")))
    code, err = _run(capsys, *args)
    assert code == 1, err
    assert _tree(out) == before and _no_stage(out)
    assert _stamps(out) == parts  # resumed: no part computed again
    # a refusal (an unknown scheduler) changes nothing either
    code, err = _run(capsys, *args, "--scheduler", "somewhere")
    assert code == 2 and "scheduler" in err
    assert _tree(out) == before


# --------------------------------------------------------------------------------- sweep


@pytest.fixture(scope="module")
def sweep_data(tmp_path_factory):
    return synth_dir(tmp_path_factory, "staged-sweep", scenes=4, size=48, seed=2)


def _sweep(capsys, data, out, *extra):
    return _run(
        capsys,
        "sweep",
        "--data",
        data,
        "--out",
        out,
        "--classifiers",
        "band-threshold",
        "--planners",
        "track-center,straight-nadir",
        "--folds",
        2,
        "--quiet",
        *extra,
    )


def test_sweep_failing_rerun_keeps_table_and_figure(sweep_data, tmp_path, capsys, monkeypatch):
    from dyntarget.evaluate import sweep as sweep_module

    out = tmp_path / "s"
    grid = ("--grid", "denoise_iterations=0,2")
    code, err = _sweep(capsys, sweep_data, out, *grid)
    assert code == 0, err
    before = _tree(out)
    assert {"sweep.csv", "sweep.png"} <= set(before)
    parts = _stamps(out)

    def fail(table, path):  # the figure fails after the new table was written
        Path(path).write_bytes(b"half a figure")
        raise RuntimeError("disk full")

    # a rerun with one more grid value: new parts are kept for the resume, the result is not
    monkeypatch.setattr(sweep_module, "summary_figure", fail)
    code, err = _sweep(capsys, sweep_data, out, "--grid", "denoise_iterations=0,1,2")
    assert code == 1, err
    after = _tree(out)
    assert _results(after) == _results(before) and _no_stage(out)
    assert all(after[k] == v for k, v in before.items())  # nothing lost
    grown = _stamps(out)
    assert set(parts) < set(grown) and all(grown[k] == t for k, t in parts.items())
    # a refusal found in the library (an unknown planner) changes nothing
    monkeypatch.undo()
    code, err = _run(
        capsys, "sweep", "--data", sweep_data, "--out", out, "--classifiers", "band-threshold",
        "--planners", "no-such-planner", "--folds", 2, "--quiet",
    )  # fmt: skip
    assert code == 2 and "no-such-planner" in err
    assert _tree(out) == after
    # the rerun resumes from every part and moves its table in
    code, err = _sweep(capsys, sweep_data, out, "--grid", "denoise_iterations=0,1,2")
    assert code == 0, err
    assert _stamps(out) == grown
    assert (out / "sweep.csv").read_text().count("\n") == 1 + 4 * 3 * 2
    # a sweep with nothing swept draws no figure: the earlier one goes with the earlier table
    code, err = _sweep(capsys, sweep_data, out)
    assert code == 0, err
    assert not (out / "sweep.png").exists() and (out / "sweep.csv").is_file() and _no_stage(out)


# ----------------------------------------------------------------------- datasets prepare


POS = "site-a_2019-05-09T10:26:31.tif"
NEG = "site-b_2019-06-01T10:20:00.tif"


def _s2_tif(seed: int, size: int = 32) -> bytes:
    """A 13-band uint16 Sentinel-2 stack (as tests/datasets/test_industrial_smoke.py)."""
    import warnings

    import numpy as np
    import rasterio
    from affine import Affine

    rng = np.random.default_rng(seed)
    data = rng.integers(100, 2000, (13, size, size)).astype(np.uint16)
    with warnings.catch_warnings(), rasterio.MemoryFile() as mem:
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        profile = {"driver": "GTiff", "height": size, "width": size, "count": 13}
        transform = Affine(10, 0, 4e5, 0, -10, 5.5e6)
        with mem.open(**profile, dtype="uint16", crs="EPSG:32633", transform=transform) as ds:
            ds.write(data)
        return bytes(mem.read())


def _tar(path: Path, members: dict[str, bytes]) -> None:
    import io
    import tarfile

    with tarfile.open(path, "w:gz") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))


def _archives(tmp_path: Path) -> Path:
    """The two archives in the published layout: one labelled positive, one negative image."""
    import json

    src = tmp_path / "download"
    src.mkdir()
    _tar(
        src / "images.tar.gz",
        {f"images/positive/{POS}": _s2_tif(0), f"images/negative/{NEG}": _s2_tif(1)},
    )
    label = {
        "data": {"image": f"/data/upload/7-{POS.replace('.tif', '.png')}"},
        "completions": [
            {"result": [{"value": {"points": [[10, 10], [50, 10], [50, 50], [10, 50]]}}]}
        ],
    }
    _tar(
        src / "segmentation_labels.tar.gz",
        {"segmentation_labels/7.json": json.dumps(label).encode()},
    )
    return src


def test_prepare_is_staged_as_a_whole(tmp_path, capsys, monkeypatch):
    from dyntarget.datasets import industrial_smoke as smoke

    src, out = _archives(tmp_path), tmp_path / "scenes"
    prepare = ("datasets", "prepare", "industrial-smoke", "--from", src, "--out", out, "--quiet")
    code, err = _run(capsys, *prepare, "--negatives")
    assert code == 0, err
    before = _tree(out)
    assert len([k for k in before if k.endswith("_mask.tif")]) == 2  # positive + negative
    real = smoke.prepare

    def fail(source, into, **kwargs):  # every scene written, then a late failure
        real(source, into, **kwargs)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(smoke, "prepare", fail)
    code, err = _run(capsys, *prepare)
    assert code != 0 and "No space left" in err
    assert _tree(out) == before and _no_stage(out)
    monkeypatch.undo()
    # a refusal (no labels where --from points) changes nothing
    empty = tmp_path / "empty"
    empty.mkdir()
    code, err = _run(capsys, *prepare[:4], empty, *prepare[5:])
    assert code == 2 and "segmentation_labels" in err
    assert _tree(out) == before
    # without --negatives the new directory holds the positive scene only: nothing mixed in
    code, err = _run(capsys, *prepare)
    assert code == 0, err
    after = _tree(out)
    assert sorted(after) == [
        ".dyntarget-output",
        "site-a_2019-05-09T10-26-31.tif",
        "site-a_2019-05-09T10-26-31_mask.tif",
    ], sorted(after)
    assert after["site-a_2019-05-09T10-26-31.tif"] == before["site-a_2019-05-09T10-26-31.tif"]
    assert _no_stage(out)
