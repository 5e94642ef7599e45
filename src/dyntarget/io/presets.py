"""Sensor presets: where R, G, B, NIR sit in a product's file and how to scale its numbers.

Data only (no rasterio), so listing the presets costs nothing; the readers are in
:mod:`dyntarget.io.sensors`.
"""

from __future__ import annotations

from dataclasses import dataclass

from dyntarget.errors import UnknownNameError

_S2_L1C = ("B1", "B2", "B3", "B4", "B5", "B6", "B7", "B8", "B8A", "B9", "B10", "B11", "B12")
_S2_L2A = ("B1", "B2", "B3", "B4", "B5", "B6", "B7", "B8", "B8A", "B9", "B11", "B12")
_LANDSAT = ("B1", "B2", "B3", "B4", "B5", "B6", "B7")


@dataclass(frozen=True)
class Preset:
    """Where R, G, B, NIR are in a product's file and how to scale its numbers.

    Parameters
    ----------
    name : str
        Preset name (``--preset``).
    bands : tuple of int
        1-based band numbers of R, G, B and NIR in the file.
    scale : float
        Reflectance per digital number (``reflectance = DN * scale + offset``).
    offset : float
        Reflectance added after scaling.
    band_names : tuple of str
        Names of the file's bands in order, so ``--bands`` may name them.
    description : str
        One line for listings.
    """

    name: str
    bands: tuple[int, int, int, int]
    scale: float
    offset: float
    band_names: tuple[str, ...] = ()
    description: str = ""


PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset(
            "planetscope",
            (3, 2, 1, 4),
            1e-4,
            0.0,
            ("B", "G", "R", "NIR"),
            "PlanetScope 4-band (B, G, R, NIR)",
        ),
        Preset(
            "skysat",
            (3, 2, 1, 4),
            1e-4,
            0.0,
            ("B", "G", "R", "NIR"),
            "SkySat 4-band (B, G, R, NIR)",
        ),
        Preset(
            "sentinel2-l1c", (4, 3, 2, 8), 1e-4, 0.0, _S2_L1C, "Sentinel-2 L1C, 13 bands, DN/10000"
        ),
        Preset(
            "sentinel2-l2a",
            (4, 3, 2, 8),
            1e-4,
            0.0,
            _S2_L2A,
            "Sentinel-2 L2A, 12 bands (no B10), DN/10000",
        ),
        Preset(
            "landsat8", (4, 3, 2, 5), 2e-5, -0.1, _LANDSAT, "Landsat 8 OLI L1 TOA (DN * 2e-5 - 0.1)"
        ),
        Preset(
            "landsat9",
            (4, 3, 2, 5),
            2e-5,
            -0.1,
            _LANDSAT,
            "Landsat 9 OLI-2 L1 TOA (DN * 2e-5 - 0.1)",
        ),
    )
}


def get_preset(name: str) -> Preset:
    """The preset called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`PRESETS`.

    Returns
    -------
    Preset
        Its band positions and scaling.

    Examples
    --------
    >>> get_preset("sentinel2-l2a").bands
    (4, 3, 2, 8)
    """
    try:
        return PRESETS[name]
    except KeyError:
        raise UnknownNameError(
            f"unknown preset {name!r}; expected one of: {', '.join(PRESETS)}"
        ) from None
