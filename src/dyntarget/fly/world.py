"""Moved (issue 39): the worlds a pass flies over are :mod:`dyntarget.synth.worlds`."""

from dyntarget.synth.worlds import Truth, WorldBase  # moved (issue 39)

__all__ = ["Truth", "WorldBase"]
