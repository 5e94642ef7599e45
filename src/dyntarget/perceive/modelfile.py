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
from pathlib import Path
from typing import Any

from dyntarget.errors import DataFileError, InvalidParameterError, ModelFileError
from dyntarget.perceive.base import CLASSIFIERS, Classifier
from dyntarget.scene import BANDS

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
