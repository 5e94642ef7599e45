"""
What a pointing is worth
========================

The NFOV simulator scores pointings on two utility maps computed on the
high-resolution truth: intensity (plume × blue band, normalised to 0–1) and its
gradient (Sobel magnitude, normalised to 0–1), the paper's Table 2 columns.
"""

import matplotlib.pyplot as plt

from dyntarget.observe import UtilityMaps
from dyntarget.synth import generate_scene

scene = generate_scene(0, 1, size=256)[0]
maps = UtilityMaps.from_scene(scene)
print(f"intensity max {maps.intensity.max():.2f}, gradient max {maps.gradient.max():.2f}")

fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
for ax, (name, data) in zip(
    axes, [("intensity", maps.intensity), ("gradient", maps.gradient)], strict=True
):
    shown = ax.imshow(data, cmap="viridis", vmin=0, vmax=1)
    fig.colorbar(shown, ax=ax, label=f"{name} utility (0–1)", shrink=0.85)
    ax.set_title(name)
    ax.set_xlabel("column (px, 8 m)")
axes[0].set_ylabel("row (px, 8 m)")
plt.show()
