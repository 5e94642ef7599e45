"""What a pass flies over: a long strip whose look-ahead frames and truth may change with time.

The pass loop talks to the world through one small interface, :class:`World`:

* ``shape``, ``gsd``, ``crs``, ``transform``: the high-resolution strip grid;
* ``image_at(t, top, bottom)``: the 4-band high-resolution rows ``top:bottom``
  as the look-ahead sensor sees them at pass time ``t`` (seconds after the
  first frame's acquisition);
* ``truth_at(t)``: the plume truth over the whole strip at time ``t``
  (:class:`Truth`: label, utility maps, plume identities);
* ``label_rows(t, top, bottom)``, ``plumes_at_start()``, ``quantize(t)``: the true
  label of some rows, the plumes there at t = 0, the truth's time grid;
* ``is_long``: the truth is rendered by rows only (``truth_rows``, a long strip);
  ``spec``, ``wind``, ``truth_step_s``, ``acquired``: the synthetic world, its wind, the
  truth's time step and when t = 0 is (``None`` where the strip has none);
* ``is_3d``, ``look_at(t, top, bottom, nadir_xy=, altitude_m=)``, ``heights_at(t)``: a
  world whose plumes and clouds have heights (:attr:`WorldSpec.is_3d
  <dyntarget.synth.dynamic.WorldSpec.is_3d>`) is seen by the look-ahead displaced by
  its parallax from where the spacecraft is (``look_at``: the frame and the plume mask it
  shows), and the truth's plumes have top heights (``heights_at``, per plume id). The
  truth (``truth_at``, ``label_rows``) stays the plumes' true ground positions. A flat
  world's ``look_at`` is exactly ``image_at`` and ``label_rows``, its ``heights_at``
  ``None``.

:class:`WorldBase` answers all but ``image_at`` and ``truth_at`` from the truth (a
world built whole); :class:`StaticWorld` and the moving strips
(:mod:`dyntarget.fly.strip`) subclass it.

:class:`StaticWorld` wraps one labelled scene (a user's large GeoTIFF, or a
static synthetic strip): the same image and truth at every time.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING, Protocol

import cv2
import numpy as np
from affine import Affine

from dyntarget.errors import InvalidSceneError
from dyntarget.observe.nfov import UtilityMaps
from dyntarget.scene import Scene, block_mean

if TYPE_CHECKING:
    from dyntarget.synth.dynamic import Wind, WorldSpec

MIN_PLUME_FRACTION = 0.01
"""Connected components of a label smaller than this fraction of the largest are not
counted as plumes of their own (ragged label edges), see :func:`plume_ids`."""


@dataclass(frozen=True, eq=False)
class Truth:
    """The plume truth over the strip at one time, high resolution.

    ``ids`` numbers the plumes (0: no plume), so a pass can count how many
    distinct plumes it observed.

    Parameters
    ----------
    maps : dyntarget.observe.nfov.UtilityMaps
        Label and utility maps of the strip.
    ids : numpy.ndarray
        ``(H, W)`` plume id per pixel.
    """

    maps: UtilityMaps
    ids: np.ndarray


class World(Protocol):
    """A strip the pass flies over (see the module docstring)."""

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the strip, high resolution."""
        ...

    @property
    def gsd(self) -> float:
        """Metres per high-resolution pixel."""
        ...

    @property
    def crs(self) -> str | None:
        """The strip's CRS, ``None`` for pixel coordinates."""
        ...

    @property
    def transform(self) -> Affine | None:
        """The strip's geotransform, ``None`` for pixel coordinates."""
        ...

    @property
    def valid(self) -> np.ndarray | None:
        """Where the strip has data, ``None`` when everywhere."""
        ...

    @property
    def id(self) -> str:
        """The strip's name (its file stem)."""
        ...

    def image_at(self, t: float, top: int, bottom: int) -> np.ndarray:
        """Rows ``top:bottom`` of the strip as the look-ahead sensor sees them at ``t``.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            ``(4, bottom - top, W)`` reflectance.
        """
        ...

    def truth_at(self, t: float) -> Truth:
        """The plume truth over the whole strip at ``t``.

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        Truth
            Utility maps and plume ids, high resolution.
        """
        ...

    @property
    def is_long(self) -> bool:
        """Whether the truth is rendered by rows only (a long strip: ``truth_rows``)."""
        ...

    @property
    def spec(self) -> WorldSpec | None:
        """The synthetic world the strip renders, ``None`` for a static strip."""
        ...

    @property
    def wind(self) -> Wind | None:
        """The strip's true wind, ``None`` when unknown."""
        ...

    @property
    def truth_step_s(self) -> float | None:
        """The truth's time step, s (``None``: the truth does not change)."""
        ...

    @property
    def acquired(self) -> datetime | str | None:
        """When pass time 0 is (ISO-8601 text or a datetime), ``None`` when unknown."""
        ...

    def label_rows(self, t: float, top: int, bottom: int) -> np.ndarray:
        """The true label of rows ``top:bottom`` at ``t``.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            Boolean ``(bottom - top, W)``.
        """
        ...

    def plumes_at_start(self) -> frozenset[int]:
        """Plume ids present at t = 0.

        Returns
        -------
        frozenset of int
            The ids (as :attr:`Truth.ids` numbers them, all > 0) of the plumes in the
            strip's truth at pass time 0; empty when there are none.
        """
        ...

    def quantize(self, t: float) -> float:
        """``t`` on the truth's time grid.

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        float
            Seconds into the pass: ``t`` rounded to the nearest multiple of
            :attr:`truth_step_s`, or ``t`` itself when the truth has no time grid.
        """
        ...

    def vent_pixels(self) -> np.ndarray | None:
        """``(n, 2)`` strip ``(col, row)`` of a synthetic strip's vents, ``None`` otherwise.

        Returns
        -------
        numpy.ndarray or None
            ``(n, 2)`` float64 ``(col, row)`` of each vent on the strip's
            high-resolution grid (``n`` may be 0); ``None`` when no synthetic world
            is behind the strip.
        """
        ...

    @property
    def is_3d(self) -> bool:
        """Whether plumes or clouds have heights (seen displaced by their parallax)."""
        ...

    def look_at(
        self,
        t: float,
        top: int,
        bottom: int,
        *,
        nadir_xy: tuple[float, float],
        altitude_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``top:bottom`` as the look-ahead sees them at ``t`` from over ``nadir_xy``.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.
        nadir_xy : tuple of float
            The spacecraft's nadir ``(x, y)`` in strip high-resolution pixels.
        altitude_m : float
            The spacecraft's altitude, metres.

        Returns
        -------
        image : numpy.ndarray
            ``(4, bottom - top, W)`` reflectance, raised features displaced by their parallax.
        mask : numpy.ndarray
            Boolean ``(bottom - top, W)``: the plume the frame shows (displaced). A flat
            world: exactly ``image_at`` and ``label_rows``.
        """
        ...

    def heights_at(self, t: float) -> np.ndarray | None:
        """Top height of each truth plume at ``t``, ``None`` for a flat world.

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        numpy.ndarray or None
            float64, metres above sea level, indexed by plume id (:attr:`Truth.ids`;
            index 0, no plume, is 0.0); ``None`` when the world is flat.
        """
        ...


def plume_ids(label: np.ndarray, *, min_fraction: float = MIN_PLUME_FRACTION) -> np.ndarray:
    """Number the plumes of a label: 8-connected components, small fragments merged away.

    Components smaller than ``min_fraction`` of the largest get id 0 (they are
    fringes of a plume cut off by the label threshold, not plumes of their own).

    Parameters
    ----------
    label : bool (H, W) plume label.
    min_fraction : smallest component kept, as a fraction of the largest.

    Returns
    -------
    int32 (H, W): 0 outside plumes, 1..n inside (largest first).

    Examples
    --------
    >>> m = np.zeros((6, 8), bool); m[1:3, 1:3] = True; m[3:6, 5:8] = True
    >>> plume_ids(m)[[1, 4], [1, 6]].tolist()
    [2, 1]
    """
    n, comp = cv2.connectedComponents(np.asarray(label, np.uint8), connectivity=8)
    if n <= 1:
        return np.zeros(label.shape, np.int32)
    areas = np.bincount(comp.ravel(), minlength=n)[1:]
    order = np.argsort(-areas, kind="stable")
    new = np.zeros(n, np.int32)
    keep = areas[order] >= min_fraction * areas.max()
    new[order[keep] + 1] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    return new[comp]


class WorldBase:
    """What a :class:`World` whose truth is built whole (:meth:`truth_at`) answers by default.

    The label's rows and the plumes at t = 0 are read from :meth:`truth_at`; no time
    grid, no synthetic world, no known wind. A world subclasses it and implements
    ``image_at`` and ``truth_at`` (and the grid attributes); the moving strips override
    what their world knows.

    Examples
    --------
    >>> img = np.zeros((4, 4, 4), np.float32); lab = np.zeros((4, 4), bool); lab[1:3, 2] = True
    >>> w = StaticWorld(Scene(img, label=lab, gsd=8.0))
    >>> isinstance(w, WorldBase), w.is_long, sorted(w.plumes_at_start()), w.quantize(0.3)
    (True, False, [1], 0.3)
    """

    is_long = False
    """Whether the truth is rendered by rows only (a long strip: ``truth_rows``)."""
    is_3d = False
    """Whether plumes or clouds have heights (a flat world: no parallax)."""
    spec: WorldSpec | None = None
    wind: Wind | None = None
    truth_step_s: float | None = None
    acquired: datetime | str | None = None

    def truth_at(self, t: float) -> Truth:
        """The plume truth over the whole strip at ``t`` (a subclass implements it).

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        Truth
        """
        raise NotImplementedError

    def label_rows(self, t: float, top: int, bottom: int) -> np.ndarray:
        """The true label of rows ``top:bottom`` at ``t`` (rows of :meth:`truth_at`).

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            Boolean ``(bottom - top, W)``.
        """
        return self.truth_at(t).maps.label[top:bottom]

    def plumes_at_start(self) -> frozenset[int]:
        """Plume ids present at t = 0 (those of :meth:`truth_at` at 0).

        Returns
        -------
        frozenset of int
            The non-zero ids of ``truth_at(0.0).ids``.
        """
        ids0 = self.truth_at(0.0).ids
        return frozenset(int(i) for i in np.unique(ids0[ids0 > 0]))

    def quantize(self, t: float) -> float:
        """``t`` itself (no time grid).

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        float
            ``t`` unchanged, seconds into the pass.
        """
        return t

    def vent_pixels(self) -> np.ndarray | None:
        """No vents known (no synthetic world behind the strip).

        Returns
        -------
        None
            Always ``None``.
        """
        return None

    def image_at(self, t: float, top: int, bottom: int) -> np.ndarray:
        """Rows ``top:bottom`` as the look-ahead sees them at ``t`` (a subclass implements it).

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            ``(4, bottom - top, W)`` reflectance.
        """
        raise NotImplementedError

    def look_at(
        self,
        t: float,
        top: int,
        bottom: int,
        *,
        nadir_xy: tuple[float, float],
        altitude_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A flat world seen from anywhere: :meth:`image_at` and :meth:`label_rows`.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.
        nadir_xy : tuple of float
            The spacecraft's nadir ``(x, y)``, strip high-resolution pixels (no effect).
        altitude_m : float
            The spacecraft's altitude, metres (no effect).

        Returns
        -------
        image : numpy.ndarray
            ``image_at(t, top, bottom)``.
        mask : numpy.ndarray
            ``label_rows(t, top, bottom)``.

        Examples
        --------
        >>> img = np.zeros((4, 4, 4), np.float32); lab = np.eye(4, dtype=bool)
        >>> w = StaticWorld(Scene(img, label=lab, gsd=8.0))
        >>> im, m = w.look_at(0.0, 1, 3, nadir_xy=(2.0, 9e4), altitude_m=500e3)
        >>> im.shape, m.tolist()
        ((4, 2, 4), [[False, True, False, False], [False, False, True, False]])
        """
        return self.image_at(t, top, bottom), self.label_rows(t, top, bottom)

    def heights_at(self, t: float) -> np.ndarray | None:
        """``None``: a flat world's plumes lie on the ground.

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        None
            Always ``None``.
        """
        return None


class StaticWorld(WorldBase):
    """A labelled scene that does not change during the pass.

    Parameters
    ----------
    scene : the high-resolution strip with its plume label and GSD.
    ids : optional plume identities (int (H, W), 0 = none); by default
        :func:`plume_ids` of the label.

    Examples
    --------
    >>> img = np.full((4, 8, 4), 0.1, np.float32); lab = np.zeros((8, 4), bool); lab[2, 1] = True
    >>> w = StaticWorld(Scene(img, label=lab, gsd=8.0))
    >>> w.image_at(30.0, 2, 4).shape, int(w.truth_at(99.0).ids.max())
    ((4, 2, 4), 1)
    """

    def __init__(self, scene: Scene, ids: np.ndarray | None = None) -> None:
        if scene.label is None:
            raise InvalidSceneError(
                f"scene {scene.id!r}: a pass is scored against the truth; the strip needs a label"
            )
        if scene.gsd is None:
            raise InvalidSceneError(
                f"scene {scene.id!r}: the strip's ground sampling distance is unknown; "
                "give it (GeoTIFF in metres, the DYNTARGET_GSD tag, or --gsd)"
            )
        self.scene = scene
        self.acquired: datetime | str | None = None  # the instant of t = 0, when known
        self.shape = scene.shape
        self.gsd = float(scene.gsd)
        self.crs, self.transform, self.valid, self.id = (
            scene.crs,
            scene.transform,
            scene.valid,
            scene.id,
        )
        if ids is None:
            ids = plume_ids(scene.label)
        elif np.shape(ids) != scene.shape:
            raise InvalidSceneError(
                f"ids: shape {np.shape(ids)} does not match the strip's {scene.shape}"
            )
        self._truth = Truth(UtilityMaps.from_scene(scene), np.asarray(ids, np.int32))

    def image_at(self, t: float, top: int, bottom: int) -> np.ndarray:
        """The rows ``top:bottom`` of the strip (the same at every time).

        Parameters
        ----------
        t : float
            Seconds into the pass (ignored).
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            ``(4, bottom - top, W)`` image.
        """
        return self.scene.image[:, top:bottom]

    def truth_at(self, t: float) -> Truth:
        """The truth (the same at every time).

        Parameters
        ----------
        t : float
            Seconds into the pass (ignored).

        Returns
        -------
        Truth
            The strip's truth.
        """
        return self._truth


@dataclass(frozen=True, eq=False)
class WfovTruth:
    """The truth averaged onto NFOV footprints centred on every WFOV pixel of the strip.

    ``plume``, ``intensity`` and ``gradient`` are the means over the footprint
    (as :func:`dyntarget.observe.nfov.observe` scores a pointing); ``ids`` the
    largest plume id under the WFOV pixel; ``valid`` false where any
    high-resolution pixel under the WFOV pixel is nodata.

    Parameters
    ----------
    plume : numpy.ndarray
        ``(H, W)`` WFOV mean plume fraction.
    intensity : numpy.ndarray
        ``(H, W)`` WFOV mean intensity utility.
    gradient : numpy.ndarray
        ``(H, W)`` WFOV mean gradient utility.
    ids : numpy.ndarray
        ``(H, W)`` largest plume id under each WFOV pixel.
    valid : numpy.ndarray
        Boolean ``(H, W)``.
    """

    plume: np.ndarray
    intensity: np.ndarray
    gradient: np.ndarray
    ids: np.ndarray
    valid: np.ndarray


def wfov_truth(truth: Truth, factor: int, footprint: int = 1) -> WfovTruth:
    """Average a high-resolution truth onto the WFOV grid and the NFOV footprint.

    Parameters
    ----------
    truth : high-resolution truth of the whole strip.
    factor : high-res -> WFOV downsampling factor.
    footprint : NFOV footprint in WFOV pixels (odd, >= 1).

    Returns
    -------
    WfovTruth on the strip's WFOV grid.

    Examples
    --------
    >>> lab = np.zeros((4, 4), bool); lab[:2, :2] = True
    >>> img = np.ones((4, 4, 4), np.float32)
    >>> t = StaticWorld(Scene(img, label=lab, gsd=1.0)).truth_at(0)
    >>> wfov_truth(t, 2).plume.tolist()
    [[1.0, 0.0], [0.0, 0.0]]
    """
    maps = truth.maps
    stack = np.stack([maps.label.astype(np.float32), maps.intensity, maps.gradient])
    per = block_mean(stack, factor)
    if footprint > 1:
        k = (footprint, footprint)
        ones = cv2.blur(np.ones(per.shape[1:], np.float32), k, borderType=cv2.BORDER_CONSTANT)
        per = np.stack([cv2.blur(c, k, borderType=cv2.BORDER_CONSTANT) / ones for c in per])
    h, w = per.shape[1:]
    ids = truth.ids[: h * factor, : w * factor].reshape(h, factor, w, factor).max(axis=(1, 3))
    if maps.valid is None:
        valid = np.ones((h, w), bool)
    else:
        valid = block_mean(maps.valid[None].astype(np.float32), factor)[0] == 1.0
    return WfovTruth(per[0], per[1], per[2], ids.astype(np.int32), valid)
