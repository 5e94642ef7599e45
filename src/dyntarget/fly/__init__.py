"""Fly a pass: the onboard loop over a stream of look-ahead frames (see ``docs/onboard.md``)."""

from dyntarget.fly.heights import HeightEstimate
from dyntarget.fly.loop import (
    PARALLAX_MODES,
    FramePlan,
    PassConfig,
    PassResult,
    fly_pass,
    frame_plan,
)
from dyntarget.fly.world import StaticWorld, Truth, World, WorldBase, plume_ids

__all__ = [
    "PARALLAX_MODES",
    "FramePlan",
    "HeightEstimate",
    "PassConfig",
    "PassResult",
    "StaticWorld",
    "Truth",
    "World",
    "WorldBase",
    "fly_pass",
    "frame_plan",
    "plume_ids",
]
