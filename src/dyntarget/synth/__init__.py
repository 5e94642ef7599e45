"""Procedural volcanic scenes: the built-in default data."""

from dyntarget.synth.noise import fractal_noise
from dyntarget.synth.volcano import SceneParams, generate_scene, generate_scenes, sample_params

__all__ = ["SceneParams", "fractal_noise", "generate_scene", "generate_scenes", "sample_params"]
