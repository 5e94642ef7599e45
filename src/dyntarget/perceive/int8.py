"""Static INT8 quantization of an exported ONNX model (U-Nets and the MLP).

:func:`quantize_int8` writes ``model.int8.onnx`` beside ``model.onnx``
(onnxruntime.quantization, QDQ format); :func:`dyntarget.perceive.onnx.load_onnx` with
``int8=True`` runs it.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError, ModelFileError
from dyntarget.perceive.base import CLASSIFIERS, pixels
from dyntarget.perceive.modelfile import read_metadata
from dyntarget.perceive.onnx import INT8_FILE, ONNX_FILE, _require

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
        A model directory holding ``model.onnx`` (see :func:`dyntarget.perceive.onnx_export.export_onnx`).
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
