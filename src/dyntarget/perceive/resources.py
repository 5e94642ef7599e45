"""Process-wide resources every inference path shares: the heap and the usable cores."""

from __future__ import annotations

import os


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
