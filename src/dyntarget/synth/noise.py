"""Fractal (power-law spectrum) noise by spectral synthesis."""

from __future__ import annotations

import numpy as np


def fractal_noise(
    rng: np.random.Generator,
    shape: tuple[int, int],
    *,
    beta: float = 2.0,
    stretch: float = 1.0,
    angle: float = 0.0,
) -> np.ndarray:
    """Gaussian random field with power spectrum ``|k|^-beta``, zero mean, unit std.

    ``beta`` near 2 gives cloud-like multi-octave texture, near 3 smooth
    terrain. ``stretch > 1`` elongates features along direction ``angle``
    (radians, image x axis), as for cirrus streaks. Deterministic in ``rng``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the random phases and amplitudes.
    shape : tuple of int
        ``(H, W)`` of the field.
    beta : float
        Spectral slope.
    stretch : float
        Elongation of the features (1: isotropic).
    angle : float
        Direction of the elongation, radians from the image x axis.

    Returns
    -------
    numpy.ndarray
        ``float32 (H, W)`` field.

    Examples
    --------
    >>> f = fractal_noise(np.random.default_rng(0), (64, 64))
    >>> f.shape, f.dtype, round(float(f.std()), 6)
    ((64, 64), dtype('float32'), 1.0)
    """
    h, w = shape
    ky = np.fft.fftfreq(h)[:, None]
    kx = np.fft.rfftfreq(w)[None, :]
    c, s = np.cos(angle), np.sin(angle)
    ku = kx * c + ky * s
    kv = -kx * s + ky * c
    k = np.sqrt((ku * stretch) ** 2 + kv**2)
    k[0, 0] = np.inf
    spectrum = np.fft.rfft2(rng.standard_normal((h, w))) * k ** (-beta / 2.0)
    field = np.fft.irfft2(spectrum, s=(h, w))
    field -= field.mean()
    std = field.std()
    if std > 0:
        field /= std
    return field.astype(np.float32)
