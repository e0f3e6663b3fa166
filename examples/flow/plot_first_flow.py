"""
A first flow and its error
==========================

The default method, ``tvl1``, on Middlebury's RubberWhale pair (frame10 → frame11):
the flow in the Middlebury colour coding beside its endpoint error against the ground
truth.  Without the benchmark data, a photographic pair with exact flow stands in.
"""

import time

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.evaluation.datasets import load_middlebury_pair
from varflow.evaluation.metrics import endpoint_error_map

try:
    frame0, frame1, gt = load_middlebury_pair("RubberWhale")
    title = "Middlebury RubberWhale"
except FileNotFoundError:
    from varflow.generators.photo_pairs import make_photo_pair

    pair = make_photo_pair("objects", seed=0, shape=(240, 320))
    frame0, frame1 = pair.frame0, pair.frame1
    gt = np.where(pair.valid[..., None], pair.flow, np.nan).astype(np.float32)
    title = "photographic pair (objects)"

# %%
# Estimate the flow and score it.  ``evaluate`` ignores the pixels whose ground truth
# is unknown (NaN).
t0 = time.perf_counter()
flow = varflow.flow(frame0, frame1)
seconds = time.perf_counter() - t0
scores = varflow.evaluate(flow, gt)
print(f"{title}: AEE {scores['aee']:.3f} px, AAE {scores['aae']:.2f} deg, "
      f"{seconds:.2f} s")

# %%
# The flow, coloured by direction and length (the legend's radius is the largest
# motion), and the endpoint error.
error = endpoint_error_map(flow, gt)  # NaN where the ground truth is unknown
radius = float(np.nanmax(np.hypot(gt[..., 0], gt[..., 1])))
fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
axes[0].imshow(frame0)
axes[0].set_title("frame 0")
axes[1].imshow(varflow.flow_to_color(flow, max_radius=radius))
axes[1].set_title(f"flow (max {radius:.1f} px)")
im = axes[2].imshow(error, cmap="magma", vmin=0, vmax=1)
axes[2].set_title(f"endpoint error, AEE {scores['aee']:.3f} px")
fig.colorbar(im, ax=axes[2], fraction=0.046, label="px")
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()
plt.show()
