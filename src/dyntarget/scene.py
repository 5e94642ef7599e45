"""The scene model: a 4-band image, an optional plume label, GSD and georeferencing.

Conventions (see ``docs/architecture.md``): the image is ``float32`` of shape
``(4, H, W)`` in band order R, G, B, NIR holding top-of-atmosphere-like
reflectance (roughly 0..1); the label is ``bool (H, W)``, ``True`` = plume.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from affine import Affine

from dyntarget.errors import InvalidParameterError, InvalidSceneError

BANDS: tuple[str, ...] = ("red", "green", "blue", "nir")
"""Band order of every image in dyntarget."""

LABEL_FRACTION = 0.5
"""A WFOV pixel is labelled plume when at least this fraction of its high-res pixels are."""


def check_image(image: object, *, name: str = "image") -> np.ndarray:
    """Validate a 4-band image and return it as ``float32 (4, H, W)``.

    Raises :class:`InvalidSceneError` naming ``name`` when the array has the wrong
    number of dimensions or bands, is empty, is not floating point, or holds
    NaN or infinite values. The input is never modified.

    Parameters
    ----------
    image : object
        Array-like reflectance, ``(4, H, W)`` (R, G, B, NIR), floating point.
    name : str
        What to call it in error messages.

    Returns
    -------
    numpy.ndarray
        The image as float32 ``(4, H, W)`` (the input itself when it already is).

    Examples
    --------
    >>> check_image(np.zeros((4, 2, 3))).dtype
    dtype('float32')
    """
    arr = np.asarray(image)
    if arr.ndim != 3:
        raise InvalidSceneError(
            f"{name}: expected an array of shape (4, H, W), got {arr.ndim} dimension(s) {arr.shape}"
        )
    if arr.shape[0] != len(BANDS):
        raise InvalidSceneError(
            f"{name}: expected 4 bands (R, G, B, NIR), got {arr.shape[0]} band(s) in shape {arr.shape}"
        )
    if arr.shape[1] < 1 or arr.shape[2] < 1:
        raise InvalidSceneError(f"{name}: image is empty, shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise InvalidSceneError(
            f"{name}: expected floating-point reflectance, got dtype {arr.dtype}; "
            "scale integer digital numbers first (dyntarget.io reads them with a scale)"
        )
    arr = arr.astype(np.float32, copy=False)
    if not np.isfinite(arr).all():
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise InvalidSceneError(f"{name}: {bad} value(s) are NaN or infinite")
    return arr


def check_label(label: object, shape: tuple[int, int], *, name: str = "label") -> np.ndarray:
    """Validate a plume label for an image of ``shape`` (H, W); return ``bool (H, W)``.

    Booleans and integers are accepted (non-zero = plume); floats are refused
    because their meaning (probability? 0/255?) is ambiguous.

    Parameters
    ----------
    label : object
        Array-like boolean or integer mask.
    shape : tuple of int
        The image's ``(H, W)``, which the label must match.
    name : str
        What to call it in error messages.

    Returns
    -------
    numpy.ndarray
        Boolean ``(H, W)``, true on plume.

    Raises
    ------
    dyntarget.errors.InvalidSceneError
        On a shape mismatch or a dtype other than bool or integer.
    """
    arr = np.asarray(label)
    if arr.shape != tuple(shape):
        raise InvalidSceneError(
            f"{name}: shape {arr.shape} does not match the image's {tuple(shape)}"
        )
    if arr.dtype == bool:
        return arr
    if np.issubdtype(arr.dtype, np.integer):
        return arr != 0
    raise InvalidSceneError(f"{name}: expected a boolean or integer mask, got dtype {arr.dtype}")


@dataclass(frozen=True, eq=False)
class Scene:
    """One scene: image, optional label, ground sampling distance, georeferencing.

    Parameters
    ----------
    image : array (4, H, W)
        Reflectance in band order R, G, B, NIR; converted to ``float32``.
    label : array (H, W) or None
        Plume mask (``True`` = plume); ``None`` for unlabeled scenes.
    gsd : float or None
        Ground sampling distance in metres per pixel; ``None`` when unknown.
    crs : str or None
        Coordinate reference system (anything ``rasterio.crs.CRS.from_user_input``
        takes, e.g. ``"EPSG:32605"``); ``None`` for pixel-only scenes.
    transform : affine.Affine or None
        Pixel -> CRS affine transform (GDAL convention, top-left corner).
    id : str
        Scene identifier, also the file stem on disk.
    valid : array (H, W) or None
        ``False`` where the sensor has no data (nodata); ``None`` when every pixel
        is valid. Nodata pixels are left out of training and metrics and are
        never observed; their image values are placeholders (0).

    Examples
    --------
    >>> s = Scene(np.ones((4, 4, 4), np.float32), label=np.eye(4, dtype=bool), gsd=2.0)
    >>> w = s.to_wfov(2)
    >>> w.shape, w.gsd
    ((2, 2), 4.0)
    """

    image: np.ndarray
    label: np.ndarray | None = None
    gsd: float | None = None
    crs: str | None = None
    transform: Affine | None = None
    id: str = "scene"
    valid: np.ndarray | None = None

    def __post_init__(self) -> None:
        image = check_image(self.image, name=f"scene {self.id!r} image")
        object.__setattr__(self, "image", image)
        if self.label is not None:
            label = check_label(self.label, image.shape[1:], name=f"scene {self.id!r} label")
            object.__setattr__(self, "label", label)
        if self.valid is not None:
            valid = np.asarray(self.valid)
            if valid.shape != image.shape[1:] or valid.dtype != bool:
                raise InvalidSceneError(
                    f"scene {self.id!r} valid mask: expected bool {image.shape[1:]}, got {valid.dtype} {valid.shape}"
                )
            if not valid.any():
                raise InvalidSceneError(f"scene {self.id!r}: no valid pixel (everything is nodata)")
            object.__setattr__(self, "valid", None if valid.all() else valid)
        if self.gsd is not None:
            gsd = float(self.gsd)
            if not np.isfinite(gsd) or gsd <= 0:
                raise InvalidParameterError(
                    f"gsd: expected a positive number of metres, got {self.gsd!r}"
                )
            object.__setattr__(self, "gsd", gsd)
        if self.transform is not None and not isinstance(self.transform, Affine):
            object.__setattr__(self, "transform", Affine(*tuple(self.transform)[:6]))
        if self.crs is not None and self.transform is None:
            raise InvalidSceneError(f"scene {self.id!r}: a CRS was given without a transform")
        if not self.id or "/" in self.id or "\\" in self.id:
            raise InvalidParameterError(f"id: expected a non-empty file stem, got {self.id!r}")

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the image."""
        return (int(self.image.shape[1]), int(self.image.shape[2]))

    @property
    def truth(self) -> np.ndarray:
        """The plume label, for training and scoring: ``bool (H, W)``.

        Raises
        ------
        dyntarget.errors.InvalidSceneError
            When the scene has no label.

        Examples
        --------
        >>> Scene(np.ones((4, 2, 2), np.float32), label=np.eye(2, dtype=bool)).truth.sum()
        np.int64(2)
        """
        if self.label is None:
            raise InvalidSceneError(f"scene {self.id!r}: no plume label (needed to train or score)")
        return self.label

    @property
    def valid_mask(self) -> np.ndarray:
        """``bool (H, W)``: ``True`` where there is data (all ``True`` without nodata)."""
        return self.valid if self.valid is not None else np.ones(self.shape, bool)

    @property
    def georeferenced(self) -> bool:
        """Whether the scene has both a CRS and a geotransform."""
        return self.crs is not None and self.transform is not None

    def to_wfov(self, factor: int) -> Scene:
        """Downsample by an integer ``factor`` to the WFOV grid.

        The image is area-averaged over ``factor x factor`` blocks. A WFOV pixel
        is labelled plume when at least :data:`LABEL_FRACTION` (half) of its
        high-resolution pixels are plume. Rows and columns that do not fill a
        whole block (``H % factor``, ``W % factor`` at the bottom/right edge) are
        dropped, so the top-left origin and the transform stay exact; the new
        transform is ``transform @ Affine.scale(factor)`` and the GSD is
        multiplied by ``factor``. A WFOV pixel is valid only when all of its
        high-resolution pixels are.

        Parameters
        ----------
        factor : int
            High-resolution pixels per WFOV pixel along each axis (1 returns this scene).

        Returns
        -------
        Scene
            The WFOV scene: image, label and valid mask downsampled, transform and GSD scaled.

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For a factor that is not a positive integer or exceeds the smaller side.
        dyntarget.errors.InvalidSceneError
            When no WFOV pixel is free of nodata.
        """
        factor = check_factor(factor, self.shape)
        if factor == 1:
            return self
        h, w = self.shape[0] // factor, self.shape[1] // factor
        image = block_mean(self.image, factor)
        label = None
        if self.label is not None:
            frac = block_mean(self.label[None].astype(np.float32), factor)[0]
            label = frac >= LABEL_FRACTION
        valid = None
        if self.valid is not None:
            valid = block_mean(self.valid[None].astype(np.float32), factor)[0] == 1.0
            if not valid.any():
                raise InvalidSceneError(
                    f"scene {self.id!r}: no WFOV pixel at factor {factor} is free of nodata"
                )
        assert image.shape == (4, h, w)
        return replace(
            self,
            image=image,
            label=label,
            gsd=None if self.gsd is None else self.gsd * factor,
            transform=None if self.transform is None else self.transform @ Affine.scale(factor),
            valid=valid,
        )


