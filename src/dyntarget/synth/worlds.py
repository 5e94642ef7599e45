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
* ``truth_rows(t, top, bottom)``: the truth of some rows (:class:`Truth`);
* ``is_long``: the truth is rendered by rows only (``truth_rows``; ``truth_at`` refused);
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
(:mod:`dyntarget.synth.strip_world`) subclass it.

:class:`StaticWorld` wraps one labelled scene (a user's large GeoTIFF, or a
static synthetic strip): the same image and truth at every time.

What a pass reads of a world on its WFOV grid is computed here too: a frame's look
(:func:`wfov_look`: image, valid pixels and, for the oracle, the plume mask it shows)
and the truth on NFOV footprints (:func:`wfov_truth`, band by band with
:class:`TruthBands`, which also answers which true plume top a line of sight meets).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING, Protocol

import cv2
import numpy as np
from affine import Affine

from dyntarget import parallax
from dyntarget.errors import InvalidSceneError
from dyntarget.scene import LABEL_FRACTION, Scene, block_mean
from dyntarget.utility import UtilityMaps

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
    maps : dyntarget.utility.UtilityMaps
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

    def truth_rows(self, t: float, top: int, bottom: int) -> Truth:
        """The truth of rows ``top:bottom`` at ``t`` (the only truth of a long strip).

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        Truth
            Utility maps and plume ids of the rows.
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
    ids: np.ndarray = new[comp]
    return ids


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

    def truth_rows(self, t: float, top: int, bottom: int) -> Truth:
        """The truth of rows ``top:bottom`` at ``t`` (rows of :meth:`truth_at`).

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        Truth
            Utility maps and plume ids of the rows.

        Examples
        --------
        >>> img = np.zeros((4, 4, 4), np.float32); lab = np.eye(4, dtype=bool)
        >>> StaticWorld(Scene(img, label=lab, gsd=8.0)).truth_rows(0.0, 1, 3).ids.tolist()
        [[0, 1, 0, 0], [0, 0, 1, 0]]
        """
        whole = self.truth_at(t)
        m = whole.maps
        valid = None if m.valid is None else m.valid[top:bottom]
        rows = UtilityMaps(
            m.label[top:bottom], m.intensity[top:bottom], m.gradient[top:bottom], valid
        )
        return Truth(rows, whole.ids[top:bottom])

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


WFOV_FIELDS = ("plume", "intensity", "gradient", "ids", "valid")
"""The fields of :class:`WfovTruth`, in order."""


def wfov_look(
    world: World,
    t: float,
    top: int,
    rows: int,
    factor: int,
    width: int,
    *,
    oracle: bool,
    nadir_xy: tuple[float, float] | None = None,
    altitude_m: float = 0.0,
    what: str = "frame",
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """WFOV rows ``top:top + rows`` of the strip as the look-ahead sees them at ``t``.

    Without ``nadir_xy`` the look is :meth:`World.image_at` (a flat world's, the same
    from anywhere); with it, the oblique look :meth:`World.look_at` from over that nadir
    (a 3D world's plumes displaced by their parallax). The high-resolution rows are
    averaged onto the WFOV grid (``factor``), ``width`` WFOV columns wide.

    Parameters
    ----------
    world : World
        The strip.
    t : float
        Seconds into the pass.
    top, rows : int
        First WFOV row and number of rows.
    factor : int
        High-res -> WFOV factor.
    width : int
        WFOV columns kept.
    oracle : bool
        Also return the true plume mask the look shows (the oracle classifier's).
    nadir_xy : tuple of float or None
        The spacecraft's nadir ``(x, y)``, strip high-resolution pixels (``None``:
        the flat look).
    altitude_m : float
        The spacecraft's altitude, metres (with ``nadir_xy``).
    what : str
        What the look is, for the error message (e.g. ``"frame 3"``).

    Returns
    -------
    image : numpy.ndarray
        ``(4, rows, width)`` float32 WFOV reflectance.
    valid : numpy.ndarray or None
        Boolean ``(rows, width)``: WFOV pixels whose high-resolution pixels all hold
        data (``None``: the strip is valid everywhere).
    mask : numpy.ndarray or None
        With ``oracle``: boolean ``(rows, width)``, WFOV pixels at least
        :data:`~dyntarget.scene.LABEL_FRACTION` plume; ``None`` otherwise.

    Raises
    ------
    dyntarget.errors.InvalidSceneError
        When the world returns an image of another shape.

    Examples
    --------
    >>> img = np.full((4, 8, 8), 0.2, np.float32); lab = np.zeros((8, 8), bool)
    >>> lab[4:6, 0:4] = True
    >>> w = StaticWorld(Scene(img, label=lab, gsd=8.0))
    >>> image, valid, mask = wfov_look(w, 0.0, 2, 2, 2, 4, oracle=True)
    >>> image.shape, valid, mask.astype(int).tolist()
    ((4, 2, 4), None, [[1, 1, 0, 0], [0, 0, 0, 0]])
    """
    f = factor
    a, b, w = top * f, (top + rows) * f, width * f
    label: np.ndarray | None = None
    if nadir_xy is None:
        hr = world.image_at(t, a, b)
    else:
        hr, label = world.look_at(t, a, b, nadir_xy=nadir_xy, altitude_m=altitude_m)
    expected = (4, rows * f, w)
    if hr.shape[0] != 4 or hr.shape[1] != expected[1] or hr.shape[2] < expected[2]:
        raise InvalidSceneError(
            f"world {world.id!r}: {what} image has shape {hr.shape}, expected {expected}"
        )
    image = block_mean(np.asarray(hr, np.float32)[:, :, :w], f)
    valid = None
    if world.valid is not None:
        v = world.valid[a:b, :w]
        valid = block_mean(v[None].astype(np.float32), f)[0] == 1.0
    if not oracle:
        return image, valid, None
    if label is None:
        label = world.label_rows(t, a, b)
    mask = block_mean(np.asarray(label)[None, :, :w].astype(np.float32), f)[0]
    return image, valid, mask >= LABEL_FRACTION


class TruthBands:
    """A world's truth on the WFOV footprints, as a pass scores against it.

    A world built whole is averaged once per truth object (:func:`wfov_truth`, rebuilt
    only when the world's truth changes); a long strip (``world.is_long``) band by band:
    ``band`` WFOV rows at a time (with the footprint's margin, from
    :meth:`World.truth_rows`), recent bands kept.

    Parameters
    ----------
    world : World
        The strip.
    factor : int
        High-res -> WFOV factor.
    footprint : int
        NFOV footprint, WFOV pixels (odd).
    band : int
        WFOV rows per band of a long strip.

    Examples
    --------
    >>> lab = np.zeros((8, 8), bool); lab[:4, :4] = True
    >>> w = StaticWorld(Scene(np.ones((4, 8, 8), np.float32), label=lab, gsd=1.0))
    >>> truth, r0 = TruthBands(w, 2, 1).at(0.0, 3)
    >>> truth.plume.tolist()[0], r0
    ([1.0, 1.0, 0.0, 0.0], 0)
    """

    def __init__(self, world: World, factor: int, footprint: int, band: int = 64) -> None:
        self.world, self.factor, self.footprint = world, factor, footprint
        self.lazy = world.is_long
        self.band = max(1, int(band))
        self._key: int | None = None
        self._value: WfovTruth | None = None
        self._bands: OrderedDict[tuple[float, int], WfovTruth] = OrderedDict()

    def at(self, t: float, r: int = 0) -> tuple[WfovTruth, int]:
        """The WFOV truth at ``t`` holding strip WFOV row ``r``, and its first row.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        r : int
            A strip WFOV row.

        Returns
        -------
        truth : WfovTruth
            The whole strip's (first row 0), or a long strip's band holding ``r``.
        first : int
            The strip WFOV row of its first row.
        """
        if not self.lazy:
            truth = self.world.truth_at(t)
            if self._key != id(truth) or self._value is None:
                self._value = wfov_truth(truth, self.factor, self.footprint)
                self._key = id(truth)
            return self._value, 0
        tq = self.world.quantize(t)
        b = int(r) // self.band
        key = (tq, b)
        hit = self._bands.get(key)
        r0 = b * self.band
        if hit is None:
            f, pad = self.factor, self.footprint // 2
            hw = self.world.shape[0] // f
            a, z = max(0, r0 - pad), min(hw, r0 + self.band + pad)
            w = wfov_truth(self.world.truth_rows(tq, a * f, z * f), f, self.footprint)
            lo, hi = r0 - a, min(r0 - a + self.band, z - a)
            hit = WfovTruth(*(getattr(w, n)[lo:hi] for n in WFOV_FIELDS))
            self._bands[key] = hit
            if len(self._bands) > 32:
                self._bands.popitem(last=False)
        else:
            self._bands.move_to_end(key)
        return hit, r0

    def true_heights(
        self,
        pts: np.ndarray,
        ts: np.ndarray,
        t_k: float,
        top: int,
        *,
        nadir: tuple[float, float],
        altitude_m: float,
        gsd_m: float,
        look: bool = False,
    ) -> np.ndarray:
        """The true top height of the plume the look-ahead saw at each of a frame's points.

        Of the truth's plumes with a height, highest first, the first whose true position
        under the point, seen from ``nadir`` at ``t_k``
        (:func:`dyntarget.parallax.unshift_xy`), holds it; NaN where none does.

        Parameters
        ----------
        pts : numpy.ndarray
            ``(n, 2)`` ``(x, y)`` frame WFOV pixels (the frame's top row is ``top``).
        ts : numpy.ndarray
            ``(n,)`` seconds after ``t_k`` of each point (its pointing's time).
        t_k : float
            When the look-ahead saw the frame, seconds into the pass.
        top : int
            The frame's top strip WFOV row.
        nadir : tuple of float
            The spacecraft's nadir ``(x, y)`` at ``t_k``, strip WFOV pixels.
        altitude_m : float
            The spacecraft's altitude, metres.
        gsd_m : float
            Metres per WFOV pixel.
        look : bool
            Each height at ``t_k`` (when the look-ahead saw it), else at ``t_k + ts``.

        Returns
        -------
        numpy.ndarray
            ``(n,)`` float64 metres (NaN: no plume top there, or a flat world).

        Examples
        --------
        >>> img = np.zeros((4, 8, 8), np.float32); lab = np.zeros((8, 8), bool); lab[2, 2] = True
        >>> bands = TruthBands(StaticWorld(Scene(img, label=lab, gsd=8.0)), 1, 1)
        >>> bands.true_heights(np.zeros((1, 2)), np.zeros(1), 0.0, 0,
        ...                    nadir=(0.0, 4e4), altitude_m=5e5, gsd_m=8.0).tolist()
        [nan]
        """
        world = self.world
        out = np.full(len(pts), np.nan)
        at_look = world.heights_at(t_k)
        if at_look is None or not len(pts):
            return out
        nx, ny = nadir
        along = (ny - (pts[:, 1] + top)) * gsd_m
        cross = (pts[:, 0] - nx) * gsd_m
        best = np.full(len(pts), -1.0)
        hw, ww = world.shape[0] // self.factor, world.shape[1] // self.factor
        for i in np.argsort(at_look)[::-1]:
            h = float(at_look[i])
            if i == 0 or h <= 0:
                continue
            ta, tc = parallax.unshift_xy(altitude_m, along, cross, h)
            r = np.floor(ny - ta / gsd_m + 0.5).astype(np.int64)
            c = np.floor(nx + tc / gsd_m + 0.5).astype(np.int64)
            todo = np.flatnonzero((r >= 0) & (r < hw) & (c >= 0) & (c < ww) & (best < 0))
            while len(todo):  # one truth band at a time, its points at once
                truth, r0 = self.at(t_k, int(r[todo[0]]))
                band = (r[todo] >= r0) & (r[todo] < r0 + truth.ids.shape[0])
                band[0] = True
                js = todo[band]
                hit = truth.ids[r[js] - r0, c[js]] == int(i)
                best[js[hit]] = float(i)
                todo = todo[~band]
        for j in np.flatnonzero(best > 0):
            now = at_look if look else world.heights_at(t_k + float(ts[j]))
            out[j] = float(now[int(best[j])]) if now is not None else np.nan
        return out
