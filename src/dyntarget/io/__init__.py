"""File input/output: scenes (GeoTIFF + labels), atomic writes."""

from dyntarget.io.atomic import atomic_path, write_bytes, write_text
from dyntarget.io.scenes import (
    DEFAULT_SCALE,
    read_geojson_label,
    read_label,
    read_scene,
    read_scene_dir,
    scene_ids,
    write_scene,
)
from dyntarget.io.sequences import (
    read_sequence,
    read_sequence_dir,
    sequence_ids,
    write_sequence,
)

__all__ = [
    "DEFAULT_SCALE",
    "atomic_path",
    "read_geojson_label",
    "read_label",
    "read_scene",
    "read_scene_dir",
    "read_sequence",
    "read_sequence_dir",
    "scene_ids",
    "sequence_ids",
    "write_bytes",
    "write_scene",
    "write_sequence",
    "write_text",
]
