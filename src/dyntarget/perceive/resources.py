"""Process-wide resources every inference path shares: the heap and the usable cores."""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping, MutableMapping


def keep_freed_memory(limit: int = 2**31 - 1) -> bool:
    """Let glibc's malloc keep large freed blocks for reuse (a process-wide setting).

    By default glibc maps every block above a threshold (at most 32 MiB) on its own
    and hands it back to the system when it is freed, so each large activation of a
    network is page-faulted in and zeroed again on every pass: at 1024 px, 40 % of
    UNET-Xception's time in PyTorch (docs/performance.md). Raising the mmap and trim
    thresholds to ``limit`` makes freed blocks stay in the heap for the next pass, as
    ONNX Runtime's own arena does; the process's resident memory then stays near its
    peak instead of shrinking between passes. The ``dyntarget`` command calls this at
    start; a program using the library can call it (or set the environment variables
    ``MALLOC_MMAP_THRESHOLD_`` and ``MALLOC_TRIM_THRESHOLD_``).

    Parameters
    ----------
    limit : int
        Bytes: blocks up to this size come from the heap and freed memory up to it is
        kept (default the largest value ``mallopt`` takes).

    Returns
    -------
    bool
        Whether both settings took (``False`` off glibc: macOS, Windows, musl).

    Examples
    --------
    >>> isinstance(keep_freed_memory(), bool)
    True
    """
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # <malloc.h>
    trim = mallopt(m_trim_threshold, int(limit)) == 1
    # some glibc versions refuse an mmap threshold above 32 MiB: keep that much, then
    mmap = mallopt(m_mmap_threshold, int(limit)) == 1 or mallopt(m_mmap_threshold, 32 << 20) == 1
    return trim and mmap


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity on Linux, else ``os.cpu_count()``).

    Every inference path sizes its one thread pool with this: PyTorch's intra-op
    threads, onnxruntime's intra-op threads and the pixel classifiers' chunk pool (whose
    chunks then run single-threaded inside), so no two pools multiply.

    Returns
    -------
    int
        At least 1.

    Examples
    --------
    >>> available_cores() >= 1
    True
    """
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _running_tasks() -> tuple[int, int] | None:
    """``(runnable tasks on the machine, runnable threads of this process)`` now (Linux)."""
    try:
        with open("/proc/stat", encoding="ascii") as fh:
            total = next(int(line.split()[1]) for line in fh if line.startswith("procs_running"))
        own = 0
        for task in os.listdir("/proc/self/task"):
            try:
                with open(f"/proc/self/task/{task}/stat", encoding="ascii", errors="replace") as fh:
                    stat = fh.read()
            except OSError:  # the thread ended meanwhile
                continue
            own += stat[stat.rindex(")") + 2 : stat.rindex(")") + 3] == "R"
    except (OSError, StopIteration, ValueError):
        return None
    return total, own


def busy_cores(samples: int = 5) -> int:
    """Cores other processes keep busy now: runnable tasks not of this process (median of samples).

    Read from the kernel's count of runnable tasks (``procs_running`` in ``/proc/stat``)
    less this process's own runnable threads, sampled ``samples`` times about a
    millisecond apart; 0 where it cannot be read (not Linux).

    Parameters
    ----------
    samples : int
        Readings (the median is returned).

    Returns
    -------
    int
        At least 0.

    Examples
    --------
    >>> busy_cores() >= 0
    True
    """
    import time

    counts = []
    for i in range(max(int(samples), 1)):
        now = _running_tasks()
        if now is None:
            return 0
        counts.append(max(now[0] - now[1], 0))
        if i + 1 < samples:
            time.sleep(0.001)
    return int(sorted(counts)[len(counts) // 2])


OPENMP_SPIN_COUNT = 10_000
"""Spins an OpenMP thread of PyTorch's waits at a barrier before it sleeps, as the
``dyntarget`` command sets it (:func:`bound_openmp_spin`): about 0.1 ms by libgomp's own
estimate of 100,000 spins a millisecond, against its default of 300,000 (3 ms); libgomp
says its estimate may be five times off either way, with the CPU."""


def _parse_spin_count(value: str) -> int | None:
    """``GOMP_SPINCOUNT`` as libgomp reads it (``None`` where it would not take it).

    ``strtoull`` then a suffix: an optional sign (a negative count wraps modulo 2**64),
    digits (a count beyond 2**64 - 1 is refused), an optional ``k``/``M``/``G``/``T``
    (powers of 1000, the product capped at 2**64 - 1); or ``infinite``/``infinity``.
    """
    import re

    most = 2**64 - 1
    if value.strip().lower() in ("infinite", "infinity"):
        return most
    match = re.fullmatch(r"\s*([+-]?)(\d+)\s*([kmgt]?)\s*", value, re.ASCII | re.IGNORECASE)
    if match is None or int(match[2]) > most:
        return None
    count = -int(match[2]) % 2**64 if match[1] == "-" else int(match[2])
    return min(count * 1000 ** " kmgt".index(match[3].lower() or " "), most)


def openmp_spin_count(environ: Mapping[str, str] | None = None) -> int:
    """How long libgomp's threads spin at a barrier before sleeping, as the environment says.

    libgomp (the OpenMP runtime of PyTorch's Linux wheels, x86-64 and aarch64) reads
    ``GOMP_SPINCOUNT`` (a count, with an optional ``k``/``M``/``G``/``T`` suffix, or
    ``infinite``) and else ``OMP_WAIT_POLICY``: ``PASSIVE`` sleeps at once,
    ``ACTIVE`` spins for good (30 billion spins), unset spins 300,000 times (about
    3 ms by libgomp's estimate). It reads them once, when it is loaded (with ``import torch``).

    Parameters
    ----------
    environ : mapping or None
        The environment to read (default ``os.environ``).

    Returns
    -------
    int
        Spins before a waiting thread sleeps.

    Examples
    --------
    >>> openmp_spin_count({})
    300000
    >>> openmp_spin_count({"OMP_WAIT_POLICY": "passive"})
    0
    >>> openmp_spin_count({"GOMP_SPINCOUNT": "10k", "OMP_WAIT_POLICY": "ACTIVE"})
    10000
    """
    env = os.environ if environ is None else environ
    spins = _parse_spin_count(env.get("GOMP_SPINCOUNT", ""))
    if spins is not None:
        return spins
    policy = env.get("OMP_WAIT_POLICY", "").strip().upper()
    return {"PASSIVE": 0, "ACTIVE": 30_000_000_000}.get(policy, 300_000)


def bound_openmp_spin(environ: MutableMapping[str, str] | None = None) -> bool:
    """Let PyTorch's OpenMP threads sleep soon when they wait at a barrier (a process-wide setting).

    A U-Net pass runs some hundred parallel regions, each ending at a barrier. Under
    libgomp's default a thread that reaches it first spins (300,000 spins, about 3 ms by
    libgomp's estimate); when other processes share the cores it spins on a core its
    partner thread needed, so on this 2-core machine with every core shared UNET-Xception
    ran 3.8-4.2x its FLOP bound on 1 thread and up to 7x on 2 (docs/performance.md).
    With :data:`OPENMP_SPIN_COUNT` spins it sleeps 30 times sooner and hands the core
    back: both cores then run the pass under the loads measured (up to four other
    single-threaded processes on two cores; :func:`inference_threads`), with no cost
    measured on a quiet machine. Sets ``GOMP_SPINCOUNT`` unless the environment already says how OpenMP
    threads wait (``GOMP_SPINCOUNT`` or ``OMP_WAIT_POLICY``: the user's choice wins) or
    torch is already imported (its OpenMP runtime read the environment when it loaded).
    The ``dyntarget`` command calls this at start; the processes it starts inherit it
    (Dask's local workers among them; workers started elsewhere, ``--scheduler
    tcp://...``, do not, and keep the load rule of :func:`inference_threads`).

    Parameters
    ----------
    environ : mutable mapping or None
        The environment to set it in (default ``os.environ``, the one torch reads).

    Returns
    -------
    bool
        Whether this call set it.

    Examples
    --------
    >>> env = {"OMP_WAIT_POLICY": "ACTIVE"}  # the user's choice
    >>> bound_openmp_spin(env), env
    (False, {'OMP_WAIT_POLICY': 'ACTIVE'})
    """
    import sys

    env = os.environ if environ is None else environ
    if "torch" in sys.modules or {"GOMP_SPINCOUNT", "OMP_WAIT_POLICY"} & set(env):
        return False
    env["GOMP_SPINCOUNT"] = str(OPENMP_SPIN_COUNT)
    return True


def _libgomp_runs_torch() -> bool:
    """Whether the loaded torch runs on GNU libgomp alone (Linux: the process's mapped files).

    PyTorch's Linux wheels use libgomp; other builds (macOS, Windows, conda with Intel's
    or LLVM's runtime) read neither ``GOMP_SPINCOUNT`` nor its default. Read once, after
    torch has loaded its runtime (every U-Net pass asks).
    """
    import sys

    return "torch" in sys.modules and _maps_show_libgomp_alone()


@functools.cache
def _maps_show_libgomp_alone() -> bool:
    try:
        with open("/proc/self/maps", encoding="ascii", errors="replace") as fh:
            maps = fh.read()
    except OSError:
        return False
    return "libgomp" in maps and "libiomp" not in maps and "libomp." not in maps


def inference_threads(limit: int | None = None) -> int:
    """Intra-op threads for one network pass: every core, or those other processes leave free.

    Where OpenMP's waiting threads sleep soon (a spin count of at most
    :data:`OPENMP_SPIN_COUNT`, :func:`openmp_spin_count`, read by GNU libgomp, the
    runtime of PyTorch's Linux wheels; the ``dyntarget`` command sets it,
    :func:`bound_openmp_spin`) a pass runs on every core whatever the load: a
    thread that waits at a barrier gives its core back, and two threads sharing the
    cores with other processes get more of them than one. Otherwise the rule of
    OpenMP's dynamic adjustment (libgomp's ``OMP_DYNAMIC``: the online cores less the
    load), with the load read as it is now (:func:`busy_cores`) rather than as a
    minutes-long average, which would count this process's own past work: a pass of a
    U-Net runs some hundred parallel regions, each ending at a barrier that waits for
    its slowest thread, and a thread spinning there for milliseconds keeps its partner
    off the core (docs/performance.md). On a quiet machine both rules give
    :func:`available_cores`.

    Parameters
    ----------
    limit : int or None
        Upper bound (e.g. ``torch.get_num_threads()``, a caller's own setting).

    Returns
    -------
    int
        Between 1 and ``min(limit, available_cores())``.

    Examples
    --------
    >>> 1 <= inference_threads() <= available_cores()
    True
    >>> inference_threads(limit=1)
    1
    """
    cores = available_cores() if limit is None else min(available_cores(), int(limit))
    if openmp_spin_count() <= OPENMP_SPIN_COUNT and _libgomp_runs_torch():
        return max(1, cores)
    return max(1, min(cores, available_cores() - busy_cores()))
