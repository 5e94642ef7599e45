from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def cluster():
    """The address of a dask LocalCluster with 2 single-threaded workers on loopback.

    Module-scoped on purpose: a live cluster's threads draw from the global ``random``
    module, which Hypothesis (in other test modules) reports as flaky data generation.
    """
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=False,
        protocol="tcp",
        host="127.0.0.1",
        dashboard_address=":0",
    ) as c:
        yield c.scheduler_address
