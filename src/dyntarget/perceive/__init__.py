"""Perception: plume classifiers (registry ``CLASSIFIERS``, lazy: a classifier's module,
and torch or scikit-learn with it, is imported when it is first used)."""

from dyntarget.perceive.base import CLASSIFIERS, Classifier, Predictor, make_classifier
from dyntarget.perceive.modelfile import load_classifier, read_metadata

__all__ = [
    "CLASSIFIERS",
    "Classifier",
    "Predictor",
    "load_classifier",
    "make_classifier",
    "read_metadata",
]
