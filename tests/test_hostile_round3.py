"""Reliability round 3 (issue 29): a representative of every class of hostile input.

Classes: files that hang (FIFOs, devices), data loss (passes, plans, rows), unbounded
world specs, ONNX graphs that run without end or answer wrongly, tracebacks where one
line and exit 2 belong, silently wrong answers, and the live watcher's survival.
Every input is built here, in ``tmp_path``.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from affine import Affine

from dyntarget.cli import main
from dyntarget.errors import DataFileError, InvalidParameterError, ModelFileError
from dyntarget.io import write_scene
from dyntarget.scene import Scene


@pytest.fixture(autouse=True)
def no_hang():
    """Fail (rather than hang CI) when something blocks for 60 s: a FIFO opened, say."""

    def fail(signum, frame):
        raise TimeoutError("blocked for 60 s")

    previous = signal.signal(signal.SIGALRM, fail)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def _run(capsys, *args) -> tuple[int, str]:
    code = main([str(a) for a in args])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def _one_line_error(capsys, *args) -> str:
    code, err = _run(capsys, *args)
    lines = [ln for ln in err.splitlines() if ln.startswith("dyntarget:")]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("dyntarget: error: "), err
    return lines[0]


def _strip(directory, *, rows=256, cols=64, scene_id="strip", when=None):
    """A static labelled strip (one bright plume), georeferenced in UTM 5N, 8 m pixels."""
    image = np.full((4, rows, cols), 0.05, np.float32)
    label = np.zeros((rows, cols), bool)
    label[rows // 2 : rows // 2 + 24, 16:40] = True
    image[:, label] = 0.8
    transform = Affine(8.0, 0.0, 250000.0, 0.0, -8.0, 2150000.0)
    scene = Scene(image, label=label, gsd=8.0, crs="EPSG:32605", transform=transform, id=scene_id)
    tags = None if when is None else {"ACQUISITIONDATETIME": when}
    write_scene(scene, directory, tags=tags)
    return directory / f"{scene_id}.tif"


# --------------------------------------------------------------------------- files that hang


def test_fifo_as_scene_is_refused_at_once(tmp_path, capsys):
    os.mkfifo(tmp_path / "s.tif")
    line = _one_line_error(
        capsys, "fly", "--scene", tmp_path / "s.tif", "--truth", "--out", tmp_path / "o"
    )
    assert "FIFO" in line and not (tmp_path / "o").exists()


def test_fifo_as_strip_sidecar_is_refused(tmp_path, capsys):
    strip = _strip(tmp_path / "in")
    os.mkfifo(tmp_path / "in" / "strip.world.json")
    line = _one_line_error(capsys, "fly", "--scene", strip, "--truth", "--out", tmp_path / "o")
    assert "strip.world.json" in line and "FIFO" in line


def test_fifo_as_sequence_frame_is_refused(tmp_path):
    from dyntarget.io import read_sequence

    seq = tmp_path / "s1"
    seq.mkdir()
    os.mkfifo(seq / "f000.tif")
    doc = {
        "format": "dyntarget-sequence",
        "version": 1,
        "frames": [{"file": "f000.tif", "time_s": 0}],
    }
    (seq / "sequence.json").write_text(json.dumps(doc))
    with pytest.raises(DataFileError, match="FIFO"):
        read_sequence(seq)


def test_device_link_as_raster_is_refused(tmp_path):
    from dyntarget.io import read_scene

    (tmp_path / "z.tif").symlink_to("/dev/zero")
    with pytest.raises(DataFileError, match="character device"):
        read_scene(tmp_path / "z.tif")


def test_campaign_folder_junk_is_not_read(tmp_path):
    from dyntarget.fly.campaign import _digest, strip_files, strips_in

    strip = _strip(tmp_path / "c")
    clean = _digest(strip)
    os.mkfifo(tmp_path / "c" / "strip.lock")
    (tmp_path / "c" / "strip.raw").symlink_to("/dev/zero")
    (tmp_path / "c" / "strip.notes").mkdir()
    (tmp_path / "c" / "strip.old").symlink_to(tmp_path / "gone")
    assert strips_in(tmp_path / "c") == [strip]
    assert [p.name for p in strip_files(strip)] == ["strip.tif", "strip_mask.tif"]
    assert _digest(strip) == clean  # the junk beside it changes nothing


def test_campaign_refuses_a_strip_label_that_is_a_fifo(tmp_path):
    from dyntarget.fly.campaign import strips_in

    _strip(tmp_path / "c")
    (tmp_path / "c" / "strip_mask.tif").unlink()
    os.mkfifo(tmp_path / "c" / "strip_mask.tif")
    with pytest.raises(DataFileError, match="strip_mask.tif: a FIFO"):
        strips_in(tmp_path / "c")


def test_strip_named_like_a_glob_is_one_strip(tmp_path):
    from dyntarget.fly.campaign import _digest

    a = _strip(tmp_path / "c", scene_id="strip-[0]")
    b = _strip(tmp_path / "c", scene_id="strip-0")
    assert _digest(a) != _digest(b)


def test_safe_reader_limits_size_and_depth(tmp_path):
    from dyntarget.io.safeopen import read_bytes, read_json

    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(3 * 1024**3)  # 3 GB, sparse: refused from its size, never read
    with pytest.raises(DataFileError, match="3,221,225,472 bytes"):
        read_json(big)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(DataFileError, match="nested more than 64 levels"):
        read_json(deep)
    (tmp_path / "ok.json").write_text('{"a": "[[[[", "b": [1]}')  # brackets in strings: not depth
    assert read_json(tmp_path / "ok.json") == {"a": "[[[[", "b": [1]}
    with pytest.raises(DataFileError, match="23 bytes, more than the 2 accepted"):
        read_bytes(tmp_path / "ok.json", max_bytes=2)


# --------------------------------------------------------------------------- data loss


def test_campaign_strips_sharing_a_world_id_keep_both_passes(tmp_path, capsys):
    data = tmp_path / "strips"
    code, _ = _run(capsys, "synth", "--strip", "--scenes", "1", "--size", "64", "--length", "256",
                   "--plumes", "1", "--out", data, "--quiet")  # fmt: skip
    assert code == 0
    for suffix in (".tif", "_mask.tif", ".world.json"):  # the same world under another name
        shutil.copy(data / f"strip-0000{suffix}", data / f"twin{suffix}")
    out = tmp_path / "out"
    code, err = _run(capsys, "fly", "--campaign", data, "--truth", "--agility", "unlimited",
                     "--compute-budget-s", "0.05", "--out", out, "--quiet")  # fmt: skip
    assert code == 0, err
    passes = sorted(p.name for p in (out / "passes").iterdir())
    assert passes == [
        "strip-0000-lawnmower-transect-unlimited",
        "twin-lawnmower-transect-unlimited",
    ]
    rows = list(csv.DictReader((out / "campaign.csv").read_text().splitlines()))
    assert [r["strip"] for r in rows] == ["strip-0000", "twin"]


@pytest.fixture(scope="module")
def classifier(tiny_scenes):
    from dyntarget.perceive import make_classifier

    return make_classifier("band-threshold").fit([s.to_wfov(4) for s in tiny_scenes])


def _watch_config(**kw):
    from dyntarget.fly.watch import WatchConfig

    base = dict(factor=4, poll_s=0.02, settle_s=0.0, corrupt_after_s=0.2, idle_exit_s=1.0)
    return WatchConfig(**{**base, **kw})


def test_watch_keeps_a_tif_and_a_tiff_apart_and_appends_on_restart(
    tmp_path, classifier, tiny_scenes
):
    from dyntarget.fly.watch import FRAMES, Watcher

    watched, out = tmp_path / "in", tmp_path / "out"
    frame = write_scene(tiny_scenes[0], tmp_path / "src")[0]
    watched.mkdir()
    shutil.copy(frame, watched / "a.tif")
    shutil.copy(frame, watched / "a.tiff")
    assert Watcher(watched, out, classifier, _watch_config()).run() == 2
    assert sorted(p.name for p in out.glob("*.geojson")) == ["a.geojson", "a.tiff.geojson"]
    shutil.copy(frame, watched / "b.tif")
    assert Watcher(watched, out, classifier, _watch_config()).run() == 1  # a restart: only b
    rows = list(csv.DictReader((out / FRAMES).read_text().splitlines()))
    assert [(r["frame"], r["plan"]) for r in rows] == [
        ("a.tif", "a.geojson"), ("a.tiff", "a.tiff.geojson"), ("b.tif", "b.geojson"),
    ]  # fmt: skip


# --------------------------------------------------------------------------- the live watcher


def test_watcher_survives_a_frame_it_cannot_date(tmp_path, classifier, tiny_scenes):
    from dyntarget.fly.watch import REJECTED, Watcher

    watched, out = tmp_path / "in", tmp_path / "out"
    watched.mkdir()
    write_scene(
        tiny_scenes[0], tmp_path / "bad", tags={"DYNTARGET_ACQUIRED": "0001-01-01T00:00:00+14:00"}
    )
    shutil.copy(tmp_path / "bad" / f"{tiny_scenes[0].id}.tif", watched / "bad.tif")
    shutil.copy(write_scene(tiny_scenes[1], tmp_path / "good")[0], watched / "good.tif")
    w = Watcher(watched, out, classifier, _watch_config())
    assert w.run() == 1
    assert [r["frame"] for r in w.rows] == ["good.tif"]
    rejected = list(csv.DictReader((out / REJECTED).read_text().splitlines()))
    assert [r["frame"] for r in rejected] == ["bad.tif"] and "time" in rejected[0]["reason"]
    assert "idle-exit" in w.stop_reason


def test_watcher_survives_a_frame_that_cannot_be_planned(
    tmp_path, classifier, tiny_scenes, monkeypatch
):
    from dyntarget.fly import watch

    watched, out = tmp_path / "in", tmp_path / "out"
    watched.mkdir()
    frame = write_scene(tiny_scenes[0], tmp_path / "src")[0]
    shutil.copy(frame, watched / "a.tif")
    shutil.copy(frame, watched / "b.tif")
    real = watch.plan_scene

    def flaky(image, *a, **kw):  # the first frame provokes an error no check foresaw
        if not flaky.calls:
            flaky.calls.append(1)
            raise OverflowError("cannot convert float infinity to integer")
        return real(image, *a, **kw)

    flaky.calls = []
    monkeypatch.setattr(watch, "plan_scene", flaky)
    w = watch.Watcher(watched, out, classifier, _watch_config())
    assert w.run() == 1
    reasons = (out / watch.REJECTED).read_text()
    assert "a.tif,cannot be planned (OverflowError" in reasons


def test_watcher_stops_saying_the_folder_was_removed(tmp_path, classifier):
    from dyntarget.fly.watch import Watcher

    watched = tmp_path / "in"
    watched.mkdir()
    w = Watcher(watched, tmp_path / "out", classifier, _watch_config(idle_exit_s=None))
    calls = []

    def stop():
        calls.append(1)
        if len(calls) == 3:
            watched.rmdir()
            watched.write_text("now a file")
        return False

    with pytest.raises(DataFileError, match="watched folder was replaced by a file"):
        w.run(stop)


def test_frame_renamed_in_is_read_without_waiting_to_settle(tmp_path, classifier, tiny_scenes):
    pytest.importorskip("inotify_simple")
    from dyntarget.fly.watch import Watcher

    watched = tmp_path / "in"
    watched.mkdir()
    w = Watcher(watched, tmp_path / "out", classifier, _watch_config(settle_s=600.0))
    if w._events is None:
        pytest.skip("no inotify here")
    frame = write_scene(tiny_scenes[0], tmp_path / "src")[0]
    part = watched / "f.tif.part"
    shutil.copy(frame, part)
    part.rename(watched / "f.tif")
    planned = 0
    for _ in range(100):  # a settle of 600 s would never be reached in these polls
        planned += w.step()
        if planned:
            break
        time.sleep(0.02)
    w.close()
    assert planned == 1
    row = w.rows[0]
    assert set(row) >= {"waited_s", "read_s", "planned_s", "acquired_to_written_s"}


# --------------------------------------------------------------------------- world specs


def _spec_dict(**changes):
    from dyntarget.synth.strip import strip_spec

    spec, _ = strip_spec(0, width=64, length=256, plumes=1, wind_mps=5.0)
    d = spec.to_dict()
    for key, value in changes.items():
        if key.startswith("vent_"):
            d["vents"][0][key[5:]] = value
        elif key.startswith("cloud_"):
            d["clouds"] = [{"x": 1.0, "y": 1.0, key[6:]: value}]
        else:
            d[key] = value
    return d


@pytest.mark.parametrize(
    "changes, fragment",
    [
        ({"vents": [{"x": 1.0, "y": 1.0}] * 20000}, "vents: 20000 of them, more than the 64"),
        ({"clouds": [{"x": 1.0, "y": 1.0}] * 100000}, "clouds: 100000 of them, more than the 256"),
        ({"tile": 2**40}, "tile"),
        ({"tile": 16384}, "tile"),
        ({"seed": "abc"}, "seed"),
        ({"seed": -5}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"gsd": 1e-300}, "gsd"),
        ({"gsd": 1e300}, "gsd"),
        ({"vent_source_sigma_m": 1e300}, "source_sigma_m"),
        ({"vent_eruption_age_s": 1e300}, "eruption_age_s"),
        ({"cloud_radius_m": 1e300}, "radius_m"),
        ({"sun_azimuth_deg": math.inf}, "sun_azimuth_deg"),
        ({"crs": "EPSG:999999"}, "not a known CRS"),
        ({"epoch": "9999-01-01T00:00:00Z"}, "year in 1900..2200"),
        ({"epoch": 12}, "epoch"),
        ({"size": 10**9}, "size"),
    ],
)
def test_world_spec_bounds(changes, fragment):
    from dyntarget.synth.dynamic import WorldSpec

    with pytest.raises(InvalidParameterError, match=fragment.replace("(", r"\(")):
        WorldSpec.from_dict(_spec_dict(**changes))


@pytest.mark.parametrize(
    "window, fragment",
    [(["a", 0, 64, 256], "integers"), (None, "integers"), ([0, 0, 16000, 16000], "more than the"),
     ([0, 0, float("nan"), 256], "integers")],
)  # fmt: skip
def test_sidecar_window_checked_from_the_cli(tmp_path, capsys, window, fragment):
    strip = _strip(tmp_path / "in")
    doc = {"format": "dyntarget-strip", "version": 1, "world": _spec_dict(), "window": window}
    (tmp_path / "in" / "strip.world.json").write_text(json.dumps(doc))
    line = _one_line_error(capsys, "fly", "--scene", strip, "--truth", "--out", tmp_path / "o")
    assert "strip.world.json" in line and fragment in line


def test_sidecar_nested_100000_deep_is_one_line(tmp_path, capsys):
    strip = _strip(tmp_path / "in")
    (tmp_path / "in" / "strip.world.json").write_text("[" * 100_000 + "]" * 100_000)
    assert "nested more than" in _one_line_error(
        capsys, "fly", "--scene", strip, "--truth", "--out", tmp_path / "o"
    )


def test_sequence_meta_as_a_list_is_refused(tmp_path):
    from dyntarget.io import read_sequence

    seq = tmp_path / "s1"
    write_scene(Scene(np.full((4, 8, 8), 0.1, np.float32), id="f000"), seq)
    doc = {"format": "dyntarget-sequence", "version": 1, "meta": [1, 2],
           "frames": [{"file": "f000.tif", "time_s": 0}]}  # fmt: skip
    (seq / "sequence.json").write_text(json.dumps(doc))
    with pytest.raises(DataFileError, match='"meta" must be an object'):
        read_sequence(seq)


@pytest.mark.parametrize(
    "args, fragment",
    [(["--strip", "--plumes", "100000"], "plumes"), (["--frames", "10000000"], "frames")],
)
def test_synth_refuses_unbounded_worlds_before_writing(tmp_path, capsys, args, fragment):
    out = tmp_path / "o"
    line = _one_line_error(capsys, "synth", *args, "--size", "64", "--out", out, "--quiet")
    assert fragment in line and not any(out.glob("**/*.tif"))


# --------------------------------------------------------------------------- ONNX graphs


def _pixel_graph(kind: str) -> bytes:
    """A graph with the pixel classifiers' signature that answers wrongly (or never)."""
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("pixels", TensorProto.FLOAT, ["n", 4])
    label = helper.make_tensor_value_info("label", TensorProto.INT64, ["n"])
    proba = helper.make_tensor_value_info("probabilities", TensorProto.FLOAT, ["n", 2])
    c = lambda name, v, t=TensorProto.INT64: helper.make_node(  # noqa: E731
        "Constant", [], [name], value=helper.make_tensor(name, t, [len(v)], v)
    )
    nodes = [
        c("s", [0]),
        c("e", [2]),
        c("ax", [1]),
        helper.make_node("Slice", ["pixels", "s", "e", "ax"], ["two"]),
    ]
    if kind == "nan":
        nodes += [
            c("nan", [float("nan")], TensorProto.FLOAT),
            helper.make_node("Mul", ["two", "nan"], ["p"]),
        ]
    elif kind == "one-row":
        nodes += [helper.make_node("ReduceMean", ["two"], ["p"], axes=[0], keepdims=1)]
    else:  # a Loop of 2**62 iterations (its carried value depends on the input: not foldable)
        scalar = lambda name: helper.make_tensor_value_info(name, TensorProto.FLOAT, [])  # noqa: E731
        body = helper.make_graph(
            [helper.make_node("Identity", ["cond_in"], ["cond_out"]),
             helper.make_node("Identity", ["x_in"], ["x_out"])], "body",
            [helper.make_tensor_value_info("i", TensorProto.INT64, []),
             helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []), scalar("x_in")],
            [helper.make_tensor_value_info("cond_out", TensorProto.BOOL, []), scalar("x_out")],
        )  # fmt: skip
        tensor = helper.make_tensor
        nodes += [
            helper.make_node(
                "Constant", [], ["trip"], value=tensor("trip", TensorProto.INT64, [], [2**62])
            ),
            helper.make_node(
                "Constant", [], ["go"], value=tensor("go", TensorProto.BOOL, [], [True])
            ),
            helper.make_node("ReduceSum", ["two"], ["x0"], keepdims=0),
            helper.make_node("Loop", ["trip", "go", "x0"], ["x_end"], body=body),
            helper.make_node("Mul", ["x_end", "zero"], ["nil"]),
            helper.make_node("Add", ["two", "nil"], ["p"]),
            helper.make_node(
                "Constant", [], ["zero"], value=tensor("zero", TensorProto.FLOAT, [], [0.0])
            ),
        ]
    nodes += [
        helper.make_node("ArgMax", ["p"], ["l2"], axis=1, keepdims=0),
        helper.make_node("Identity", ["p"], ["probabilities"]),
        helper.make_node("Identity", ["l2"], ["label"]),
    ]
    graph = helper.make_graph(nodes, "hostile", [x], [label, proba])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    return model.SerializeToString()


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory, tiny_scenes):
    from dyntarget.perceive import make_classifier

    d = tmp_path_factory.mktemp("m") / "model"
    make_classifier("naive-bayes").fit([s.to_wfov(4) for s in tiny_scenes]).save(d)
    return d


