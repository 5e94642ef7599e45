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


def test_nodata_pixels_do_not_count_by_hand():
    # integer masks (any non-zero is True) and an integer validity mask, as files deliver them
    pred = np.array([[2, 1, 0], [0, 1, 1]])
    true = np.array([[1, 0, 0], [1, 2, 1]])
    valid = np.array([[1, 1, 0], [1, 1, 0]])  # the right column is nodata
    # valid pixels: (0,0) TP, (0,1) FP, (1,0) FN, (1,1) TP -> tp 2, fp 1, fn 1, tn 0
    c = Confusion.from_masks(pred, true, valid)
    assert c.as_dict() == {"tp": 2, "fp": 1, "fn": 1, "tn": 0}
    # without the validity mask the right column counts: (0,2) TN, (1,2) TP
    assert Confusion.from_masks(pred, true).as_dict() == {"tp": 3, "fp": 1, "fn": 1, "tn": 1}


def test_metrics_keys_and_background_by_hand():
    m = Confusion(tp=2, fp=1, fn=3, tn=4).metrics()
    assert set(m) == {
        "accuracy",
        "precision",
        "recall",
        "iou",
        "precision_background",
        "recall_background",
        "iou_background",
    }
    # background: its true positives are the 4 TN; predicted background = tn + fn = 7
    assert m["precision_background"] == pytest.approx(4 / 7)
    assert m["recall_background"] == pytest.approx(4 / 5)  # true background = tn + fp
    assert m["iou_background"] == pytest.approx(4 / 8)
    assert m["accuracy"] == pytest.approx(6 / 10)
