"""Benchmark harness: per-stage latency and peak memory for every classifier and planner.

For each WFOV size (default 256, 512, 1024, 2048 px) a synthetic scene of that
size is generated and used directly as the WFOV grid. Every classifier (trained
once on four 256 px scenes; U-Nets for a few epochs — latency does not depend on
how well a model is trained) is timed on it, then denoising of its mask, every
planner on the denoised polygons, and the NFOV simulator on each trajectory.
Each number is the median of ``repeats`` runs after one warm-up run.

Peak memory is the process's resident high-water mark during a stage minus the
resident size before it (Linux: freed heap pages are first returned to the OS
with ``malloc_trim`` and the mark is reset through ``/proc/self/clear_refs``);
elsewhere it is not reported.

Lower bounds (:func:`lower_bounds`) put each stage's time in perspective: reading
the image once from memory at the machine's measured copy bandwidth, and for the
U-Nets the network's multiply-adds for one pass over the image at the machine's
measured single-precision matrix-multiply rate. That rate is measured once at the
start (the ``bounds`` table) and, for each timed U-Net classification, again right
before and right after it (:func:`matmul_rate`), so that each run's time is set
against a bound measured under the same load: the run's record holds ``runs`` (time,
both rates, the 1-minute load average, threads) and ``ratios`` (time over its bound).
"""

from __future__ import annotations

import ctypes
import gc
import os
import platform
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive import CLASSIFIERS, make_classifier
from dyntarget.perceive.resources import openmp_spin_count
from dyntarget.pipeline import PipelineConfig, classify, clean, plan_segmentation, segment
from dyntarget.plan import geometric_planners
from dyntarget.synth import generate_scene

DEFAULT_SIZES = (256, 512, 1024, 2048)


