"""Procedural volcanic scenes: the built-in default data (static), and moving worlds."""

from dyntarget.synth.dynamic import (
    CloudSpec,
    TruthCache,
    VentSpec,
    Wind,
    World,
    WorldFrame,
    WorldSpec,
    generate_sequences,
    sample_strip,
    sample_world,
    truth_provider,
    with_heights,
    world_sequence,
)
from dyntarget.synth.noise import fractal_noise
from dyntarget.synth.volcano import SceneParams, generate_scene, generate_scenes, sample_params

__all__ = [
    "CloudSpec",
    "SceneParams",
    "TruthCache",
    "VentSpec",
    "Wind",
    "World",
    "WorldFrame",
    "WorldSpec",
    "fractal_noise",
    "generate_scene",
    "generate_scenes",
    "generate_sequences",
    "sample_params",
    "sample_strip",
    "sample_world",
    "truth_provider",
    "with_heights",
    "world_sequence",
]
