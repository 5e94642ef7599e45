"""Onboard inference: run a model directory's ONNX export with ONNX Runtime.

:func:`load_onnx` returns an :class:`OnnxClassifier` with the same ``predict_proba`` /
``predict`` as the native classifier (it satisfies :class:`dyntarget.perceive.base.Predictor`),
built from the model directory alone (``metadata.json`` beside ``model.onnx``): neither
torch nor scikit-learn nor skops is imported. A random forest's ``forest.npz`` runs on
dyntarget's forest kernel (:mod:`dyntarget.perceive.compiled`) where it can.

Inference needs ``pip install "dyntarget[onboard]"`` (onnxruntime). Writing the export is
:mod:`dyntarget.perceive.onnx_export` (``dyntarget[full]``); INT8 quantization is
:mod:`dyntarget.perceive.int8`.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, cast

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError, ModelFileError
from dyntarget.perceive.base import CLASSIFIERS, pixels
from dyntarget.perceive.modelfile import read_metadata
from dyntarget.perceive.resources import available_cores
from dyntarget.perceive.validate import check_onnx_file, check_onnx_session, run_onnx
from dyntarget.scene import BANDS, check_image

if TYPE_CHECKING:
    from dyntarget.perceive.unet import _UNetClassifier

ONNX_FILE = "model.onnx"
INT8_FILE = "model.int8.onnx"
"""The INT8 twin written by :func:`dyntarget.perceive.int8.quantize_int8`."""

ENSEMBLE_BACKEND = "onnxruntime, forest.npz"
""":attr:`OnnxClassifier.backend` when a random forest's ``forest.npz`` runs as ONNX
Runtime's double-precision tree ensemble (bit-identical to the kernel), its graph from this
user's cache or built here."""

SHIPPED_BACKEND = "onnxruntime, forest.onnx"
""":attr:`OnnxClassifier.backend` when that graph is the model directory's ``forest.onnx``."""


def _require(module: str, extra: str = "full") -> ModuleType:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{module} is not installed; ONNX {'inference' if extra == 'onboard' else 'export'} "
            f"needs it: pip install 'dyntarget[{extra}]'"
        ) from None


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
        dyntarget's forest kernel where the one of this user's cache (built here, or
        installed) runs a path faster than ONNX Runtime
        (:func:`dyntarget.perceive.compiled.fast_predictor`; then onnxruntime is not even
        imported); else through the packed forest as ONNX Runtime's double-precision
        tree ensemble where its graph can be had (:mod:`dyntarget.perceive.ensemble`;
        bit-identical to the kernel); through ``model.onnx`` otherwise, said once on
        stderr. :attr:`backend` says which ran.
    forest_graph : bytes or None
        The model directory's ``forest.onnx`` (:data:`dyntarget.perceive.ensemble.GRAPH_FILE`),
        the graph of ``forest`` that the lean install runs where no kernel does (it has no
        ``onnx`` to build one).
    say_fallback : bool
        Say on stderr (once per process) when a random forest runs on ONNX Runtime's
        tree ensemble; ``False`` where that was asked for (``load_onnx(kernel=False)``).
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
        forest_graph: bytes | None = None,
        say_fallback: bool = True,
    ) -> None:
        self.forest, self._kernel, self._say = forest, None, say_fallback
        self.forest_graph = forest_graph
        self.backend = "onnxruntime"  # "forest kernel" once a forest has predicted on it
        self.name, self.kind, self.tile, self.path = name, kind, int(tile), path
        self._threads, self._session = threads, None
        self.stitching = None
        if self._forest_kernel() is not None:
            return  # the kernel predicts: onnxruntime is not imported (started when needed)
        self.session  # noqa: B018 (opened and checked now: a broken model fails at load)
        if kind == "unet":
            from dyntarget.perceive.unet import Stitching

            cls = cast("type[_UNetClassifier]", CLASSIFIERS.get(name))
            dims = self.session.get_inputs()[0].shape[2:]
            if all(isinstance(d, int) for d in dims):
                stitch = "blend"
            self.stitching = Stitching.for_architecture(
                cls.architecture, levels=cls.levels, width=width, tile=tile, stitch=stitch
            )

    @property
    def session(self):
        """The ONNX Runtime session of ``model.onnx``, opened and checked on first use.

        Returns
        -------
        onnxruntime.InferenceSession
            One intra-op thread per core, no inter-op pool.
        """
        if self._session is None:
            ort = _require("onnxruntime", "onboard")
            options = ort.SessionOptions()
            options.log_severity_level = 3
            # one pool of intra-op threads, one per core; no inter-op pool on top of it
            options.intra_op_num_threads = self._threads or available_cores()
            options.inter_op_num_threads = 1
            options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
            try:
                session = ort.InferenceSession(
                    str(self.path), sess_options=options, providers=["CPUExecutionProvider"]
                )
            except Exception as exc:  # onnxruntime raises its own types on a corrupt file
                raise ModelFileError(f"{self.path}: not a readable ONNX model ({exc})") from None
            check_onnx_session(session, self.kind, tile=self.tile, where=self.path)
            self._session = session
        return self._session

    @property
    def input(self) -> str:
        """The name of the model's input.

        Returns
        -------
        str
            From the session.
        """
        return str(self.session.get_inputs()[0].name)

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

            assert self.stitching is not None  # set for every U-Net in __init__
            proba = self.stitching.run(image, forward)
        elif self._forest_kernel() is not None:
            from dyntarget.perceive.pixel import predict_in_chunks

            proba = predict_in_chunks(image, self._kernel)
        else:
            from dyntarget.perceive.pixel import PREDICT_CHUNK

            self._say_tree_ensemble()
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
        """The packed forest's predictor, built on first use; ``None`` to run ``model.onnx``.

        The forest kernel where it runs a path faster than ONNX Runtime; else the packed
        forest as ONNX Runtime's double-precision tree ensemble
        (:func:`~dyntarget.perceive.ensemble.ensemble_predictor`: bit-identical to the kernel,
        from the model's ``forest.onnx``, the cache, or built with ``onnx``); else ``None``.
        """
        if self.forest is not None and self._kernel is None:
            from dyntarget.perceive.compiled import fast_predictor

            self._kernel = fast_predictor(self.forest, against="onnxruntime")
            if self._kernel is not None:
                self.backend = "forest kernel"
                return self._kernel
            from dyntarget.perceive.ensemble import ensemble_predictor

            try:
                self._kernel = ensemble_predictor(
                    self.forest, graph=self.forest_graph, where=self.path.parent / "forest.onnx"
                )
            except (MissingExtraError, InvalidParameterError):  # no graph to be had: model.onnx
                self.forest = None
            else:
                shipped = self._kernel.shipped
                self.backend = SHIPPED_BACKEND if shipped else ENSEMBLE_BACKEND
        return self._kernel

    def _say_tree_ensemble(self) -> None:
        """Say once that a random forest runs ``model.onnx`` on ONNX Runtime (the slow fallback)."""
        from dyntarget.perceive import compiled

        if self._say and self.name == "random-forest" and compiled.forced_isa() != "off":
            compiled._say_once(
                f"dyntarget: {self.path.parent}: no forest kernel runs this random forest on "
                f"this CPU ({compiled.cpu_class()}); ONNX Runtime's tree ensemble predicts, "
                "slower than the kernel (docs/performance.md; a C compiler builds the "
                "kernel here, or 'dyntarget install-kernel' installs one built elsewhere)"
            )

    def work_units(self, shape: tuple[int, int]) -> float:
        """Work of classifying an image of ``shape``, as the native classifier counts it.

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        float
            Pixels for a pixel classifier; for a U-Net, the pixels its tiles run over.
        """
        if self.stitching is not None:
            return float(self.stitching.work_units(shape))
        return float(shape[0] * shape[1])

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