@pytest.mark.parametrize(
    "kind, fragment",
    [
        ("nan", "NaN or infinite"),
        ("one-row", "has shape (1,) for 4096 input rows"),
        ("loop", "holds a Loop node"),
    ],
)
def test_hostile_onnx_model_is_one_line(tmp_path, capsys, model_dir, tiny_scene, kind, fragment):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    model = tmp_path / "model"
    shutil.copytree(model_dir, model)
    (model / "model.onnx").write_bytes(_pixel_graph(kind))
    image = write_scene(tiny_scene, tmp_path / "img")[0]
    line = _one_line_error(capsys, "plan", image, "--model", model, "--onnx",
                           "--planner", "lawnmower-transect", "--out", tmp_path / "t.geojson")  # fmt: skip
    assert fragment in line and not (tmp_path / "t.geojson").exists()


def test_onnx_run_time_limit_stops_an_endless_loop(tmp_path):
    ort = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    from dyntarget.perceive.validate import run_onnx

    session = ort.InferenceSession(_pixel_graph("loop"), providers=["CPUExecutionProvider"])
    with pytest.raises(ModelFileError, match="longer than 0.5 s and was stopped"):
        run_onnx(session, {"pixels": np.zeros((3, 4), np.float32)}, "pixel", limit_s=0.5)


