"""Long-horizon foresight from geostationary imagery: detect, nowcast, plan a blueprint.

A stage of its own (it imports only :mod:`dyntarget.schedule` and the core):

* :func:`detect` — plume candidates on a coarse GEO image: a brightness threshold
  above the image's background (the median), on coarse pixels. It cannot tell a
  plume from a meteorological cloud (both are bright): clouds are false targets.
* :func:`unmix` — per-cell cover fractions of end-member spectra (cloud, ash,
  steam) over the clear-sky background, by non-negative least squares: the plume
  fraction tells a plume from a cloud as bright.
* :func:`nowcast` — the GEO field carried to future times with pysteps
  (dense Lucas-Kanade motion from the last images, semi-Lagrangian
  extrapolation); needs the ``[geo]`` extra (pysteps).
* :func:`prior_targets` — the catalog baseline's targets: the known volcanoes of a
  catalog (:func:`read_catalog`, the Smithsonian GVP's columns) over the strip, no
  GEO image (:mod:`dyntarget.geo.catalog`).
* :func:`plan_blueprint` — which targets to observe, in what order, with how
  many pointings, over the whole pass: a dynamic programme over targets in
  along-track order and sensor time slots (polynomial; see its docstring).

* :mod:`dyntarget.geo.targets` — the blueprint's targets from GEO images
  (``plume_field``, ``geo_targets``: detection, nowcast, persistence) and the
  omniscient reference (``omniscient_targets``: the true plumes).
* :mod:`dyntarget.geo.endmembers` — ``estimate_members``: the cloud, ash and steam
  end-members found in the GEO images themselves (N-FINDR, named by spectral shape),
  for ``GeoSettings(endmembers="estimated")``.
* :mod:`dyntarget.geo.refine` — ``BlueprintGate``: the onboard refinement within the
  blueprint and the staging of the idle sensor.

The blueprint is computed **on the ground** (where the GEO images are) before
the pass and uplinked; the onboard loop only refines within it
(:class:`dyntarget.geo.refine.BlueprintGate`, wired by :mod:`dyntarget.passes.geo`).
The pass, the GEO images and the world come in through the typed protocols of
:mod:`dyntarget.geo.seams`. Nothing here needs pysteps except :func:`nowcast`.
"""

from dyntarget.geo.blueprint import Blueprint, Target, plan_blueprint
from dyntarget.geo.catalog import prior_targets, read_catalog
from dyntarget.geo.nowcast import detect, nowcast, unmix

__all__ = [
    "Blueprint",
    "Target",
    "detect",
    "nowcast",
    "plan_blueprint",
    "prior_targets",
    "read_catalog",
    "unmix",
]
