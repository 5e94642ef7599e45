"""Allocation: the exact bound against brute force, greedy and distributed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget.constellation.allocate import (
    Opportunities,
    bound,
    brute_force,
    distributed,
    greedy,
    pairs,
)
from dyntarget.errors import InvalidParameterError


def _random_instance(seed: int, n: int = 12) -> Opportunities:
    g = np.random.default_rng(seed)
    t = np.sort(g.uniform(0, 3000, n))
    value = np.where(g.uniform(size=n) < 0.8, g.uniform(0.5, 1.0, n), 0.0)
    return Opportunities(
        g.integers(0, 3, n), g.integers(0, 3, n), t, t - 100.0, np.maximum(value, 0.6), value
    )


@pytest.mark.parametrize("seed", range(6))
def test_bound_equals_brute_force_on_tiny_instances(seed):
    opp = _random_instance(seed)
    conflict_set = {(0, 1), (3, 4), (5, 9)}

    def conflict(a, b):
        return (min(a, b), max(a, b)) in conflict_set

    chosen, best = bound(opp, dup_window_s=600.0, conflict=conflict)
    excluded = pairs(opp, dup_window_s=600.0, conflict=conflict)
    assert best == pytest.approx(brute_force(opp.value.tolist(), excluded), abs=1e-9)
    assert not any(a in chosen and b in chosen for a, b in excluded)
    # the greedy's realized utility never beats the bound
    g = greedy(opp, dup_window_s=600.0, conflict=conflict)
    assert sum(opp.value[i] for i in g) <= best + 1e-9


def test_pairs_by_hand():
    opp = Opportunities(
        np.array([0, 1, 0]),
        np.array([0, 0, 1]),
        np.array([0.0, 500.0, 100.0]),
        np.zeros(3),
        np.ones(3),
        np.ones(3),
    )
    # 0 and 1: same eruption 500 s apart (< 600); 0 and 2: same satellite, conflicting
    assert pairs(opp, dup_window_s=600.0, conflict=lambda a, b: True) == [(0, 1), (0, 2)]
    assert pairs(opp, dup_window_s=400.0, conflict=lambda a, b: False) == []


def test_bound_refuses_large_instances():
    opp = _random_instance(0, n=30)
    with pytest.raises(
        InvalidParameterError, match="30 opportunities, more than the exact solver's 20"
    ):
        bound(opp, dup_window_s=600.0, conflict=lambda a, b: False, limit=20)


def test_greedy_prefers_value_and_avoids_duplicates():
    opp = Opportunities(
        np.array([0, 1, 2]),
        np.array([0, 0, 0]),
        np.array([0.0, 300.0, 900.0]),
        np.zeros(3),
        np.array([0.7, 0.9, 0.8]),
        np.array([0.7, 0.9, 0.8]),
    )
    # 1 (0.9) first; 0 is 300 s from it (duplicate), 2 is 600 s after it (not)
    assert greedy(opp, dup_window_s=600.0, conflict=lambda a, b: False) == [1, 2]


def test_distributed_duplicates_only_when_claims_arrive_late():
    opp = Opportunities(
        np.array([0, 1, 2]),
        np.array([0, 0, 0]),
        np.array([0.0, 100.0, 200.0]),
        np.array([-50.0, -40.0, 150.0]),
        np.ones(3),
        np.ones(3),
    )

    def late(src, t, dst):
        return t if src == dst else t + 30.0

    # sat 1 decides 10 s after sat 0's claim (not heard yet): both; sat 2 hears: yields
    assert distributed(opp, dup_window_s=600.0, conflict=lambda a, b: False, heard=late) == [0, 1]


def _never_heard(src, t, dst):  # no board: a satellite hears only itself
    return t if src == dst else float("inf")


def test_without_a_board_a_predicted_earlier_look_takes_the_overflight():
    # satellites 0 and 1 pass over eruption 0's vent 300 s apart, each having seen the
    # plume with its own look-ahead; satellite 2 passes 700 s after satellite 0
    opp = Opportunities(
        np.array([0, 1, 2]),
        np.array([0, 0, 0]),
        np.array([0.0, 300.0, 700.0]),
        np.array([-100.0, 200.0, 600.0]),
        np.ones(3),
        np.ones(3),
    )
    kw = dict(dup_window_s=600.0, conflict=lambda a, b: False, heard=_never_heard)
    # nothing predicted: each takes what its own look-ahead found (1 is a duplicate of 0)
    assert distributed(opp, **kw) == [0, 1, 2]
    looks = {0: [(0.0, 0), (300.0, 1), (700.0, 2)]}
    # by hand, in time order: 0 at 0 s taken; 1 at 300 s within 600 s of it: not; 2 at
    # 700 s, 700 s after the last taken: taken
    assert distributed(opp, predicted=looks, **kw) == [0, 2]
    # satellite 1's own look is all it knows of (0's look-ahead misses the vent): it takes it
    assert distributed(opp, predicted={0: [(300.0, 1), (700.0, 2)]}, **kw) == [0, 1]


def test_without_a_board_a_satellite_yields_to_a_look_that_saw_nothing():
    # the cost of predicting from the ephemerides alone: satellite 0's look-ahead passed
    # over the vent 300 s earlier but saw no plume (no opportunity), and satellite 1,
    # which cannot know that, yields: nobody observes
    opp = Opportunities(
        np.array([1]), np.array([0]), np.array([300.0]), np.array([200.0]), np.ones(1), np.ones(1)
    )
    kw = dict(dup_window_s=600.0, conflict=lambda a, b: False, heard=_never_heard)
    assert distributed(opp, **kw) == [0]
    assert distributed(opp, predicted={0: [(0.0, 0), (300.0, 1)]}, **kw) == []
    # a look at the same time breaks the tie by satellite number, as every satellite does
    assert distributed(opp, predicted={0: [(300.0, 0)]}, **kw) == []
    assert distributed(opp, predicted={0: [(300.0, 2)]}, **kw) == [0]
