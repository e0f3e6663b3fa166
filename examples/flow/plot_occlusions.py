"""
Where the flow cannot be right: occlusions
==========================================

A pixel of the first frame that is covered in the second has no correspondence, and its
flow is a guess of the regulariser.  The forward-backward check finds such pixels: the
flow forward and the flow back do not return to where they started
(:func:`varflow.ops.occlusion.hidden_mask`).  On MPI-Sintel (alley_1, frame 2, with the
true occlusion mask), or a photographic pair with moving objects without the data,
the detected mask is compared with the truth and the error is scored over all pixels
and over the visible ones, as Sintel's protocol does.
"""

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.evaluation.datasets import load_sintel_pair
from varflow.evaluation.metrics import endpoint_error_map
from varflow.ops.occlusion import hidden_mask

try:
    frame0, frame1, gt, occluded, _ = load_sintel_pair("alley_1", 2, "clean")
    title = "MPI-Sintel alley_1, frame 2 (clean)"
except FileNotFoundError:
    from varflow.generators.photo_pairs import make_photo_pair

    pair = make_photo_pair("objects", seed=1, shape=(240, 320))
    frame0, frame1, gt = pair.frame0, pair.frame1, pair.flow
    occluded = ~pair.valid
    title = "photographic pair (objects)"

# %%
# Flows both ways, and the pixels of frame 0 hidden in frame 1.
forward = varflow.flow(frame0, frame1)
backward = varflow.flow(frame1, frame0)
hidden = hidden_mask(forward, backward, tolerance=1.0, relative=0.05)
recall = float((hidden & occluded).sum() / max(occluded.sum(), 1))
precision = float((hidden & occluded).sum() / max(hidden.sum(), 1))
aee_all = varflow.evaluate(forward, gt)["aee"]
aee_visible = varflow.evaluate(forward, gt, mask=~occluded)["aee"]
print(f"{title}: {occluded.mean():.1%} occluded; detected with precision {precision:.2f}, "
      f"recall {recall:.2f}")
print(f"AEE all {aee_all:.3f} px, visible {aee_visible:.3f} px")

# %%
# The error concentrates where the truth says the pixel is covered.
overlay = np.zeros(hidden.shape + (3,), np.float32)
overlay[..., 0] = occluded
overlay[..., 1] = hidden
fig, axes = plt.subplots(1, 3, figsize=(13, 3.2))
axes[0].imshow(varflow.flow_to_color(forward))
axes[0].set_title("forward flow")
axes[1].imshow(overlay)
axes[1].set_title("occluded: true (red), detected (green), both (yellow)", fontsize=9)
axes[2].imshow(endpoint_error_map(forward, gt), cmap="magma", vmin=0, vmax=3)
axes[2].set_title(f"endpoint error: all {aee_all:.2f}, visible {aee_visible:.2f} px",
                  fontsize=9)
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()
plt.show()