def test_sparse_3gb_onnx_refused_from_its_size(tmp_path):
    from dyntarget.perceive.validate import check_onnx_file

    p = tmp_path / "model.onnx"
    with open(p, "wb") as f:
        f.truncate(3 * 1024**3)
    with pytest.raises(ModelFileError, match="more than the 536,870,912"):
        check_onnx_file(p)


def test_onnx_control_flow_found_without_the_onnx_package():
    from dyntarget.perceive.validate import _scan_ops

    pytest.importorskip("onnx")
    assert _scan_ops(_pixel_graph("loop")) == ["Loop"]
    assert _scan_ops(_pixel_graph("nan")) == []


def _ops_by_onnx(data: bytes) -> list[str]:
    """Every node's op_type as the onnx package parses and walks the model (the reference)."""
    import onnx

    model = onnx.ModelProto()
    model.ParseFromString(data)
    ops, graphs = [], [model.graph, *model.functions]
    while graphs:
        g = graphs.pop()
        for node in g.node:
            ops.append(node.op_type)
            for a in node.attribute:
                graphs += [a.g] if a.HasField("g") else []
                graphs += list(a.graphs)
    return ops


def test_the_node_parse_finds_what_onnx_finds_in_graphs_subgraphs_and_functions():
    """validate's own protobuf parse (no onnx import) against onnx's: the same operators in
    the same order, a Loop's body, an If's branches and a function's nodes included."""
    pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    from dyntarget.perceive.validate import _onnx_ops

    branch = helper.make_graph([helper.make_node("Scan", [], [])], "then", [], [])
    other = helper.make_graph([helper.make_node("Relu", [], [])], "else", [], [])
    graph = helper.make_graph(
        [helper.make_node("If", ["c"], [], then_branch=branch, else_branch=other),
         helper.make_node("Add", [], [])], "g",
        [helper.make_tensor_value_info("c", TensorProto.BOOL, [])], [],
    )  # fmt: skip
    function = helper.make_function("f", "fn", [], [], [helper.make_node("Loop", [], [])], [])
    model = helper.make_model(graph, functions=[function]).SerializeToString()
    for data in (model, _pixel_graph("loop"), _pixel_graph("nan")):
        assert _onnx_ops(data, "x") == _ops_by_onnx(data)
    assert sorted(_onnx_ops(model, "x")) == ["Add", "If", "Loop", "Relu", "Scan"]


