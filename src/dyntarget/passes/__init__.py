"""A pass's settings, frames and record, and its GEO wiring: what the loop fills, the writers read.

:mod:`dyntarget.passes.record` holds the settings (:class:`PassConfig`), the frame plan
(:class:`FramePlan`) and the record (:class:`FrameRecord`, :class:`Flown`,
:class:`PassResult`, :class:`FrameView`); :mod:`dyntarget.passes.geo` wires the GEO
stages for a pass (:class:`~dyntarget.passes.geo.GeoSettings`,
:func:`~dyntarget.passes.geo.prepare`). The pass
loop (:mod:`dyntarget.fly`) sits above this layer and the pass's writers
(:mod:`dyntarget.view.pass_report`) above it too.
"""

from dyntarget.passes.record import (
    PARALLAX_MODES,
    Flown,
    FramePlan,
    FrameRecord,
    FrameView,
    PassConfig,
    PassResult,
    frame_plan,
)

__all__ = [
    "PARALLAX_MODES",
    "Flown",
    "FramePlan",
    "FrameRecord",
    "FrameView",
    "PassConfig",
    "PassResult",
    "frame_plan",
]
