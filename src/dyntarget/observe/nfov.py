"""NFOV observation simulator and the paper's utility metrics (Table 2 columns).

Utility maps are computed on the **high-resolution** scene (the truth the
NFOV sensor would see):

* intensity: the plume label overlaid on the blue band (``label * blue``),
  divided by its maximum so it spans 0..1 per scene;
* gradient: the Sobel gradient magnitude of the intensity with a 5x5 kernel,
  divided by its maximum (0..1 per scene) — high at the plume's diffuse edges
  and inner structure.

A pointing at WFOV pixel ``(x, y)`` (rounded to the nearest pixel centre)
observes the high-resolution footprint under ``footprint x footprint`` WFOV
pixels centred there (default 1: exactly the ``factor x factor`` block under
one WFOV pixel). Pointings outside the image observe nothing and are
dropped, and so are pointings on nodata; several pointings at the same WFOV pixel count once.

Metrics per trajectory: pixels observed (distinct pointings), ratio plume
(mean plume fraction of the observed footprints), intensity and gradient
(mean utility over the observed footprints). Empty trajectories score 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.scene import Scene, block_mean, check_factor
from dyntarget.trajectory import Trajectory


@dataclass(frozen=True)
class UtilityMaps:
    """High-resolution truth used for scoring: plume label and the two utility maps."""

    label: np.ndarray
    intensity: np.ndarray
    gradient: np.ndarray
    valid: np.ndarray | None = None

    @classmethod
    def from_scene(cls, scene: Scene) -> UtilityMaps:
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


@dataclass(frozen=True)
class ObservationMetrics:
    """What the NFOV sensor observed along one trajectory."""

    pixels_observed: int
    ratio_plume: float
    intensity: float
    gradient: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def observed_pixels(trajectory: Trajectory, wfov_shape: tuple[int, int]) -> np.ndarray:
    """Distinct WFOV pixels ``(row, col)`` hit by the pointings, in first-visit order."""
    if len(trajectory) == 0:
        return np.zeros((0, 2), np.int64)
    cols = np.floor(trajectory.points[:, 0] + 0.5).astype(np.int64)
    rows = np.floor(trajectory.points[:, 1] + 0.5).astype(np.int64)
    h, w = wfov_shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rc = np.column_stack([rows[inside], cols[inside]])
    _, first = np.unique(rc[:, 0] * w + rc[:, 1], return_index=True)
    return rc[np.sort(first)]


def observe(
    trajectory: Trajectory,
    truth: Scene | UtilityMaps,
    *,
    factor: int,
    footprint: int = 1,
) -> ObservationMetrics:
    """Score a trajectory planned on the WFOV grid against the high-resolution truth.

    ``factor`` is the high-res -> WFOV downsampling factor the trajectory was
    planned at; ``footprint`` the NFOV footprint in WFOV pixels (odd, >= 1).
    """
    maps = truth if isinstance(truth, UtilityMaps) else UtilityMaps.from_scene(truth)
    factor = check_factor(factor, maps.label.shape)
    if (
        isinstance(footprint, bool)
        or not isinstance(footprint, int)
        or footprint < 1
        or footprint % 2 == 0
    ):
        raise InvalidParameterError(
            f"footprint: expected an odd positive number of WFOV pixels, got {footprint!r}"
        )
    stack = np.stack([maps.label.astype(np.float32), maps.intensity, maps.gradient])
    per_wfov = block_mean(stack, factor)  # (3, H/f, W/f): mean over each WFOV pixel's footprint
    if footprint > 1:
        per_wfov = np.stack(
            [
                cv2.blur(ch, (footprint, footprint), borderType=cv2.BORDER_CONSTANT)
                for ch in per_wfov
            ]
        )
        # at the image edge, average only over footprint pixels that exist
        ones = cv2.blur(
            np.ones(per_wfov.shape[1:], np.float32),
            (footprint, footprint),
            borderType=cv2.BORDER_CONSTANT,
        )
        per_wfov = per_wfov / ones
    rc = observed_pixels(trajectory, per_wfov.shape[1:])
    if maps.valid is not None and len(rc):  # nodata is never observed
        valid_wfov = block_mean(maps.valid[None].astype(np.float32), factor)[0] == 1.0
        rc = rc[valid_wfov[rc[:, 0], rc[:, 1]]]
    if len(rc) == 0:
        return ObservationMetrics(0, 0.0, 0.0, 0.0)
    vals = per_wfov[:, rc[:, 0], rc[:, 1]].astype(np.float64)
    return ObservationMetrics(
        pixels_observed=len(rc),
        ratio_plume=float(vals[0].mean()),
        intensity=float(vals[1].mean()),
        gradient=float(vals[2].mean()),
    )
