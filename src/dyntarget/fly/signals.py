"""Stop a long-lived loop cleanly on SIGINT/SIGTERM: finish the frame in hand, write, return."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


class StopFlag(threading.Event):
    """An event that also remembers which signals set it (``caught``)."""

    def __init__(self) -> None:
        super().__init__()
        self.caught: list[int] = []


@contextlib.contextmanager
def stop_on_signals() -> Iterator[StopFlag]:
    """A :class:`StopFlag` set by SIGINT/SIGTERM while inside (the old handlers restored after).

    The loop polls it between frames, so the frame in hand is finished and its
    outputs written before the loop returns.

    Returns
    -------
    a context manager yielding the flag.

    Examples
    --------
    >>> import os
    >>> with stop_on_signals() as stop:
    ...     os.kill(os.getpid(), signal.SIGTERM)
    ...     stop.wait(5)
    True
    >>> stop.caught == [signal.SIGTERM]
    True
    """
    stop = StopFlag()

    def handler(signum, _frame):
        stop.caught.append(signum)
        stop.set()

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in old.items():
            signal.signal(s, h)
