"""
Reading a flow: the colour coding and the files
===============================================

``varflow.flow_to_color`` codes a flow as the Middlebury benchmark does: the hue is the
direction, the saturation the length (relative to ``max_radius``).  A synthetic
rotation and zoom shows the wheel; the flow is then written to and read back from a
``.flo`` file (unknown pixels NaN in memory, 1e10 in the file) and a KITTI 16-bit PNG
(1/64 px steps), and the round-trip errors are measured.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import varflow

h, w = 181, 181
yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
cx, cy = (w - 1) / 2, (h - 1) / 2
flow = np.stack([-(yy - cy) * 0.1 + (xx - cx) * 0.05, (xx - cx) * 0.1 + (yy - cy) * 0.05],
                axis=-1).astype(np.float32)
flow[:20, :20] = np.nan  # an unknown corner

with tempfile.TemporaryDirectory() as tmp:
    varflow.write_flo(Path(tmp) / "f.flo", flow)
    back = varflow.read_flo(Path(tmp) / "f.flo")
    varflow.write_kitti_png(Path(tmp) / "f.png", flow)
    kitti = varflow.read_kitti_png(Path(tmp) / "f.png")
known = np.isfinite(flow[..., 0])
flo_exact = bool(np.array_equal(back[known], flow[known]) and np.isnan(back[~known]).all())
kitti_err = float(np.abs(kitti[known] - flow[known]).max())
print(f".flo round trip exact: {flo_exact}; KITTI PNG largest error {kitti_err:.4f} px")

# %%
radius = float(np.nanmax(np.hypot(flow[..., 0], flow[..., 1])))
fig, axes = plt.subplots(1, 2, figsize=(8, 4))
axes[0].imshow(varflow.flow_to_color(flow, max_radius=radius))
axes[0].set_title(f"rotation + zoom (max {radius:.1f} px)")
step = 15
axes[1].quiver(xx[::step, ::step], yy[::step, ::step], flow[::step, ::step, 0],
               flow[::step, ::step, 1], angles="xy", scale_units="xy", scale=0.5)
axes[1].set_xlim(0, w - 1)
axes[1].set_ylim(h - 1, 0)
axes[1].set_aspect("equal")
axes[1].set_title("the same vectors")
axes[0].set_axis_off()
fig.tight_layout()
plt.show()
