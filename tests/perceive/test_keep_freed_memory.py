"""keep_freed_memory: a freed 64 MiB block stays in the heap for reuse (glibc only).

Each check runs in a fresh interpreter, since the setting is process-wide. The evidence
is glibc's own account (``mallinfo2``): the bytes free inside the heap after the block is
freed, which is what a later allocation of that size is served from.
"""

from __future__ import annotations

import ctypes
import subprocess
import sys

import pytest

SCRIPT = """
import ctypes, sys
import numpy as np
from dyntarget.perceive.resources import keep_freed_memory

class Info(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]

mallinfo2 = ctypes.CDLL(None).mallinfo2
mallinfo2.restype = Info
took = keep_freed_memory() if sys.argv[1] == "keep" else None
block = np.ones(64 << 20, np.uint8)
mapped = mallinfo2().hblkhd  # bytes in blocks mapped on their own
del block
print(took, mapped >= 64 << 20, mallinfo2().fordblks >= 64 << 20)
"""


def _run(mode: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, check=True
    )
    return done.stdout.split()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc only")
def test_a_freed_large_block_stays_in_the_heap_only_when_asked():
    if not hasattr(ctypes.CDLL(None), "mallinfo2"):
        pytest.skip("no mallinfo2 (glibc < 2.33 or not glibc)")
    took, mapped, kept = _run("keep")
    assert (took, mapped, kept) == ("True", "False", "True")  # heap block, kept when freed
    took, mapped, kept = _run("default")
    assert (took, mapped, kept) == ("None", "True", "False")  # mapped alone, handed back


def test_the_command_sets_it_before_running(monkeypatch, capsys):
    from dyntarget import cli
    from dyntarget.perceive import resources

    calls = []
    monkeypatch.setattr(resources, "keep_freed_memory", lambda: calls.append(True) or True)
    assert cli.main(["planners"]) == 0
    assert calls == [True]
    assert cli.main(["--help"]) == 0  # argparse exits first: nothing set
    assert calls == [True]
