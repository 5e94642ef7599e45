"""U-Net prediction on every core where OpenMP's waiting threads sleep soon (else on the cores
other processes leave free), and in one pass where it fits."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from dyntarget.perceive import make_classifier, resources
from dyntarget.perceive.resources import (
    available_cores,
    busy_cores,
    inference_threads,
    openmp_spin_count,
)
from dyntarget.perceive.unet import Stitching


def test_inference_threads_never_exceeds_the_limit_nor_the_cores():
    assert inference_threads(limit=1) == 1
    assert 1 <= inference_threads() <= available_cores()


@pytest.mark.slow
def test_other_busy_processes_leave_one_thread(monkeypatch):
    # libgomp's default wait (3 ms of spinning): the load rule
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    # as many spinning processes as cores: none is free, so one thread (never zero)
    code = "while True: pass"
    spinners = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(available_cores())]
    try:
        time.sleep(0.5)
        assert busy_cores() >= available_cores()
        assert inference_threads() == 1
    finally:
        for p in spinners:
            p.kill()
            p.wait()


@pytest.mark.parametrize(
    ("environ", "spins"),
    [
        # libgomp's manual: unset waits 300,000 spins, PASSIVE none, ACTIVE 30 billion;
        # GOMP_SPINCOUNT takes a count with k/M/G/T (powers of 1000) or "infinite", and
        # overrides the policy; a value it cannot read is ignored
        ({}, 300_000),
        ({"OMP_WAIT_POLICY": "passive"}, 0),
        ({"OMP_WAIT_POLICY": " ACTIVE "}, 30_000_000_000),
        ({"OMP_WAIT_POLICY": "sometimes"}, 300_000),
        ({"GOMP_SPINCOUNT": "10000"}, 10_000),
        ({"GOMP_SPINCOUNT": "2 k", "OMP_WAIT_POLICY": "ACTIVE"}, 2_000),
        ({"GOMP_SPINCOUNT": "3M"}, 3_000_000),
        ({"GOMP_SPINCOUNT": "1t"}, 10**12),
        ({"GOMP_SPINCOUNT": "Infinity"}, 2**64 - 1),
        ({"GOMP_SPINCOUNT": "ten", "OMP_WAIT_POLICY": "PASSIVE"}, 0),
        ({"GOMP_SPINCOUNT": "5x"}, 300_000),
        ({"GOMP_SPINCOUNT": "\u00b2"}, 300_000),  # a digit to Python, not to strtoull
        # strtoull: a sign is read, a negative count wraps modulo 2**64, a count beyond
        # 2**64 - 1 is refused; a suffix's product is capped at 2**64 - 1
        ({"GOMP_SPINCOUNT": "+5000"}, 5_000),
        ({"GOMP_SPINCOUNT": "-1"}, 2**64 - 1),
        ({"GOMP_SPINCOUNT": "18446744073709551616"}, 300_000),
        ({"GOMP_SPINCOUNT": "18446744073709551615"}, 2**64 - 1),
        ({"GOMP_SPINCOUNT": "1000000000T"}, 2**64 - 1),
    ],
)
def test_openmp_spin_count_reads_the_environment_as_libgomp_does(environ, spins):
    assert openmp_spin_count(environ) == spins


def test_a_bounded_spin_under_libgomp_gives_a_pass_every_core_whatever_the_load(monkeypatch):
    # four cores, every one kept busy by other processes; GNU libgomp runs torch
    monkeypatch.setattr(resources, "available_cores", lambda: 4)
    monkeypatch.setattr(resources, "_libgomp_runs_torch", lambda: True)
    monkeypatch.setattr(resources, "busy_cores", lambda samples=5: 4)
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    assert inference_threads() == 1  # 3 ms spins: the cores the load leaves free
    monkeypatch.setenv("GOMP_SPINCOUNT", "10000")
    assert inference_threads() == 4
    assert inference_threads(limit=3) == 3
    monkeypatch.setenv("GOMP_SPINCOUNT", "10001")  # just above the bound: the load rule
    assert inference_threads() == 1
    monkeypatch.delenv("GOMP_SPINCOUNT")
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    assert inference_threads() == 4
    monkeypatch.setattr(resources, "_libgomp_runs_torch", lambda: False)
    assert inference_threads() == 1  # another OpenMP runtime reads neither: the load rule
    monkeypatch.setattr(resources, "_libgomp_runs_torch", lambda: True)
    monkeypatch.setattr(resources, "busy_cores", lambda samples=5: 1)
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    assert inference_threads() == 3


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PyTorch's Linux wheels")
def test_this_torch_runs_on_gnu_libgomp():
    # the wheels the README installs (torch==2.13.0+cpu) bring libgomp: the bound takes
    import torch

    assert torch.ones(64).sum().item() == 64.0
    assert resources._libgomp_runs_torch()
    assert "OpenMP" in torch.__config__.parallel_info()


def _display_openmp_env(code: str, **env: str) -> str:
    """libgomp's own report of its settings (``OMP_DISPLAY_ENV``) in a fresh interpreter."""
    import os

    clean = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    done = subprocess.run(
        [sys.executable, "-c", code],
        env={**clean, "OMP_DISPLAY_ENV": "VERBOSE", **env},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


def test_the_dyntarget_command_bounds_the_spin_of_the_torch_it_loads():
    # the command sets it before torch loads, and torch's libgomp says it took it
    code = (
        "from dyntarget.cli import main\n"
        "assert main(['classifiers']) == 0\n"
        "import torch\n"
        "torch.ones(8).sum()\n"
    )
    report = _display_openmp_env(code)
    # every OpenMP runtime loaded (torch's, and any other library's copy) took it
    loaded = report.count("OPENMP DISPLAY ENVIRONMENT BEGIN")
    assert loaded >= 1 and report.count("GOMP_SPINCOUNT = '10000'") == loaded


@pytest.mark.slow
def test_the_user_s_openmp_setting_and_an_early_torch_are_left_alone():
    code = (
        "import os, sys\n"
        "{pre}"
        "from dyntarget.perceive.resources import bound_openmp_spin\n"
        "print('set', bound_openmp_spin(), os.environ.get('GOMP_SPINCOUNT'))\n"
        "import torch\n"
    )
    active = _display_openmp_env(code.format(pre=""), OMP_WAIT_POLICY="ACTIVE")
    assert "set False None" in active and "GOMP_SPINCOUNT = '30000000000'" in active
    early = _display_openmp_env(code.format(pre="import torch\n"))
    assert "set False None" in early and "GOMP_SPINCOUNT = '300000'" in early


_THREADS_CODE = """
import numpy as np
from dyntarget.perceive import make_classifier, resources
model = make_classifier({name!r}, width=4, tile=32)
model.model.eval()
model.fitted = True
image = np.random.default_rng(0).random((4, 96, 80), dtype=np.float32)
got = []
for t in (1, 2):
    resources.inference_threads = lambda limit=None, t=t: t
    got.append(model.predict_proba(image))
    assert model.threads_used == t
d = np.abs(got[0] - got[1])
print(float(d.max()), float(np.spacing(np.float32(1.0))), bool(((got[0] > 0.5) == (got[1] > 0.5)).all()))
"""


def _on_1_and_2_threads(name: str, **env: str) -> tuple[float, float, bool]:
    """Largest difference of the probabilities on 1 and 2 threads, float32's epsilon, and
    whether the masks at 0.5 agree, in a fresh interpreter (``env``: e.g. oneDNN's ISA)."""
    import os

    done = subprocess.run(
        [sys.executable, "-c", _THREADS_CODE.format(name=name)],
        env={**os.environ, **env}, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    diff, eps, same = done.stdout.split()
    return float(diff), float(eps), same == "True"


@pytest.mark.parametrize("isa", ["native", "AVX2"])
@pytest.mark.parametrize("name", ["unet-uavsar", "unet-xception"])
def test_probabilities_on_1_and_2_threads_agree_to_an_ulp(name, isa):
    # The load picks the thread count. With AVX-512 (the Intel Xeon the docs measured on)
    # the probabilities were equal bit for bit; with oneDNN's AVX2 kernels (an AMD EPYC
    # without AVX-512, or any x86 CPU with ONEDNN_MAX_CPU_ISA=AVX2, forced here)
    # unet-uavsar's head convolution splits its sums by thread and differs by up to one
    # float32 step (6e-8 near 0.6) on about 0.01 % of pixels. Checked: at most an ulp at
    # 1.0, and the same masks at 0.5 here (a probability within an ulp of 0.5 could flip).
    env = {} if isa == "native" else {"ONEDNN_MAX_CPU_ISA": isa}
    diff, eps, same_mask = _on_1_and_2_threads(name, **env)
    assert diff <= eps and same_mask


def test_width_16_models_predict_1024_px_in_one_pass_and_2048_in_windows():
    for name in ("unet-uavsar", "unet-xception"):
        st = make_classifier(name).stitching()
        assert len(st.windows((1024, 1024))) == 1
    # Xception: 4 * (4 * 16 + 32) = 384 B/px; 2048**2 px * 384 B = 1536 MiB > 1024 MiB
    xception = make_classifier("unet-xception").stitching()
    assert xception.bytes_per_pixel == 384.0
    assert len(xception.windows((2048, 2048))) > 1
    # ONNX Runtime's estimate (the sum of every layer's output) is unchanged
    onnx = Stitching.for_architecture("xception", levels=4, width=16, tile=64)
    assert onnx.bytes_per_pixel == 4 * (20.0 * 16 + 8)


PEAK_SCRIPT = """
import gc, ctypes, sys
import numpy as np
from dyntarget.perceive import make_classifier
name, width, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
model = make_classifier(name, width=width)
model.model.eval()
model.fitted = True
model.set_stitching("halo", memory_mib=1e6)
image = np.random.default_rng(0).random((4, size, size), dtype=np.float32)
model.predict_proba(image)
def kb(field):
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1])
gc.collect()
ctypes.CDLL("libc.so.6").malloc_trim(0)
open("/proc/self/clear_refs", "w").write("5")
start = kb("VmRSS")
model.predict_proba(image)
print((kb("VmHWM") - start) * 1024 / size**2, model.stitching().bytes_per_pixel)
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("name", ["unet-uavsar", "unet-xception"])
@pytest.mark.parametrize("width", [8, 16])
def test_peak_estimate_bounds_the_measured_peak_of_one_pass(name, width):
    # a fresh process: the resident high-water mark of one 512 px pass above its start
    out = subprocess.run(
        [sys.executable, "-c", PEAK_SCRIPT, name, str(width), "512"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    measured, estimate = map(float, out.stdout.split())
    assert measured <= estimate
    assert measured >= 0.25 * estimate  # an estimate, not a blanket allowance