def _shipped_graph(model_dir: Path) -> bytes | None:
    """The model's ``forest.onnx`` read once and checked as ``model.onnx`` is (size, no
    control flow); ``None`` when absent, or refused: said once, the forest runs otherwise."""
    from dyntarget.perceive.ensemble import GRAPH_FILE

    path = model_dir / GRAPH_FILE
    if not os.path.lexists(path):
        return None
    from dyntarget.errors import DataFileError
    from dyntarget.io.safeopen import read_bytes
    from dyntarget.perceive.compiled import _say_once
    from dyntarget.perceive.validate import MAX_ONNX_BYTES, check_onnx_bytes

    try:
        data = read_bytes(path, max_bytes=MAX_ONNX_BYTES)
        check_onnx_bytes(data, path)  # what is checked is what runs
    except (DataFileError, ModelFileError) as exc:
        _say_once(f"dyntarget: {exc}; {GRAPH_FILE} not used")
        return None
    return data


def load_onnx(
    model_dir: str | os.PathLike[str], *, int8: bool = False, kernel: bool = True
) -> OnnxClassifier:
    """The ONNX twin of the model in ``model_dir`` (exported with :func:`dyntarget.perceive.onnx_export.export_onnx`).

    Only ``metadata.json``, ``model.onnx`` and, for a random forest, ``forest.npz`` and
    ``forest.onnx`` are read (``forest.npz`` checked rule by rule, and against the SHA-256
    of the ``model.onnx`` it was exported with: :func:`dyntarget.perceive.compiled.load_forest`;
    ``forest.onnx`` as ``model.onnx`` is, and run only if it names that forest);
    the native weights, torch, scikit-learn and skops are not touched.

    Parameters
    ----------
    model_dir : path
        A model directory with ``model.onnx``.
    int8 : bool
        Load ``model.int8.onnx`` (from :func:`dyntarget.perceive.int8.quantize_int8`) instead.
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
    if name == "random-forest":
        from dyntarget.perceive.compiled import forced_isa

        forced_isa()  # a DYNTARGET_FOREST_ISA that names no path is one line, on every path
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
    graph = _shipped_graph(Path(model_dir)) if forest is not None else None
    return OnnxClassifier(
        path, name=name, kind=kind, tile=tile, width=width, forest=forest, forest_graph=graph,
        say_fallback=kernel,
    )  # fmt: skip
