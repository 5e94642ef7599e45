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
training tiles with random flips; seeded, deterministic on CPU for a fixed thread count.
Weights are saved with safetensors.

Prediction (:meth:`_UNetClassifier.tiled`, shared by PyTorch and ONNX Runtime) has two
stitchings:

* ``"halo"`` (default): the networks are fully convolutional, so the image (padded at
  the bottom/right to a multiple of the total downsampling factor ``2**levels``) is
  predicted in one pass when it fits :data:`DEFAULT_MEMORY_MIB`, else in large windows
  whose origins sit on multiples of that factor, each with a halo of at least the
  network's receptive-field radius (``receptive_radius()`` of each network), keeping only the centre.
  Normalisation uses the per-band statistics stored in the model (never per-tile
  statistics), and the windows stop at the image's edge, so each pixel sees exactly
  the context and the zero padding of a whole-image pass: the result equals one
  whole-image pass to float32 rounding (tested).
* ``"blend"``: the former stitching, ``tile`` px tiles at stride ``tile/2`` blended with
  a smooth window (each pixel computed about four times).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch import nn

from dyntarget.errors import InvalidParameterError, ModelFileError
from dyntarget.perceive.base import CLASSIFIERS, Classifier

WEIGHTS_FILE = "model.safetensors"
STITCHINGS = ("halo", "blend")
DEFAULT_STITCH = "halo"
DEFAULT_MEMORY_MIB = 1024.0
"""Budget for one network pass's activations in ``"halo"`` stitching (estimated, MiB)."""
IGNORE = -1
"""Target value of nodata pixels: left out of the loss."""
_GLOBAL_RNG_LOCK = threading.Lock()