def check_factor(factor: object, shape: tuple[int, int]) -> int:
    """Validate an integer downsampling factor for an image of ``shape``.

    Parameters
    ----------
    factor : object
        The factor to check: a positive integer (not a bool).
    shape : tuple of int
        The image's ``(H, W)``; the factor may not exceed ``min(H, W)``.

    Returns
    -------
    int
        The factor as a Python int.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For anything else.
    """
    if isinstance(factor, bool) or not isinstance(factor, int | np.integer):
        raise InvalidParameterError(f"factor: expected a positive integer, got {factor!r}")
    factor = int(factor)
    if factor < 1:
        raise InvalidParameterError(f"factor: expected a positive integer, got {factor}")
    if factor > min(shape):
        raise InvalidParameterError(
            f"factor: {factor} is larger than the image's smaller side ({min(shape)} px)"
        )
    return factor


def block_mean(stack: np.ndarray, factor: int) -> np.ndarray:
    """Mean over non-overlapping ``factor x factor`` blocks of a ``(C, H, W)`` stack.

    Trailing rows/columns that do not fill a block are dropped.

    Parameters
    ----------
    stack : numpy.ndarray
        ``(C, H, W)`` array.
    factor : int
        Block side, pixels.

    Returns
    -------
    numpy.ndarray
        ``(C, H // factor, W // factor)`` float32 block means (accumulated in float64).

    Examples
    --------
    >>> block_mean(np.arange(16, dtype=np.float32).reshape(1, 4, 4), 2)[0]
    array([[ 2.5,  4.5],
           [10.5, 12.5]], dtype=float32)
    """
    c, h, w = stack.shape
    hh, ww = h // factor, w // factor
    blocks = stack[:, : hh * factor, : ww * factor].reshape(c, hh, factor, ww, factor)
    return blocks.mean(axis=(2, 4), dtype=np.float64).astype(np.float32)
