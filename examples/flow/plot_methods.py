"""
Accuracy against time: the two-frame methods
============================================

The registered two-frame methods on one Middlebury pair with ground truth (Grove2), or a
photographic pair without the data: the endpoint error and the seconds of each, after
an untimed warm-up run that loads the compiled kernels.
"""

import time

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.evaluation.datasets import load_middlebury_pair

try:
    frame0, frame1, gt = load_middlebury_pair("Grove2")
    title = "Middlebury Grove2"
except FileNotFoundError:
    from varflow.generators.photo_pairs import make_photo_pair

    pair = make_photo_pair("nonrigid", seed=100, shape=(240, 320))
    frame0, frame1 = pair.frame0, pair.frame1
    gt = np.where(pair.valid[..., None], pair.flow, np.nan).astype(np.float32)
    title = "photographic pair (nonrigid)"

methods = ["tvl1-fast", "tvl1", "tvl1-ld", "tvl1-tensor"]
aee, seconds = [], []
for method in methods:
    varflow.flow(frame0[:64, :64], frame1[:64, :64], method)  # warm-up
    t0 = time.perf_counter()
    flow = varflow.flow(frame0, frame1, method)
    seconds.append(time.perf_counter() - t0)
    aee.append(varflow.evaluate(flow, gt)["aee"])
    print(f"{title}, {method}: AEE {aee[-1]:.3f} px in {seconds[-1]:.2f} s")

# %%
fig, ax = plt.subplots(figsize=(6, 4))
ax.scatter(seconds, aee)
for m, x, y in zip(methods, seconds, aee, strict=True):
    ax.annotate(m, (x, y), textcoords="offset points", xytext=(5, 5))
ax.set_xlabel("seconds per pair")
ax.set_ylabel("mean endpoint error (px)")
ax.set_title(title)
ax.grid(alpha=0.3)
fig.tight_layout()
plt.show()
