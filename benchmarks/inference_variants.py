"""Inference variants behind issue 17's choices: U-Net layouts, the forest's predictors,
ONNX Runtime thread spinning, and a roofline bound for the U-Nets.

``unet-layouts``
    Each U-Net (width 16) at ``--size`` px, one whole-image pass on the machine's
    threads: the trained network as it is, a channels-last copy, the copy with its
    batch norms folded, and the copy prediction runs (``networks.prepare_inference``:
    for UNET-Xception also in-place ReLUs and sums and one upsampling per up stage). With ``--models DIR`` (``DIR/fold-K/NAME``,
    e.g. ``reproduce/models``) and ``--data SCENES``, also the largest probability
    difference and the pixels whose class changes between the default network and the
    prediction copy on the cross-validation's held-out scenes (WFOV factor 4).
``unet-profile``
    UNET-Xception's operators at ``--size`` px by self CPU time (``torch.profiler``, top
    ``--top``), in the folded channels-last network and in the prediction copy.
``forest-kernel``
    The random forest of ``--model`` on ``--image``: scikit-learn, the former TL2cgen
    backend (when installed), and dyntarget's kernel built portable and with
    ``-march=native``, each on one thread (median of ``--repeats``), with build time and
    parity; then the kernel through ``predict_proba`` on the chunk pool, and the mean
    root-to-leaf depth the pixels take (every ``--stride``-th pixel).
``ort-spinning``
    The ONNX export of ``--model`` on ``--image`` (4 chunks, 2 intra-op threads) with
    ``session.intra_op.allow_spinning`` on and off, alternating, 5 runs each.
``roofline``
    Each U-Net's one-pass FLOP bound at ``--size`` px against a roofline bound that adds,
    per convolution, the input + output activations beyond the L3 cache at the copy rate.

    python benchmarks/inference_variants.py unet-layouts [--models reproduce/models --data scenes/]
    python benchmarks/inference_variants.py unet-profile [--default-allocator]
    python benchmarks/inference_variants.py forest-kernel --model RF --image IMG.tif
    python benchmarks/inference_variants.py ort-spinning --model RF --image IMG.tif
    python benchmarks/inference_variants.py roofline

Each prints a Markdown table; ``--out FILE.json`` also keeps the numbers. Like the
``dyntarget`` command, the script keeps large freed blocks in the heap
(``keep_freed_memory``); ``--default-allocator`` leaves glibc's defaults.
"""

from __future__ import annotations

import argparse
import copy
import json
import statistics
import time
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine, machine_rates
from dyntarget.evaluate.tables import markdown_table
from dyntarget.io import read_scene
from dyntarget.io.atomic import write_text
from dyntarget.perceive.resources import available_cores, keep_freed_memory


def _median_s(fn, repeats: int = 3) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def unet_layouts(args) -> list[dict]:
    import torch

    from dyntarget.perceive import make_classifier
    from dyntarget.perceive.networks import fold_batch_norms, prepare_inference

    rows = []
    x = torch.rand(1, 4, args.size, args.size, generator=torch.Generator().manual_seed(0))
    xc = x.contiguous(memory_format=torch.channels_last)
    for name in ("unet-uavsar", "unet-xception"):
        net = make_classifier(name).model.eval()
        last = copy.deepcopy(net).to(memory_format=torch.channels_last)
        folded = fold_batch_norms(copy.deepcopy(net)).to(memory_format=torch.channels_last)
        prepared = prepare_inference(copy.deepcopy(net))  # what prediction runs
        with torch.inference_mode():
            row = {
                "classifier": name,
                "default (s)": _median_s(lambda net=net: net(x)),
                "channels-last (s)": _median_s(lambda last=last: last(xc)),
                "folded + channels-last (s)": _median_s(lambda folded=folded: folded(xc)),
                "prediction copy (s)": _median_s(lambda prepared=prepared: prepared(xc)),
            }
        if args.models and args.data:
            row.update(_held_out_change(name, args.models, args.data))
        rows.append(row)
    return rows


def unet_profile(args) -> list[dict]:
    import torch
    from torch.profiler import ProfilerActivity, profile

    from dyntarget.perceive import make_classifier
    from dyntarget.perceive.networks import fold_batch_norms, prepare_inference

    x = torch.rand(1, 4, args.size, args.size, generator=torch.Generator().manual_seed(0))
    x = x.contiguous(memory_format=torch.channels_last)
    net = make_classifier("unet-xception").model.eval()
    rows = []
    for label, copy_ in (
        ("folded + channels-last", fold_batch_norms(copy.deepcopy(net)).to(
            memory_format=torch.channels_last)),
        ("prediction copy", prepare_inference(copy.deepcopy(net))),
    ):  # fmt: skip
        with torch.inference_mode():
            copy_(x)
            with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as prof:
                copy_(x)
        events = prof.key_averages(group_by_input_shape=True)
        total = sum(e.self_cpu_time_total for e in events)
        for e in sorted(events, key=lambda e: -e.self_cpu_time_total)[: args.top]:
            rows.append(
                {
                    "network": label,
                    "op": e.key,
                    "input shapes": str(e.input_shapes)[:60],
                    "calls": e.count,
                    "self ms": e.self_cpu_time_total / 1e3,
                    "share": e.self_cpu_time_total / total,
                }
            )
    return rows


