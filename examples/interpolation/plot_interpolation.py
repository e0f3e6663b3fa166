"""
An in-between frame beside the true one
=======================================

``varflow.interpolate`` synthesises the frame at time ``t`` between two frames from the
motion between them.  Middlebury's interpolation set has the true middle frame
(``frame10i11``); without the data, a photograph shifted by 2 and 4 px stands in.  The
default method, ``splat``, is compared with FFmpeg's motion-compensated
``minterpolate`` (run through PyAV in the same process), the simple scheme ``naive``
and the cross-fade.
"""

import time

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.evaluation.frame_metrics import psnr
from varflow.evaluation.interpolation_peers import blend, minterpolate
from varflow.evaluation.interpolation_sets import interpolation_cases

try:
    case = next(c for c in interpolation_cases("middlebury", "all") if c.name == "Urban2")
    frames = case.load()
    frame0, frame1, truth = frames.frame0, frames.frame1, frames.gt
    title = "Middlebury Urban2"
except (FileNotFoundError, StopIteration):
    from varflow.generators.photo import load_photo

    photo = (load_photo("astronaut")[:240, :320] * 255).astype(np.uint8)
    shift = lambda s: np.roll(photo, (int(s), int(2 * s)), axis=(0, 1))  # noqa: E731
    frame0, truth, frame1 = shift(0), shift(2), shift(4)
    title = "a photograph shifted by 2 and 4 px"

# %%
# Each method makes the frame at t = 0.5.
made = {}
for name, run in (("splat", lambda: varflow.interpolate(frame0, frame1, 0.5)),
                  ("naive", lambda: varflow.interpolate(frame0, frame1, 0.5, "naive")),
                  ("minterpolate", lambda: minterpolate(frame0, frame1, 0.5)),
                  ("blend", lambda: blend(frame0, frame1, 0.5))):
    t0 = time.perf_counter()
    made[name] = run()
    print(f"{title}, {name}: PSNR {psnr(made[name], truth):.2f} dB, "
          f"{time.perf_counter() - t0:.2f} s")

# %%
# A crop of each frame, and the true one.
h, w = truth.shape[:2]
crop = (slice(h // 4, h // 4 + h // 2), slice(w // 4, w // 4 + w // 2))
fig, axes = plt.subplots(1, 5, figsize=(16, 3.4))
axes[0].imshow(truth[crop])
axes[0].set_title("true middle frame")
for ax, (name, img) in zip(axes[1:], made.items(), strict=True):
    ax.imshow(img[crop])
    ax.set_title(f"{name}: {psnr(img, truth):.2f} dB")
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()
plt.show()
