"""Adapters for real public datasets (readers, converters, downloaders).

:data:`DATASETS` lists the datasets ``dyntarget datasets`` can fetch and prepare:
name -> the module with ``fetch(to, api_url=..., progress=...)``, ``prepare(source,
out, negatives=..., progress=...)`` and ``RECORD_API``, and its one-line summary.
Modules are imported on first use.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType

from dyntarget.errors import UnknownNameError


@dataclass(frozen=True)
class Dataset:
    """A fetchable dataset: its adapter module and a one-line summary.

    Parameters
    ----------
    module : str
        Adapter module (``fetch``, ``prepare``, ``RECORD_API``).
    summary : str
        Shown by ``dyntarget datasets list``.
    """

    module: str
    summary: str

    def adapter(self) -> ModuleType:
        """The adapter module (imported now).

        Returns
        -------
        types.ModuleType
            The module named by ``module``.
        """
        return importlib.import_module(self.module)


DATASETS: dict[str, Dataset] = {
    "industrial-smoke": Dataset(
        "dyntarget.datasets.industrial_smoke",
        "Mommert et al. 2020, Sentinel-2 industrial smoke plumes (Zenodo 4250706)",
    ),
}


def get_dataset(name: str) -> Dataset:
    """The dataset called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`DATASETS`.

    Returns
    -------
    Dataset
        Its adapter and summary.

    Examples
    --------
    >>> get_dataset("industrial-smoke").module
    'dyntarget.datasets.industrial_smoke'
    """
    try:
        return DATASETS[name]
    except KeyError:
        raise UnknownNameError(
            f"unknown dataset {name!r}; expected one of: {', '.join(DATASETS)}"
        ) from None
