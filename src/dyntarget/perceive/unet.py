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
  predicted in one pass when its activations fit :data:`DEFAULT_MEMORY_MIB` (estimated
  by the peak of a PyTorch pass, :data:`PEAK_FLOATS_PER_PIXEL`; by the sum of every
  layer's output in ONNX Runtime), else in
  large windows whose origins sit on multiples of that factor, each with a halo of at
  least the network's receptive-field radius (:func:`receptive_radius`), keeping only
  the centre. Normalisation uses the per-band statistics stored in the model (never
  per-tile statistics), and the windows stop at the image's edge, so every pixel sees
  the context and the zero padding of a whole-image pass: the result equals one
  whole-image pass to float32 rounding (tested).
* ``"blend"``: the former stitching (:func:`tiled`), ``tile`` px tiles at stride
  ``tile/2`` blended with a smooth window, each pixel computed about four times.

PyTorch prediction runs a copy of the network with its batch norms folded into the
convolutions, in channels-last memory format (faster on the CPU; equal to the trained
network to float rounding, tested), on every core where a thread waiting at a barrier
gives its core back soon, else on the cores other processes leave free
(:func:`dyntarget.perceive.resources.inference_threads`).

This module imports no torch: the networks (:mod:`dyntarget.perceive.networks`)
and torch are loaded when a U-Net is built, trained or loaded natively; the
tiling (:func:`tiled`) is shared with the ONNX runtime.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np

from dyntarget.errors import InvalidParameterError, ModelFileError
from dyntarget.perceive.base import CLASSIFIERS, TRAIN_THREADS, Classifier
from dyntarget.perceive.validate import check_state_dict

WEIGHTS_FILE = "model.safetensors"
STITCHINGS = ("halo", "blend")
DEFAULT_STITCH = "halo"
DEFAULT_MEMORY_MIB = 1024.0
"""Budget for one network pass's activations in ``"halo"`` stitching (estimated, MiB)."""
IGNORE = -1
"""Target value of nodata pixels: left out of the loss."""


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
    """Start offsets of tiles of ``tile`` px covering ``length`` px (last one flush with the end).

    Parameters
    ----------
    length : int
        Length to cover, px.
    tile : int
        Tile side, px.
    stride : int
        Step between tile starts, px.

    Returns
    -------
    list of int
        The starts (``[0]`` when one tile covers ``length``).
    """
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
        mode: Literal["reflect", "edge"] = "reflect" if (h > ph and w > pw) else "edge"
        image = np.pad(image, ((0, 0), (0, ph), (0, pw)), mode=mode)
    return image


def _pad_multiple(image: np.ndarray, multiple: int) -> np.ndarray:
    """Pad ``(C, H, W)`` at the bottom/right to multiples of ``multiple`` (reflect, or
    edge where the image is too small to reflect)."""
    h, w = image.shape[1:]
    ph, pw = -h % multiple, -w % multiple
    if ph or pw:
        mode: Literal["reflect", "edge"] = "reflect" if (h > ph and w > pw) else "edge"
        image = np.pad(image, ((0, 0), (0, ph), (0, pw)), mode=mode)
    return image


def receptive_radius(architecture: str) -> int:
    """Input pixels on each side that one output pixel of a network can depend on.

    An upper bound, summed layer by layer along the deepest path; a layer at
    stride ``j`` (``j`` input pixels per feature pixel) reaches ``j`` further per
    unit of kernel half-width.

    * ``uavsar`` (3 levels): per encoder level at stride ``j`` two 3x3 convs and a
      2x2 stride-2 max pool, ``3 j``; bottleneck two 3x3 convs at ``j = 8``; per
      decoder level a 2x2 stride-2 transpose conv (``j``, generously) and two 3x3
      convs: ``3 * (1+2+4) + 16 + 3 * (1+2+4) = 58``.
    * ``xception`` (4 levels): entry 3x3 stride-2 conv 1; per down block at stride
      ``j`` = 2, 4, 8 two depthwise 3x3 convs and a 3x3 max pool, ``3 j``; per up block
      at ``j`` = 16, 8, 4, 2 two 3x3 transpose convs ``2 j`` and a nearest 2x upsampling
      (``j/2``); head 3x3 conv 1; the 1x1 residual paths reach less far:
      ``1 + 42 + 60 + 15 + 1 = 119``.

    Checked against the gradient of a randomly initialised network in the tests.

    Parameters
    ----------
    architecture : str
        ``"uavsar"`` or ``"xception"``.

    Returns
    -------
    int
        The radius in input pixels.

    Examples
    --------
    >>> receptive_radius("uavsar"), receptive_radius("xception")
    (58, 119)
    """
    if architecture == "uavsar":
        levels = (1, 2, 4)
        return 3 * sum(levels) + 2 * 8 + 3 * sum(levels)
    if architecture == "xception":
        return 1 + 3 * (2 + 4 + 8) + 2 * (16 + 8 + 4 + 2) + (8 + 4 + 2 + 1) + 1
    raise InvalidParameterError(
        f"architecture: expected 'uavsar' or 'xception', got {architecture!r}"
    )


def blend_window(tile: int) -> np.ndarray:
    """Smooth, strictly positive 2-D weight for blending overlapping tiles.

    Parameters
    ----------
    tile : int
        Tile side, px.

    Returns
    -------
    numpy.ndarray
        ``float32 (tile, tile)`` Hann window product, plus 1e-3.
    """
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


def check_stitching(stitch: str, memory_mib: float) -> tuple[str, float]:
    """Validate a stitching name and memory budget; returns them (budget as float).

    Parameters
    ----------
    stitch : str
        ``"halo"`` or ``"blend"``.
    memory_mib : float
        Activation budget of one pass, MiB (positive, finite).

    Returns
    -------
    stitch : str
        The stitching.
    memory_mib : float
        The budget.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For another stitching or a budget that is not a positive number.
    """
    if stitch not in STITCHINGS:
        raise InvalidParameterError(
            f"stitch: expected one of {', '.join(STITCHINGS)}, got {stitch!r}"
        )
    try:
        budget = float(memory_mib)
    except (TypeError, ValueError):
        budget = float("nan")
    if isinstance(memory_mib, bool) or not (np.isfinite(budget) and budget > 0):
        raise InvalidParameterError(
            f"memory_mib: expected a positive number of MiB, got {memory_mib!r}"
        )
    return stitch, budget


ACTIVATION_FLOATS_PER_WIDTH = {"uavsar": 24.5, "xception": 20.0}
"""float32 activations per input pixel per unit of network width, summed over every
layer's output of one pass (an upper bound on the peak: a pass frees most of them as it
goes). Counted with forward hooks in the tests. The memory estimate of ONNX Runtime's
passes, whose arena keeps what it allocates."""

PEAK_FLOATS_PER_PIXEL = {"uavsar": (10.0, 16.0), "xception": (4.0, 32.0)}
"""``(per unit of width, constant)``: float32 values per input pixel that one PyTorch
pass of the prediction copy (:meth:`_UNetClassifier.inference_network`) holds at its
peak, with margin. The copy frees each activation once used and UNET-Xception's works in
place, so the peak is far below the sum of every layer's output
(:data:`ACTIVATION_FLOATS_PER_WIDTH`): measured as the process's resident high-water
mark above its start at 1024 px, 8.2-8.6 (Uavsar) and 3.4-5.2 (Xception) floats per pixel
per unit of width at widths 8 and 16, 1 and 2 threads (checked in the tests). With it a
1024 px image fits the default budget in one pass (18.9 GFLOP for UNET-Xception at width
16) instead of four halo windows (29.5 GFLOP)."""


class Stitching:
    """How a U-Net's prediction covers an image; needs no torch (ONNX Runtime uses it too).

    Parameters
    ----------
    tile : int
        Training tile size (px): the tile of ``"blend"`` stitching.
    factor : int
        Total downsampling factor ``2**levels``: window origins sit on its multiples.
    halo : int
        Halo width (px), at least the receptive-field radius, a multiple of ``factor``.
    bytes_per_pixel : float
        Estimated activation bytes per input pixel of one pass.
    stitch : {"halo", "blend"}
        The stitching.
    memory_mib : float
        Activation budget of one pass (MiB) for ``"halo"``.

    Examples
    --------
    Rows of the windows over a 200 x 72 px image (input rows, kept rows within them):

    >>> st = Stitching(tile=64, factor=8, halo=16, bytes_per_pixel=1000.0, memory_mib=10.0)
    >>> w = st.windows((200, 72))
    >>> len(w), [(r.start, r.stop, k.start, k.stop) for r, c, k, _ in w][::2]
    (8, [(0, 72, 0, 56), (40, 128, 16, 72), (96, 184, 16, 72), (152, 200, 16, 48)])
    >>> st.run(np.ones((4, 200, 70), np.float32), lambda b: b[:, 0] * 0.5).max()
    np.float32(0.5)
    """

    def __init__(
        self,
        *,
        tile: int,
        factor: int,
        halo: int,
        bytes_per_pixel: float,
        stitch: str = DEFAULT_STITCH,
        memory_mib: float = DEFAULT_MEMORY_MIB,
    ) -> None:
        self.stitch, self.memory_mib = check_stitching(stitch, memory_mib)
        self.tile, self.factor, self.halo = int(tile), int(factor), int(halo)
        self.bytes_per_pixel = float(bytes_per_pixel)

    @classmethod
    def for_architecture(
        cls,
        architecture: str,
        *,
        levels: int,
        width: int,
        tile: int,
        stitch: str = DEFAULT_STITCH,
        memory_mib: float = DEFAULT_MEMORY_MIB,
        peak: bool = False,
    ) -> Stitching:
        """The stitching of a ``uavsar`` / ``xception`` U-Net of ``width`` and ``levels``.

        Parameters
        ----------
        architecture : {"uavsar", "xception"}
            The network.
        levels : int
            Its down-sampling levels (the factor is ``2**levels``).
        width : int
            Its base channel count (sets the memory per pixel).
        tile : int
            Training tile size, px.
        stitch : {"halo", "blend"}
            The stitching.
        memory_mib : float
            Activation budget of one pass, MiB (``"halo"``).
        peak : bool
            Estimate a pass's memory by the PyTorch prediction copy's peak
            (:data:`PEAK_FLOATS_PER_PIXEL`) instead of the sum of every layer's output
            (:data:`ACTIVATION_FLOATS_PER_WIDTH`, ONNX Runtime's estimate).

        Returns
        -------
        Stitching
            The stitching, halo from the network's receptive-field radius.

        Examples
        --------
        >>> Stitching.for_architecture("xception", levels=4, width=16, tile=64).bytes_per_pixel
        1312.0
        >>> Stitching.for_architecture(
        ...     "xception", levels=4, width=16, tile=64, peak=True
        ... ).bytes_per_pixel
        384.0
        """
        factor = 2**levels
        if peak:
            per_width, constant = PEAK_FLOATS_PER_PIXEL[architecture]
        else:
            per_width, constant = ACTIVATION_FLOATS_PER_WIDTH[architecture], 8.0
        return cls(
            tile=tile,
            factor=factor,
            halo=-(-receptive_radius(architecture) // factor) * factor,
            bytes_per_pixel=4 * (per_width * width + constant),
            stitch=stitch,
            memory_mib=memory_mib,
        )

    def windows(self, shape: tuple[int, int]) -> list[tuple[slice, slice, slice, slice]]:
        """``"halo"`` windows over a padded image of ``shape`` (multiples of ``factor``).

        Each entry is ``(rows_in, cols_in, rows_keep, cols_keep)``: the input window
        and, relative to it, the centre whose prediction is kept. The kept centres
        partition the image; a window reaches ``halo`` px beyond its centre except at
        the image's edge. One window covers the whole image when it fits the budget.

        Parameters
        ----------
        shape : tuple of int
            The padded image's ``(H, W)``, multiples of ``factor``.

        Returns
        -------
        list of tuple of slice
            ``(rows_in, cols_in, rows_keep, cols_keep)`` per window.
        """
        hp, wp = shape
        f, halo = self.factor, self.halo
        budget = self.memory_mib * 2**20 / self.bytes_per_pixel  # input pixels per pass
        if hp * wp <= budget:
            return [(slice(0, hp), slice(0, wp), slice(0, hp), slice(0, wp))]
        core = max((int(np.sqrt(budget)) - 2 * halo) // f * f, 2 * f)

        def cuts(length: int) -> list[tuple[int, int]]:
            n = -(-length // core)
            step = -(-length // (n * f)) * f  # n equal parts, on multiples of f
            return [(a, min(a + step, length)) for a in range(0, length, step)]

        out = []
        for r0, r1 in cuts(hp):
            for c0, c1 in cuts(wp):
                a, b = max(r0 - halo, 0), min(r1 + halo, hp)
                c, d = max(c0 - halo, 0), min(c1 + halo, wp)
                out.append((slice(a, b), slice(c, d), slice(r0 - a, r1 - a), slice(c0 - c, c1 - c)))
        return out

    def padded_shape(self, shape: tuple[int, int]) -> tuple[int, int]:
        """``shape`` rounded up to multiples of ``factor`` (what ``"halo"`` runs on).

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        tuple of int
            The padded ``(H, W)``.
        """
        return (
            -(-shape[0] // self.factor) * self.factor,
            -(-shape[1] // self.factor) * self.factor,
        )

    def work_units(self, shape: tuple[int, int]) -> float:
        """Input pixels the network runs over for an image of ``shape``, in ``tile`` × ``tile`` tiles.

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        float
            Input pixels over ``tile**2`` (for ``"blend"``: the number of tiles).
        """
        if self.stitch == "blend":
            hp, wp = max(shape[0], self.tile), max(shape[1], self.tile)
            stride = self.tile // 2
            return float(
                len(tile_origins(hp, self.tile, stride)) * len(tile_origins(wp, self.tile, stride))
            )
        px = sum(
            (r.stop - r.start) * (c.stop - c.start)
            for r, c, _, _ in self.windows(self.padded_shape(shape))
        )
        return px / self.tile**2

    def run(self, image: np.ndarray, forward) -> np.ndarray:
        """Plume probability ``(H, W)`` of a ``(4, H, W)`` image.

        ``forward`` maps a ``(n, 4, h, w)`` float32 batch to ``(n, h, w)`` plume
        probability (``h, w`` multiples of ``factor`` for ``"halo"``, ``tile`` for ``"blend"``).

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` image.
        forward : callable
            The network's batch prediction.

        Returns
        -------
        numpy.ndarray
            ``float32 (H, W)`` plume probability.
        """
        if self.stitch == "blend":
            return tiled(image, forward, self.tile)
        h, w = image.shape[1:]
        img = _pad_multiple(image, self.factor)
        out = np.empty(img.shape[1:], np.float32)
        for rows, cols, keep_r, keep_c in self.windows(img.shape[1:]):
            prob = forward(np.ascontiguousarray(img[None, :, rows, cols]))[0]
            out[rows, cols][keep_r, keep_c] = prob[keep_r, keep_c]
        return out[:h, :w]


class _UNetClassifier(Classifier):
    kind = "unet"
    architecture: ClassVar[str]
    """Key of :data:`dyntarget.perceive.networks.NETWORKS`."""
    levels: ClassVar[int]
    """Down-sampling levels of the network: tiles are multiples of ``2**levels`` px."""

    def network(self, width: int):
        """A fresh, untrained network of this architecture (imports torch).

        Its initial weights come from a generator seeded with ``self.seed``, not from
        torch's global one, so networks built at once on several threads (a Dask
        worker) do not change each other's weights.

        Parameters
        ----------
        width : int
            Base channel count.

        Returns
        -------
        torch.nn.Module
            The untrained network.
        """
        from dyntarget.perceive.networks import NETWORKS, build

        return build(NETWORKS[self.architecture], width, self.seed)

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
        """Constructor arguments as JSON-able values (stored in the model's metadata).

        Returns
        -------
        dict
            ``seed``, ``epochs``, ``tile``, ``width``, ``batch_size`` and ``learning_rate``.
        """
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
        model = self.network(width=self.width)  # seeded by self.seed, thread-safe
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

    threads_used: int | None = None
    """Intra-op threads the last PyTorch prediction ran on (``None`` before one)."""

    def _predict_proba(self, image: np.ndarray) -> np.ndarray:
        import torch

        from dyntarget.perceive.resources import inference_threads

        net = self.inference_network()
        channels_last = torch.channels_last

        def forward(batch: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                x = torch.from_numpy(batch).contiguous(memory_format=channels_last)
                return torch.softmax(net(x), dim=1)[:, 1].numpy()

        # every core where OpenMP's waiting threads sleep soon (the dyntarget command's
        # setting), else the cores other processes leave free; at most torch's own
        # setting. The probabilities do not depend on the thread count (tested)
        self.threads_used = inference_threads(limit=torch.get_num_threads())
        with _fixed_threads(self.threads_used):
            return self.tiled(image, forward)

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.pop("_inference", None)  # a cache: rebuilt on first use
        return state

    def inference_network(self):
        """The copy of the network prediction runs (see ``networks.prepare_inference``).

        Its batch norms are folded into the convolutions before them and it runs
        channels-last (1.3-2x faster at 1024 px); the sums run in another order, so
        probabilities move by float rounding (up to 2.4e-6 on the 50-epoch models, no
        pixel changing class on the 38 held-out scenes). UNET-Xception's copy also skips
        six passes over its largest activations without changing a number. The trained
        network itself stays as it is, so saving, export and further training are
        unchanged. Rebuilt when ``model`` changes.

        Returns
        -------
        torch.nn.Module
            The evaluation copy (cached; do not train it).
        """
        import copy

        from dyntarget.perceive.networks import prepare_inference

        cached = getattr(self, "_inference", None)
        if cached is None or cached[0] is not self.model:
            net = prepare_inference(copy.deepcopy(self.model).eval())
            self._inference = cached = (self.model, net)
        return cached[1]

    # -- stitching (shared by the PyTorch and ONNX runtimes) -------------------------
    stitch: str = DEFAULT_STITCH
    """``"halo"`` or ``"blend"``; an inference setting, not stored in the model file."""
    memory_mib: float = DEFAULT_MEMORY_MIB
    """Activation budget of one pass in ``"halo"`` stitching (MiB)."""

    def set_stitching(
        self, stitch: str = DEFAULT_STITCH, *, memory_mib: float = DEFAULT_MEMORY_MIB
    ) -> _UNetClassifier:
        """Choose how prediction covers the image (see the module docstring).

        Parameters
        ----------
        stitch : {"halo", "blend"}
            Large windows with a receptive-field halo (default), or the former
            overlapping ``tile`` px tiles blended with a smooth window.
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
        self.stitch, self.memory_mib = check_stitching(stitch, memory_mib)
        return self

    def stitching(self) -> Stitching:
        """This model's :class:`Stitching` (tile, factor, halo, memory per pixel).

        The memory per pixel is the PyTorch prediction copy's peak
        (:data:`PEAK_FLOATS_PER_PIXEL`); ONNX Runtime builds its own with the larger
        estimate.

        Returns
        -------
        Stitching
            Built from the model's architecture, levels, width, tile and stitching settings.
        """
        return Stitching.for_architecture(
            self.architecture,
            levels=self.levels,
            width=self.width,
            tile=self.tile,
            stitch=self.stitch,
            memory_mib=self.memory_mib,
            peak=True,
        )

    def work_units(self, shape: tuple[int, int]) -> float:
        """Input pixels the network runs over for an image of ``shape``, in ``tile`` × ``tile`` tiles.

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        float
            :meth:`Stitching.work_units` of ``shape``.
        """
        return self.stitching().work_units(shape)

    def tiled(self, image: np.ndarray, forward) -> np.ndarray:
        """:meth:`Stitching.run` with this model's settings.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` image.
        forward : callable
            The network's batch prediction (see :meth:`Stitching.run`).

        Returns
        -------
        numpy.ndarray
            ``float32 (H, W)`` plume probability.
        """
        return self.stitching().run(image, forward)

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
    """The compact classic U-Net (see the module docstring), trained with PyTorch.

    Parameters
    ----------
    seed : int
        Seed of the initial weights and the training order.
    epochs : int
        Training epochs (at least 1).
    tile : int
        Training tile size, px (a multiple of ``2**levels``).
    width : int
        Channels of the first level (at least 2).
    batch_size : int
        Tiles per training batch (at least 1).
    learning_rate : float
        Adam's learning rate, in (0, 1).
    """

    name = "unet-uavsar"
    summary = (
        "compact classic U-Net (conv-conv-pool encoder, transpose-conv decoder, skip connections)"
    )
    architecture = "uavsar"
    levels = 3


@CLASSIFIERS.register("unet-xception")
class XceptionUNetClassifier(_UNetClassifier):
    """The Xception-style U-Net (see the module docstring), trained with PyTorch.

    Parameters
    ----------
    seed : int
        Seed of the initial weights and the training order.
    epochs : int
        Training epochs (at least 1).
    tile : int
        Training tile size, px (a multiple of ``2**levels``).
    width : int
        Base channel count (at least 2).
    batch_size : int
        Tiles per training batch (at least 1).
    learning_rate : float
        Adam's learning rate, in (0, 1).
    """

    name = "unet-xception"
    summary = (
        "Xception-style U-Net (separable convs, residual down/up blocks) as in the Keras example"
    )
    architecture = "xception"
    levels = 4