def test_a_loop_hidden_from_a_byte_scan_is_still_refused(tmp_path):
    """op_type's length written as a two-byte varint (0x84 0x00: legal protobuf, which ONNX
    Runtime reads as "Loop"): the old scan of the raw bytes missed it; the parse does not."""
    from dyntarget.perceive.validate import _scan_ops, check_onnx_file

    data = b"\x3a\x09\x0a\x07\x22\x84\x00Loop"  # graph { node { op_type: "Loop" } }
    assert _scan_ops(data) == []  # what the lean install relied on before
    (tmp_path / "model.onnx").write_bytes(data)
    with pytest.raises(ModelFileError, match="holds a Loop node"):
        check_onnx_file(tmp_path / "model.onnx")


def test_checking_an_onnx_file_does_not_import_onnx(tmp_path):
    """The check parses with protobuf alone: ``onnx`` (half a second of start-up) stays out."""
    pytest.importorskip("onnx")
    (tmp_path / "model.onnx").write_bytes(_pixel_graph("nan"))
    probe = (
        "import sys\n"
        "from dyntarget.perceive.validate import check_onnx_file\n"
        f"check_onnx_file({str(tmp_path / 'model.onnx')!r})\n"
        "print('onnx' in sys.modules)\n"
    )
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


# --------------------------------------------------------------------------- one line, exit 2


