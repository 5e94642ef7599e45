"""dyntarget: dynamic targeting of plumes from orbit.

A look-ahead wide-field image is segmented (plume / not plume), the mask is
denoised, and a trajectory is planned for an agile narrow-field sensor
(Zilberstein, Candela, Chien, JPL 2025).
"""

from dyntarget.errors import (
    DataFileError,
    DynTargetError,
    InvalidParameterError,
    InvalidSceneError,
    ModelFileError,
    UnknownNameError,
)


def _version() -> str:
    """The installed distribution's version: one source, ``pyproject.toml``, via its metadata."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("dyntarget")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str):  # Scene and BANDS on first use: `dyntarget --help` needs no numpy
    if name == "__version__":  # read on first use (importlib.metadata costs ~20 ms at start-up)
        globals()["__version__"] = value = _version()
        return value
    if name in ("BANDS", "Scene"):
        from dyntarget import scene

        return getattr(scene, name)
    raise AttributeError(f"module 'dyntarget' has no attribute {name!r}")


__all__ = [
    "BANDS",
    "DataFileError",
    "DynTargetError",
    "InvalidParameterError",
    "InvalidSceneError",
    "ModelFileError",
    "Scene",
    "UnknownNameError",
    "__version__",
]
