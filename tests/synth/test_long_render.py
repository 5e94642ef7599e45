"""Rendering a long world lazily: only what a window needs, the same pixels as an eager render."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dyntarget.synth.dynamic import GROUND_BLOCK, VentSpec, Wind, World, WorldSpec
from dyntarget.synth.strip import long_strip_spec
from dyntarget.synth.strip_world import LongStrip

GSD = 8.0


def _spec(vents, size=128) -> WorldSpec:  # wind from the west
    return WorldSpec(seed=11, size=size, gsd=GSD, wind=Wind(8.0, 270.0), vents=tuple(vents))


def test_lazy_frames_equal_one_eager_render_of_the_whole_strip():
    # 20 km strip, 2500 x 256 px: small enough to render at once (the eager reference)
    spec, window = long_strip_spec(4, 20.0, plumes=3, wind_mps=7.0, wind_from_deg=200.0)
    spec = replace(spec, tile=512)  # smaller noise tiles: quicker to build, the same code paths
    strip = LongStrip(spec, window, truth_step_s=0.0)
    t = 31.0
    eager = World(spec).render(t, window)
    assert eager.mask.any()  # the plumes are there to compare
    # frames as a pass asks for them: bottom first, half overlapping, across ground bands
    for top in range(2500 - 256, 1000, -128 - 5):
        frame = strip.image_at(t, top, top + 256)
        np.testing.assert_array_equal(frame, eager.image[:, top : top + 256])
        np.testing.assert_array_equal(
            strip.label_rows(t, top, top + 256), eager.mask[top : top + 256]
        )


def test_ground_from_bands_equals_the_ground_of_the_window_itself():
    spec, _ = long_strip_spec(2, 30.0, plumes=2)
    world = World(replace(spec, tile=512))
    for r0, h in [(0, 1), (5, GROUND_BLOCK), (GROUND_BLOCK - 1, 2), (3000, 300), (-70, 90)]:
        banded = world._ground((0, r0, 256, h))
        direct = world._ground_window((0, r0, 256, h))  # no bands, no cache
        np.testing.assert_array_equal(banded, direct)


def test_a_far_vent_changes_nothing_near_another():
    # vent 0 alone, and with a second vent 40 km (40 world sizes) away: the same pixels near
    # vent 0 (its cone, lava and plume do not reach that far; the draws are per vent)
    a = VentSpec(x=40.0, y=64.0, eruption_age_s=900.0, source_sigma_m=80.0, pulsation=0.3)
    far = VentSpec(x=40.0, y=64.0 + 5000.0, eruption_age_s=900.0)
    window = (0, 0, 128, 128)
    alone = World(_spec([a])).render(20.0, window)
    both = World(_spec([a, far])).render(20.0, window)
    assert alone.mask.any()
    np.testing.assert_array_equal(both.image, alone.image)
    np.testing.assert_array_equal(both.tau, alone.tau)


def test_a_vent_downwind_does_not_strip_the_texture_of_a_plume_upwind_of_it():
    # wind from the west (blowing east, +x). Vent A's plume runs east along row 100; vent B
    # sits further east (every pixel of A's plume is upwind of B) and 200 rows south, so
    # B's plume, going east from B, never reaches A's. A's optical depth must be what it
    # is with A alone; before the fix the texture amplitude was the smallest over all vents,
    # zero upwind of B, so A's plume lost its texture.
    a = VentSpec(x=40.0, y=100.0, eruption_age_s=1200.0, source_sigma_m=60.0)
    b = VentSpec(x=600.0, y=300.0, eruption_age_s=1200.0, source_sigma_m=60.0)
    window = (20, 60, 400, 80)
    alone = World(_spec([a], size=512)).truth(30.0, window)[1]
    both = World(_spec([a, b], size=512)).truth(30.0, window)[1]
    assert (alone > 0.35).sum() > 500  # a plume, far enough downwind to be textured
    np.testing.assert_allclose(both, alone, rtol=1e-6, atol=1e-7)
    # and the texture is there: along the plume's axis, far downwind, the optical depth
    # varies by more than the smooth envelope alone would (a puff train without texture
    # changes by < 5 % over 10 px there)
    axis = alone[100 - 60, 250 - 20 : 350 - 20]
    assert np.abs(np.diff(axis) / axis[1:]).max() > 0.05
