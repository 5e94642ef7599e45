"""Moved (issue 39): the moving strips are :mod:`dyntarget.synth.strip_world`."""

from dyntarget.synth.strip_world import LongStrip, MovingStrip  # moved (issue 39)

__all__ = ["LongStrip", "MovingStrip"]
