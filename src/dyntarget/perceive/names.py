"""The classifier registry: each classifier's name, in the paper's Table 1 order, and its class.

The entries are lazy (``"module:Class"``): a classifier's module, and the heavy library it
uses, is imported when the classifier is first used. The registry lives apart from the
interface (:mod:`dyntarget.perceive.base`) so that reading a model directory
(:mod:`dyntarget.perceive.modelfile`) can check a classifier's name without importing the
interface that saves and loads through it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from dyntarget.registry import Registry

if TYPE_CHECKING:
    from dyntarget.perceive.base import Classifier

CLASSIFIERS: Registry[type[Classifier]] = Registry(
    "classifier",
    order=(  # the paper's Table 1 order
        "band-threshold",
        "naive-bayes",
        "logistic-regression",
        "decision-tree",
        "random-forest",
        "mlp",
        "unet-xception",
        "unet-uavsar",
    ),
)
for _name, _target in (  # lazy: the module is imported when the classifier is first used
    ("band-threshold", "dyntarget.perceive.threshold:BandThreshold"),
    ("naive-bayes", "dyntarget.perceive.pixel:NaiveBayes"),
    ("logistic-regression", "dyntarget.perceive.pixel:LogisticRegressionClassifier"),
    ("decision-tree", "dyntarget.perceive.pixel:DecisionTree"),
    ("random-forest", "dyntarget.perceive.pixel:RandomForest"),
    ("mlp", "dyntarget.perceive.pixel:MLP"),
    ("unet-xception", "dyntarget.perceive.unet:XceptionUNetClassifier"),
    ("unet-uavsar", "dyntarget.perceive.unet:UavsarUNetClassifier"),
):
    CLASSIFIERS.register_lazy(_name, _target)
