"""The two U-Net architectures (PyTorch modules), built by :mod:`dyntarget.perceive.unet`.

Imported only when a U-Net is built, trained or loaded natively (it imports torch).
"""

from __future__ import annotations

import torch
from torch import nn


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


NETWORKS = {"uavsar": UavsarUNet, "xception": XceptionUNet}
