"""Shared test helpers (importable because pytest's pythonpath includes tests/)."""

FAST_KWARGS = {
    "unet-uavsar": {"epochs": 1, "tile": 32, "width": 4},
    "unet-xception": {"epochs": 1, "tile": 32, "width": 4},
}
"""Constructor arguments that keep the U-Nets fast in tests."""


def ramp(*shape: int):
    """A non-constant float32 array in 0..0.5 (files with constant images are refused on read)."""
    import numpy as np

    n = int(np.prod(shape))
    return np.linspace(0.0, 0.5, n, dtype=np.float32).reshape(shape)
