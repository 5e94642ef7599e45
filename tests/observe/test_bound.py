"""The pass's upper bound (dyntarget.observe.bound) against independent methods.

* brute force: every order of a few pixels, each started at the earliest time the real
  kinematics allow (:class:`~dyntarget.schedule.Timer`) or held until a chosen release
  time, scored at the truth's rounded time: the bound is never below the best of them,
  and equal to it where the best is worked out by hand;
* the relaxation's optimum against enumerating every assignment;
* the bound against passes flown by ``dyntarget fly`` (subprocess) on small strips.
"""

from __future__ import annotations

import itertools
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.observe.bound import (
    _prune,
    _solve,
    dual_bound,
    pixel_windows,
    upper_bound_utility,
    values_from_bands,
)
from dyntarget.schedule import OrbitGeometry, Timer, get_agility, visibility_windows

G = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=64.0)
SHAPE = (2, 2)  # strip WFOV grid; one frame of 2 rows (frame 0, acquired at pass time 0)


def _table_values(table: dict[int, np.ndarray]):
    """value_at from a table: truth time step (s) -> (2, 2) map; 0 at other times."""

    def value_at(t, r0, r1):
        return table.get(round(t), np.zeros(SHAPE))[r0:r1]

    return value_at


def _brute_force(value_at, agility, releases, repeats=False, most=None):
    """Best utility over every sequence of pixels, each started at the earliest feasible
    time after a release time chosen from ``releases`` (the loop's kinematics)."""
    h, w = SHAPE
    pixels = [(r, c) for r in range(h) for c in range(w)]
    best = 0.0
    most = most or len(pixels)
    for n in range(1, most + 1):
        seqs = itertools.product(pixels, repeat=n) if repeats else itertools.permutations(pixels, n)
        for seq in seqs:
            pts = np.array([[c, r] for r, c in seq], np.float64)
            along, cross = G.ground(pts, SHAPE)  # frame 0 = the whole strip, t_k = 0
            t_in, t_out = visibility_windows(G, agility, along, cross)
            for rel in itertools.product(releases, repeat=n):
                timer = Timer(G, agility)
                total = 0.0
                for i, (r, c) in enumerate(seq):
                    a = timer.arrival_one(float(along[i]), float(cross[i]), float(t_in[i]))
                    start = max(a, rel[i])
                    if start + agility.dwell_s > t_out[i]:
                        total = -math.inf
                        break
                    timer.take(along[i], cross[i], start)
                    total += float(value_at(start, r, r + 1)[0, c])
                best = max(best, total)
    return best


