"""Every shared default, stated once (core: imports nothing).

The owners (configs, stages) and the CLI take their defaults from here, so a
default changes in one place. Values follow the paper where it states them.

Examples
--------
>>> FACTOR, FOLDS, EPOCHS, THRESHOLD
(4, 5, 50, 0.5)
"""

from __future__ import annotations

SEED = 0
"""Random seed of training, folds and synthetic scenes."""
FACTOR = 4
"""High-resolution -> WFOV downsampling factor of the evaluations."""
FOLDS = 5
"""Cross-validation folds (paper: 5)."""
EPOCHS = 50
"""U-Net training epochs (paper: 50)."""
THRESHOLD = 0.5
"""Plume probability at or above which a pixel is plume."""
DENOISE_ITERATIONS = 1
"""3x3 closing iterations of Algorithm 2."""
MIN_AREA_FRACTION = 0.01
"""Smallest kept polygon, as a fraction of the image area (Algorithm 2)."""
STEP_FRACTION = 0.01
"""Pointing step as a fraction of the image width (paper: 1 %)."""
WIDTH_STEPS = 2.0
"""Transect spacing in steps (paper: 2 x step)."""
ALTITUDE_M = 500e3
"""Orbit altitude, metres."""
LOOK_AHEAD_M = 500e3
"""Ground distance from nadir to the WFOV scene centre at acquisition, metres."""
OBJECTIVES = ("gradient", "intensity", "plume")
"""What ``utility-max`` can maximise (its predicted utility)."""
OBJECTIVE = "gradient"
"""The default ``utility-max`` objective."""
AGILITY_CLASSIFIER = "unet-uavsar"
"""The classifier the agility evaluation plans on."""
DYNAMIC_LATENCIES_S = (0.0, 30.0, 60.0, 90.0, 180.0)
"""``evaluate dynamic``: seconds from the decision frame's acquisition to the start of pointing."""
DYNAMIC_WIND_BINS_MPS = (
    (0.0, 2.0),
    (2.0, 5.0),
    (5.0, 8.0),
    (8.0, 12.0),
    (12.0, 16.0),
    (16.0, float("inf")),
)
"""``evaluate dynamic``: wind speed bins, m/s (lower bound inclusive)."""
DYNAMIC_MODES = ("static", "predictive", "wind-prior")
"""``evaluate dynamic``: how a plan meets a moving plume (``dyntarget.evaluate.dynamic.MODES``)."""
RELOOK_FRAMES = 1
"""The most frames one re-look of the look-ahead takes, a mosaic down the strip, where its
search asks more rows than one frame holds (``fly --relook-frames``)."""
MAX_RELOOK_FRAMES = 32
"""The most ``--relook-frames`` may allow."""
