"""Onboard-ready models: export classifiers to ONNX and run them with onnxruntime.

* The two U-Nets are exported with PyTorch's ONNX exporter (``torch.onnx.export``,
  opset 18, batch dimension dynamic); prediction stitches the same overlapping
  tiles as the PyTorch path (:meth:`~dyntarget.perceive.unet._UNetClassifier.tiled`).
* The five scikit-learn pixel classifiers are converted with skl2onnx
  (probabilities as a plain ``(n, 2)`` tensor, no ZipMap).
* ``band-threshold`` is not exported: it is three comparisons per pixel in numpy.

:func:`export_onnx` writes ``model.onnx`` into the model directory beside the
native weights; :func:`load_onnx` returns an :class:`OnnxClassifier` with the
same ``predict_proba`` / ``predict`` as the native classifier. Outputs agree
with the native ones to :data:`TOLERANCE` (tested): onnxruntime computes in
float32 where scikit-learn uses float64, and fuses convolutions differently.

Needs the optional dependencies: ``pip install "dyntarget[onnx]"``.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import warnings
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError, ModelFileError
from dyntarget.perceive.base import Classifier, pixels
from dyntarget.scene import check_image

ONNX_FILE = "model.onnx"
TOLERANCE = 1e-4
"""Largest absolute difference in plume probability between ONNX and native outputs."""
OPSET = 18


def _require(module: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InvalidParameterError(
            f"ONNX export and inference need {module}: pip install 'dyntarget[onnx]'"
        ) from None


def supports_onnx(classifier: Classifier) -> bool:
    return classifier.name != "band-threshold"


def export_onnx(classifier: Classifier, model_dir: str | os.PathLike[str]) -> Path:
    """Write ``model_dir/model.onnx`` for a fitted classifier; returns its path."""
    if not classifier.fitted:
        raise InvalidParameterError(f"{classifier.name}: fit or load the classifier before export")
    if not supports_onnx(classifier):
        raise InvalidParameterError(
            f"{classifier.name}: not exported to ONNX (three comparisons per pixel in numpy "
            "already run at memory speed)"
        )
    from dyntarget.io.atomic import atomic_path

    path = Path(model_dir) / ONNX_FILE
    if classifier.name.startswith("unet-"):
        data = _export_unet(classifier)
    else:
        data = _export_sklearn(classifier)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    return path


def _export_unet(classifier) -> bytes:
    import torch

    _require("onnx")
    _require("onnxscript")
    net = classifier.model.eval()
    f = classifier.factor  # height and width: any multiple of the downsampling factor
    example = torch.zeros(2, 4, 2 * f, 3 * f)
    exporter_log = logging.getLogger("torch.onnx")
    level = exporter_log.level
    exporter_log.setLevel(logging.ERROR)  # e.g. "torchvision is not installed", irrelevant here
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            # the exporter's own progress lines and deprecation notices (torch internals)
            warnings.simplefilter("ignore", FutureWarning)
            warnings.simplefilter("ignore", DeprecationWarning)
            program = torch.onnx.export(
                net,
                (example,),
                dynamo=True,
                input_names=["image"],
                output_names=["logits"],
                dynamic_shapes={
                    "x": {
                        0: torch.export.Dim("batch", min=1, max=4096),
                        2: f * torch.export.Dim("rows", min=1, max=4096),
                        3: f * torch.export.Dim("cols", min=1, max=4096),
                    }
                },
                opset_version=OPSET,
                verbose=False,
            )
    finally:
        exporter_log.setLevel(level)
    buf = io.BytesIO()
    program.save(buf)
    return buf.getvalue()


def _export_sklearn(classifier) -> bytes:
    skl2onnx = _require("skl2onnx")
    from skl2onnx.common.data_types import FloatTensorType

    est = classifier.estimator
    model = skl2onnx.convert_sklearn(
        est,
        initial_types=[("pixels", FloatTensorType([None, 4]))],
        options={id(est): {"zipmap": False}},
        target_opset={"": OPSET, "ai.onnx.ml": 3},
    )
    model.graph.name = classifier.name  # skl2onnx names the graph with a random UUID
    return model.SerializeToString()


class OnnxClassifier:
    """A native classifier's ONNX twin: the same ``predict_proba`` and ``predict``."""

    def __init__(self, native: Classifier, path: Path) -> None:
        ort = _require("onnxruntime")
        options = ort.SessionOptions()
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(
                str(path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own types on a corrupt file
            raise ModelFileError(f"{path}: not a readable ONNX model ({exc})") from None
        self.native, self.name, self.path = native, native.name, path
        self.input = self.session.get_inputs()[0].name

    def predict_proba(self, image: np.ndarray) -> np.ndarray:
        image = check_image(image)
        if self.name.startswith("unet-"):

            def forward(batch: np.ndarray) -> np.ndarray:
                logits = self.session.run(None, {self.input: batch})[0]
                z = logits - logits.max(axis=1, keepdims=True)
                e = np.exp(z)
                return (e[:, 1] / e.sum(axis=1)).astype(np.float32)

            proba = self.native.tiled(image, forward)
        else:
            h, w = image.shape[1:]
            x = np.ascontiguousarray(pixels(image), dtype=np.float32)
            out = self.session.run(None, {self.input: x})
            probs = next(o for o in out if getattr(o, "ndim", 0) == 2)
            proba = probs[:, 1].reshape(h, w)
        proba = np.asarray(proba, np.float32)
        return np.clip(proba, 0.0, 1.0, out=proba)

    def predict(self, image: np.ndarray, threshold: float = 0.5) -> np.ndarray:
        if not 0.0 <= float(threshold) <= 1.0:
            raise InvalidParameterError(
                f"threshold: expected a probability in 0..1, got {threshold!r}"
            )
        return self.predict_proba(image) >= threshold


def load_onnx(model_dir: str | os.PathLike[str]) -> OnnxClassifier:
    """The ONNX twin of the model in ``model_dir`` (exported with :func:`export_onnx`)."""
    from dyntarget.perceive import load_classifier

    native = load_classifier(model_dir)
    path = Path(model_dir) / ONNX_FILE
    if not path.is_file():
        raise ModelFileError(f"{model_dir}: no {ONNX_FILE}; run 'dyntarget export-onnx' first")
    return OnnxClassifier(native, path)
