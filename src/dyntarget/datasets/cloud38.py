"""38-Cloud patches (Mohajerani & Saeedi, IGARSS 2019): Landsat 8, one file per band, cloud mask.

A patch folder holds ``red.tif``, ``green.tif``, ``blue.tif``, ``nir.tif`` (uint16
Landsat 8 digital numbers, bands 4, 3, 2, 5) and ``gt.tif`` (255 = cloud). The
dataset's own tree names them ``train_red/red_patch_...TIF`` etc.; give the four
band files and the mask explicitly for that layout.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from dyntarget.io import read_label
from dyntarget.io.sensors import read_band_files
from dyntarget.scene import Scene

BAND_FILES = ("red.tif", "green.tif", "blue.tif", "nir.tif")
MASK_FILE = "gt.tif"
GSD_M = 30.0


def read_patch(directory: str | os.PathLike[str]) -> Scene:
    """Read a 38-Cloud patch folder as a labelled scene (Landsat 8 TOA reflectance, 30 m).

    Parameters
    ----------
    directory : str or os.PathLike
        The patch folder, holding the four band files and the ground-truth mask.

    Returns
    -------
    dyntarget.scene.Scene
        The 4-band scene with its cloud label, id = the folder's name, GSD 30 m.
    """
    d = Path(directory)
    scene = read_band_files([d / f for f in BAND_FILES], preset="landsat8", scene_id=d.name)
    label = read_label(d / MASK_FILE, shape=scene.shape, crs=scene.crs, transform=scene.transform)
    return replace(scene, label=label, gsd=GSD_M)
