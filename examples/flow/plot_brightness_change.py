"""
Flow under a change of brightness
=================================

Brightness constancy, the data term of the book's plain TV-L1, fails when the light
changes between the frames: the residual of the correct motion is no longer zero, and
the coarse levels drift.  ``tvl1``'s default energy adds a gradient-constancy term
(Brox et al. 2004), which an additive change of brightness leaves alone.  The pair is a
photograph under a moving, brightening light, with exact flow.
"""

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.generators.photo_pairs import make_photo_pair
from varflow.twoframe.params import preset

pair = make_photo_pair("illumination", seed=100, shape=(192, 256))
gt = np.where(pair.valid[..., None], pair.flow, np.nan).astype(np.float32)

# %%
# The default energy, the same without its gradient term, and the book's plain energy.
runs = {
    "tvl1 (default)": varflow.flow(pair.frame0, pair.frame1),
    "tvl1, gradient_weight=0": varflow.flow(pair.frame0, pair.frame1, gradient_weight=0.0),
    "plain TV-L1 (the book)": varflow.flow(pair.frame0, pair.frame1,
                                           params=preset("plain")),
}
aee = {name: varflow.evaluate(flow, gt)["aee"] for name, flow in runs.items()}
for name, value in aee.items():
    print(f"{name}: AEE {value:.3f} px")

# %%
radius = float(np.nanmax(np.hypot(gt[..., 0], gt[..., 1])))
fig, axes = plt.subplots(1, 5, figsize=(16, 3.2))
axes[0].imshow(pair.frame0)
axes[0].set_title("frame 0")
axes[1].imshow(pair.frame1)
axes[1].set_title("frame 1 (brighter)")
for ax, (name, flow) in zip(axes[2:], runs.items(), strict=True):
    ax.imshow(varflow.flow_to_color(flow, max_radius=radius))
    ax.set_title(f"{name}\nAEE {aee[name]:.2f} px", fontsize=9)
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()
plt.show()
