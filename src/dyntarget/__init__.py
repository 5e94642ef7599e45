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
from dyntarget.scene import BANDS, Scene

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