@pytest.mark.parametrize("command", ["synth", "plan", "fly"])
def test_unwritable_out_is_refused_before_any_work(
    tmp_path, capsys, monkeypatch, tiny_scene, command
):
    locked = tmp_path / "locked"
    locked.mkdir()
    image = write_scene(tiny_scene, tmp_path / "img")[0]
    mask = image.with_name(f"{image.stem}_mask.tif")
    args = {
        "synth": ["synth", "--scenes", "1", "--size", "64", "--out", locked / "x"],
        "plan": [
            "plan",
            image,
            "--mask",
            mask,
            "--planner",
            "lawnmower-transect",
            "--out",
            locked / "t.geojson",
        ],
        "fly": ["fly", "--scene", image, "--truth", "--out", locked / "o"],
    }[command]
    import dyntarget.io.sensors

    def never(*a, **k):  # proves the refusal comes before the image is read
        raise AssertionError("the input was read")

    monkeypatch.setattr(dyntarget.io.sensors, "read_any", never)
    locked.chmod(0o555)
    if os.geteuid() == 0:  # root may write anywhere: make os.access say what it says to users
        real = os.access
        monkeypatch.setattr(
            os, "access", lambda p, m, **k: False if str(p) == str(locked) else real(p, m, **k)
        )
    try:
        line = _one_line_error(capsys, *args)
    finally:
        locked.chmod(0o755)
    assert "cannot write in" in line and str(locked) in line
    assert list(locked.iterdir()) == []


