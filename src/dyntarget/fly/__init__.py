"""Fly a pass: the onboard loop over a stream of look-ahead frames (see ``docs/onboard.md``).

The package holds the loop (:mod:`~dyntarget.fly.loop`), campaigns of passes
(:mod:`~dyntarget.fly.campaign`), the watch of a folder of frames
(:mod:`~dyntarget.fly.watch`) and stopping on signals (:mod:`~dyntarget.fly.signals`).
The pass's settings and record are :mod:`dyntarget.passes.record` (the names below come
from there, with the loop's entry point), the worlds it flies over
:mod:`dyntarget.synth.worlds`, its re-looks and heights :mod:`dyntarget.predict.relooks`,
its outputs :mod:`dyntarget.view.pass_report`.
"""

from dyntarget.fly.loop import fly_pass
from dyntarget.passes.record import PARALLAX_MODES, FramePlan, PassConfig, PassResult, frame_plan

__all__ = [
    "PARALLAX_MODES",
    "FramePlan",
    "PassConfig",
    "PassResult",
    "fly_pass",
    "frame_plan",
]
