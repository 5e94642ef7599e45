"""The one check that a model runs at the resolution it was trained at (``plan``, ``fly``).

``train`` records the WFOV factor and ground sample distance in the model's
``metadata.json`` (``training.factor``, ``training.wfov_gsd_m``). A run at
another resolution is said once on stderr, naming both; more than a factor of
2 apart is refused (exit 2) unless ``--force``. A model directory written before
these fields existed is said to have an unknown training resolution, and runs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from dyntarget.cli._common import log
from dyntarget.errors import InvalidParameterError

MAX_RATIO = 2.0
"""Largest training/run resolution ratio allowed without ``--force``."""


def _describe(factor: object, gsd: object) -> str:
    parts = [f"WFOV factor {factor}"] if factor is not None else []
    if isinstance(gsd, (int, float)) and math.isfinite(gsd):
        parts.append(f"{gsd:g} m GSD")
    return ", ".join(parts) or "an unknown resolution"


def check_resolution(
    model: str | None, *, factor: int, gsd: float | None, force: bool = False, what: str = "--model"
) -> None:
    """Say (once) when ``model`` runs at another resolution than it was trained at.

    Parameters
    ----------
    model : str or None
        The model directory (nothing is checked for ``None``).
    factor : int
        This run's high-res -> WFOV factor.
    gsd : float or None
        This run's WFOV ground sample distance in metres, when known.
    force : bool
        Run even when the resolutions are more than a factor of 2 apart.
    what : str
        The option that named the model, for the messages.

    Raises
    ------
    InvalidParameterError
        When they are more than a factor of 2 apart and ``force`` is false.

    Examples
    --------
    >>> check_resolution(None, factor=4, gsd=32.0)  # no model: nothing to check
    """
    if model is None:
        return
    try:
        meta = json.loads((Path(model) / "metadata.json").read_text(encoding="utf-8"))
        training = meta.get("training") or {}
    except (OSError, ValueError, AttributeError):
        return  # the model loader names what is wrong with the directory
    t_factor, t_gsd = training.get("factor"), training.get("wfov_gsd_m")
    if t_factor is None and t_gsd is None:
        log(
            f"{what} {model}: training resolution unknown (metadata.json records none); not checked"
        )
        return
    if isinstance(t_gsd, (int, float)) and gsd is not None and t_gsd > 0:
        ratio = max(gsd / t_gsd, t_gsd / gsd)
    elif isinstance(t_factor, int) and t_factor > 0:
        ratio = max(factor / t_factor, t_factor / factor)
    else:
        return
    if math.isclose(ratio, 1.0, rel_tol=1e-6):
        return
    said = (
        f"{what} {model} was trained at {_describe(t_factor, t_gsd)}; "
        f"this run is at {_describe(factor, gsd)}"
    )
    if ratio > MAX_RATIO and not force:
        raise InvalidParameterError(
            f"{said}: {ratio:g} times apart, more than {MAX_RATIO:g} "
            "(use --factor to match, or --force to run anyway)"
        )
    log(f"warning: {said} ({ratio:g} times apart)")
