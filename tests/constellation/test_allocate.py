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
