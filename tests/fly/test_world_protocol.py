"""The one World protocol: static, moving and long strips answer the same questions."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget.scene import Scene
from dyntarget.synth.strip import long_strip_spec, strip_spec
from dyntarget.synth.strip_world import LongStrip, MovingStrip
from dyntarget.synth.worlds import StaticWorld


def _static() -> StaticWorld:
    lab = np.zeros((8, 6), bool)
    lab[1:3, 1:3] = True  # 4 px: the smaller plume, id 2
    lab[4:8, 3:6] = True  # 12 px: the larger, id 1
    img = np.full((4, 8, 6), 0.1, np.float32)
    return StaticWorld(Scene(img, label=lab, gsd=8.0))


def test_a_static_world_answers_the_protocol_without_a_synthetic_world():
    w = _static()
    assert not w.is_long and w.spec is None and w.wind is None and w.truth_step_s is None
    assert w.vent_pixels() is None
    assert w.quantize(3.7) == 3.7  # the truth never changes: no time grid
    assert w.label_rows(99.0, 1, 3).tolist() == [[False, True, True, False, False, False]] * 2
    assert w.plumes_at_start() == frozenset({1, 2})


def test_a_moving_strip_answers_the_protocol_from_its_world():
    spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    w = MovingStrip(spec, window, truth_step_s=2.0)
    assert not w.is_long and w.spec is spec and w.truth_step_s == 2.0
    assert w.quantize(2.9) == 2.0 and w.quantize(3.1) == 4.0
    # the window starts at the world's origin: vent pixels are the vents' own coordinates
    assert window[:2] == (0, 0)
    assert w.vent_pixels().tolist() == [[v.x, v.y] for v in spec.vents]
    assert w.source_rows(0.0, 4) == pytest.approx([v.y / 4 for v in spec.vents])
    label = w.truth_at(3.0).maps.label
    assert np.array_equal(w.label_rows(3.0, 10, 40), label[10:40])


@pytest.mark.slow
def test_a_long_strip_is_the_one_world_rendered_by_rows():
    w = LongStrip(*long_strip_spec(0, 100.0, plumes=2, wind_mps=5.0))
    assert w.is_long and w.quantize(0.4) == 0.0
    assert sorted(w.plumes_at_start()) == [1, 2]  # both vents erupt before t = 0
    assert w.label_rows(0.0, 100, 164).shape == (64, 256)
