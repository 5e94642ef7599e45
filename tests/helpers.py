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


def shared_data():
    """``../shared/data`` beside the checkout (or $DYNTARGET_SHARED_DATA); ``None`` when absent."""
    import os
    from pathlib import Path

    root = Path(
        os.environ.get(
            "DYNTARGET_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"
        )
    )
    return root if root.is_dir() else None


def write_raw_tif(path, data, **profile):
    """Write ``data (bands, H, W)`` as a GeoTIFF exactly as given (no dyntarget conventions applied)."""
    import warnings

    import rasterio

    full = {
        "driver": "GTiff",
        "height": data.shape[1],
        "width": data.shape[2],
        "count": data.shape[0],
        "dtype": data.dtype.name,
        **profile,
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(path, "w", **full) as dst:
            dst.write(data)
    return path


def synth_dir(tmp_path_factory, name: str, *, scenes: int, size: int, seed: int):
    """A scene directory made by ``dyntarget synth`` (the command users run)."""
    from dyntarget.cli import main

    d = tmp_path_factory.mktemp(name)
    args = ["synth", "--scenes", str(scenes), "--size", str(size), "--seed", str(seed)]
    assert main([*args, "--out", str(d), "--quiet"]) == 0
    return d
