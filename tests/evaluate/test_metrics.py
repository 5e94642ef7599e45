from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidSceneError
from dyntarget.evaluate.metrics import Confusion


def test_counts_and_metrics_by_hand():
    pred = np.array([[1, 1, 0, 0], [1, 0, 0, 0]], bool)
    true = np.array([[1, 0, 0, 0], [1, 1, 0, 0]], bool)
    c = Confusion.from_masks(pred, true)
    assert (c.tp, c.fp, c.fn, c.tn) == (2, 1, 1, 4)
    m = c.metrics()
    assert m["accuracy"] == pytest.approx(6 / 8)
    assert m["precision"] == pytest.approx(2 / 3)
    assert m["recall"] == pytest.approx(2 / 3)
    assert m["iou"] == pytest.approx(2 / 4)
    assert m["iou_background"] == pytest.approx(4 / 6)


def test_summed_over_scenes():
    a = Confusion(1, 2, 3, 4)
    assert a + Confusion(10, 20, 30, 40) == Confusion(11, 22, 33, 44)


def test_empty_denominators_defined():
    nothing = Confusion.from_masks(np.zeros((3, 3), bool), np.zeros((3, 3), bool)).metrics()
    assert nothing["precision"] == nothing["recall"] == nothing["iou"] == nothing["accuracy"] == 1.0
    missed = Confusion.from_masks(np.zeros((2, 2), bool), np.ones((2, 2), bool)).metrics()
    assert missed["precision"] == 1.0 and missed["recall"] == 0.0 and missed["iou"] == 0.0


def test_swap_symmetry():
    c = Confusion(5, 2, 3, 90)
    assert c.swapped().swapped() == c
    assert c.metrics()["accuracy"] == c.swapped().metrics()["accuracy"]


def test_shape_mismatch():
    with pytest.raises(InvalidSceneError, match="differ in shape"):
        Confusion.from_masks(np.zeros((2, 2), bool), np.zeros((2, 3), bool))
