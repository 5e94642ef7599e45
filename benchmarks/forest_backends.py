"""Random-forest backends side by side, on one fitted forest and one scene, in one run.

The forest is a project random forest (``dyntarget train ... --classifier random-forest``:
50 trees, depth <= 14) and its ONNX export (``export-onnx``); the scene a 1024 x 1024 px
WFOV image (1 M pixels, ``(n, 4) float32``). Each backend predicts the plume probability
of every pixel; the table gives the build time (where there is one), the median of
``--repeats`` runs after one warm-up, and the largest absolute difference from
scikit-learn's ``predict_proba`` (the reference, float64, and rounded to float32 as the
classifiers return it):

* scikit-learn ``predict_proba`` (one call, ``n_jobs=1``; and in the project's chunk pool,
  one thread per core);
* ONNX Runtime's TreeEnsemble on ``model.onnx`` with ``intra_op_num_threads`` 1 and 2
  (sequential execution, all graph optimisations; spinning on and off for 2 threads); and
  on another graph form, built here from the packed forest and not what ``export-onnx``
  writes: one ``TreeEnsembleRegressor`` (``ai.onnx.ml`` opset 3) giving the plume fraction
  only (float32, ``AVERAGE`` of the leaves' fractions, no label, no second class, no
  ZipMap), thresholds rounded down to float32 as the kernel has them;
* TL2cgen (Treelite 4 model, C generated per tree, compiled with gcc; ``nthread`` 1 and 2),
  with and without threshold quantisation;
* dyntarget's kernel forced on each path this CPU runs (``avx512``, ``avx2``, ``sse2``,
  ``portable``), one thread and in the chunk pool.

    python benchmarks/forest_backends.py --model RF --image IMG.tif [--repeats 5]
        [--out docs/benchmarks/forest_backends.json] [--before OLD/_forest.c]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.io.atomic import write_text


def timed(
    fn: Callable[[], np.ndarray], repeats: int
) -> tuple[list[float], list[float], np.ndarray]:
    """Wall and process-CPU seconds of ``repeats`` calls after one warm-up, and the last result.

    The CPU seconds (all threads of this process) move less with the load of other
    processes than the wall seconds do, so they compare rows measured on a busy machine.
    """
    out = fn()
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return times, cpu, np.asarray(out, np.float64).ravel()


def library_from(source: Path, isa: str, where: Path) -> Path:
    """The kernel of another ``_forest.c`` (``--before``) built for the forced path ``isa``."""
    import shlex
    import subprocess

    from dyntarget.perceive import compiled

    cc = compiled.compiler()
    if cc is None:
        raise SystemExit("--before needs a C compiler")
    flags = [f for f in compiled.FLAGS if f != "-march=native"] + list(compiled.ISA_FLAGS[isa])
    out = where / f"before-{isa}.so"
    subprocess.run([*shlex.split(cc), *flags, str(source), "-o", str(out)], check=True)
    out.with_name(out.name + ".sha256").write_text(compiled._sha256(out) + "\n")
    return out


def regressor_graph(packed) -> bytes:
    """One ``TreeEnsembleRegressor`` giving a packed forest's plume fraction (see the module)."""
    from onnx import TensorProto, helper

    total, ntrees = len(packed.value), len(packed.roots)
    bounds = [*packed.roots.tolist(), total]
    leaf = np.isposinf(packed.threshold[:total])
    tree = np.repeat(np.arange(ntrees), np.diff(bounds))
    local = np.arange(total) - np.asarray(bounds[:-1])[tree]
    child = (packed.code[:total] >> packed.fshift) - np.asarray(bounds[:-1])[tree]
    feature = packed.code[:total] & ((1 << packed.fshift) - 1)
    node = helper.make_node(
        "TreeEnsembleRegressor", ["pixels"], ["plume"], domain="ai.onnx.ml",
        nodes_treeids=tree.tolist(), nodes_nodeids=local.tolist(),
        nodes_featureids=np.where(leaf, 0, feature).tolist(),
        nodes_values=np.where(leaf, 0.0, packed.threshold[:total]).tolist(),
        nodes_modes=["LEAF" if lf else "BRANCH_LEQ" for lf in leaf],
        nodes_truenodeids=np.where(leaf, 0, child).tolist(),
        nodes_falsenodeids=np.where(leaf, 0, child + 1).tolist(),
        target_treeids=tree[leaf].tolist(), target_nodeids=local[leaf].tolist(),
        target_ids=[0] * int(leaf.sum()), target_weights=packed.value[leaf].tolist(),
        n_targets=1, aggregate_function="AVERAGE", post_transform="NONE",
    )  # fmt: skip
    graph = helper.make_graph(
        [node], "plume-fraction",
        [helper.make_tensor_value_info("pixels", TensorProto.FLOAT, [None, packed.features])],
        [helper.make_tensor_value_info("plume", TensorProto.FLOAT, [None, 1])],
    )  # fmt: skip
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", 17), helper.make_opsetid("ai.onnx.ml", 3)]
    )
    model.ir_version = 8
    return model.SerializeToString()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", required=True, help="random-forest model dir with model.onnx")
    parser.add_argument("--image", required=True, help="the scene (a 4-band GeoTIFF)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--skip",
        default="",
        help="comma-separated row names to leave out ('tl2cgen': all its rows and builds)",
    )
    parser.add_argument(
        "--before",
        default=None,
        help="another _forest.c (e.g. from an older commit): its forced paths are measured "
        "too, each row next to the current kernel's, for a before/after in one run",
    )
    parser.add_argument("--isas", default="avx512,avx2,sse2,portable", help="kernel paths to run")
    parser.add_argument("--out", default="docs/benchmarks/forest_backends.json")
    a = parser.parse_args()
    skip = set(filter(None, a.skip.split(",")))
    load_start = round(os.getloadavg()[0], 2)

    from dyntarget.io.sensors import read_any
    from dyntarget.perceive import compiled, load_classifier
    from dyntarget.perceive.pixel import predict_in_chunks
    from dyntarget.perceive.resources import available_cores

    image = read_any([a.image]).image.astype(np.float32)  # as plan reads it
    x = np.ascontiguousarray(image.reshape(4, -1).T)
    model = load_classifier(a.model)
    est = model.estimator
    cores = available_cores()
    ref = est.predict_proba(x)[:, 1]  # float64
    ref32 = ref.astype(np.float32).astype(np.float64)  # as the classifiers return it
    rows: list[dict] = []

    def add(name: str, fn: Callable[[], np.ndarray], build_s: float | None = None, **kw) -> None:
        if name in skip:
            return
        times, cpu, out = timed(fn, a.repeats)
        row = {"backend": name, "build_s": build_s, "seconds": times,
               "median_s": statistics.median(times), "cpu_seconds": cpu,
               "median_cpu_s": statistics.median(cpu),
               "max_abs_diff": float(np.abs(out - ref).max()),
               "max_abs_diff_float32": float(np.abs(out - ref32).max()), **kw}  # fmt: skip
        rows.append(row)
        print(
            f"{name:58s} {row['median_s']:8.3f} s (cpu {row['median_cpu_s']:.3f} s)  "
            f"max|d| {row['max_abs_diff']:.2g} "
            f"(float32 ref {row['max_abs_diff_float32']:.2g})",
            flush=True,
        )

    add("scikit-learn predict_proba (1 thread)", lambda: est.predict_proba(x)[:, 1], threads=1)
    add(
        f"scikit-learn in the chunk pool ({cores} threads)",
        lambda: predict_in_chunks(image, lambda p: est.predict_proba(p)[:, 1]),
        threads=cores,
    )

    import onnxruntime as ort

    onnx_path = str(Path(a.model) / "model.onnx")
    for threads, spin in ((1, True), (2, True), (2, False)):
        opts = ort.SessionOptions()
        opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        if not spin:
            opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
        sess = ort.InferenceSession(onnx_path, opts, providers=["CPUExecutionProvider"])

        def run_ort(sess=sess) -> np.ndarray:
            return sess.run(["probabilities"], {"pixels": x})[0][:, 1]

        label = f"ONNX Runtime TreeEnsemble ({threads} thread{'s' if threads > 1 else ''}"
        add(label + ("" if spin else ", no spinning") + ")", run_ort, threads=threads)

    packed = compiled.pack_forest(est)
    for threads in (1, cores):
        opts = ort.SessionOptions()
        opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        sess = ort.InferenceSession(
            regressor_graph(packed), opts, providers=["CPUExecutionProvider"]
        )

        def run_reg(sess=sess) -> np.ndarray:
            return sess.run(None, {"pixels": x})[0][:, 0]

        add(f"ONNX Runtime TreeEnsembleRegressor, plume fraction only ({threads} threads)",
            run_reg, threads=threads)  # fmt: skip

    try:
        if "tl2cgen" in skip:
            raise ImportError("left out with --skip tl2cgen")
        import tl2cgen
        import treelite
    except ImportError as exc:
        print(f"TL2cgen / Treelite not measured ({exc})")
    else:
        tl_model = treelite.sklearn.import_model(est)
        tmp = Path(tempfile.mkdtemp(prefix="tl2cgen-"))
        dmat = tl2cgen.DMatrix(x, dtype="float32")
        for quantize in (0, 1):
            lib = tmp / f"forest-q{quantize}.so"
            t0 = time.perf_counter()
            tl2cgen.export_lib(
                tl_model, toolchain="gcc", libpath=str(lib),
                params={"parallel_comp": 50, "quantize": quantize}, nthread=cores,
            )  # fmt: skip
            build = time.perf_counter() - t0
            for threads in (1, cores):
                pred = tl2cgen.Predictor(str(lib), nthread=threads)

                def run_tl(pred=pred) -> np.ndarray:
                    out = np.asarray(pred.predict(dmat))
                    return out.reshape(len(x), -1)[:, -1]

                add(f"TL2cgen -O2{' quantized' if quantize else ''} ({threads} threads)",
                    run_tl, build, threads=threads, quantize=quantize)  # fmt: skip

    for isa in a.isas.split(","):
        if not compiled.cpu_runs(isa):
            print(f"kernel {isa}: this CPU does not run it")
            continue
        with tempfile.TemporaryDirectory() as cache:
            t0 = time.perf_counter()
            predict = compiled.forest_predictor(packed, directory=cache, isa=isa)
            build = time.perf_counter() - t0
            kernels = [("", predict, build)]
            if a.before:
                lib = library_from(Path(a.before), isa, Path(cache))
                kernels.insert(0, (" before", compiled.forest_predictor(packed, library=lib), None))
            for label, p, b in kernels:  # before and after side by side
                add(f"dyntarget kernel {isa}{label} (1 thread)", lambda p=p: p(x), b, threads=1)
            for label, p, b in kernels:
                add(
                    f"dyntarget kernel {isa}{label} in the chunk pool ({cores} threads)",
                    lambda p=p: predict_in_chunks(image, p),
                    b,
                    threads=cores,
                )

    result = {
        "command": "python benchmarks/forest_backends.py --model RF --image IMG "
        f"--repeats {a.repeats}" + (" --before OLD/_forest.c" if a.before else ""),
        "pixels": len(x),
        "trees": len(est.estimators_),
        "nodes": int(sum(t.tree_.node_count for t in est.estimators_)),
        "rows": rows,
        "load_1min_start": load_start,
        "machine": machine(),  # its load_1min: at the end
    }
    write_text(Path(a.out), json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
