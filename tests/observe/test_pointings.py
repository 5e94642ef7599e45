"""Scoring a pass's pointings against the truth at each one's own time (issue 39: in observe)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from dyntarget.observe import score_pointings


def _maps(value: float, pid: int, *, rows: int = 6, cols: int = 5) -> SimpleNamespace:
    plume = np.zeros((rows, cols))
    plume[4, 2] = value
    return SimpleNamespace(
        plume=plume,
        intensity=plume * 10,
        gradient=plume * 100,
        ids=np.where(plume > 0, pid, 0),
        valid=np.ones((rows, cols), bool),
    )


def test_each_pointing_sees_the_truth_at_its_own_time_on_the_pixel_it_rounds_to():
    # the plume at strip pixel (row 4, col 2) is 0.25 at t = 1 s and 0.75 at t = 2 s
    early, late = _maps(0.25, 3), _maps(0.75, 3)
    asked = []

    def truth_at(t, r):
        asked.append((t, r))
        return (early if t < 1.5 else late), 0

    # frame top 2: frame row 1.6 -> strip row floor(1.6 + 0.5) + 2 = 4; x 2.4 -> col 2
    points = np.array([[2.4, 1.6], [2.4, 1.6], [1.0, 1.6]])
    s = score_pointings(points, [1.0, 2.0, 2.0], 2, (6, 5), truth_at)
    assert s.plume == [0.25, 0.75, 0.0]
    assert s.intensity == [2.5, 7.5, 0.0]
    assert s.plume_id == [3, 3, 0]
    assert s.rows.tolist() == [4, 4, 4] and s.cols.tolist() == [2, 2, 1]
    assert asked == [(1.0, 4), (2.0, 4), (2.0, 4)]
    assert s.totals() == (1.0, 10.0, 100.0)


def test_pointings_off_the_strip_or_on_nodata_observe_nothing():
    maps = _maps(0.5, 9)
    maps.valid[4, 2] = False
    off = np.array([[2.0, 2.0], [-1.0, 0.0], [5.0, 0.0], [0.0, 9.0]])
    s = score_pointings(off, [0.0] * 4, 2, (6, 5), lambda t, r: (maps, 0))
    assert s.inside.tolist() == [True, False, False, False]  # cols -1 and 5, row 11 off the grid
    assert s.plume == [0.0] * 4 and s.plume_id == [0] * 4


def test_a_band_of_a_long_strip_is_read_from_its_first_row():
    # truth_at returns rows 4..5 only (first row 4): strip row 4 is the band's row 0
    band = SimpleNamespace(
        plume=np.array([[0.0, 0.0, 0.5, 0.0, 0.0], [0.0] * 5]),
        intensity=np.zeros((2, 5)),
        gradient=np.zeros((2, 5)),
        ids=np.array([[0, 0, 4, 0, 0], [0] * 5]),
        valid=np.ones((2, 5), bool),
    )
    s = score_pointings(np.array([[2.0, 0.0]]), [0.0], 4, (6, 5), lambda t, r: (band, 4))
    assert s.plume == [0.5] and s.plume_id == [4]


def test_no_pointing_scores_nothing():
    s = score_pointings(np.zeros((0, 2)), [], 0, (6, 5), lambda t, r: (_maps(1.0, 1), 0))
    assert s.plume == [] and s.totals() == (0.0, 0.0, 0.0)
