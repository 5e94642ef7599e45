"""dyntarget: dynamic targeting of plumes from orbit.

A look-ahead wide-field image is segmented (plume / not plume), the mask is
denoised, and a trajectory is planned for an agile narrow-field sensor
(Zilberstein, Candela, Chien, JPL 2025).
"""

__version__ = "0.1.0"

from dyntarget.errors import (
    DataFileError,
    DynTargetError,
    InvalidParameterError,
    InvalidSceneError,
    ModelFileError,
    UnknownNameError,
)


def __getattr__(name: str):  # Scene and BANDS on first use: `dyntarget --help` needs no numpy
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
