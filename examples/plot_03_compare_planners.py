"""
Compare the planners
====================

The paper's four look-ahead planners and two baselines on one scene's true mask, each
scored by the NFOV simulator on the high-resolution truth (ratio plume: the plume
fraction of the observed footprints, 0–1).
"""

import matplotlib.pyplot as plt

from dyntarget.evaluate.figures import draw_trajectory, rgb
from dyntarget.observe import observe
from dyntarget.pipeline import plan_scene
from dyntarget.plan import PAPER_PLANNERS
from dyntarget.synth import generate_scene

factor = 4
scene = generate_scene(0, 2, size=256)[0]
wfov = scene.to_wfov(factor)

fig, axes = plt.subplots(2, 3, figsize=(11, 7.5), layout="constrained")
for ax, planner in zip(axes.flat, PAPER_PLANNERS, strict=True):
    result = plan_scene(wfov.image, None, planner, mask=wfov.label)
    metrics = observe(result.trajectory, scene, factor=factor)
    print(
        f"{planner:20s} {len(result.trajectory):4d} pointings, ratio plume {metrics.ratio_plume:.2f}"
    )
    ax.imshow(rgb(wfov.image))
    ax.contour(wfov.label, levels=[0.5], colors="yellow", linewidths=0.7)
    draw_trajectory(ax, result.trajectory, label="pointings")
    ax.set_title(f"{planner}\nratio plume {metrics.ratio_plume:.2f}", fontsize=9)
    ax.set_axis_off()
fig.suptitle("yellow: true plume outline; dot: first pointing; dashed: travel")
plt.show()
