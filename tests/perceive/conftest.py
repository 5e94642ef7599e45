"""The forest kernel's own tests choose their code path themselves.

``DYNTARGET_FOREST_ISA`` (``off``, ``portable``, ``avx2``, ...) set for a whole test run
simulates a CPU without the faster paths: the classifiers, ONNX, the lean install and the
pass loop then run as they would there. The kernel's mechanics tests (its builds, cache,
compiler handling, fuzzing) force each path by argument, with the path in the test ID, so
the variable is cleared for them.
"""

from __future__ import annotations

import pytest

KERNEL_MODULES = {
    "test_compiled_forest",
    "test_compiled_edges",
    "test_kernel_cache_trust",
    "test_forest_kernel_fuzz",
    "test_ensemble",
}


@pytest.fixture(autouse=True)
def _kernel_tests_choose_their_path(request, monkeypatch):
    if request.module.__name__.rpartition(".")[2] in KERNEL_MODULES:
        monkeypatch.delenv("DYNTARGET_FOREST_ISA", raising=False)


@pytest.fixture(scope="module")
def project_forest(tiny_scenes):
    """The project's own random forest (50 trees, depth <= 14) on three tiny scenes."""
    from dyntarget.perceive import make_classifier

    model = make_classifier("random-forest", max_pixels_per_class=3000)
    return model.fit(tiny_scenes[:3])
