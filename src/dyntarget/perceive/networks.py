"""The two U-Net architectures (PyTorch modules), built by :mod:`dyntarget.perceive.unet`.

Imported only when a U-Net is built, trained or loaded natively (it imports torch).
"""

from __future__ import annotations

import functools
import itertools
import math
import threading

import torch
from torch import nn


def _bn_relu_conv(cin: int, cout: int) -> list[nn.Module]:
    return [
        nn.Conv2d(cin, cout, 3, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    ]


class _Normalise(nn.Module):
    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, channels: int = 4) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(1, channels, 1, 1))
        self.register_buffer("std", torch.ones(1, channels, 1, 1))

    def reset_parameters(self) -> None:
        self.mean.zero_()
        self.std.fill_(1.0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std


class UavsarUNet(nn.Module):
    """Classic compact U-Net (conv-conv-pool encoder, transpose-conv decoder, skips).

    Parameters
    ----------
    width : int
        Channels of the first level (``w``: levels ``w, 2w, 4w``, bottleneck ``8w``).
    in_channels : int
        Input bands.
    classes : int
        Output classes.
    """

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
        """Logits of a batch.

        Parameters
        ----------
        x : torch.Tensor
            ``(n, in_channels, h, w)`` reflectance, ``h`` and ``w`` multiples of 8.

        Returns
        -------
        torch.Tensor
            ``(n, classes, h, w)`` logits.
        """
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
    """Xception-style U-Net of the Keras segmentation example (residual blocks, no long skips).

    Parameters
    ----------
    width : int
        Base channels ``w`` (``2w, 4w, 8w`` down, ``8w, 4w, 2w, w`` up).
    in_channels : int
        Input bands.
    classes : int
        Output classes.
    """

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
        self.inference = False  # set by prepare_inference() on an evaluation copy

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits of a batch.

        Parameters
        ----------
        x : torch.Tensor
            ``(n, in_channels, h, w)`` reflectance, ``h`` and ``w`` multiples of 16.

        Returns
        -------
        torch.Tensor
            ``(n, classes, h, w)`` logits.
        """
        if self.inference:
            return self._infer(x)
        x = self.entry(self.norm(x))
        for block, res in zip(self.down, self.down_res, strict=True):
            x = block(x) + res(x)
        for block, res in zip(self.upb, self.up_res, strict=True):
            x = block(x) + res(x)
        return self.head(x)

    def _infer(self, x: torch.Tensor) -> torch.Tensor:
        # forward() with fewer passes over the activations, the same numbers bit for bit,
        # for a copy whose ReLUs work in place (prepare_inference): each residual branch
        # runs before the block that overwrites its input, sums are formed in place, and
        # an up stage upsamples once, after its sum (nearest upsampling commutes with the
        # 1x1 convolution of the residual and with the sum)
        x = self.entry(self.norm(x))
        for block, res in zip(self.down, self.down_res, strict=True):
            r = res(x)
            x = block(x).add_(r)
        for block, res in zip(self.upb, self.up_res, strict=True):
            r = res[1](x)  # type: ignore[index]
            x = block[-1](block[:-1](x).add_(r))  # type: ignore[index]
        return self.head(x)


NETWORKS = {"uavsar": UavsarUNet, "xception": XceptionUNet}


def fold_batch_norms(model: nn.Module) -> nn.Module:
    """Fold every batch norm into the convolution just before it (evaluation mode only).

    In each ``nn.Sequential`` a ``BatchNorm2d`` that follows a convolution (or a
    separable convolution, whose last layer is the pointwise one) is merged into that
    convolution's weights and bias (``torch.nn.utils.fusion.fuse_conv_bn_eval``) and
    replaced by ``nn.Identity``: one pass over the activations fewer, the same function
    up to float rounding.

    Parameters
    ----------
    model : torch.nn.Module
        A network of this module in evaluation mode; changed in place.

    Returns
    -------
    torch.nn.Module
        ``model``.

    Examples
    --------
    >>> net = build(UavsarUNet, 4, seed=0).eval()
    >>> x = torch.rand(1, 4, 32, 32)
    >>> with torch.no_grad():
    ...     before = net(x)
    ...     after = fold_batch_norms(net)(x)
    >>> bool(torch.allclose(before, after, atol=1e-5)), any(
    ...     isinstance(m, nn.BatchNorm2d) for m in net.modules())
    (True, False)
    """
    from torch.nn.utils.fusion import fuse_conv_bn_eval

    if model.training:
        raise ValueError("fold_batch_norms: the network must be in evaluation mode")
    for seq in [m for m in model.modules() if isinstance(m, nn.Sequential)]:
        names = list(seq._modules)
        for before, name in itertools.pairwise(names):
            bn, conv_owner, conv_name = seq._modules[name], seq, before
            if not isinstance(bn, nn.BatchNorm2d):
                continue
            conv = seq._modules[before]
            if isinstance(conv, _SeparableConv):
                conv_owner, conv_name = conv, list(conv._modules)[-1]
                conv = conv._modules[conv_name]
            if not isinstance(conv, (nn.Conv2d, nn.ConvTranspose2d)):
                continue
            transpose = isinstance(conv, nn.ConvTranspose2d)
            conv_owner._modules[conv_name] = fuse_conv_bn_eval(conv, bn, transpose=transpose)
            seq._modules[name] = nn.Identity()
    return model


def prepare_inference(model: nn.Module) -> nn.Module:
    """Turn an evaluation copy of a network into the one prediction runs.

    Batch norms are folded (:func:`fold_batch_norms`: the same function up to float
    rounding) and the weights and activations go channels-last, where oneDNN's
    convolutions run faster on the CPU. An :class:`XceptionUNet` also runs its ReLUs in
    place and a forward pass that computes each residual branch before the block that
    overwrites its input, forms its sums in place and upsamples each up stage once,
    after its sum instead of both terms before it; those steps change no number (tested
    bit for bit on this machine: it relies on oneDNN computing a 1x1 convolution alike at
    both resolutions) and save six passes over its largest activations. Never train the
    result: the in-place forward is for evaluation only.

    Parameters
    ----------
    model : torch.nn.Module
        A copy of a network of this module in evaluation mode; changed in place.

    Returns
    -------
    torch.nn.Module
        ``model``.

    Examples
    --------
    >>> import copy
    >>> net = build(XceptionUNet, 4, seed=0).eval()
    >>> x = torch.rand(1, 4, 32, 32)
    >>> with torch.no_grad():
    ...     before = net(x)
    ...     after = prepare_inference(copy.deepcopy(net))(x)
    >>> bool(torch.allclose(before, after, atol=1e-5))
    True
    """
    fold_batch_norms(model)
    if isinstance(model, XceptionUNet):
        for module in model.modules():
            if isinstance(module, nn.ReLU):
                module.inplace = True
        model.inference = True
    return model.to(memory_format=torch.channels_last)  # type: ignore[call-overload]


def build(network: type[nn.Module], width: int, seed: int) -> nn.Module:
    """Build ``network`` with PyTorch's default initial weights, drawn from its own generator.

    The weights are those ``torch.manual_seed(seed); network(width=width)`` gives,
    but torch's global generator is neither read nor advanced, so networks built at
    the same time on several threads (a Dask worker) cannot change each other's
    weights. The modules are created on the ``meta`` device (no draws), then each
    convolution is initialised as ``_ConvNd.reset_parameters`` does, in module order.

    Parameters
    ----------
    network : type
        :class:`UavsarUNet` or :class:`XceptionUNet`.
    width : int
        Channels of the first level.
    seed : int
        Seed of the generator the initial weights are drawn from.

    Returns
    -------
    torch.nn.Module
        The network on the CPU, in training mode.

    Examples
    --------
    >>> a, b = build(UavsarUNet, 4, seed=1), build(UavsarUNet, 4, seed=1)
    >>> all(torch.equal(a.state_dict()[k], b.state_dict()[k]) for k in a.state_dict())
    True
    """
    with torch.device("meta"):
        model = network(width=width)
    model = model.to_empty(device="cpu")
    modules = dict(model.named_modules())
    gen = torch.Generator().manual_seed(int(seed))
    with torch.no_grad():
        for name in _creation_order(network):  # type: ignore[arg-type]  # torch's init order
            module = modules[name]
            if isinstance(module, nn.modules.conv._ConvNd):
                nn.init.kaiming_uniform_(module.weight, a=math.sqrt(5), generator=gen)
                if module.bias is not None:
                    fan_in, _ = nn.init._calculate_fan_in_and_fan_out(module.weight)
                    bound = 1 / math.sqrt(fan_in) if fan_in > 0 else 0
                    nn.init.uniform_(module.bias, -bound, bound, generator=gen)
            else:
                module.reset_parameters()
    return model


@functools.cache
def _creation_order(network: type[nn.Module]) -> tuple[str, ...]:
    """Names of the modules of ``network`` holding parameters or buffers, in creation order.

    Modules are created (and initialised) in the order ``__init__`` runs, which is
    not always the order of ``named_modules()`` (a U-Net builds each ``up`` block
    next to its ``dec`` block). Found once per class from the registration hooks.
    """
    me, created = threading.get_ident(), []

    def hook(module: nn.Module, name: str, tensor: torch.Tensor | None) -> None:
        if threading.get_ident() == me:
            created.append(module)

    hooks = [
        nn.modules.module.register_module_parameter_registration_hook(hook),
        nn.modules.module.register_module_buffer_registration_hook(hook),
    ]
    try:
        with torch.device("meta"):
            model = network(width=2)
    finally:
        for h in hooks:
            h.remove()
    names = {id(m): n for n, m in model.named_modules()}
    return tuple(dict.fromkeys(names[id(m)] for m in created if id(m) in names))
