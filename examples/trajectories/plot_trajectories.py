"""
Dense trajectories and their visibility
=======================================

``varflow.track`` follows every pixel of a reference frame through a clip (``rlr``,
Robust Low-Rank trajectories, by default) and tells where each point is hidden.  The
clip is rendered from photographs with moving objects, so the true trajectories and
visibility are known; the score is the mean endpoint error over the visible points of
every frame, against a loop of ``varflow.flow`` from the reference (``twoframe``).
"""

import time

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.generators.photo import make_photo_clip
from varflow.viz.plots import draw_tracks

clip = make_photo_clip("objects", seed=100, n_frames=9, shape=(96, 128))
frames, ref = clip.frames, clip.ref
print(f"{len(frames)} frames of {frames.shape[2]}x{frames.shape[1]}, reference {ref}")


def epe(traj: np.ndarray) -> float:
    """Mean endpoint error over the visible points of every frame but the reference."""
    err = np.hypot(*(traj - clip.trajectories).transpose(3, 0, 1, 2))
    keep = clip.visibility.copy()
    keep[ref] = False
    return float(err[keep].mean())


# %%
# RLR with its visibility, and the two-frame loop.
t0 = time.perf_counter()
traj, visible = varflow.track(frames, ref=ref, method="rlr", return_visibility=True)
rlr_seconds = time.perf_counter() - t0
loop = varflow.track(frames, ref=ref, method="twoframe")
hidden = ~clip.visibility
accuracy = float((visible == clip.visibility).mean())
print(f"rlr: EPE {epe(traj):.3f} px ({rlr_seconds:.1f} s); twoframe: EPE {epe(loop):.3f} px")
print(f"visibility: {hidden.mean():.1%} of the points hidden, accuracy {accuracy:.3f}")

# %%
# About 150 points drawn as TAP-Vid draws them: over the last frame, each point's tail
# runs through its positions in every frame, coloured by where the point is in the
# reference frame; where the estimate says it is hidden the tail is dashed in grey and
# the point is a grey ring.
picture = draw_tracks(frames[-1], traj, ref, visibility=visible, points=150, line_width=1)
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
axes[0].imshow(frames[0])
axes[0].set_title("first frame")
axes[1].imshow(picture)
axes[1].set_title(f"rlr tracks over the last frame, EPE {epe(traj):.2f} px")
axes[2].imshow(visible.mean(axis=0), cmap="gray", vmin=0, vmax=1)
axes[2].set_title("share of the frames in which each point is seen")
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()
plt.show()
