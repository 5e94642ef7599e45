from __future__ import annotations

import os

import numpy as np
import pytest
from affine import Affine

from dyntarget.scene import Scene
from dyntarget.synth import generate_scene


@pytest.fixture(autouse=True)
def _openmp_spin_left_as_found():
    """A test that runs ``dyntarget.cli.main`` in-process (or a doctest) may set
    ``GOMP_SPINCOUNT`` (``bound_openmp_spin``): put it back, so later tests and the
    processes they start see the environment pytest started with."""
    before = os.environ.get("GOMP_SPINCOUNT")
    yield
    if before is None:
        os.environ.pop("GOMP_SPINCOUNT", None)
    else:
        os.environ["GOMP_SPINCOUNT"] = before


@pytest.fixture
def tiny_scene() -> Scene:
    """A 64x64 synthetic scene (seed 0, index 0), georeferenced."""
    return generate_scene(0, 0, size=64)[0]


@pytest.fixture
def plain_scene() -> Scene:
    """A hand-made 8x8 scene without georeferencing: bright square plume on dark ground."""
    image = np.full((4, 8, 8), 0.05, np.float32)
    image[:, 2:6, 2:6] = 0.8
    label = np.zeros((8, 8), bool)
    label[2:6, 2:6] = True
    return Scene(image, label=label, gsd=2.0, id="plain")


@pytest.fixture
def georef_scene() -> Scene:
    rng = np.random.default_rng(1)
    image = rng.uniform(0, 1, (4, 16, 12)).astype(np.float32)
    label = rng.uniform(size=(16, 12)) > 0.7
    return Scene(
        image,
        label=label,
        gsd=10.0,
        crs="EPSG:32605",
        transform=Affine(10.0, 0.0, 250000.0, 0.0, -10.0, 2150000.0),
        id="geo",
    )


@pytest.fixture(scope="session")
def tiny_scenes() -> list[Scene]:
    """Four 64x64 synthetic scenes (seed 0), shared read-only by many tests."""
    return [generate_scene(0, i, size=64)[0] for i in range(4)]


from hypothesis import settings  # noqa: E402

# Derandomised so CI runs the same examples every time; counts are in docs/reliability.md.
settings.register_profile(
    "dyntarget", max_examples=60, deadline=None, derandomize=True, print_blob=True
)
settings.load_profile("dyntarget")


def pytest_collection_modifyitems(config, items):
    """A run with ``DYNTARGET_FOREST_ISA`` forcing a kernel path this CPU cannot run (e.g.
    ``avx512`` on an AVX2-only CPU) simulates a machine this is not: every test skips, saying so."""
    forced = os.environ.get("DYNTARGET_FOREST_ISA", "").strip().lower()
    if forced in ("", "auto", "off"):
        return
    from dyntarget.perceive import compiled

    if forced in compiled.ISA_FLAGS and compiled.cpu_runs(forced):
        return
    import pytest

    why = (
        f"this CPU ({compiled.cpu_class()}) does not run that forest-kernel path"
        if forced in compiled.ISA_FLAGS
        else f"not a forest-kernel path (auto, off, {', '.join(compiled.ISA_FLAGS)})"
    )
    skip = pytest.mark.skip(
        reason=f"DYNTARGET_FOREST_ISA={forced}: {why}; the run forcing it is skipped"
    )
    for item in items:
        item.add_marker(skip)
