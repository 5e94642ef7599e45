"""The truth a pointing is scored against: a plume label and its two utility maps.

Computed on the **high-resolution** scene (what the NFOV sensor would see):

* intensity: the plume label times the red band (``label * image[2]``), divided by its
  maximum so it spans 0..1 per scene;
* gradient: the Sobel gradient magnitude of the intensity with a 5x5 kernel, divided by
  its maximum (0..1 per scene): high at the plume's diffuse edges and inner structure.

A core type: the worlds a pass flies over (:mod:`dyntarget.synth.worlds`) build it and
the observation stage (:mod:`dyntarget.observe`) scores against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from dyntarget.errors import InvalidSceneError
from dyntarget.scene import Scene


@dataclass(frozen=True)
class UtilityMaps:
    """High-resolution truth used for scoring: plume label and the two utility maps.

    Parameters
    ----------
    label : numpy.ndarray
        Boolean ``(H, W)`` high-resolution plume label.
    intensity : numpy.ndarray
        ``(H, W)`` float32 intensity utility, 0..1.
    gradient : numpy.ndarray
        ``(H, W)`` float32 gradient utility, 0..1.
    valid : numpy.ndarray or None
        Boolean ``(H, W)``, false on nodata; ``None`` when all pixels are valid.
    """

    label: np.ndarray
    intensity: np.ndarray
    gradient: np.ndarray
    valid: np.ndarray | None = None

    @classmethod
    def from_scene(cls, scene: Scene) -> UtilityMaps:
        """The utility maps of a labelled high-resolution scene (see the module docstring).

        Parameters
        ----------
        scene : dyntarget.scene.Scene
            The high-resolution scene, with its label.

        Returns
        -------
        UtilityMaps
            Its label, intensity and gradient maps and valid mask.

        Raises
        ------
        dyntarget.errors.InvalidSceneError
            When the scene has no label.
        """
        if scene.label is None:
            raise InvalidSceneError(
                f"scene {scene.id!r} has no label; scoring observations needs the truth"
            )
        intensity = scene.label.astype(np.float32) * scene.image[2]
        peak = float(intensity.max())
        intensity = intensity / peak if peak > 0 else intensity
        gx = cv2.Sobel(intensity, cv2.CV_32F, 1, 0, ksize=5)
        gy = cv2.Sobel(intensity, cv2.CV_32F, 0, 1, ksize=5)
        gradient = np.hypot(gx, gy)
        gpeak = float(gradient.max())
        gradient = gradient / gpeak if gpeak > 0 else gradient
        return cls(
            scene.label, intensity.astype(np.float32), gradient.astype(np.float32), scene.valid
        )
