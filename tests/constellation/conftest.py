from __future__ import annotations

from pathlib import Path

import pytest

GVP = Path(__file__).resolve().parents[3] / "shared" / "data" / "gvp-holocene" / "volcanoes.csv"


@pytest.fixture
def gvp() -> Path:
    if not GVP.is_file():
        pytest.skip(f"the GVP Holocene catalog is not at {GVP}")
    return GVP


@pytest.fixture
def cli():
    """``dyntarget.cli.main`` with the constellation command registered (until the lead adds it)."""
    return run_cli


def run_cli(argv: list[str]) -> int:
    """``dyntarget.cli.main`` with the constellation command registered (until the lead adds it)."""
    import dyntarget.cli as cli
    from dyntarget.cli import constellation

    if constellation not in cli.COMMANDS:
        saved = cli.COMMANDS
        cli.COMMANDS = (*saved, constellation)
        try:
            return cli.main(argv)
        finally:
            cli.COMMANDS = saved
    return cli.main(argv)