def _held_out_change(name: str, models: str, data: str) -> dict:
    from dyntarget.evaluate.crossval import CVConfig, kfold_indices
    from dyntarget.io import read_scene_dir
    from dyntarget.perceive import load_classifier

    config = CVConfig()
    wfov = [s.to_wfov(config.factor) for s in read_scene_dir(data, require_labels=True)]
    flips = pixels = 0
    largest = 0.0
    for k, test in enumerate(kfold_indices(len(wfov), config.folds, config.seed)):
        model = load_classifier(Path(models) / f"fold-{k}" / name)
        for i in test:
            scene = wfov[i]
            copy_ = model.predict_proba(scene.image)  # the prediction copy
            model._inference = (model.model, model.model.eval())  # the network as trained
            plain = model.predict_proba(scene.image)
            del model._inference
            largest = max(largest, float(np.abs(copy_ - plain).max()))
            valid = scene.valid_mask
            flips += int(((copy_ >= 0.5) != (plain >= 0.5))[valid].sum())
            pixels += int(valid.sum())
    return {"largest difference": largest, "class changes": f"{flips} of {pixels}"}


def forest_kernel(args) -> list[dict]:
    import tempfile

    from dyntarget.perceive import compiled, load_classifier

    model = load_classifier(args.model)
    forest = model.estimator
    image = read_scene(args.image).image
    pixels = np.ascontiguousarray(image.reshape(4, -1).T, dtype=np.float32)
    expected = forest.predict_proba(pixels)[:, 1].astype(np.float32)
    trees = len(forest.estimators_)
    out: dict = {}
    rows = []

    def row(name, build_s, fn, threads=1):
        seconds = _median_s(lambda: out.__setitem__("p", fn()), repeats=args.repeats)
        rows.append(
            {
                "predictor": name,
                "threads": threads,
                "build (s)": build_s,
                "predict (s)": seconds,
                "ns per pixel and tree": seconds * threads / (len(pixels) * trees) * 1e9,
                "bit-identical to scikit-learn": bool(
                    np.array_equal(np.asarray(out["p"], np.float32).ravel(), expected)
                ),
            }
        )

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        row("scikit-learn predict_proba", 0.0, lambda: forest.predict_proba(pixels)[:, 1])
    with tempfile.TemporaryDirectory() as tmp:
        try:
            import tl2cgen
            import treelite
        except ImportError:
            tl2cgen = None
        if tl2cgen is not None:  # the former backend, when installed, for comparison
            lib = Path(tmp) / "tl2cgen.so"
            t0 = time.perf_counter()
            tl2cgen.export_lib(
                treelite.sklearn.import_model(forest), toolchain="gcc", libpath=str(lib),
                params={"parallel_comp": trees, "quantize": 1}, nthread=1, options=["-O1"],
            )  # fmt: skip
            build_s = time.perf_counter() - t0
            predictor, dmat = tl2cgen.Predictor(str(lib), nthread=1), tl2cgen.DMatrix(pixels)
            row(
                "TL2cgen C per tree, -O1, quantized (former backend)",
                build_s,
                lambda: np.asarray(predictor.predict(dmat)).reshape(len(pixels), -1)[:, -1],
            )
        for portable in (True, False):
            t0 = time.perf_counter()
            predict = compiled.compile_forest(forest, directory=tmp, portable=portable)
            build_s = time.perf_counter() - t0
            what = "AVX-512" if predict.vectorised else "no AVX-512"
            name = f"dyntarget kernel, {'portable' if portable else '-march=native'} ({what})"
            row(name, build_s, lambda predict=predict: predict(pixels))
    model.set_backend("compiled")
    row("dyntarget kernel through predict_proba (chunk pool)", 0.0,
        lambda: model.predict_proba(image), threads=available_cores())  # fmt: skip
    leaves = forest.apply(pixels[:: args.stride])
    depth = [_node_depths(t.tree_)[leaves[:, i]] for i, t in enumerate(forest.estimators_)]
    print(f"mean root-to-leaf depth over pixels and trees: {np.mean(depth):.2f} "
          f"(max_depth {max(t.tree_.max_depth for t in forest.estimators_)})")  # fmt: skip
    return rows


