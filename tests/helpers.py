"""Shared test helpers (importable because pytest's pythonpath includes tests/)."""

FAST_KWARGS = {
    "unet-uavsar": {"epochs": 1, "tile": 32, "width": 4},
    "unet-xception": {"epochs": 1, "tile": 32, "width": 4},
}
"""Constructor arguments that keep the U-Nets fast in tests."""
