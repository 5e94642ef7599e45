"""Perception: plume classifiers (registry ``CLASSIFIERS``) and denoising."""

from dyntarget.perceive import pixel, threshold, unet  # noqa: F401  (register the classifiers)
from dyntarget.perceive.base import (
    CLASSIFIERS,
    Classifier,
    load_classifier,
    make_classifier,
    read_metadata,
)

__all__ = ["CLASSIFIERS", "Classifier", "load_classifier", "make_classifier", "read_metadata"]
