"""Moved to :mod:`dyntarget.predict.relooks` (issue 39); kept while the loop's imports move."""

from dyntarget.predict.relooks import (  # noqa: F401
    RELOOK_KM,
    Geometry3D,
    HeightEstimate,
    HeightTracker,
    Plume,
    Relook,
    Render,
    relook_seconds,
)