def test_pixel_windows_hold_every_window_in_the_cell():
    rng = np.random.default_rng(0)
    agility = get_agility("fast")
    shape, frame_px = (40, 16), 8
    g = OrbitGeometry(wfov_gsd_m=120.0)
    t_in, t_out = pixel_windows(g, agility, shape, frame_px)
    hw = shape[0]
    for _ in range(60):
        r, c = int(rng.integers(hw)), int(rng.integers(shape[1]))
        k = int(rng.integers(0, (hw - frame_px) // 4 + 1))  # any frame of the pass
        top = hw - frame_px - 4 * k
        # the point as a frame sees it: local row, its own geometry, shifted by t_k
        dy, dx = rng.uniform(-0.5, 0.5, 2)
        pt = np.array([[c + dx, r - top + dy]])
        along, cross = g.ground(pt, (frame_px, shape[1]))
        t_k = 4 * k * g.wfov_gsd_m / g.ground_speed  # step of 4 rows between frames
        a, b = visibility_windows(g, agility, along + g.ground_speed * t_k, cross)
        assert t_in[r, c] <= a[0] + 1e-9
        assert t_out[r, c] >= b[0] - 1e-9


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bound_is_never_below_the_best_brute_force_schedule(seed):
    rng = np.random.default_rng(seed)
    agility = get_agility("slow")
    table = {q: rng.uniform(0, 1, SHAPE) * (rng.uniform() < 0.8) for q in range(38, 44)}
    value_at = _table_values(table)
    releases = [0.0, *[q - 0.4 for q in range(38, 44)]]
    best = _brute_force(value_at, agility, releases, most=3)
    b = upper_bound_utility(value_at, SHAPE, 2, G, agility, time_step_s=1.0)
    assert best > 0
    assert b.value >= best - 1e-9
    assert b.exact


def test_bound_equals_the_best_schedule_worked_out_by_hand():
    # the plume is there for two truth steps only (40 s and 41 s): slow agility (1.1 s a
    # pointing) holds one pointing in each. Best: pixel (0, 0) at 40 s (0.9), then its
    # neighbour (0, 1) at 41 s (0.7): 1.6; the kinematics fly it too (slew to a neighbour
    # ~0.2 s), so brute force finds 1.6 as well.
    agility = get_agility("slow")
    table = {40: np.array([[0.9, 0.2], [0.1, 0.3]]), 41: np.array([[0.8, 0.7], [0.1, 0.0]])}
    value_at = _table_values(table)
    b = upper_bound_utility(value_at, SHAPE, 2, G, agility, time_step_s=1.0)
    assert b.value == pytest.approx(1.6, abs=1e-4)
    assert b.value >= 1.6
    assert _brute_force(value_at, agility, [0.0, 39.6, 40.6], most=2) == pytest.approx(1.6)


def test_bound_on_a_static_world_with_room_for_every_pixel_is_their_sum():
    # 4 pixels, each visible ~41 s, 1.1 s a pointing: all fit; bound = 0.5+0.25+0+1.0
    vals = np.array([[0.5, 0.25], [0.0, 1.0]])
    b = upper_bound_utility(
        lambda t, r0, r1: vals[r0:r1], SHAPE, 2, G, get_agility("slow"), time_step_s=None
    )
    assert b.value == pytest.approx(1.75)
    assert b.pixels == 3


def test_a_pixel_pointed_twice_is_bounded_without_distinct():
    # one pixel worth 0.5 in steps 40 and 41 only; slow: one pointing per step; the same
    # pixel twice scores 1.0 (brute force with repeats), the distinct bound says 0.5
    agility = get_agility("slow")
    one = np.array([[0.5, 0.0], [0.0, 0.0]])
    value_at = _table_values({40: one, 41: one})
    assert _brute_force(value_at, agility, [0.0, 39.6, 40.6], repeats=True, most=2) == (
        pytest.approx(1.0)
    )
    both = upper_bound_utility(value_at, SHAPE, 2, G, agility, time_step_s=1.0, distinct=False)
    once = upper_bound_utility(value_at, SHAPE, 2, G, agility, time_step_s=1.0)
    assert both.value == pytest.approx(1.0)
    assert once.value == pytest.approx(0.5)


def test_fast_agility_holds_eleven_pointings_a_second():
    # one pixel worth 1 in step 40 only, pointed again and again (not distinct):
    # 0.1 s a pointing over [39.5, 40.5] -> floor(1 / 0.1) + 1 = 11 starts
    one = np.array([[1.0, 0.0], [0.0, 0.0]])
    b = upper_bound_utility(
        _table_values({40: one}), SHAPE, 2, G, get_agility("fast"), time_step_s=1.0,
        distinct=False,
    )  # fmt: skip
    assert b.value == pytest.approx(11.0)


@pytest.mark.parametrize("seed", range(6))
def test_relaxation_optimum_matches_enumerating_every_assignment(seed):
    rng = np.random.default_rng(seed)
    n_pix, n_blk = 5, 3
    cap = rng.integers(1, 3, n_blk).astype(np.float64)
    pairs = [(p, k) for p in range(n_pix) for k in range(n_blk) if rng.uniform() < 0.7]
    p = np.array([a for a, _ in pairs])
    k = np.array([b for _, b in pairs])
    u = rng.uniform(0.01, 1.0, len(pairs))
    w = {(a, b): v for (a, b), v in zip(pairs, u, strict=True)}
    best = 0.0
    for choice in itertools.product(range(-1, n_blk), repeat=n_pix):  # -1: not flown
        if any(c >= 0 and (i, c) not in w for i, c in enumerate(choice)):
            continue
        if any(sum(c == j for c in choice) > cap[j] for j in range(n_blk)):
            continue
        best = max(best, sum(w[(i, c)] for i, c in enumerate(choice) if c >= 0))
    bound, _relax, exact = _solve(p, k, u, cap, True)
    assert exact
    assert bound == pytest.approx(best, abs=1e-7)
    assert bound >= best - 1e-12
    # any prices give a bound at least the optimum (weak duality)
    for _ in range(20):
        assert dual_bound(p, k, u, cap, rng.uniform(0, 1, n_blk)) >= best - 1e-12


@pytest.mark.parametrize("seed", range(4))
def test_pruned_candidates_keep_the_optimum_of_every_assignment(seed):
    # 8 pixels, each visible in 2 neighbouring blocks of 3, one pointing per block: a
    # block's 3 best candidates are all an optimum needs (pruning drops the others)
    rng = np.random.default_rng(10 + seed)
    n_pix, n_blk = 8, 3
    first = rng.integers(0, n_blk - 1, n_pix)
    p = np.repeat(np.arange(n_pix), 2)
    k = np.stack([first, first + 1], axis=1).ravel()
    u = rng.uniform(0.01, 1.0, len(p))
    cap = np.ones(n_blk)
    assert not _prune(p, k, u, cap).all()
    w = {(int(a), int(b)): float(v) for a, b, v in zip(p, k, u, strict=True)}
    best = 0.0
    for choice in itertools.product(range(3), repeat=n_pix):  # 0: not flown, 1/2: a block
        blocks = [first[i] + c - 1 for i, c in enumerate(choice) if c]
        if len(blocks) != len(set(blocks)):
            continue
        best = max(best, sum(w[(i, first[i] + c - 1)] for i, c in enumerate(choice) if c))
    bound, _relax, exact = _solve(p, k, u, cap, True)
    assert exact
    assert bound == pytest.approx(best, abs=1e-7)


def test_unlimited_agility_on_a_changing_world_needs_an_end_time():
    value_at = _table_values({0: np.ones(SHAPE)})
    with pytest.raises(InvalidParameterError, match="t_end_s"):
        upper_bound_utility(value_at, SHAPE, 2, G, get_agility("unlimited"), time_step_s=1.0)
    # with it: each pixel at its best over [0, 2] s (1 at 0 s, 0 after): 4 pixels x 1
    b = upper_bound_utility(
        value_at, SHAPE, 2, G, get_agility("unlimited"), time_step_s=1.0, t_end_s=2.0
    )
    assert b.value == pytest.approx(4.0)


def test_a_truth_without_a_time_step_is_refused():
    with pytest.raises(InvalidParameterError, match="time step"):
        upper_bound_utility(_table_values({}), SHAPE, 2, G, get_agility("fast"), time_step_s=0.0)


def test_values_from_bands_stitches_bands_and_zeroes_nodata():
    from types import SimpleNamespace

    def at(t, r):
        b0 = (r // 3) * 3
        vals = np.arange(b0, b0 + 3, dtype=float)[:, None].repeat(2, axis=1)
        valid = np.ones((3, 2), bool)
        valid[:, 1] = False
        return SimpleNamespace(intensity=vals, valid=valid), b0

    out = values_from_bands(at, 2)(0.0, 1, 7)
    assert out[:, 0].tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert out[:, 1].tolist() == [0.0] * 6


def _cli(*args):
    proc = subprocess.run(
        [sys.executable, "-m", "dyntarget", *args], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def _strip_bound(path, agility, factor=4):
    from dyntarget.passes.record import PassConfig, frame_plan
    from dyntarget.synth.strip_world import load_world
    from dyntarget.synth.worlds import TruthBands

    world = load_world(path)
    cfg = PassConfig(agility=agility, factor=factor)
    frames = frame_plan(world, cfg)
    truth = TruthBands(world, factor, cfg.footprint, band=frames.frame_px)
    return upper_bound_utility(
        values_from_bands(truth.at, frames.wfov_shape[1]),
        frames.wfov_shape,
        frames.frame_px,
        frames.geometry,
        get_agility(agility),
        time_step_s=world.truth_step_s,
    )


@pytest.mark.slow
def test_bound_is_above_the_passes_fly_flies_on_small_strips(tmp_path):
    pytest.importorskip("pysteps")  # --geo's nowcast
    data = tmp_path / "strips"
    # flat strips: the bound here is the flat world's (moving worlds are 3D by default)
    _cli("synth", "--strip", "--scenes", "2", "--size", "128", "--plumes", "3", "--seed", "5",
         "--flat", "--out", str(data), "--quiet")  # fmt: skip
    strips = sorted(data.glob("*.tif"))
    strips = [s for s in strips if not s.stem.endswith("_mask")]
    assert len(strips) == 2
    modes = [[], ["--geo", "--geo-latency-s", "0"]]
    if "--geo-prior" in _cli("fly", "--help"):  # the catalog baseline, once fly has it
        modes.append(["--geo-prior", "vents"])
    seen = 0
    for strip, agility in [(strips[0], "fast"), (strips[0], "slow"), (strips[1], "fast")]:
        bound = _strip_bound(strip, agility)
        for extra in modes:
            out = tmp_path / f"{strip.stem}-{agility}-{'-'.join(extra)}"
            _cli("fly", "--scene", str(strip), "--truth", "--agility", agility,
                 "--compute-budget-s", "0.05", "--no-picture", "--no-html", "--quiet",
                 "--out", str(out), *extra)  # fmt: skip
            doc = json.loads((out / "summary.json").read_text())
            assert doc["utility"] <= bound.value, (strip.stem, agility, extra, doc, bound)
            if "upper_bound_utility" in doc:  # fly writes the same bound
                assert doc["upper_bound_utility"] == pytest.approx(bound.value, abs=1e-4)
            seen += doc["utility"] > 0
    assert seen >= 4  # the passes did score: the comparison says something


def _bands(intensity):
    from types import SimpleNamespace

    band = SimpleNamespace(intensity=np.asarray(intensity, float), valid=np.ones((2, 2), bool))
    return lambda t, r: (band, 0)


def test_a_pass_bound_over_a_truth_without_utility_is_zero():
    from dyntarget.observe.bound import pass_upper_bound

    b = pass_upper_bound(
        _bands(np.zeros((2, 2))), SHAPE, 2, G, get_agility("fast"),
        time_step_s=None, distinct=True,
    )  # fmt: skip
    assert b.value == 0.0


def test_a_pass_bound_with_one_pixel_of_utility_and_unlimited_agility_is_that_pixel():
    from dyntarget.observe.bound import pass_upper_bound

    # unlimited agility, the plan ready at 0 s: one pointing at the only valuable pixel, once
    b = pass_upper_bound(
        _bands([[0.0, 0.0], [0.0, 0.75]]), SHAPE, 2, G, get_agility("unlimited"),
        time_step_s=None, distinct=True, ready_s=[0.0],
    )  # fmt: skip
    assert b.value == pytest.approx(0.75)


def test_a_pass_bound_on_a_3d_world_is_refused_naming_the_world():
    from dyntarget.observe.bound import pass_upper_bound

    with pytest.raises(InvalidParameterError, match="world 'w3' is 3D: the upper bound"):
        pass_upper_bound(
            _bands(np.zeros((2, 2))), SHAPE, 2, G, get_agility("fast"),
            time_step_s=None, distinct=True, is_3d=True, world_id="w3",
        )  # fmt: skip