def test_fallback_model_nested_100000_deep_is_one_line(tmp_path, capsys, tiny_scene):
    bad = tmp_path / "fallback"
    bad.mkdir()
    (bad / "metadata.json").write_text("{" * 50_000 + "}" * 50_000)
    image = write_scene(tiny_scene, tmp_path / "img")[0]
    line = _one_line_error(capsys, "plan", image, "--mask", image.with_name(f"{image.stem}_mask.tif"),
                           "--fallback-model", bad, "--planner", "lawnmower-transect",
                           "--out", tmp_path / "t.geojson")  # fmt: skip
    assert "nested more than" in line


@pytest.mark.parametrize("when", ["9999-12-31T23:59:59Z", "0001-01-01T00:00:00+14:00"])
def test_acquired_at_the_ends_of_time_with_agility(tmp_path, capsys, when):
    strip = _strip(tmp_path / "in")
    line = _one_line_error(capsys, "plan", strip, "--mask", strip.with_name("strip_mask.tif"),
                           "--planner", "lawnmower-transect", "--agility", "fast",
                           "--acquired", when, "--out", tmp_path / "t.geojson")  # fmt: skip
    assert "outside the years 1900..2200" in line


def test_look_ahead_beyond_the_horizon_is_refused(tmp_path, capsys):
    strip = _strip(tmp_path / "in")
    line = _one_line_error(capsys, "fly", "--scene", strip, "--truth", "--look-ahead-km", "30000",
                           "--out", tmp_path / "o")  # fmt: skip
    assert "beyond the horizon" in line


def test_label_studio_completions_of_the_wrong_type(tmp_path):
    from dyntarget.datasets.industrial_smoke import parse_label

    with pytest.raises(DataFileError, match="not a Label Studio annotation"):
        parse_label({"data": {"image": "/data/upload/x.tif"}, "completions": "abc"}, "l.json")