def _status_kb(field: str) -> int | None:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _release_free_memory() -> None:
    """Hand freed heap pages back to the OS (glibc ``malloc_trim``), so that the
    next stage's resident high-water mark shows what it allocates rather than
    reusing pages an earlier run left in the allocator."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def measure(
    fn: Callable[[], Any], *, repeats: int, probe: Callable[[], float] | None = None
) -> dict[str, Any]:
    """Median wall time (s) of ``repeats`` runs after a warm-up, and peak memory (MiB) above the start.

    Parameters
    ----------
    fn : callable
        The work, called without arguments.
    repeats : int
        Timed runs.
    probe : callable or None
        Called right before and right after each timed run (outside its time), e.g.
        :func:`matmul_rate`'s FLOP/s: its two readings are kept with the run.

    Returns
    -------
    dict
        ``median_s``, ``min_s`` and ``peak_mib`` (``None`` where peak memory cannot be
        measured); with a ``probe`` also ``runs``, one ``{"s", "probe_before",
        "probe_after", "load_1min"}`` per timed run.

    Examples
    --------
    >>> r = measure(lambda: sum(range(1000)), repeats=2, probe=lambda: 1.0)
    >>> len(r["runs"]), r["runs"][0]["probe_before"], r["min_s"] <= r["median_s"]
    (2, 1.0, True)
    """
    fn()
    times, runs = [], []
    for _ in range(repeats):
        reading = probe() if probe is not None else None
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if probe is not None:
            runs.append(
                {
                    "s": times[-1],
                    "probe_before": reading,
                    "probe_after": probe(),
                    "load_1min": round(os.getloadavg()[0], 2),
                }
            )
    peak = None
    gc.collect()
    _release_free_memory()
    if _reset_peak():
        before = _status_kb("VmRSS")
        fn()
        after = _status_kb("VmHWM")
        if before is not None and after is not None:
            peak = max(after - before, 0) / 1024
    out: dict[str, Any] = {
        "median_s": float(np.median(times)),
        "min_s": float(np.min(times)),
        "peak_mib": peak,
    }
    if probe is not None:
        out["runs"] = runs
    return out


def per_run_bound(record: dict[str, Any], flops: float, threads: int | None) -> dict[str, Any]:
    """A record of :func:`measure` with a matmul probe, each run set against its own bound.

    Each run's bound is ``flops`` at the higher of the two matmul rates measured around
    it (the stricter bound).

    Parameters
    ----------
    record : dict
        :func:`measure`'s result with ``runs`` (probe readings in FLOP/s).
    flops : float
        The stage's FLOPs (a U-Net's one pass over the image).
    threads : int or None
        Threads the stage ran on (recorded with each run).

    Returns
    -------
    dict
        ``record`` with, per run, ``bound_s``, ``ratio`` and ``threads``, and
        ``ratios`` (per run), ``ratio_median``, ``load_1min`` (per run).

    Examples
    --------
    >>> rec = {"runs": [{"s": 0.3, "probe_before": 1e9, "probe_after": 2e9, "load_1min": 4.0}]}
    >>> per_run_bound(rec, 1e8, 1)["ratios"]
    [6.0]
    """
    runs = []
    for run in record["runs"]:
        bound = flops / max(run["probe_before"], run["probe_after"])
        runs.append(run | {"bound_s": bound, "ratio": run["s"] / bound, "threads": threads})
    ratios = [round(r["ratio"], 3) for r in runs]
    return record | {
        "runs": runs,
        "ratios": ratios,
        "ratio_median": float(np.median(ratios)),
        "load_1min": [r["load_1min"] for r in runs],
    }


def _torch_threads() -> int | None:
    try:
        import torch
    except ImportError:
        return None
    return torch.get_num_threads()


MACHINE_FLAGS = (
    "sse4_2", "avx", "avx2", "fma", "avx512f", "avx512bw", "avx512_vnni", "avx_vnni",
    "amx_tile", "asimd", "sve",
)  # fmt: skip
"""CPU flags recorded with a benchmark: the ones that decide a code path (the forest kernel's
SIMD path, INT8 with or without VNNI, ONNX Runtime's kernels; ``asimd`` is NEON on aarch64)."""

MACHINE_LIBRARIES = (
    "numpy", "scipy", "torch", "scikit-learn", "onnxruntime", "onnx", "opencv-python-headless",
    "rasterio", "shapely", "dask", "pysteps", "tl2cgen", "treelite",
)  # fmt: skip
"""Libraries whose versions a benchmark records (those installed)."""


def _cpu_model_and_flags() -> tuple[str, list[str]]:
    model, flags = platform.processor() or platform.machine(), set()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                key = key.strip()
                if key in ("model name", "Model") and value.strip():
                    model = value.strip()
                elif key in ("flags", "Features"):
                    flags.update(value.split())
    except OSError:
        pass
    return model, [f for f in MACHINE_FLAGS if f in flags]


def _commit() -> str | None:
    """The git commit of the checkout dyntarget runs from (``+dirty`` with local changes)."""
    import subprocess

    here = os.path.dirname(os.path.abspath(__file__))
    try:
        head = subprocess.run(
            ["git", "-C", here, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
        dirty = subprocess.run(
            ["git", "-C", here, "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=10,
        )  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    if head.returncode != 0:
        return None  # an installed package, not a checkout
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def machine() -> dict[str, Any]:
    """The machine and code a benchmark ran on, as asv records them.

    Returns
    -------
    dict
        ``commit`` (``None`` outside a git checkout), ``platform``, ``cpu`` (model name),
        ``cpu_flags`` (those of :data:`MACHINE_FLAGS` present), ``cpus`` (cores this process
        may use), ``load_1min``, ``torch_threads``, ``openmp_spin_count`` (how long an
        OpenMP thread spins at a barrier, as the environment sets it:
        :func:`dyntarget.perceive.resources.openmp_spin_count`; it decides a U-Net pass's
        threads under load), ``python`` and ``versions`` (dyntarget, OpenCV and each
        installed one of :data:`MACHINE_LIBRARIES`).

    Examples
    --------
    >>> m = machine()
    >>> m["cpus"] >= 1 and "numpy" in m["versions"]
    True
    """
    import importlib.metadata

    import cv2

    import dyntarget

    versions: dict[str, str | None] = {
        "dyntarget": dyntarget.__version__,
        "opencv": cv2.__version__,
    }
    for dist in MACHINE_LIBRARIES:  # optional dependencies may be absent
        try:
            versions[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue
    cpu, flags = _cpu_model_and_flags()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "commit": _commit(),
        "platform": platform.platform(),
        "cpu": cpu,
        "cpu_flags": flags,
        "cpus": cores,
        "load_1min": round(os.getloadavg()[0], 2),
        "torch_threads": _torch_threads(),
        "openmp_spin_count": openmp_spin_count(),
        "python": platform.python_version(),
        "versions": versions,
    }


BENCH_BYTES_PER_PIXEL = 640
"""Estimated peak memory of one bench size per WFOV pixel: the synthetic scene
(:data:`~dyntarget.synth.volcano.SYNTH_BYTES_PER_PIXEL`) plus its utility maps,
probabilities and masks (a rough upper estimate, not a measurement)."""


def check_sizes(sizes: Sequence[int]) -> None:
    """Refuse bench sizes that are not integers >= 32, repeated, or too large for memory.

    Parameters
    ----------
    sizes : sequence of int
        WFOV sizes, px.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For an empty list or a size that is not an integer >= 32, repeated or
        too large for the memory available.

    Examples
    --------
    >>> check_sizes([64, 128])
    >>> check_sizes([64, 64])
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: sizes: 64 is listed twice; expected each size once
    """
    from dyntarget.synth.volcano import check_memory

    if not sizes:
        raise InvalidParameterError("sizes: expected at least one WFOV size")
    seen = set()
    for size in sizes:
        if isinstance(size, bool) or not isinstance(size, int) or size < 32:
            raise InvalidParameterError(
                f"sizes: each WFOV size must be an integer of at least 32 px, got {size!r}"
            )
        if size in seen:
            raise InvalidParameterError(f"sizes: {size} is listed twice; expected each size once")
        seen.add(size)
        check_memory("sizes", size, bytes_per_pixel=BENCH_BYTES_PER_PIXEL)


def parse_sizes(text: str) -> list[int]:
    """``"64,128"`` -> ``[64, 128]``, checked by :func:`check_sizes`.

    Parameters
    ----------
    text : str
        Comma-separated WFOV sizes, px.

    Returns
    -------
    list of int
        The sizes.

    Examples
    --------
    >>> parse_sizes("64, 128")
    [64, 128]
    >>> parse_sizes("a,b")
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: sizes: 'a' is not an integer; expected WFOV sizes like 128,256
    """
    sizes = []
    for token in text.split(","):
        token = token.strip()
        if not (token.isascii() and token.isdigit()):
            raise InvalidParameterError(
                f"sizes: {token!r} is not an integer; expected WFOV sizes like 128,256"
            )
        sizes.append(int(token))
    check_sizes(sizes)
    return sizes


def run_bench(
    *,
    sizes: Sequence[int] = DEFAULT_SIZES,
    classifiers: Sequence[str] | None = None,
    planners: Sequence[str] | None = None,
    repeats: int = 5,
    epochs: int = 2,
    progress: bool = True,
    variants: Sequence[str] = (),
) -> dict[str, Any]:
    """Time classify, denoise, plan and observe at each size; returns records and the machine.

    ``variants`` adds the same trained models run another way, as extra rows named
    ``"NAME (OPTION)"``: ``unet-uavsar:blend`` / ``unet-xception:blend`` (the former
    overlapping-tile stitching), ``random-forest:sklearn`` and ``random-forest:compiled``
    (the forest on scikit-learn, or on the compiled kernel, whatever the default picks).

    Parameters
    ----------
    sizes : sequence of int
        WFOV sizes, px.
    classifiers : sequence of str or None
        Classifiers to time (default: all registered).
    planners : sequence of str or None
        Planners to time (default: all registered).
    repeats : int
        Timed runs per measurement (at least 1).
    epochs : int
        Training epochs of the U-Nets timed.
    progress : bool
        Show a progress bar.
    variants : sequence of str
        Extra ways to run the trained models (see above).

    Returns
    -------
    dict
        ``machine``, ``repeats``, ``sizes``, ``records`` (one per stage, size,
        classifier and planner; a U-Net's classify record also holds ``runs``,
        ``ratios`` and ``ratio_median``: :func:`per_run_bound`, each run against the
        matmul rate measured around it), ``bounds`` (:func:`lower_bounds`), ``forest_path``
        (the random forest's path that ran: :func:`forest_path`; ``None`` without a
        random forest), ``forest_paths`` (the same per forest row, variants included)
        and ``cpu`` (:func:`cpu_summary`).
    """
    from tqdm import tqdm

    if repeats < 1:
        raise InvalidParameterError(f"repeats: expected a positive integer, got {repeats}")
    check_sizes(sizes)
    classifiers = list(classifiers or CLASSIFIERS.available())
    planners = list(planners or geometric_planners())
    # the machine's rates first, before any model has run: measured after the timed runs,
    # the matmul rate read 112 GFLOP/s against 155-182 in fresh processes (a bound too low)
    rates = machine_rates()
    train = [generate_scene(1, i, size=256)[0] for i in range(4)]
    models = {}
    for name in classifiers:
        kw = {"epochs": epochs} if CLASSIFIERS.get(name).kind == "unet" else {}
        models[name] = make_classifier(name, **kw).fit(train)
    for variant in variants:
        models[f"{variant.split(':')[0]} ({variant.split(':')[-1]})"] = _variant(models, variant)
    config = PipelineConfig()
    records: list[dict[str, Any]] = []
    bar = tqdm(total=len(sizes) * len(classifiers), desc="bench", disable=not progress)
    for size in sizes:
        scene = generate_scene(0, 0, size=size)[0]
        maps = UtilityMaps.from_scene(scene)
        for name, model in models.items():
            bar.set_postfix_str(f"{size} px: {name}")
            rec = {"size": size, "stage": "classify", "classifier": name, "planner": None}
            if model.kind == "unet":  # each run against a bound measured under its own load
                timed = measure(partial(classify, scene.image, model), repeats=repeats,
                                probe=lambda: matmul_rate()["flop_per_s"])  # fmt: skip
                flops = unet_flops(model, size)["one_pass"]
                rec |= per_run_bound(timed, flops, getattr(model, "threads_used", None))
            else:
                rec |= measure(partial(classify, scene.image, model), repeats=repeats)
            records.append(rec)
            # the pipeline's own stages, timed one by one (Algorithm 1 as plan_scene runs it)
            seg = segment(scene.image, probability=classify(scene.image, model), config=config)
            records.append(
                {"size": size, "stage": "denoise", "classifier": name, "planner": None}
                | measure(partial(clean, seg.raw_mask, config), repeats=repeats)
            )
            for pname in planners:
                traj = plan_segmentation(seg, pname, config)
                base = {"size": size, "classifier": name, "planner": pname, "pointings": len(traj)}
                records.append(
                    base
                    | {"stage": "plan"}
                    | measure(partial(plan_segmentation, seg, pname, config), repeats=repeats)
                )
                records.append(
                    base
                    | {"stage": "observe"}
                    | measure(partial(observe, traj, maps, factor=1), repeats=repeats)
                )
            bar.update()
    bar.close()
    paths = {n: forest_path(m) for n, m in models.items() if forest_path(m) is not None}
    return {
        "forest_path": paths.get("random-forest"),
        "forest_paths": paths,
        "cpu": cpu_summary(),
        "machine": machine(),
        "repeats": repeats,
        "sizes": list(sizes),
        "records": records,
        "bounds": lower_bounds(
            sizes, {n: m for n, m in models.items() if m.kind == "unet"}, rates=rates
        ),
    }


FOREST_CPU_FLAGS = ("avx512f", "avx2", "asimd")
"""CPU flags that decide the forest kernel's path (``asimd``: NEON on aarch64)."""


def forest_path(model: Any) -> str | None:
    """The path a random forest's predictions actually took, once it has predicted.

    Parameters
    ----------
    model : a classifier (anything but a random forest gives ``None``).

    Returns
    -------
    str or None
        The compiled kernel's path (``"avx512"``, ``"avx2"``, ``"sse2"``, ``"neon"``,
        ``"portable"``: what the loaded library reports), ``"onnxruntime"`` when ONNX
        Runtime's tree ensemble predicted (no kernel: off, absent or refused;
        :mod:`dyntarget.perceive.ensemble`), ``"sklearn"`` when scikit-learn predicted
        (asked for, or neither of the others could run), ``None`` for another
        classifier or a forest that has not predicted yet.

    Examples
    --------
    >>> from dyntarget.perceive import make_classifier
    >>> forest_path(make_classifier("band-threshold")) is None
    True
    """
    from dyntarget.perceive.pixel import RandomForest

    if not isinstance(model, RandomForest):
        return None
    if getattr(model, "backend", None) == "sklearn":
        return "sklearn"
    cached = getattr(model, "_compiled", None)
    if cached is None:
        return None
    return getattr(cached[1], "isa", None) or "sklearn"


def cpu_summary() -> dict[str, Any]:
    """The CPU's model name and the flags that decide the forest kernel's path.

    Returns
    -------
    dict
        ``model`` (``/proc/cpuinfo``'s model name, else the platform's), ``arch``
        (``platform.machine()``) and ``flags``: those of :data:`FOREST_CPU_FLAGS` present.

    Examples
    --------
    >>> c = cpu_summary()
    >>> sorted(c), set(c["flags"]) <= set(FOREST_CPU_FLAGS)
    (['arch', 'flags', 'model'], True)
    """
    model, _ = _cpu_model_and_flags()
    flags: set[str] = set()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() in ("flags", "Features"):
                    flags.update(value.split())
    except OSError:
        pass
    return {
        "model": model,
        "arch": platform.machine(),
        "flags": [f for f in FOREST_CPU_FLAGS if f in flags],
    }


def _variant(models: dict[str, Any], variant: str) -> Any:
    import copy

    base, _, option = variant.partition(":")
    if base not in models:
        raise InvalidParameterError(
            f"variants: {variant!r} names {base!r}, which is not among the benchmarked classifiers"
        )
    twin = copy.copy(models[base])
    if option == "blend" and hasattr(twin, "set_stitching"):
        return twin.set_stitching("blend")
    if option in ("compiled", "sklearn") and hasattr(twin, "set_backend"):
        twin.set_backend(option)
        twin.predict_proba(np.zeros((4, 32, 32), np.float32))  # compile before timing
        return twin
    raise InvalidParameterError(
        f"variants: expected unet-*:blend or random-forest:sklearn|compiled, got {variant!r}"
    )


def machine_rates() -> dict[str, float]:
    """Measured memory copy bandwidth (bytes/s, read + write) and float32 matmul rate (FLOP/s).

    Returns
    -------
    dict of str to float
        ``copy_bytes_per_s`` (best of 10 runs) and ``matmul_flop_per_s``
        (:func:`matmul_rate` with 10 runs per thread count).
    """
    src = np.ones(1 << 23)  # 64 MiB, far beyond any cache
    dst = np.empty_like(src)
    copy_s = min(_timed(lambda: np.copyto(dst, src)) for _ in range(10))
    mm = matmul_rate(repeats=10)["flop_per_s"]  # best of 10: the peak
    return {"copy_bytes_per_s": 2 * src.nbytes / copy_s, "matmul_flop_per_s": mm}


def matmul_rate(*, n: int = 2048, repeats: int = 3) -> dict[str, Any]:
    """The machine's float32 matrix-multiply rate now: best of ``repeats`` ``n``-square products.

    Measured on 1 thread and on every available core, and the higher taken: on a loaded
    machine one thread can outrun two that wait for each other (the stricter bound).

    Parameters
    ----------
    n : int
        Matrix side.
    repeats : int
        Products timed per thread count.

    Returns
    -------
    dict
        ``flop_per_s`` (the best) and ``by_threads`` (thread count as a string to FLOP/s).

    Examples
    --------
    >>> r = matmul_rate(n=64, repeats=1)
    >>> r["flop_per_s"] == max(r["by_threads"].values()) > 0
    True
    """
    import torch

    from dyntarget.perceive.resources import available_cores

    a, b = torch.randn(n, n), torch.randn(n, n)
    before = torch.get_num_threads()
    rates = {}
    try:
        for threads in sorted({1, available_cores()}):
            torch.set_num_threads(threads)
            best = min(_timed(lambda: torch.mm(a, b)) for _ in range(repeats))
            rates[str(threads)] = 2 * n**3 / best
    finally:
        torch.set_num_threads(before)
    return {"flop_per_s": max(rates.values()), "by_threads": rates}


def _timed(fn: Callable[[], Any]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def unet_flops(model: Any, size: int) -> dict[str, float]:
    """FLOPs of one U-Net pass over a ``size`` × ``size`` image without tile overlap, and as tiled.

    Counted on the network prediction runs (``inference_network()``): UNET-Xception's
    copy convolves its up stages' residuals before upsampling them, 13 % fewer FLOPs
    than the trained architecture's own forward pass, so its bound is the stricter one.

    Parameters
    ----------
    model : dyntarget.perceive.Classifier
        A fitted U-Net classifier.
    size : int
        Image side, px.

    Returns
    -------
    dict of str to float
        ``one_pass`` and ``tiled`` FLOPs.
    """
    import torch
    from torch.utils.flop_counter import FlopCounterMode

    tile = model.tile
    with FlopCounterMode(display=False) as counter, torch.inference_mode():
        model.inference_network()(torch.zeros(1, 4, tile, tile))
    per_tile = counter.get_total_flops()
    return {
        "one_pass": per_tile * size * size / tile**2,
        "tiled": per_tile * model.work_units((size, size)),  # the tiles the stitching runs
    }


def lower_bounds(
    sizes: Sequence[int], unets: dict[str, Any], rates: dict[str, float] | None = None
) -> dict[str, Any]:
    """Simple lower bounds on a stage's time at each size (see the module docstring).

    Parameters
    ----------
    sizes : sequence of int
        WFOV sizes, px.
    unets : dict
        Name to fitted U-Net classifier.
    rates : dict or None
        :func:`machine_rates` measured earlier (default: measured now).

    Returns
    -------
    dict
        ``rates`` (:func:`machine_rates`) and, per size (as a string), the time to
        read the image once (``read_image_s``) and each U-Net's :func:`unet_flops`
        with their times at the matmul rate.
    """
    rates = rates or machine_rates()
    out: dict[str, Any] = {"rates": rates, "sizes": {}}
    for size in sizes:
        entry: dict[str, Any] = {"read_image_s": 4 * 4 * size * size / rates["copy_bytes_per_s"]}
        for name, model in unets.items():
            flops = unet_flops(model, size)
            entry[name] = flops | {
                "one_pass_s": flops["one_pass"] / rates["matmul_flop_per_s"],
                "tiled_s": flops["tiled"] / rates["matmul_flop_per_s"],
            }
        out["sizes"][str(size)] = entry
    return out


def scaling_exponent(sizes: Sequence[int], seconds: Sequence[float]) -> float:
    """Slope of log(time) against log(pixels): 1.0 means cost grows linearly with the pixel count.

    Parameters
    ----------
    sizes : sequence of int
        Image sides, px.
    seconds : sequence of float
        Time at each size.

    Returns
    -------
    float
        The slope; NaN with fewer than two positive times.
    """
    px = np.asarray(sizes, float) ** 2
    t = np.asarray(seconds, float)
    ok = t > 0
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(px[ok]), np.log(t[ok]), 1)[0])


def summary_tables(result: dict[str, Any]) -> str:
    """Markdown: pipeline latency per classifier and size, stage breakdown, planners, scaling.

    Parameters
    ----------
    result : dict
        A :func:`run_bench` result.

    Returns
    -------
    str
        The Markdown tables.
    """
    from dyntarget.evaluate.tables import markdown_table

    recs = result["records"]
    sizes = result["sizes"]

    def get(stage, size, classifier=None, planner=None, key="median_s"):
        for r in recs:
            if (
                r["stage"] == stage
                and r["size"] == size
                and (classifier is None or r["classifier"] == classifier)
                and (planner is None or r["planner"] == planner)
            ):
                return r[key]
        return None

    classifiers = list(dict.fromkeys(r["classifier"] for r in recs))
    planners = list(dict.fromkeys(r["planner"] for r in recs if r["planner"]))
    ref_planner = "lawnmower-transect" if "lawnmower-transect" in planners else planners[0]
    measurable = len(sizes) >= 2  # a slope needs two sizes: no column otherwise
    rows = []
    for c in classifiers:
        row: dict[str, Any] = {"classifier": c}
        totals = []
        for s in sizes:
            total = get("classify", s, c) + get("denoise", s, c) + get("plan", s, c, ref_planner)
            totals.append(total)
            row[f"{s} px (s)"] = total
        exponent = scaling_exponent(sizes, totals)
        if measurable:
            row["scaling exponent"] = exponent if np.isfinite(exponent) else "n/a"
        peak = [get("classify", s, c, key="peak_mib") for s in sizes]
        row["classify peak MiB (largest)"] = peak[-1] if peak[-1] is not None else "n/a"
        rows.append(row)
    cols = [
        "classifier",
        *[f"{s} px (s)" for s in sizes],
        *(["scaling exponent"] if measurable else []),
        "classify peak MiB (largest)",
    ]
    parts = [
        f"Pipeline (classify + denoise + plan with {ref_planner}), median seconds per WFOV scene:\n",
        markdown_table(rows, cols),
    ]
    stage_rows = []
    for c in classifiers:
        for s in sizes:
            stage_rows.append(
                {
                    "classifier": c,
                    "size": s,
                    "classify (ms)": 1000 * get("classify", s, c),
                    "denoise (ms)": 1000 * get("denoise", s, c),
                    f"plan {ref_planner} (ms)": 1000 * get("plan", s, c, ref_planner),
                    "observe (ms)": 1000 * get("observe", s, c, ref_planner),
                }
            )
    parts += [
        "\nPer stage, milliseconds:\n",
        markdown_table(stage_rows, list(stage_rows[0]), digits=1),
    ]
    plan_rows = []
    for p in planners:
        row = {"planner": p}
        for s in sizes:
            vals = [
                r["median_s"]
                for r in recs
                if r["stage"] == "plan" and r["planner"] == p and r["size"] == s
            ]
            row[f"{s} px median / max (ms)"] = (
                f"{1000 * np.median(vals):.1f} / {1000 * np.max(vals):.1f}"
            )
        plan_rows.append(row)
    parts += [
        "\nPlanning alone, over the classifiers' masks (median / max over classifiers):\n",
        markdown_table(plan_rows, list(plan_rows[0])),
    ]
    bounds = result.get("bounds")
    if bounds:
        parts += ["\n", bounds_table(result, get)]
    return "".join(parts)


def bounds_table(result: dict[str, Any], get: Callable[..., Any]) -> str:
    """Markdown: each classifier's time against its lower bound, at the largest size.

    Parameters
    ----------
    result : dict
        A :func:`run_bench` result.
    get : callable
        ``get(stage, size, classifier)``: the measured median seconds of a record.

    Returns
    -------
    str
        The Markdown table.
    """
    from dyntarget.evaluate.tables import markdown_table

    bounds = result["bounds"]
    size = max(result["sizes"])
    entry = bounds["sizes"][str(size)]
    rates = bounds["rates"]
    rows = []
    for c in dict.fromkeys(r["classifier"] for r in result["records"]):
        measured = get("classify", size, c)
        if c in entry:
            bound, what = (
                entry[c]["one_pass_s"],
                f"{entry[c]['one_pass'] / 1e9:.1f} GFLOP one pass "
                f"({entry[c]['tiled'] / 1e9:.1f} as tiled) at the matmul rate",
            )
        else:
            bound, what = entry["read_image_s"], "read the image once"
        rec = next(
            r for r in result["records"]
            if r["stage"] == "classify" and r["size"] == size and r["classifier"] == c
        )  # fmt: skip
        ratios = rec.get("ratios")
        rows.append(
            {
                "classifier": c,
                "classify (ms)": 1000 * measured,
                "lower bound (ms)": 1000 * bound,
                "measured / bound": measured / bound,
                "per run, bound interleaved (median; runs)": (
                    f"{np.median(ratios):.2f}; " + ", ".join(f"{x:.2f}" for x in ratios)
                    if ratios
                    else "n/a"
                ),
                "bound": what,
            }
        )
    head = (
        f"Classification at {size} px against a lower bound (copy bandwidth "
        f"{rates['copy_bytes_per_s'] / 1e9:.1f} GB/s, float32 matmul "
        f"{rates['matmul_flop_per_s'] / 1e9:.0f} GFLOP/s, both measured at the start; "
        "per run: each U-Net classification against the matmul rate measured right "
        "before and after it):\n"
    )
    return head + markdown_table(rows, list(rows[0]), digits=1)
