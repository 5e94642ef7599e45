"""
Fly a pass
==========

A long moving strip with several plumes, cut into look-ahead frames at the frame
cadence; each frame is planned (here on the truth mask: the oracle classifier), the
pointings of one shared NFOV are scheduled under the ``fast`` agility preset and
scored against the plume at their own time.
"""

import matplotlib.pyplot as plt
import numpy as np

from dyntarget.fly import PassConfig, fly_pass
from dyntarget.synth.strip import strip_spec
from dyntarget.synth.strip_world import MovingStrip

spec, window = strip_spec(0, width=128, length=576, plumes=3)
world = MovingStrip(spec, window)
result = fly_pass(world, None, PassConfig(agility="fast", compute_budget_s=0.2))
totals = result.totals()
print({k: totals[k] for k in ("frames", "pointings_flown", "plumes_observed", "plumes_total")})

flown = result.flown
fig, ax = plt.subplots(figsize=(11, 3.6), layout="constrained")
f = result.config.factor
image = world.image_at(0.0, 0, world.shape[0])
ax.imshow(np.clip(image[:3, ::f, ::f].transpose(2, 1, 0)[:, ::-1] * 2.5, 0, 1), origin="upper")
h = world.shape[0] // f
shown = ax.scatter(h - 1 - np.asarray(flown.y), flown.x, c=flown.t, s=8, cmap="viridis")
fig.colorbar(shown, ax=ax, label="pointing time (s after the first look)")
ax.set_xlabel("along track (WFOV px, flight →)")
ax.set_ylabel("across (WFOV px)")
ax.set_title(f"{totals['plumes_observed']} of {totals['plumes_total']} plumes observed")
plt.show()
