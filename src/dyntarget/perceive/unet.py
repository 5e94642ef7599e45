"""The two U-Nets (PyTorch): ``unet-uavsar`` and ``unet-xception``.

* ``unet-uavsar``: a compact classic U-Net as in the UAVSAR flood-mapping
  model — three encoder levels of conv-conv-pool, a bottleneck, and a
  transpose-conv decoder with skip connections (channels ``w, 2w, 4w``,
  bottleneck ``8w``; ``w = 16`` by default).
* ``unet-xception``: the Xception-style U-Net of the Keras example "Image
  segmentation with a U-Net-like architecture" — a strided entry conv, three
  blocks of depthwise-separable convs with 1x1 strided residual shortcuts, and
  four decoder blocks of transpose convs + 2x upsampling with upsampled 1x1
  residuals (channels ``2w, 4w, 8w`` down, ``8w, 4w, 2w, w`` up).

Both take the raw 4-band reflectance (standardised per band with statistics
of the training scenes, stored in the model) tiled into square patches
(``tile`` px, default 64), and output two-class logits. Training: Adam,
learning rate 1e-3, cross-entropy, ``epochs`` (paper: 50), batch 16, non-overlapping
training tiles with random flips; seeded, deterministic on CPU for a fixed thread count. Prediction runs
overlapping tiles (stride ``tile/2``) and blends them with a smooth window,
so there are no seams. Weights are saved with safetensors.

This module imports no torch: the networks (:mod:`dyntarget.perceive.networks`)
and torch are loaded when a U-Net is built, trained or loaded natively; the
tiling (:func:`tiled`) is shared with the ONNX runtime.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from dyntarget.errors import InvalidParameterError, ModelFileError
from dyntarget.perceive.base import CLASSIFIERS, TRAIN_THREADS, Classifier
from dyntarget.perceive.validate import check_state_dict

WEIGHTS_FILE = "model.safetensors"
IGNORE = -1
"""Target value of nodata pixels: left out of the loss."""
_GLOBAL_RNG_LOCK = threading.Lock()


@contextlib.contextmanager
def _fixed_threads(n: int) -> Iterator[None]:
    """Run the block with ``n`` PyTorch intra-op threads (this thread's setting), then restore."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def tile_origins(length: int, tile: int, stride: int) -> list[int]:
    """Start offsets of tiles of ``tile`` px covering ``length`` px (last one flush with the end)."""
    if length <= tile:
        return [0]
    starts = list(range(0, length - tile + 1, stride))
    if starts[-1] != length - tile:
        starts.append(length - tile)
    return starts


def _pad_to(image: np.ndarray, tile: int) -> np.ndarray:
    h, w = image.shape[1:]
    ph, pw = max(0, tile - h), max(0, tile - w)
    if ph or pw:
        mode = "reflect" if (h > ph and w > pw) else "edge"
        image = np.pad(image, ((0, 0), (0, ph), (0, pw)), mode=mode)
    return image


def blend_window(tile: int) -> np.ndarray:
    """Smooth, strictly positive 2-D weight for blending overlapping tiles."""
    w = np.hanning(tile + 2)[1:-1]
    return np.outer(w, w).astype(np.float32) + 1e-3


def tiled(image: np.ndarray, forward, tile: int) -> np.ndarray:
    """Stitch ``forward`` over overlapping tiles (stride ``tile/2``, blended).

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` float32 image.
    forward : callable
        ``(n, 4, tile, tile)`` batch -> ``(n, tile, tile)`` plume probability;
        shared by the PyTorch and ONNX runtimes.
    tile : int
        Tile size in pixels.

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` float32 plume probability.

    Examples
    --------
    >>> img = np.zeros((4, 40, 50), np.float32)
    >>> p = tiled(img, lambda b: np.full((len(b), 16, 16), 0.25, np.float32), 16)
    >>> p.shape, float(p.min()), float(p.max())
    ((40, 50), 0.25, 0.25)
    """
    h, w = image.shape[1:]
    img = _pad_to(image, tile)
    hp, wp = img.shape[1:]
    stride = tile // 2
    origins = [
        (r, c) for r in tile_origins(hp, tile, stride) for c in tile_origins(wp, tile, stride)
    ]
    window = blend_window(tile)
    acc = np.zeros((hp, wp), np.float32)
    weight = np.zeros((hp, wp), np.float32)
    for i in range(0, len(origins), 32):
        batch = origins[i : i + 32]
        xb = np.stack([img[:, r : r + tile, c : c + tile] for r, c in batch])
        prob = forward(xb)
        for (r, c), p in zip(batch, prob, strict=True):
            acc[r : r + tile, c : c + tile] += p * window
            weight[r : r + tile, c : c + tile] += window
    return (acc / weight)[:h, :w]


class _UNetClassifier(Classifier):
    kind = "unet"
    architecture: ClassVar[str]
    """Key of :data:`dyntarget.perceive.networks.NETWORKS`."""
    levels: ClassVar[int]
    """Down-sampling levels of the network: tiles are multiples of ``2**levels`` px."""

    def network(self, width: int):
        """A fresh, untrained network of this architecture (imports torch)."""
        from dyntarget.perceive.networks import NETWORKS

        return NETWORKS[self.architecture](width=width)

    def __init__(
        self,
        *,
        seed: int = 0,
        epochs: int = 50,
        tile: int = 64,
        width: int = 16,
        batch_size: int = 16,
        learning_rate: float = 1e-3,
    ) -> None:
        super().__init__(seed=seed)
        for name, value, minimum in (
            ("epochs", epochs, 1),
            ("width", width, 2),
            ("batch_size", batch_size, 1),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
                raise InvalidParameterError(
                    f"{name}: expected an integer >= {minimum}, got {value!r}"
                )
        multiple = 2**self.levels
        if (
            isinstance(tile, bool)
            or not isinstance(tile, int)
            or tile < multiple
            or tile % multiple
        ):
            raise InvalidParameterError(
                f"tile: expected a positive multiple of {multiple}, got {tile!r}"
            )
        if not 0 < float(learning_rate) < 1:
            raise InvalidParameterError(
                f"learning_rate: expected a number in (0, 1), got {learning_rate!r}"
            )
        self.epochs, self.tile, self.width = epochs, tile, width
        self.batch_size, self.learning_rate = batch_size, float(learning_rate)
        self.model = self.network(width=width)
        self.history: list[float] = []

    def get_config(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "epochs": self.epochs,
            "tile": self.tile,
            "width": self.width,
            "batch_size": self.batch_size,
            "learning_rate": self.learning_rate,
        }

    def _tiles(self, scenes) -> tuple[np.ndarray, np.ndarray]:
        xs, ys = [], []
        stride = self.tile  # training tiles do not overlap; random flips augment them
        for s in scenes:
            img = _pad_to(s.image, self.tile)
            target = np.where(
                s.valid_mask, s.label.astype(np.float32), float(IGNORE)
            )  # nodata: no loss
            target = _pad_to(target[None], self.tile)[0].astype(np.int64)
            for r in tile_origins(img.shape[1], self.tile, stride):
                for c in tile_origins(img.shape[2], self.tile, stride):
                    t = target[r : r + self.tile, c : c + self.tile]
                    if (t != IGNORE).any():
                        xs.append(img[:, r : r + self.tile, c : c + self.tile])
                        ys.append(t)
        return np.stack(xs), np.stack(ys)

    def _fit(self, scenes) -> None:
        import torch
        from torch import nn

        x, y = self._tiles(scenes)
        stack = np.concatenate([s.image[:, s.valid_mask] for s in scenes], axis=1)
        # float64: per-band statistics independent of summation order (float32 sums are not)
        mean, std = (
            stack.mean(axis=1, dtype=np.float64),
            np.maximum(stack.std(axis=1, dtype=np.float64), 1e-4),
        )
        # the initial weights come from torch's global generator: seed it under a lock so
        # that models trained at once on several threads (a Dask worker) stay deterministic
        with _GLOBAL_RNG_LOCK, torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed)
            model = self.network(width=self.width)
        model.norm.mean.copy_(torch.from_numpy(mean.astype(np.float32)).view(1, 4, 1, 1))
        model.norm.std.copy_(torch.from_numpy(std.astype(np.float32)).view(1, 4, 1, 1))
        gen = torch.Generator().manual_seed(self.seed)
        xt, yt = torch.from_numpy(x), torch.from_numpy(y)
        opt = torch.optim.Adam(model.parameters(), lr=self.learning_rate)
        loss_fn = nn.CrossEntropyLoss(ignore_index=IGNORE)
        model.train()
        self.history = []
        with _fixed_threads(TRAIN_THREADS):  # scheduler-independent float reductions
            for _ in range(self.epochs):
                order = torch.randperm(len(xt), generator=gen)
                total = 0.0
                for i in range(0, len(order), self.batch_size):
                    idx = order[i : i + self.batch_size]
                    xb, yb = xt[idx], yt[idx]
                    flips = torch.randint(0, 2, (2,), generator=gen)
                    if flips[0]:
                        xb, yb = xb.flip(-1), yb.flip(-1)
                    if flips[1]:
                        xb, yb = xb.flip(-2), yb.flip(-2)
                    opt.zero_grad(set_to_none=True)
                    loss = loss_fn(model(xb), yb)
                    loss.backward()
                    opt.step()
                    total += float(loss.detach()) * len(idx)
                self.history.append(total / len(xt))
        model.eval()
        self.model = model

    def _predict_proba(self, image: np.ndarray) -> np.ndarray:
        import torch

        self.model.eval()

        def forward(batch: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                return torch.softmax(self.model(torch.from_numpy(batch)), dim=1)[:, 1].numpy()

        return self.tiled(image, forward)

    def work_units(self, shape: tuple[int, int]) -> float:
        """Tiles the stitching runs (overlapping, stride ``tile/2``)."""
        hp, wp = max(shape[0], self.tile), max(shape[1], self.tile)
        stride = self.tile // 2
        return float(
            len(tile_origins(hp, self.tile, stride)) * len(tile_origins(wp, self.tile, stride))
        )

    def tiled(self, image: np.ndarray, forward) -> np.ndarray:
        """:func:`tiled` with this model's tile size."""
        return tiled(image, forward, self.tile)

    def _save_weights(self, directory: Path) -> None:
        from safetensors.torch import save_file

        state = {k: v.detach().contiguous() for k, v in self.model.state_dict().items()}
        save_file(state, str(directory / WEIGHTS_FILE), metadata={"classifier": self.name})

    def _load_weights(self, directory: Path) -> None:
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        path = directory / WEIGHTS_FILE
        if not path.is_file():
            raise ModelFileError(f"{directory}: no {WEIGHTS_FILE}")
        try:
            state = load_file(str(path))
        except (SafetensorError, OSError, ValueError) as exc:
            raise ModelFileError(f"{path}: not a readable safetensors file ({exc})") from None
        model = self.network(width=self.width)
        check_state_dict(state, model.state_dict(), path)
        model.load_state_dict(state, strict=True)
        model.eval()
        self.model = model


@CLASSIFIERS.register("unet-uavsar")
class UavsarUNetClassifier(_UNetClassifier):
    name = "unet-uavsar"
    summary = (
        "compact classic U-Net (conv-conv-pool encoder, transpose-conv decoder, skip connections)"
    )
    architecture = "uavsar"
    levels = 3


@CLASSIFIERS.register("unet-xception")
class XceptionUNetClassifier(_UNetClassifier):
    name = "unet-xception"
    summary = (
        "Xception-style U-Net (separable convs, residual down/up blocks) as in the Keras example"
    )
    architecture = "xception"
    levels = 4
