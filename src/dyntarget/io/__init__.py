"""File input/output: scenes (GeoTIFF + labels), atomic writes.

The names below are loaded on first use (PEP 562), so importing a light
submodule (``dyntarget.io.atomic``, ``dyntarget.io.presets``) does not load rasterio.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "atomic_path": "dyntarget.io.atomic",
    "write_bytes": "dyntarget.io.atomic",
    "write_text": "dyntarget.io.atomic",
    "DEFAULT_SCALE": "dyntarget.io.scenes",
    "read_geojson_label": "dyntarget.io.scenes",
    "read_label": "dyntarget.io.scenes",
    "read_scene": "dyntarget.io.scenes",
    "read_scene_dir": "dyntarget.io.scenes",
    "scene_ids": "dyntarget.io.scenes",
    "write_scene": "dyntarget.io.scenes",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'dyntarget.io' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
