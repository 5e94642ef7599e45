"""Moved (issue 39): the GEO wiring of a pass is :mod:`dyntarget.passes.geo`."""

from dyntarget.passes.geo import GeoSettings  # moved (issue 39)

__all__ = ["GeoSettings"]
