"""Model directories: write one, read and check its ``metadata.json``, load any classifier.

A saved model is a directory::

    model/
      metadata.json     format, classifier name, dyntarget version, band order, config, training
      model.skops | model.safetensors | params.json
      model.onnx, forest.npz, model.int8.onnx   (after ``dyntarget export-onnx``)

Loading checks the metadata before touching the weights and never unpickles.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dyntarget.errors import DataFileError, InvalidParameterError, ModelFileError
from dyntarget.perceive.names import CLASSIFIERS
from dyntarget.scene import BANDS

if TYPE_CHECKING:
    from dyntarget.perceive.base import Classifier

TRUST_ENV = "DYNTARGET_TRUST_WRITABLE_MODELS"
"""Set to ``1`` to load a model that other users can change (:func:`check_model_permissions`);
``0`` or unset: refused."""

MODEL_FILES = ("metadata.json", "model.skops", "model.safetensors", "params.json",
               "model.onnx", "model.int8.onnx", "forest.npz", "forest.json",
               "forest.onnx")  # fmt: skip
"""The files of a model directory that are read (each checked like the directory)."""

MODEL_FORMAT = "dyntarget-model"
MODEL_FORMAT_VERSION = 1
METADATA = "metadata.json"


def write_model_dir(classifier: Classifier, path: str | os.PathLike[str]) -> Path:
    """Write ``classifier``'s model directory ``path`` (replacing it atomically).

    Parameters
    ----------
    classifier : Classifier
        A fitted classifier.
    path : str or os.PathLike
        The model directory: free, an empty folder, or a model directory of ours.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    if not classifier.fitted:
        raise InvalidParameterError(
            f"{classifier.name}: nothing to save, the classifier is not fitted"
        )
    from dyntarget import __version__
    from dyntarget.io.outputs import check_model_dir

    path = check_model_dir(path)  # never replaces anything but a model directory of ours
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        classifier._save_weights(tmp)
        meta = {
            "format": MODEL_FORMAT,
            "format_version": MODEL_FORMAT_VERSION,
            "classifier": classifier.name,
            "dyntarget_version": __version__,
            "bands": list(BANDS),
            "config": classifier.get_config(),
            "training": classifier.training,
        }
        (tmp / METADATA).write_text(json.dumps(meta, indent=2, sort_keys=True), encoding="utf-8")
        for item in [tmp, *tmp.iterdir()]:  # writable by its user alone, whatever the umask:
            mode = stat.S_IMODE(item.lstat().st_mode)  # a model others can change is refused
            if not item.is_symlink() and mode & 0o022:
                item.chmod(mode & ~0o022)
        if path.exists():
            old = path.with_name(f".{path.name}.old-{os.getpid()}")
            path.rename(old)
            tmp.rename(path)
            shutil.rmtree(old)
        else:
            tmp.rename(path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def trust_writable_models() -> bool:
    """Whether :data:`TRUST_ENV` lets models that others can change load (``1``; ``0``/unset: no).

    Returns
    -------
    bool
        ``True`` when the variable is ``1``.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        Any other value (one line naming the allowed ones).

    Examples
    --------
    >>> trust_writable_models() if TRUST_ENV not in os.environ else False
    False
    """
    value = os.environ.get(TRUST_ENV, "").strip()
    if value not in ("", "0", "1"):
        raise InvalidParameterError(f"{TRUST_ENV}={value!r}: expected 0 or 1")
    return value == "1"


def _others_can_change(st: os.stat_result, *, ancestor: bool) -> str | None:
    """Why another user can change a file or folder of this ``stat`` (``None``: none can)."""
    from dyntarget.perceive.compiled import _private_group

    if st.st_uid not in (os.getuid(), 0):
        return f"owned by another user (uid {st.st_uid})"
    if ancestor and stat.S_ISDIR(st.st_mode) and st.st_mode & stat.S_ISVTX:
        return None  # a sticky shared folder (/tmp): others cannot rename what is ours
    mode = stat.S_IMODE(st.st_mode)
    if mode & 0o002:
        return f"writable by others (mode {mode:o})"
    if mode & 0o020 and not _private_group(st.st_gid):
        return f"writable by its group (mode {mode:o}, gid {st.st_gid})"
    return None


def check_model_permissions(path: str | os.PathLike[str]) -> None:
    """Refuse a model that another user can change: a model is data others must not swap.

    The model directory, each of its :data:`MODEL_FILES` that is there, and every folder
    above it must be owned by this user or root and writable by no one else (group
    write is allowed for this user's own private group); a sticky folder above the model's
    own (``/tmp``) is fine. Not checked where the OS has no user ids, or when
    :data:`TRUST_ENV` is ``1``.

    Parameters
    ----------
    path : path
        The model directory.

    Raises
    ------
    dyntarget.errors.ModelFileError
        One line naming the path, its owner or mode, and the opt-in.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     check_model_permissions(tmp)  # made 0700 by tempfile, under sticky /tmp
    """
    if not hasattr(os, "getuid") or trust_writable_models():
        return
    path = Path(os.path.abspath(path))
    places: list[tuple[Path, bool]] = [(path, False)]
    places += [(path / name, False) for name in MODEL_FILES]
    for chain in (path, Path(os.path.realpath(path))):
        places += [(parent, True) for parent in chain.parents]
    seen: set[Path] = set()
    for place, ancestor in places:
        if place in seen:
            continue
        seen.add(place)
        try:
            st = os.stat(place)
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise ModelFileError(f"{place}: cannot be checked ({exc.strerror})") from None
        why = _others_can_change(st, ancestor=ancestor)
        if why is None and os.path.islink(place):
            why = _others_can_change(os.lstat(place), ancestor=ancestor)
        if why is not None:
            raise ModelFileError(
                f"{place}: {why}; a model others can change is not loaded "
                f"({TRUST_ENV}=1 loads it anyway)"
            )


def _read_json(path: Path) -> Any:
    from dyntarget.io.safeopen import read_json

    return read_json(path, max_bytes=1 << 20)


def read_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and check a model directory's ``metadata.json``.

    Parameters
    ----------
    path : str or os.PathLike
        The model directory.

    Returns
    -------
    dict
        The parsed metadata.

    Raises
    ------
    dyntarget.errors.DataFileError
        When ``path`` is not a directory.
    dyntarget.errors.ModelFileError
        When the metadata is missing, not JSON, or of another format, version or band order.
    """
    path = Path(path)
    meta_path = path / METADATA
    if not path.is_dir():
        raise DataFileError(f"{path}: not a model directory")
    check_model_permissions(path)
    from dyntarget.perceive.compiled import forced_isa

    forced_isa()  # every environment switch checked with its allowed values, on every path
    if not meta_path.is_file():
        raise ModelFileError(f"{path}: no {METADATA}; not a dyntarget model")
    try:
        meta = _read_json(meta_path)  # a regular file of bounded size and depth
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{meta_path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
        raise ModelFileError(f"{meta_path}: not a dyntarget model (format field missing or wrong)")
    if meta.get("format_version") != MODEL_FORMAT_VERSION:
        raise ModelFileError(
            f"{meta_path}: model format version {meta.get('format_version')!r}, expected {MODEL_FORMAT_VERSION}"
        )
    if meta.get("bands") != list(BANDS):
        raise ModelFileError(
            f"{meta_path}: band order {meta.get('bands')!r}, expected {list(BANDS)}"
        )
    if not isinstance(meta.get("classifier"), str) or meta["classifier"] not in CLASSIFIERS:
        raise ModelFileError(f"{meta_path}: unknown classifier {meta.get('classifier')!r}")
    if not isinstance(meta.get("config"), dict):
        raise ModelFileError(f"{meta_path}: config missing")
    return meta


def load_classifier(path: str | os.PathLike[str]) -> Classifier:
    """Load any saved classifier, dispatching on its metadata.

    Parameters
    ----------
    path : str or os.PathLike
        The model directory.

    Returns
    -------
    Classifier
        The fitted classifier of the class its metadata names.
    """
    meta = read_metadata(path)
    return CLASSIFIERS.get(meta["classifier"]).load(path)
