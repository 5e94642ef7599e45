"""Export classifiers to ONNX (the full install: torch, scikit-learn, skl2onnx, onnx).

* The two U-Nets are exported with PyTorch's ONNX exporter (``torch.onnx.export``,
  opset 18, batch, height and width dynamic); prediction stitches the image as the
  PyTorch path does (:class:`dyntarget.perceive.unet.Stitching`). UNET-Xception is
  exported with the forward pass that upsamples each up stage once, after its sum
  (the same function, about a fifth faster in ONNX Runtime at 1024 px).
* The five scikit-learn pixel classifiers are converted with skl2onnx
  (probabilities as a plain ``(n, 2)`` tensor, no ZipMap).
* ``band-threshold`` is not exported: it is three comparisons per pixel in numpy.

:func:`export_onnx` writes ``model.onnx`` into the model directory beside the native
weights; :func:`export_checked` also checks that ONNX Runtime's outputs agree with the
native ones to :data:`TOLERANCE` (onnxruntime computes in float32 where scikit-learn uses
float64, and fuses convolutions differently). Running the export is
:mod:`dyntarget.perceive.onnx`.
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.perceive.base import Classifier
from dyntarget.perceive.onnx import ONNX_FILE, _require, load_onnx

if TYPE_CHECKING:
    from dyntarget.perceive.pixel import RandomForest

TOLERANCE = 1e-4
"""Largest absolute difference in plume probability between ONNX and native outputs."""
OPSET = 18


def supports_onnx(classifier: Classifier) -> bool:
    """Whether :func:`export_onnx` exports this classifier (all but the band threshold).

    Parameters
    ----------
    classifier : Classifier
        Any classifier.

    Returns
    -------
    bool
        ``True`` for the scikit-learn and U-Net classifiers.
    """
    return classifier.kind != "threshold"


def export_onnx(classifier: Classifier, model_dir: str | os.PathLike[str]) -> Path:
    """Write ``model_dir/model.onnx`` for a fitted classifier.

    A random forest also gets ``forest.npz`` (:func:`dyntarget.perceive.compiled.save_forest`):
    its packed arrays, which the ONNX twin runs on dyntarget's forest kernel where it
    builds with AVX-512, bit-identical to scikit-learn and about 4x faster than ONNX
    Runtime's tree ensemble (see :class:`dyntarget.perceive.onnx.OnnxClassifier`); and
    ``forest.onnx`` (:func:`dyntarget.perceive.ensemble.ensemble_graph`), the same
    forest as ONNX Runtime's double-precision tree ensemble, also bit-identical, which
    the lean install runs where no kernel does.

    Parameters
    ----------
    classifier : Classifier
        A fitted scikit-learn or U-Net classifier.
    model_dir : path
        Its model directory (``model.onnx`` goes beside ``metadata.json``).

    Returns
    -------
    pathlib.Path
        The written ``model.onnx``.
    """
    if not classifier.fitted:
        raise InvalidParameterError(f"{classifier.name}: fit or load the classifier before export")
    if not supports_onnx(classifier):
        raise InvalidParameterError(
            f"{classifier.name}: not exported to ONNX (three comparisons per pixel in numpy "
            "already run at memory speed)"
        )
    from dyntarget.io.atomic import atomic_path

    path = Path(model_dir) / ONNX_FILE
    if classifier.kind == "unet":
        data = _export_unet(classifier)
    else:
        data = _export_sklearn(classifier)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    if classifier.name == "random-forest":  # the lean install's way to the forest kernel
        import hashlib

        from dyntarget.io.atomic import write_bytes
        from dyntarget.perceive.compiled import FOREST_FILE, pack_forest, save_forest
        from dyntarget.perceive.ensemble import GRAPH_FILE, ensemble_graph
        from dyntarget.perceive.validate import MAX_ONNX_BYTES

        forest, graph = Path(model_dir) / FOREST_FILE, Path(model_dir) / GRAPH_FILE
        try:
            packed = pack_forest(cast("RandomForest", classifier).estimator)
        except InvalidParameterError:  # beyond the kernel (e.g. deeper than it takes)
            forest.unlink(missing_ok=True)  # model.onnx alone, run by ONNX Runtime
            graph.unlink(missing_ok=True)
        else:
            save_forest(packed, forest, model_sha256=hashlib.sha256(data).hexdigest())
            try:  # only a graph load_onnx would read; a forest too large runs on a kernel
                shipped = ensemble_graph(packed)
            except InvalidParameterError:  # more nodes than a graph is built for
                shipped = b""
            if 0 < len(shipped) <= MAX_ONNX_BYTES:
                write_bytes(graph, shipped)
            else:
                graph.unlink(missing_ok=True)
    return path


def _export_unet(classifier) -> bytes:
    import torch

    _require("onnx")
    _require("onnxscript")
    net = copy.deepcopy(classifier.model).eval()
    if hasattr(net, "inference"):  # XceptionUNet: the graph that upsamples after each sum
        net.inference = True
    f = 2**classifier.levels  # height and width: any multiple of the downsampling factor
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
    if program is None:  # dynamo=True always returns one
        raise RuntimeError("torch.onnx.export returned no program")
    buf = io.BytesIO()
    program.save(buf)  # type: ignore[arg-type]  # a file object is taken as well
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


def export_checked(
    native: Classifier, model_dir: str | os.PathLike[str], check_image: np.ndarray
) -> tuple[Path, float]:
    """Export ``native`` to ONNX and check the export on ``check_image``.

    Parameters
    ----------
    native : Classifier
        The fitted classifier loaded from ``model_dir``.
    model_dir : path
        Its model directory.
    check_image : numpy.ndarray
        ``(4, H, W)`` image both runtimes classify.

    Returns
    -------
    tuple of (pathlib.Path, float)
        ``model.onnx`` and the largest absolute difference in plume probability.
        A difference above :data:`TOLERANCE` removes the export and raises
        :class:`~dyntarget.errors.ExportError`.
    """
    from dyntarget.errors import ExportError
    from dyntarget.perceive.compiled import FOREST_FILE
    from dyntarget.perceive.ensemble import GRAPH_FILE

    def remove() -> None:
        for name in (ONNX_FILE, FOREST_FILE, GRAPH_FILE):
            (Path(model_dir) / name).unlink(missing_ok=True)

    try:
        path = export_onnx(native, model_dir)
        expected = native.predict_proba(check_image)
        ort = load_onnx(model_dir, kernel=False).predict_proba(check_image)
        diff = float(np.abs(ort - expected).max())
        twin = load_onnx(model_dir)  # a random forest's packed arrays: kernel or graph
        if twin.forest is not None:  # then bit-identical to scikit-learn, or refused
            forest = cast("RandomForest", copy.copy(native))
            reference = forest.set_backend("sklearn").predict_proba(check_image)
            got = twin.predict_proba(check_image)
            if not np.array_equal(got, reference):
                diff = max(diff, float(np.abs(got - reference).max()), 2 * TOLERANCE)
            if twin.forest_graph is not None:  # what the lean install runs: checked too
                from dyntarget.perceive.ensemble import ensemble_predictor
                from dyntarget.perceive.pixel import predict_in_chunks

                where = Path(model_dir) / GRAPH_FILE
                shipped = ensemble_predictor(twin.forest, graph=twin.forest_graph, where=where)
                same = np.array_equal(predict_in_chunks(check_image, shipped), reference)
                if not (shipped.shipped and same):  # type: ignore[attr-defined]
                    diff = max(diff, 2 * TOLERANCE)
    except BaseException:
        remove()  # nothing half-written
        raise
    if not diff <= TOLERANCE:
        remove()
        raise ExportError(
            f"{native.name}: ONNX output differs from the native model by {diff:.2e} "
            f"(> {TOLERANCE:g}); export removed"
        )
    return path, diff
