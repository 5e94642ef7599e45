"""Run an evaluation's independent tasks here or on ``dask.distributed``; stream and resume.

Every evaluation (classification folds, end-to-end scenes, planning scenes,
sweep points) is a list of independent tasks, each a pure function of its
inputs returning a JSON-serialisable result. :func:`run_tasks` runs them

* ``scheduler=None``: one after another in this process (the default);
* ``"local"``: on a ``LocalCluster`` of threads in this process (one per core);
* ``"processes"``: on a ``LocalCluster`` of one single-threaded worker process per core;
* ``"tcp://HOST:PORT"`` (any scheduler address): on an existing cluster.

Inputs every task needs (the scenes, the configuration) are passed as
``shared`` keyword arguments: on a cluster they are scattered once to every
worker rather than sent with each task. Each finished task's result is written
at once, atomically, to ``parts/<key>.json``; a rerun loads those instead of
running the tasks again, so an interrupted evaluation resumes where it stopped
and the assembled result is identical whatever the completion order. A task's
key must change whenever anything that determines its result changes
(:func:`task_key` hashes whatever it is given).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from tqdm import tqdm

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.io.atomic import write_text
from dyntarget.perceive.base import TRAIN_THREADS

T = TypeVar("T")


class Interrupted(Exception):
    """Raised by ``stop_after`` (tests simulate a killed run with it)."""


def task_key(*parts: Any) -> str:
    """A stable hex key for a task from JSON-able parts and numpy arrays (hashed by content).

    Parameters
    ----------
    *parts : object
        JSON-able values (others by their ``str``) and numpy arrays.

    Returns
    -------
    str
        24 hexadecimal digits (SHA-1).
    """
    h = hashlib.sha1(usedforsecurity=False)
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(repr((part.dtype.str, part.shape)).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(json.dumps(part, sort_keys=True, default=str).encode())
        h.update(b"\0")
    return h.hexdigest()[:24]


@contextmanager
def dask_client(scheduler: str) -> Iterator[Any]:
    """A ``distributed.Client`` for ``local``, ``processes`` or a scheduler address.

    Parameters
    ----------
    scheduler : str
        ``"local"`` (one worker, a thread per core), ``"processes"`` (a worker
        process per core) or a scheduler address.

    Yields
    ------
    distributed.Client
        The client, closed (with its local cluster) on exit.
    """
    from distributed import Client, LocalCluster

    cores = os.cpu_count() or 1
    if scheduler == "local":
        cluster = LocalCluster(
            n_workers=1, threads_per_worker=cores, processes=False, dashboard_address=":0"
        )
    elif scheduler == "processes":
        cluster = LocalCluster(
            n_workers=cores,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=":0",
        )
    else:
        check_scheduler(scheduler)
        cluster = None
    try:
        if cluster is None:
            try:
                client = Client(scheduler, timeout=10)
            except OSError as exc:
                raise InvalidParameterError(
                    f"scheduler: cannot reach {scheduler} ({exc})"
                ) from None
        else:
            client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


def check_unique(argument: str, names: Sequence[str]) -> None:
    """Refuse a list that names something twice (each would be one task: two tasks, one key).

    Parameters
    ----------
    argument : str
        The list's name, for the error message.
    names : sequence of str
        The list.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When a name is repeated.

    Examples
    --------
    >>> check_unique("classifiers", ["mlp", "naive-bayes"])
    >>> check_unique("classifiers", ["mlp", "mlp"])
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: classifiers: 'mlp' is listed twice; expected each name once
    """
    seen: set = set()
    for name in names:
        if name in seen:
            raise InvalidParameterError(
                f"{argument}: {name!r} is listed twice; expected each name once"
            )
        seen.add(name)


def check_scheduler(scheduler: str | None) -> None:
    """Refuse a malformed scheduler before any work starts.

    Parameters
    ----------
    scheduler : str or None
        ``None``, ``"local"``, ``"processes"`` or an address with ``://``.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For anything else.
    """
    if scheduler is not None and scheduler not in ("local", "processes") and "://" not in scheduler:
        raise InvalidParameterError(
            f"scheduler: expected local, processes or a scheduler address, got {scheduler!r}"
        )


PART_FORMAT = "dyntarget-part"
SETTINGS = {"torch_train_threads": TRAIN_THREADS}
"""Process settings a task's result depends on; recorded in every part, a part made
under other settings is run again."""


def _digest(result_text: str) -> str:
    return hashlib.sha256(result_text.encode("utf-8")).hexdigest()


def _part_text(key: str, result: Any) -> str:
    """A part file: the result with its key, the settings and a checksum of the result."""
    text = json.dumps(result, sort_keys=True)
    doc = {
        "format": PART_FORMAT,
        "key": key,
        "settings": SETTINGS,
        "sha256": _digest(text),
        "result": result,
    }
    return json.dumps(doc, sort_keys=True) + "\n"


def _load_part(path: Path, key: str) -> Any:
    """The result kept in ``path``, or ``None`` (run the task again) when the file is
    unreadable, not a part, another task's, made under other settings, or does not
    match its checksum (edited, truncated, hand-made)."""
    try:
        from dyntarget.io.safeopen import read_json

        doc = read_json(path, max_bytes=1 << 30)  # a FIFO or a device is not a part
    except (OSError, ValueError, RecursionError):
        return None
    if (
        not isinstance(doc, dict)
        or doc.get("format") != PART_FORMAT
        or doc.get("key") != key
        or doc.get("settings") != SETTINGS
        or "result" not in doc
    ):
        return None
    if doc.get("sha256") != _digest(json.dumps(doc["result"], sort_keys=True)):
        return None
    return doc["result"]


def _free_part_slot(path: Path) -> None:
    """Make room for a part: an empty directory in its place goes; anything else is refused."""
    if path.is_dir() and not path.is_symlink():
        try:
            path.rmdir()
        except OSError:
            raise DataFileError(
                f"{path}: a directory holding files where a resume part belongs; "
                "remove it or choose another output folder"
            ) from None


def run_tasks(
    fn: Callable[..., Any],
    tasks: Sequence[T],
    *,
    key: Callable[[T], str],
    parts: Path | None = None,
    scheduler: str | None = None,
    shared: dict[str, Any] | None = None,
    progress: bool = True,
    desc: str = "tasks",
    stop_after: int | None = None,
) -> list[Any]:
    """``[fn(task, **shared) for task in tasks]``, resumable and optionally on Dask.

    Results come back in task order. With ``parts``, finished results are kept
    as ``parts/<key(task)>.json`` and reused on the next call.

    Parameters
    ----------
    fn : callable
        ``fn(task, **shared)``, JSON-able result.
    tasks : sequence
        The tasks.
    key : callable
        ``key(task)``: a unique file-name-safe key per task.
    parts : pathlib.Path or None
        Folder of finished results.
    scheduler : str or None
        ``None`` (in process), ``"local"``, ``"processes"`` or a Dask scheduler address.
    shared : dict or None
        Keyword arguments passed to every call.
    progress : bool
        Show a progress bar.
    desc : str
        The progress bar's label.
    stop_after : int or None
        Raise :class:`Interrupted` after this many finished tasks (tests).

    Returns
    -------
    list
        The results, in task order.
    """
    check_scheduler(scheduler)
    shared = shared or {}
    keys = [key(t) for t in tasks]
    if len(set(keys)) != len(keys):
        raise InvalidParameterError(
            "tasks: two tasks share a key (the same task listed twice?); expected each task once"
        )
    results: dict[str, Any] = {}
    if parts is not None:  # created only when the first part is written
        if parts.exists() and not parts.is_dir():
            raise DataFileError(f"{parts}: a file where the folder of resume parts belongs")
        for k in keys:
            f = parts / f"{k}.json"
            _free_part_slot(f)
            if f.is_file() and (loaded := _load_part(f, k)) is not None:
                results[k] = loaded
    todo = [(k, t) for k, t in zip(keys, tasks, strict=True) if k not in results]
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc=desc, disable=not progress)
    done = 0

    def finish(k: str, result: Any) -> None:
        nonlocal done
        text = json.dumps(result)
        if parts is not None:
            write_text(parts / f"{k}.json", _part_text(k, result))
        results[k] = json.loads(text)  # the same types as a resumed result
        bar.update()
        done += 1
        if stop_after is not None and done >= stop_after:
            raise Interrupted(f"stopped after {done} task(s)")

    try:
        if todo and scheduler is None:
            for k, t in todo:
                finish(k, fn(t, **shared))
        elif todo and scheduler is not None:
            from distributed import as_completed

            with dask_client(scheduler) as client:
                remote = {
                    name: client.scatter([value], broadcast=True)[0]
                    for name, value in shared.items()
                }
                futures = client.map(fn, [t for _, t in todo], pure=False, **remote)
                key_of = {f.key: k for f, (k, _) in zip(futures, todo, strict=True)}
                try:
                    for fut in as_completed(futures):
                        finish(key_of[fut.key], fut.result())
                except BaseException:
                    client.cancel(futures)
                    raise
    finally:
        bar.close()
    return [results[k] for k in keys]
