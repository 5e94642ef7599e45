"""
A synthetic volcanic scene
==========================

dyntarget's built-in scenes: a 4-band (R, G, B, NIR) reflectance image of a volcano
whose plume drifts over land, water and weather clouds, with the true plume mask.
Scene ``i`` of a set depends only on ``(seed, i)``; each is georeferenced in UTM zone 5N.
"""

import matplotlib.pyplot as plt

from dyntarget.evaluate.figures import rgb
from dyntarget.synth import generate_scene

scene, params = generate_scene(seed=0, index=1, size=256)
print(scene.id, scene.shape, f"{scene.gsd:g} m/px", scene.crs)
print(f"plume covers {100 * scene.label.mean():.1f} % of the scene")

fig, axes = plt.subplots(1, 3, figsize=(11, 4), layout="constrained")
axes[0].imshow(rgb(scene.image))
axes[0].set_title("RGB")
axes[1].imshow(rgb(scene.image, bands=(3, 0, 1)))
axes[1].set_title("false colour (NIR, R, G)")
axes[2].imshow(scene.label, cmap="gray")
axes[2].set_title("true plume mask (white)")
for ax in axes:
    ax.set_xlabel("column (px, 8 m)")
axes[0].set_ylabel("row (px, 8 m)")
plt.show()
