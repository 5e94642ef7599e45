"""
Classify and denoise
====================

Fit the paper's band-threshold classifier (a haze test on the four bands) on three
scenes, then segment a fourth: plume probability, thresholded mask, and the mask
after Algorithm 2's denoising (contours, closing, area filter).
"""

import matplotlib.pyplot as plt

from dyntarget.perceive import make_classifier
from dyntarget.pipeline import segment
from dyntarget.synth import generate_scene

train = [generate_scene(0, i, size=256)[0].to_wfov(2) for i in range(3)]
test = generate_scene(0, 5, size=256)[0].to_wfov(2)
model = make_classifier("band-threshold").fit(train)
seg = segment(test.image, model)
print(f"{len(seg.polygons)} plume polygon(s) after denoising")

fig, axes = plt.subplots(1, 3, figsize=(12, 4), layout="constrained")
shown = axes[0].imshow(seg.probability, cmap="magma", vmin=0, vmax=1)
fig.colorbar(shown, ax=axes[0], label="plume probability (0–1)", shrink=0.8)
axes[0].set_title("classifier output")
axes[1].imshow(seg.raw_mask, cmap="gray")
axes[1].set_title("thresholded mask")
axes[2].imshow(seg.mask, cmap="gray")
axes[2].contour(test.label, levels=[0.5], colors="cyan", linewidths=0.8)
axes[2].set_title("denoised (cyan: true outline)")
plt.show()