def _node_depths(tree) -> np.ndarray:
    depth = np.zeros(tree.node_count, int)
    for k in range(tree.node_count):  # parents come before their children
        for child in (tree.children_left[k], tree.children_right[k]):
            if child != -1:
                depth[child] = depth[k] + 1
    return depth


def ort_spinning(args) -> list[dict]:
    import onnxruntime as ort

    image = read_scene(args.image).image
    pixels = np.ascontiguousarray(image.reshape(4, -1).T, dtype=np.float32)
    chunk = len(pixels) // 4 + 1
    times: dict[str, list[float]] = {"1": [], "0": []}
    for _ in range(5):
        for spin in ("1", "0"):
            options = ort.SessionOptions()
            options.intra_op_num_threads, options.inter_op_num_threads = 2, 1
            options.add_session_config_entry("session.intra_op.allow_spinning", spin)
            session = ort.InferenceSession(
                str(Path(args.model) / "model.onnx"), options, providers=["CPUExecutionProvider"]
            )
            name = session.get_inputs()[0].name

            def run(session=session, name=name):
                for i in range(0, len(pixels), chunk):
                    session.run(None, {name: pixels[i : i + chunk]})

            times[spin].append(_median_s(run, repeats=1))
    return [
        {"allow_spinning": spin, "median (s)": statistics.median(t), "min (s)": min(t)}
        for spin, t in times.items()
    ]


def roofline(args) -> list[dict]:
    import torch
    from torch import nn
    from torch.utils.flop_counter import FlopCounterMode

    from dyntarget.perceive import make_classifier

    l3 = _l3_bytes()
    rates = machine_rates()
    rows = []
    for name in ("unet-uavsar", "unet-xception"):
        net = make_classifier(name).model.eval()
        names = {m: n for n, m in net.named_modules()}
        traffic = []

        def hook(module, inputs, output, traffic=traffic):
            traffic.append((module, 4 * (inputs[0].numel() + output.numel())))

        hooks = [
            m.register_forward_hook(hook)
            for m in net.modules()
            if isinstance(m, nn.modules.conv._ConvNd)
        ]
        with FlopCounterMode(display=False) as counter, torch.inference_mode():
            net(torch.zeros(1, 4, args.size, args.size))
        for h in hooks:
            h.remove()
        per_module = counter.get_flop_counts()
        flop_s = roof_s = 0.0
        for module, nbytes in traffic:
            key = ".".join(filter(None, (type(net).__name__, names[module])))
            flops = sum(per_module.get(key, {}).values())
            flop_s += flops / rates["matmul_flop_per_s"]
            roof_s += max(
                flops / rates["matmul_flop_per_s"], max(0, nbytes - l3) / rates["copy_bytes_per_s"]
            )
        rows.append(
            {
                "classifier": name,
                "FLOP bound (s)": flop_s,
                "roofline bound (s)": roof_s,
                "roofline / FLOP": roof_s / flop_s,
            }
        )
    return rows


def _l3_bytes() -> int:
    path = Path("/sys/devices/system/cpu/cpu0/cache/index3/size")
    text = path.read_text().strip() if path.exists() else "32768K"
    return int(text[:-1]) * 1024 if text.endswith("K") else int(text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "what",
        choices=["unet-layouts", "unet-profile", "forest-kernel", "ort-spinning", "roofline"],
    )
    ap.add_argument("--size", type=int, default=1024, help="WFOV px (unet-layouts, roofline)")
    ap.add_argument("--models", help="unet-layouts: trained models, DIR/fold-K/NAME")
    ap.add_argument("--data", help="unet-layouts: the labelled scenes of those models")
    ap.add_argument("--model", help="forest-kernel, ort-spinning: a random-forest model dir")
    ap.add_argument("--image", help="forest-kernel, ort-spinning: a 4-band GeoTIFF")
    ap.add_argument("--repeats", type=int, default=5, help="forest-kernel: timed runs")
    ap.add_argument("--stride", type=int, default=16, help="forest-kernel: depth sample")
    ap.add_argument("--top", type=int, default=12, help="unet-profile: ops per network")
    ap.add_argument(
        "--default-allocator",
        action="store_true",
        help="leave glibc's malloc thresholds as they are (no keep_freed_memory)",
    )
    ap.add_argument("--out", help="also write the rows here (JSON)")
    args = ap.parse_args()
    if not args.default_allocator:
        keep_freed_memory()  # as the dyntarget command does
    run = {
        "unet-layouts": unet_layouts,
        "unet-profile": unet_profile,
        "forest-kernel": forest_kernel,
        "ort-spinning": ort_spinning,
        "roofline": roofline,
    }[args.what]
    rows = run(args)
    print(markdown_table(rows, list(rows[0]), digits=3))
    if args.out:
        write_text(
            args.out,
            json.dumps({"machine": machine(), "what": args.what, "rows": rows}, indent=1) + "\n",
        )


if __name__ == "__main__":
    main()