def test_planners_into_a_closed_pipe_exits_quietly():
    cmd = [sys.executable, "-m", "dyntarget", "planners"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.readline()
    proc.stdout.close()  # `| head -1`
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and b"Traceback" not in err and b"BrokenPipe" not in err


@pytest.mark.slow
def test_evaluate_dynamic_with_baselines_only(tmp_path, capsys):
    data = tmp_path / "seq"
    assert (
        _run(
            capsys,
            "synth",
            "--frames",
            "2",
            "--scenes",
            "2",
            "--size",
            "64",
            "--out",
            data,
            "--quiet",
        )[0]
        == 0
    )
    code, err = _run(capsys, "evaluate", "dynamic", "--data", data, "--out", tmp_path / "ev",
                     "--planners", "straight-nadir", "--folds", "2", "--classifiers", "band-threshold",
                     "--quiet")  # fmt: skip
    assert code == 0, err
    assert (tmp_path / "ev" / "dynamic.png").read_bytes()[:4] == b"\x89PNG"


# --------------------------------------------------------------------------- silently wrong


def test_plan_with_no_feasible_pointing_exits_3(tmp_path, capsys):
    strip = _strip(tmp_path / "in")
    code, err = _run(capsys, "plan", strip, "--mask", strip.with_name("strip_mask.tif"),
                     "--planner", "lawnmower-transect", "--agility", "fast", "--start-s", "1000",
                     "--out", tmp_path / "t.csv")  # fmt: skip
    assert code == 3, err
    assert "no feasible pointing: 0 of" in err and "exit 3" in err
    assert (tmp_path / "t.csv").read_text().splitlines() == ["order,x,y,part,time_s"] or (
        len((tmp_path / "t.csv").read_text().splitlines()) == 1
    )


def test_previous_taken_after_the_image_is_refused(tmp_path, capsys):
    cur = _strip(tmp_path / "cur", when="2026-01-01T00:01:00Z")
    prev = _strip(tmp_path / "prev", when="2026-01-01T00:02:00Z")  # 60 s *after*
    line = _one_line_error(capsys, "plan", cur, "--mask", cur.with_name("strip_mask.tif"),
                           "--previous", prev, "--previous-mask", prev.with_name("strip_mask.tif"),
                           "--interval-s", "10", "--lead-s", "30", "--planner", "lawnmower-transect",
                           "--out", tmp_path / "t.geojson")  # fmt: skip
    assert "60 s after the image" in line


def test_previous_of_another_size_refused_from_its_header(tmp_path, capsys):
    import rasterio

    cur = _strip(tmp_path / "cur")
    prev = tmp_path / "prev.tif"
    with rasterio.open(
        prev,
        "w",
        driver="GTiff",
        width=100_000,
        height=1,
        count=4,
        dtype="float32",
        crs="EPSG:32605",
        transform=Affine(8.0, 0.0, 250000.0, 0.0, -8.0, 2150000.0),
    ) as dst:
        dst.write(np.full((4, 1, 100_000), 0.1, np.float32))
    line = _one_line_error(capsys, "plan", cur, "--mask", cur.with_name("strip_mask.tif"),
                           "--previous", prev, "--previous-mask", prev, "--interval-s", "10",
                           "--lead-s", "30", "--planner", "lawnmower-transect",
                           "--out", tmp_path / "t.geojson")  # fmt: skip
    assert "1 x 100000 px at factor 1 does not match" in line


def test_html_of_a_huge_sparse_geotiff_refused_from_its_header(tmp_path, capsys):
    import rasterio

    big = tmp_path / "big.tif"
    with rasterio.open(big, "w", driver="GTiff", width=30000, height=30000, count=4,
                       dtype="float32", tiled=True, sparse_ok=True, crs="EPSG:32605",
                       transform=Affine(8.0, 0.0, 250000.0, 0.0, -8.0, 2150000.0)) as dst:  # fmt: skip
        dst.write(np.full((4, 16, 16), 0.1, np.float32), window=((0, 16), (0, 16)))
    line = _one_line_error(capsys, "plan", big, "--mask", big, "--factor", "2", "--html",
                           tmp_path / "v.html", "--planner", "lawnmower-transect",
                           "--out", tmp_path / "t.geojson")  # fmt: skip
    assert "15000 x 15000 px at factor 2" in line


def test_error_after_the_first_frame_leaves_no_partial_timeline(tmp_path, capsys, monkeypatch):
    import dyntarget.fly
    from dyntarget.errors import InvalidSceneError

    real = dyntarget.fly.fly_pass

    def failing(world, classifier, config, *, on_frame=None, **kw):
        seen = []

        def frame(result):
            on_frame(result)
            seen.append(1)
            if len(seen) == 2:
                raise InvalidSceneError("frame 1: hostile pixels")

        return real(world, classifier, config, on_frame=frame, **kw)

    monkeypatch.setattr(dyntarget.fly, "fly_pass", failing)
    strip = _strip(tmp_path / "in")
    out = tmp_path / "o"
    line = _one_line_error(capsys, "fly", "--scene", strip, "--truth", "--compute-budget-s", "0.05",
                           "--out", out, "--quiet")  # fmt: skip
    assert "hostile pixels" in line and "no partial timeline" in line
    assert not out.exists() or not [p for p in out.iterdir() if not p.name.startswith(".")]


# --------------------------------------------------------------------------- field sweeps

HOSTILE = [
    "a",
    None,
    float("nan"),
    float("inf"),
    -1,
    -1e300,
    1e300,
    1e-300,
    [],
    {},
    True,
    2**70,
    0,
    1.5,
]
"""Values tried in every field: wrong types, non-finite, huge, tiny, negative, boolean."""


@pytest.mark.slow
def test_every_strip_sidecar_field_refused_or_rendered(tmp_path):
    """Each field of a strip sidecar set to each hostile value: a DynTargetError or a world
    that renders (no other exception, no warning, none slow enough to trip the alarm)."""
    import copy
    import warnings

    from dyntarget.errors import DynTargetError
    from dyntarget.synth.strip_world import load_world

    base = _spec_dict()
    base["clouds"] = [{"x": 5.0, "y": 5.0, "radius_m": 300.0, "optical_depth": 2.0,
                       "volcanic": True, "ash_fraction": 0.5}]  # fmt: skip
    (tmp_path / "s.tif").write_bytes(b"")
    docs = []
    for key in base:
        docs += [(f"world.{key}", {**base, key: v}, [0, 0, 64, 256]) for v in HOSTILE]
    for sub in ("vents", "clouds", "wind"):
        for key in base[sub] if sub == "wind" else base[sub][0]:
            for v in HOSTILE:
                w = copy.deepcopy(base)
                (w["wind"] if sub == "wind" else w[sub][0])[key] = v
                docs.append((f"{sub}.{key}", w, [0, 0, 64, 256]))
    for i in range(4):
        docs += [
            (f"window[{i}]", base, [*[0, 0, 64, 256][:i], v, *[0, 0, 64, 256][i + 1 :]])
            for v in HOSTILE
        ]
    failures = []
    for label, world, window in docs:
        doc = {"format": "dyntarget-strip", "version": 1, "world": world, "window": window}
        (tmp_path / "s.world.json").write_text(json.dumps(doc))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                strip = load_world(tmp_path / "s.tif")
                strip.image_at(0.0, 0, 32)
                strip.truth_at(0.0)
        except DynTargetError:
            pass
        except Exception as exc:
            failures.append(f"{label}: {type(exc).__name__}: {exc}"[:160])
    assert failures == []


def test_every_sequence_sidecar_time_field_refused_or_read(tmp_path):
    import copy

    from dyntarget.errors import DynTargetError
    from dyntarget.io import read_sequence, write_sequence
    from dyntarget.synth.dynamic import World, sample_world, truth_provider, world_sequence

    seq = world_sequence(World(sample_world(0, 0, size=32)), frames=2, interval_s=10.0)
    write_sequence(seq, tmp_path)
    folder = tmp_path / seq.id
    base = json.loads((folder / "sequence.json").read_text())
    values = [*HOSTILE, "9999-12-31T23:59:59Z", "0001-01-01T00:00:00+14:00"]
    docs = [{**base, key: v} for key in ("epoch", "id", "meta") for v in values]
    for v in values:
        for entry in (
            {"file": "f001.tif", "time_s": v},
            {"file": "f001.tif", "time": v},
            {"file": v, "time_s": 1},
        ):
            doc = copy.deepcopy(base)
            doc["frames"][1] = entry
            docs.append(doc)
        for key in ("window", "world"):
            doc = copy.deepcopy(base)
            doc["meta"][key] = v
            docs.append(doc)
    failures = []
    for doc in docs:
        (folder / "sequence.json").write_text(json.dumps(doc))
        try:
            s = read_sequence(folder)
            provider = truth_provider(s.meta)
            if provider is not None:
                provider(5.0)
            [s.time_iso(i) for i in range(len(s))]
        except DynTargetError:
            pass
        except Exception as exc:
            failures.append(f"{json.dumps(doc)[:80]}: {type(exc).__name__}: {exc}"[:200])
    assert failures == []
