"""Segmentation metrics from confusion counts.

Counts are **summed over all test pixels of a fold** (micro-averaging), so a
large scene weighs more than a small one and a scene with no plume does not
produce an undefined per-scene IoU; the tables report the mean over folds.
Empty denominators are defined: precision is 1 when nothing was predicted
positive, recall is 1 when there was nothing to find, IoU is 1 when both
prediction and truth are empty (perfect agreement on "nothing").
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dyntarget.errors import InvalidSceneError


@dataclass(frozen=True)
class Confusion:
    """Pixel confusion counts for the plume class.

    Parameters
    ----------
    tp, fp, fn, tn : int
        True positive, false positive, false negative and true negative pixel counts.
    """

    tp: int = 0
    fp: int = 0
    fn: int = 0
    tn: int = 0

    @classmethod
    def from_masks(
        cls, predicted: np.ndarray, truth: np.ndarray, valid: np.ndarray | None = None
    ) -> Confusion:
        """Counts over the pixels where ``valid`` (default: all); nodata pixels do not count.

        Parameters
        ----------
        predicted : numpy.ndarray
            Boolean predicted mask.
        truth : numpy.ndarray
            Boolean true mask, same shape.
        valid : numpy.ndarray or None
            Boolean, false on nodata.

        Returns
        -------
        Confusion
            The counts.

        Raises
        ------
        dyntarget.errors.InvalidSceneError
            When the masks differ in shape.
        """
        predicted, truth = np.asarray(predicted, bool), np.asarray(truth, bool)
        if predicted.shape != truth.shape:
            raise InvalidSceneError(
                f"predicted mask {predicted.shape} and truth {truth.shape} differ in shape"
            )
        if valid is not None:
            valid = np.asarray(valid, bool)
            predicted, truth = predicted[valid], truth[valid]
        tp = int(np.count_nonzero(predicted & truth))
        fp = int(np.count_nonzero(predicted & ~truth))
        fn = int(np.count_nonzero(~predicted & truth))
        return cls(tp, fp, fn, truth.size - tp - fp - fn)

    def __add__(self, other: Confusion) -> Confusion:
        return Confusion(
            self.tp + other.tp, self.fp + other.fp, self.fn + other.fn, self.tn + other.tn
        )

    def swapped(self) -> Confusion:
        """The counts with the classes swapped (metrics of the non-plume class).

        Returns
        -------
        Confusion
            ``tp`` and ``tn`` swapped, ``fp`` and ``fn`` swapped.
        """
        return Confusion(tp=self.tn, fp=self.fn, fn=self.fp, tn=self.tp)

    def metrics(self) -> dict[str, float]:
        """Accuracy and plume-class precision, recall and IoU (plus the same for non-plume).

        Returns
        -------
        dict of str to float
            ``accuracy``, ``precision``, ``recall`` and ``iou``, then the same
            (accuracy excepted) with a ``_background`` suffix.
        """
        return {
            **_scores(self),
            **{f"{k}_background": v for k, v in _scores(self.swapped()).items() if k != "accuracy"},
        }

    def as_dict(self) -> dict[str, int]:
        """The four counts.

        Returns
        -------
        dict of str to int
            ``tp``, ``fp``, ``fn`` and ``tn``.
        """
        return asdict(self)


def _ratio(num: int, den: int) -> float:
    return 1.0 if den == 0 else num / den


def _scores(c: Confusion) -> dict[str, float]:
    total = c.tp + c.fp + c.fn + c.tn
    return {
        "accuracy": _ratio(c.tp + c.tn, total),
        "precision": _ratio(c.tp, c.tp + c.fp),
        "recall": _ratio(c.tp, c.tp + c.fn),
        "iou": _ratio(c.tp, c.tp + c.fp + c.fn),
    }
