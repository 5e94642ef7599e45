"""Onboard-ready models: export classifiers to ONNX and run them with onnxruntime.

* The two U-Nets are exported with PyTorch's ONNX exporter (``torch.onnx.export``,
  opset 18, batch, height and width dynamic); prediction stitches the image as the
  PyTorch path does (:class:`dyntarget.perceive.unet.Stitching`). UNET-Xception is
  exported with the forward pass that upsamples each up stage once, after its sum
  (the same function, about a fifth faster in ONNX Runtime at 1024 px).
* The five scikit-learn pixel classifiers are converted with skl2onnx
  (probabilities as a plain ``(n, 2)`` tensor, no ZipMap).
* ``band-threshold`` is not exported: it is three comparisons per pixel in numpy.

:func:`export_onnx` writes ``model.onnx`` into the model directory beside the
native weights; :func:`load_onnx` returns an :class:`OnnxClassifier` with the
same ``predict_proba`` / ``predict`` as the native classifier, built from the
model directory alone (``metadata.json`` beside ``model.onnx``): neither torch
nor scikit-learn nor skops is imported. Outputs agree with the native ones to
:data:`TOLERANCE` (tested): onnxruntime computes in float32 where scikit-learn
uses float64, and fuses convolutions differently.

Inference needs ``pip install "dyntarget[onboard]"`` (onnxruntime); export
needs ``dyntarget[full]``.
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import os
import warnings
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError, ModelFileError
from dyntarget.perceive.base import (
    CLASSIFIERS,
    Classifier,
    available_cores,
    pixels,
    read_metadata,
)
from dyntarget.perceive.validate import check_onnx_file, check_onnx_session, run_onnx
from dyntarget.scene import BANDS, check_image

ONNX_FILE = "model.onnx"
TOLERANCE = 1e-4
"""Largest absolute difference in plume probability between ONNX and native outputs."""
OPSET = 18


def _require(module: str, extra: str = "full"):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{module} is not installed; ONNX {'inference' if extra == 'onboard' else 'export'} "
            f"needs it: pip install 'dyntarget[{extra}]'"
        ) from None


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
    Runtime's tree ensemble (see :class:`OnnxClassifier`).

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

        from dyntarget.perceive.compiled import FOREST_FILE, pack_forest, save_forest

        forest = Path(model_dir) / FOREST_FILE
        try:
            packed = pack_forest(classifier.estimator)
        except InvalidParameterError:  # beyond the kernel (e.g. deeper than it takes)
            forest.unlink(missing_ok=True)  # model.onnx alone, run by ONNX Runtime
        else:
            save_forest(packed, forest, model_sha256=hashlib.sha256(data).hexdigest())
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
    """A native classifier's ONNX twin: the same ``predict_proba`` and ``predict``.

    Parameters
    ----------
    path : pathlib.Path
        The ``model.onnx`` file.
    name : str
        The classifier's registered name.
    kind : str
        ``"pixel"`` (one row of four band values per pixel) or ``"unet"`` (tiles).
    tile : int
        U-Net tile size in pixels (ignored for pixel classifiers).
    width : int
        U-Net width (sizes the ``"halo"`` windows' memory estimate).
    stitch : {"halo", "blend"}
        U-Net stitching (see :mod:`dyntarget.perceive.unet`). A model exported before
        height and width were dynamic takes only ``tile`` px tiles: ``"blend"`` is used.
    threads : int or None
        onnxruntime intra-op threads (default: the cores this process may use).
    forest : dyntarget.perceive.compiled.PackedForest or None
        A random forest's packed arrays (``forest.npz``): pixels then go through
        dyntarget's forest kernel where it builds with AVX-512 (a C compiler on the
        PATH), and through ``model.onnx`` otherwise. :attr:`backend` says which ran.
    """

    def __init__(
        self,
        path: Path,
        *,
        name: str,
        kind: str,
        tile: int = 64,
        width: int = 16,
        stitch: str = "halo",
        threads: int | None = None,
        forest=None,
    ) -> None:
        self.forest, self._kernel = forest, None
        self.backend = "onnxruntime"  # "forest kernel" once a forest has predicted on it
        ort = _require("onnxruntime", "onboard")
        options = ort.SessionOptions()
        options.log_severity_level = 3
        # one pool of intra-op threads, one per core; no inter-op pool on top of it
        options.intra_op_num_threads = threads or available_cores()
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        try:
            self.session = ort.InferenceSession(
                str(path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own types on a corrupt file
            raise ModelFileError(f"{path}: not a readable ONNX model ({exc})") from None
        check_onnx_session(self.session, kind, tile=int(tile), where=path)
        self.name, self.kind, self.tile, self.path = name, kind, int(tile), path
        self.input = self.session.get_inputs()[0].name
        self.stitching = None
        if kind == "unet":
            from dyntarget.perceive.unet import Stitching

            cls = CLASSIFIERS.get(name)
            dims = self.session.get_inputs()[0].shape[2:]
            if all(isinstance(d, int) for d in dims):
                stitch = "blend"
            self.stitching = Stitching.for_architecture(
                cls.architecture, levels=cls.levels, width=width, tile=tile, stitch=stitch
            )

    def predict_proba(self, image: np.ndarray) -> np.ndarray:
        """Plume probability ``float32 (H, W)`` in 0..1 for a ``(4, H, W)`` image.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` reflectance (R, G, B, NIR).

        Returns
        -------
        numpy.ndarray
            ``(H, W)`` float32 probability.
        """
        image = check_image(image)
        if self.kind == "unet":

            def forward(batch: np.ndarray) -> np.ndarray:
                logits = run_onnx(self.session, {self.input: batch}, "unet", where=self.path)[0]
                z = logits - logits.max(axis=1, keepdims=True)
                e = np.exp(z)
                return (e[:, 1] / e.sum(axis=1)).astype(np.float32)

            proba = self.stitching.run(image, forward)
        elif self._forest_kernel() is not None:
            from dyntarget.perceive.pixel import predict_in_chunks

            proba = predict_in_chunks(image, self._kernel)
        else:
            from dyntarget.perceive.pixel import PREDICT_CHUNK

            h, w = image.shape[1:]
            x = pixels(image)  # a view; each chunk is copied contiguous on its own
            proba = np.empty(h * w, np.float32)
            for start in range(0, h * w, PREDICT_CHUNK):  # bounded memory, as the native path
                part = np.ascontiguousarray(x[start : start + PREDICT_CHUNK], dtype=np.float32)
                out = run_onnx(self.session, {self.input: part}, "pixel", where=self.path)
                probs = next(o for o in out if getattr(o, "ndim", 0) == 2)
                proba[start : start + len(part)] = probs[:, 1]
            proba = proba.reshape(h, w)
        proba = np.asarray(proba, np.float32)
        return np.clip(proba, 0.0, 1.0, out=proba)

    def _forest_kernel(self):
        """The forest kernel's predictor, built on first use; ``None`` to use ONNX Runtime."""
        if self.forest is not None and self._kernel is None:
            from dyntarget.perceive.compiled import fast_predictor

            self._kernel = fast_predictor(self.forest)
            if self._kernel is None:
                self.forest = None  # ONNX Runtime, silently
            else:
                self.backend = "forest kernel"
        return self._kernel

    def predict(self, image: np.ndarray, threshold: float = 0.5) -> np.ndarray:
        """Plume mask ``predict_proba(image) >= threshold``.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` reflectance.
        threshold : float
            Probability threshold in 0..1.

        Returns
        -------
        numpy.ndarray
            ``(H, W)`` bool mask.
        """
        if not 0.0 <= float(threshold) <= 1.0:
            raise InvalidParameterError(
                f"threshold: expected a probability in 0..1, got {threshold!r}"
            )
        return self.predict_proba(image) >= threshold


def load_onnx(
    model_dir: str | os.PathLike[str], *, int8: bool = False, kernel: bool = True
) -> OnnxClassifier:
    """The ONNX twin of the model in ``model_dir`` (exported with :func:`export_onnx`).

    Only ``metadata.json``, ``model.onnx`` and, for a random forest, ``forest.npz`` are
    read (the last checked rule by rule, and against the SHA-256 of the ``model.onnx``
    it was exported with: :func:`dyntarget.perceive.compiled.load_forest`);
    the native weights, torch, scikit-learn and skops are not touched.

    Parameters
    ----------
    model_dir : path
        A model directory with ``model.onnx``.
    int8 : bool
        Load ``model.int8.onnx`` (from :func:`quantize_int8`) instead.
    kernel : bool
        Let a random forest run on dyntarget's forest kernel when ``forest.npz`` is there
        (default); ``False`` runs ``model.onnx`` in ONNX Runtime whatever the directory holds.

    Returns
    -------
    OnnxClassifier
        Ready to predict.
    """
    meta = read_metadata(model_dir)
    name = meta["classifier"]
    kind = CLASSIFIERS.get(name).kind
    if kind not in ("pixel", "unet"):
        raise ModelFileError(f"{model_dir}: {name} models have no ONNX export")
    path = Path(model_dir) / (INT8_FILE if int8 else ONNX_FILE)
    if not path.is_file():
        flag = " --int8" if int8 else ""
        raise ModelFileError(
            f"{model_dir}: no {path.name}; run 'dyntarget export-onnx{flag}' first"
        )
    check_onnx_file(path)  # size and graph (no Loop/Scan/If) before anything reads it whole
    tile = meta["config"].get("tile", 64)
    if kind == "unet" and (isinstance(tile, bool) or not isinstance(tile, int) or tile < 1):
        raise ModelFileError(f"{model_dir}: metadata config tile {tile!r} is not a tile size")
    width = meta["config"].get("width", 16)
    if kind == "unet" and (isinstance(width, bool) or not isinstance(width, int) or width < 1):
        raise ModelFileError(f"{model_dir}: metadata config width {width!r} is not a width")
    forest = None
    if kernel and name == "random-forest":
        from dyntarget.perceive.compiled import FOREST_FILE, load_forest

        if (Path(model_dir) / FOREST_FILE).is_file():
            import hashlib

            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            forest = load_forest(Path(model_dir) / FOREST_FILE, model_sha256=digest)
            if forest.features != len(BANDS):
                raise ModelFileError(
                    f"{model_dir}: {FOREST_FILE} takes {forest.features} features, not "
                    f"the {len(BANDS)} bands"
                )
    return OnnxClassifier(path, name=name, kind=kind, tile=tile, width=width, forest=forest)


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

    def remove() -> None:
        (Path(model_dir) / ONNX_FILE).unlink(missing_ok=True)
        (Path(model_dir) / FOREST_FILE).unlink(missing_ok=True)

    try:
        path = export_onnx(native, model_dir)
        expected = native.predict_proba(check_image)
        ort = load_onnx(model_dir, kernel=False).predict_proba(check_image)
        diff = float(np.abs(ort - expected).max())
        twin = load_onnx(model_dir)  # a random forest's packed arrays, on the kernel
        if twin.forest is not None:
            got = twin.predict_proba(check_image)
            if twin.backend == "forest kernel":  # bit-identical to scikit-learn, or refused
                reference = copy.copy(native).set_backend("sklearn").predict_proba(check_image)
                if not np.array_equal(got, reference):
                    diff = max(diff, float(np.abs(got - reference).max()), 2 * TOLERANCE)
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


INT8_FILE = "model.int8.onnx"
INT8_TOLERANCE = 0.05
"""Largest absolute difference in plume probability between the INT8 and the FP32 ONNX
model on the fixed parity scene of the tests (a pixel near 0.5 may cross the threshold;
the IoU change on held-out scenes is what the benchmark reports)."""
INT8_SUPPORTED = ("unet-uavsar", "unet-xception", "mlp")
CALIBRATION_TILES = 64
"""Training tiles (U-Nets) or chunks of 4096 training pixels (MLP) fed to calibration."""


def calibration_batches(
    kind: str, images: list[np.ndarray], *, tile: int = 64, seed: int = 0
) -> list[np.ndarray]:
    """Inputs for static-quantization calibration, cut from training images.

    Parameters
    ----------
    kind : {"unet", "pixel"}
        ``(1, 4, tile, tile)`` tiles for a U-Net, ``(4096, 4)`` pixel rows otherwise.
    images : list of numpy.ndarray
        ``(4, H, W)`` training images (on the grid the model sees).
    tile : int
        U-Net tile size.
    seed : int
        Seed of the random choice of tiles / pixels.

    Returns
    -------
    list of numpy.ndarray
        At most :data:`CALIBRATION_TILES` float32 batches.

    Examples
    --------
    >>> img = np.zeros((4, 128, 96), np.float32)
    >>> [b.shape for b in calibration_batches("unet", [img], tile=32)][:2]
    [(1, 4, 32, 32), (1, 4, 32, 32)]
    """
    if not images:
        raise InvalidParameterError("images: expected at least one calibration image, got none")
    rng = np.random.default_rng(seed)
    if kind == "unet":
        tiles = [
            img[:, r : r + tile, c : c + tile]
            for img in images
            for r in range(0, img.shape[1] - tile + 1, tile)
            for c in range(0, img.shape[2] - tile + 1, tile)
        ]
        if not tiles:
            raise InvalidParameterError(
                f"images: calibration needs images of at least {tile} px, got "
                f"{[tuple(i.shape[1:]) for i in images]}"
            )
        pick = rng.permutation(len(tiles))[:CALIBRATION_TILES]
        return [np.ascontiguousarray(tiles[i][None], dtype=np.float32) for i in sorted(pick)]
    rows = np.concatenate([pixels(img) for img in images]).astype(np.float32)
    rows = rows[rng.permutation(len(rows))[: 4096 * CALIBRATION_TILES]]
    return [np.ascontiguousarray(rows[i : i + 4096]) for i in range(0, len(rows), 4096)]


def quantize_int8(
    model_dir: str | os.PathLike[str], images: list[np.ndarray], *, seed: int = 0
) -> Path:
    """Write ``model_dir/model.int8.onnx``: the exported FP32 model with static INT8
    quantization (onnxruntime.quantization, QDQ format, per-channel INT8 weights,
    UINT8 activations calibrated by min/max on training tiles).

    Parameters
    ----------
    model_dir : path
        A model directory holding ``model.onnx`` (see :func:`export_onnx`).
    images : list of numpy.ndarray
        ``(4, H, W)`` training images to calibrate on.
    seed : int
        Seed of the choice of calibration tiles.

    Returns
    -------
    pathlib.Path
        The INT8 model file.
    """
    meta = read_metadata(model_dir)
    name = meta["classifier"]
    if name not in INT8_SUPPORTED:
        raise InvalidParameterError(
            f"{name}: INT8 quantization is offered for {', '.join(INT8_SUPPORTED)} "
            "(tree models and linear models gain nothing from it)"
        )
    src = Path(model_dir) / ONNX_FILE
    if not src.is_file():
        raise ModelFileError(f"{model_dir}: no {ONNX_FILE}; export the FP32 model first")
    _require("onnxruntime", "onboard")
    from onnxruntime.quantization import (
        CalibrationDataReader,
        QuantFormat,
        QuantType,
        quantize_static,
    )

    kind = CLASSIFIERS.get(name).kind
    batches = calibration_batches(kind, images, tile=meta["config"].get("tile", 64), seed=seed)
    input_name = "image" if kind == "unet" else "pixels"

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self.it = iter(batches)

        def get_next(self):
            batch = next(self.it, None)
            return None if batch is None else {input_name: batch}

    from dyntarget.io.atomic import atomic_path

    path = Path(model_dir) / INT8_FILE
    with atomic_path(path) as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # onnxruntime's advice to pre-process the model
        exporter_log = logging.getLogger()
        level = exporter_log.level
        exporter_log.setLevel(logging.ERROR)
        try:
            quantize_static(
                str(src),
                str(tmp),
                Reader(),
                quant_format=QuantFormat.QDQ,
                activation_type=QuantType.QUInt8,
                weight_type=QuantType.QInt8,
                per_channel=True,
            )
        finally:
            exporter_log.setLevel(level)
    return path
