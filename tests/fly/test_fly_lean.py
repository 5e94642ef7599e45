"""The pass loop is part of the lean onboard path: importing it loads nothing heavy."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("torch", "sklearn", "skops", "dask", "distributed", "matplotlib", "plotly", "pytest")


def test_importing_the_pass_loop_loads_nothing_heavy():
    code = (
        "import dyntarget.fly, dyntarget.fly.loop, dyntarget.fly.watch, dyntarget.fly.campaign\n"
        "import dyntarget.view.pass_report, dyntarget.synth.strip_world, dyntarget.passes.geo\n"
        "import dyntarget.cli.fly\n"
        "import json, sys\n"
        f"print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