def _bn_relu_conv(cin: int, cout: int) -> list[nn.Module]:
    return [
        nn.Conv2d(cin, cout, 3, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    ]


class _Normalise(nn.Module):
    def __init__(self, channels: int = 4) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(1, channels, 1, 1))
        self.register_buffer("std", torch.ones(1, channels, 1, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std


class UavsarUNet(nn.Module):
    """Classic compact U-Net (conv-conv-pool encoder, transpose-conv decoder, skips)."""

    levels = 3

    @classmethod
    def receptive_radius(cls) -> int:
        """Input pixels on each side an output pixel can depend on (an upper bound).

        At a level of stride ``j`` a 3x3 conv adds ``j``, a 2x2 stride-2 pool adds ``j``
        and a 2x2 stride-2 transpose conv ``j/2`` (counted as ``j`` here): encoder and
        decoder ``3 j`` per level, bottleneck ``2 * 2**levels``.
        """
        return 2 * (3 * (2**cls.levels - 1)) + 2 * 2**cls.levels

    def __init__(self, width: int = 16, in_channels: int = 4, classes: int = 2) -> None:
        super().__init__()
        self.norm = _Normalise(in_channels)
        ch = [width, 2 * width, 4 * width]
        self.enc = nn.ModuleList()
        cin = in_channels
        for c in ch:
            self.enc.append(nn.Sequential(*_bn_relu_conv(cin, c), *_bn_relu_conv(c, c)))
            cin = c
        self.pool = nn.MaxPool2d(2)
        self.bottleneck = nn.Sequential(
            *_bn_relu_conv(ch[-1], 2 * ch[-1]), *_bn_relu_conv(2 * ch[-1], 2 * ch[-1])
        )
        self.up = nn.ModuleList()
        self.dec = nn.ModuleList()
        cin = 2 * ch[-1]
        for c in reversed(ch):
            self.up.append(nn.ConvTranspose2d(cin, c, 2, stride=2))
            self.dec.append(nn.Sequential(*_bn_relu_conv(2 * c, c), *_bn_relu_conv(c, c)))
            cin = c
        self.head = nn.Conv2d(ch[0], classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.norm(x)
        skips = []
        for enc in self.enc:
            x = enc(x)
            skips.append(x)
            x = self.pool(x)
        x = self.bottleneck(x)
        for up, dec, skip in zip(self.up, self.dec, reversed(skips), strict=True):
            x = dec(torch.cat([up(x), skip], dim=1))
        return self.head(x)


class _SeparableConv(nn.Sequential):
    def __init__(self, cin: int, cout: int) -> None:
        super().__init__(
            nn.Conv2d(cin, cin, 3, padding=1, groups=cin, bias=False), nn.Conv2d(cin, cout, 1)
        )


class XceptionUNet(nn.Module):
    """Xception-style U-Net of the Keras segmentation example (residual blocks, no long skips)."""

    levels = 4

    @classmethod
    def receptive_radius(cls) -> int:
        """Input pixels on each side an output pixel can depend on (an upper bound).

        Entry 3x3 stride-2 conv: 1. Each down block at stride ``j`` (2, 4, 8): two
        depthwise 3x3 and a 3x3 max pool, ``3 j``. Each up block at stride ``j``
        (16, 8, 4, 2): two 3x3 transpose convs ``2 j``, then nearest 2x upsampling
        (``j/2``). Head 3x3 conv: 1. The 1x1 residual paths reach less far.
        """
        down = 3 * (2 + 4 + 8)
        up = 2 * (16 + 8 + 4 + 2) + (8 + 4 + 2 + 1)
        return 1 + down + up + 1

    def __init__(self, width: int = 16, in_channels: int = 4, classes: int = 2) -> None:
        super().__init__()
        self.norm = _Normalise(in_channels)
        self.entry = nn.Sequential(
            nn.Conv2d(in_channels, 2 * width, 3, stride=2, padding=1),
            nn.BatchNorm2d(2 * width),
            nn.ReLU(),
        )
        self.down = nn.ModuleList()
        self.down_res = nn.ModuleList()
        prev = 2 * width
        for c in (2 * width, 4 * width, 8 * width):
            self.down.append(
                nn.Sequential(
                    nn.ReLU(),
                    _SeparableConv(prev, c),
                    nn.BatchNorm2d(c),
                    nn.ReLU(),
                    _SeparableConv(c, c),
                    nn.BatchNorm2d(c),
                    nn.MaxPool2d(3, stride=2, padding=1),
                )
            )
            self.down_res.append(nn.Conv2d(prev, c, 1, stride=2))
            prev = c
        self.upb = nn.ModuleList()
        self.up_res = nn.ModuleList()
        for c in (8 * width, 4 * width, 2 * width, width):
            self.upb.append(
                nn.Sequential(
                    nn.ReLU(),
                    nn.ConvTranspose2d(prev, c, 3, padding=1),
                    nn.BatchNorm2d(c),
                    nn.ReLU(),
                    nn.ConvTranspose2d(c, c, 3, padding=1),
                    nn.BatchNorm2d(c),
                    nn.Upsample(scale_factor=2, mode="nearest"),
                )
            )
            self.up_res.append(
                nn.Sequential(nn.Upsample(scale_factor=2, mode="nearest"), nn.Conv2d(prev, c, 1))
            )
            prev = c
        self.head = nn.Conv2d(width, classes, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.entry(self.norm(x))
        for block, res in zip(self.down, self.down_res, strict=True):
            x = block(x) + res(x)
        for block, res in zip(self.upb, self.up_res, strict=True):
            x = block(x) + res(x)
        return self.head(x)


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


def _pad_multiple(image: np.ndarray, multiple: int) -> np.ndarray:
    """Pad ``(C, H, W)`` at the bottom/right to multiples of ``multiple`` (reflect, or
    edge where the image is too small to reflect)."""
    h, w = image.shape[1:]
    ph, pw = -h % multiple, -w % multiple
    if ph or pw:
        mode = "reflect" if (h > ph and w > pw) else "edge"
        image = np.pad(image, ((0, 0), (0, ph), (0, pw)), mode=mode)
    return image


def blend_window(tile: int) -> np.ndarray:
    """Smooth, strictly positive 2-D weight for blending overlapping tiles."""
    w = np.hanning(tile + 2)[1:-1]
    return np.outer(w, w).astype(np.float32) + 1e-3


class _UNetClassifier(Classifier):
    network: type[nn.Module]

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
        multiple = 2**self.network.levels
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
        self.model.eval()

        def forward(batch: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                return torch.softmax(self.model(torch.from_numpy(batch)), dim=1)[:, 1].numpy()

        return self.tiled(image, forward)

    # -- stitching (shared by the PyTorch and ONNX runtimes) -------------------------
    stitch: str = DEFAULT_STITCH
    """``"halo"`` or ``"blend"``; an inference setting, not stored in the model file."""
    memory_mib: float = DEFAULT_MEMORY_MIB
    """Activation budget of one pass in ``"halo"`` stitching (MiB)."""

    def set_stitching(
        self, stitch: str = DEFAULT_STITCH, *, memory_mib: float = DEFAULT_MEMORY_MIB
    ) -> _UNetClassifier:
        """Choose how prediction covers the image (see the module docstring); returns self.

        Parameters
        ----------
        stitch : {"halo", "blend"}
            Large windows with a receptive-field halo (default), or the former
            overlapping 64 px tiles blended with a smooth window.
        memory_mib : float
            Estimated activation memory allowed for one network pass (``"halo"``).

        Returns
        -------
        _UNetClassifier
            This classifier.

        Examples
        --------
        >>> from dyntarget.perceive import make_classifier
        >>> make_classifier("unet-uavsar").set_stitching("blend").stitch
        'blend'
        """
        if stitch not in STITCHINGS:
            raise InvalidParameterError(
                f"stitch: expected one of {', '.join(STITCHINGS)}, got {stitch!r}"
            )
        if isinstance(memory_mib, bool) or not float(memory_mib) > 0 or not np.isfinite(memory_mib):
            raise InvalidParameterError(
                f"memory_mib: expected a positive number of MiB, got {memory_mib!r}"
            )
        self.stitch, self.memory_mib = stitch, float(memory_mib)
        return self

    @property
    def factor(self) -> int:
        """Total downsampling factor ``2**levels``: window origins sit on its multiples."""
        return 2**self.network.levels

    @property
    def halo(self) -> int:
        """Halo width (px): the receptive-field radius rounded up to a multiple of :attr:`factor`."""
        f = self.factor
        return -(-self.network.receptive_radius() // f) * f

    def bytes_per_pixel(self) -> float:
        """Activation bytes per input pixel of one pass (sum over all layer outputs: an
        upper bound on the peak, since a pass frees most of them as it goes)."""
        cached = getattr(self, "_bytes_per_pixel", None)
        if cached is None:
            total = 0
            hooks = []

            def count(_module, _inputs, output) -> None:
                nonlocal total
                total += output.numel() * output.element_size()

            for mod in self.model.modules():
                if not list(mod.children()):
                    hooks.append(mod.register_forward_hook(count))
            try:
                with torch.inference_mode():
                    self.model.eval()(torch.zeros(1, 4, self.tile, self.tile))
            finally:
                for hk in hooks:
                    hk.remove()
            cached = self._bytes_per_pixel = total / self.tile**2
        return cached

    def windows(self, shape: tuple[int, int]) -> list[tuple[slice, slice, slice, slice]]:
        """``"halo"`` windows over a padded image of ``shape`` (multiples of :attr:`factor`).

        Each entry is ``(rows_in, cols_in, rows_keep, cols_keep)``: the input window and,
        relative to it, the centre whose prediction is kept. The kept centres partition
        the image; a window extends ``halo`` px beyond its centre except at the edge.
        """
        hp, wp = shape
        f, halo = self.factor, self.halo
        side = int(np.sqrt(self.memory_mib * 2**20 / self.bytes_per_pixel()))
        if hp * wp * self.bytes_per_pixel() <= self.memory_mib * 2**20:
            return [(slice(0, hp), slice(0, wp), slice(0, hp), slice(0, wp))]
        core = max((side - 2 * halo) // f * f, 2 * f)

        def cuts(length: int) -> list[tuple[int, int]]:
            n = -(-length // core)
            step = -(-length // (n * f)) * f  # equal parts, on multiples of f
            return [(a, min(a + step, length)) for a in range(0, length, step)]

        out = []
        for r0, r1 in cuts(hp):
            for c0, c1 in cuts(wp):
                a, b = max(r0 - halo, 0), min(r1 + halo, hp)
                c, d = max(c0 - halo, 0), min(c1 + halo, wp)
                out.append((slice(a, b), slice(c, d), slice(r0 - a, r1 - a), slice(c0 - c, c1 - c)))
        return out

    def work_units(self, shape: tuple[int, int]) -> float:
        """Input pixels the network runs over, in units of ``tile``² tiles."""
        if self.stitch == "blend":
            hp, wp = max(shape[0], self.tile), max(shape[1], self.tile)
            stride = self.tile // 2
            return float(
                len(tile_origins(hp, self.tile, stride)) * len(tile_origins(wp, self.tile, stride))
            )
        padded = _pad_multiple(np.empty((1, *shape), np.uint8), self.factor).shape[1:]
        px = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in self.windows(padded))
        return px / self.tile**2

    def tiled(self, image: np.ndarray, forward) -> np.ndarray:
        """Plume probability of ``image`` from ``forward`` (a ``(n, 4, h, w)`` batch ->
        ``(n, h, w)`` plume probability), stitched as :attr:`stitch` says."""
        if self.stitch == "blend":
            return self._blend(image, forward)
        h, w = image.shape[1:]
        img = _pad_multiple(image, self.factor)
        out = np.empty(img.shape[1:], np.float32)
        for rows, cols, keep_r, keep_c in self.windows(img.shape[1:]):
            prob = forward(np.ascontiguousarray(img[None, :, rows, cols]))[0]
            out[rows, cols][keep_r, keep_c] = prob[keep_r, keep_c]
        return out[:h, :w]

    def _blend(self, image: np.ndarray, forward) -> np.ndarray:
        """Overlapping ``tile`` px tiles at stride ``tile/2``, blended with a smooth window."""
        h, w = image.shape[1:]
        img = _pad_to(image, self.tile)
        hp, wp = img.shape[1:]
        stride = self.tile // 2
        origins = [
            (r, c)
            for r in tile_origins(hp, self.tile, stride)
            for c in tile_origins(wp, self.tile, stride)
        ]
        window = blend_window(self.tile)
        acc = np.zeros((hp, wp), np.float32)
        weight = np.zeros((hp, wp), np.float32)
        for i in range(0, len(origins), 32):
            batch = origins[i : i + 32]
            xb = np.stack([img[:, r : r + self.tile, c : c + self.tile] for r, c in batch])
            prob = forward(xb)
            for (r, c), p in zip(batch, prob, strict=True):
                acc[r : r + self.tile, c : c + self.tile] += p * window
                weight[r : r + self.tile, c : c + self.tile] += window
        return (acc / weight)[:h, :w]

    def _save_weights(self, directory: Path) -> None:
        state = {k: v.detach().contiguous() for k, v in self.model.state_dict().items()}
        save_file(state, str(directory / WEIGHTS_FILE), metadata={"classifier": self.name})

    def _load_weights(self, directory: Path) -> None:
        path = directory / WEIGHTS_FILE
        if not path.is_file():
            raise ModelFileError(f"{directory}: no {WEIGHTS_FILE}")
        try:
            state = load_file(str(path))
        except (SafetensorError, OSError, ValueError) as exc:
            raise ModelFileError(f"{path}: not a readable safetensors file ({exc})") from None
        model = self.network(width=self.width)
        expected = {k: tuple(v.shape) for k, v in model.state_dict().items()}
        got = {k: tuple(v.shape) for k, v in state.items()}
        if expected != got:
            missing = sorted(set(expected) - set(got))[:3]
            raise ModelFileError(
                f"{path}: weights do not match a {self.name} of width {self.width} (e.g. missing {missing})"
            )
        model.load_state_dict(state, strict=True)
        model.eval()
        self.model = model


@CLASSIFIERS.register("unet-uavsar")
class UnetUavsar(_UNetClassifier):
    name = "unet-uavsar"
    summary = (
        "compact classic U-Net (conv-conv-pool encoder, transpose-conv decoder, skip connections)"
    )
    network = UavsarUNet


@CLASSIFIERS.register("unet-xception")
class UnetXception(_UNetClassifier):
    name = "unet-xception"
    summary = (
        "Xception-style U-Net (separable convs, residual down/up blocks) as in the Keras example"
    )
    network = XceptionUNet
