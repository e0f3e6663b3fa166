"""
Repairing dirt and flicker
==========================

Old film carries dust and dirt on single frames and flickers in brightness from frame
to frame.  ``varflow.restore_clip`` chains the repair stages in the order restoration
practice uses them: here ``deflicker`` (a smooth gain and offset per frame against the
motion-compensated neighbours, corrected toward a smoothed brightness path), then
``dirt`` (blotches found as spikes in time along the flow and filled from the
neighbours).  The defects are planted by ``varflow.evaluation.defects`` in a crop of
the ``carphone`` clip (or, without the data, a photograph moving one pixel per frame),
so the result can be scored against the clean frames; the mask shows every pixel the
dirt stage replaced, beside the blotches that were planted.
"""

import matplotlib.pyplot as plt
import numpy as np

import varflow
from varflow.evaluation.datasets import data_root
from varflow.evaluation.defects import plant_dirt, plant_flicker
from varflow.evaluation.denoising import clip_psnr, protocol_clips

try:
    clean = protocol_clips(data_root(), 8, ("carphone",))["carphone"][:, 8:120, 16:160]
    title = "carphone"
except (FileNotFoundError, KeyError):
    from varflow.generators.photo import load_photo

    photo = load_photo("astronaut")[:112, :144] * 255
    clean = np.stack([np.roll(photo, k, axis=1) for k in range(8)]).astype(np.float32)
    title = "a photograph moving 1 px per frame"

flickered, _ = plant_flicker(clean, seed=3)
degraded, planted = plant_dirt(flickered, seed=3)  # planted: (F, H, W) bool, exact
degraded = np.clip(np.rint(degraded), 0, 255).astype(np.uint8)

# %%
# Both stages in one call; the mask comes back with the frames.
restored, mask = varflow.restore_clip(degraded, ["deflicker", "dirt"], return_mask=True)

found = mask & planted
print(f"{title}: PSNR degraded {clip_psnr(degraded, clean):.2f} dB, "
      f"restored {clip_psnr(restored, clean):.2f} dB")
print(f"blotched pixels: {planted.sum()}, replaced: {mask.sum()}, "
      f"precision {found.sum() / max(mask.sum(), 1):.2f}, "
      f"recall {found.sum() / max(planted.sum(), 1):.2f}")

# %%
# Before, after, and the mask (white: replaced; red: planted but missed) on one frame.
f = int(np.argmax(planted.sum(axis=(1, 2))))  # the frame with the most dirt
overlay = np.stack([mask[f] | (planted[f] & ~mask[f]), mask[f], mask[f]], -1).astype(float)
fig, axes = plt.subplots(1, 3, figsize=(10, 3.2))
for ax, image, name in zip(axes, (degraded[f], restored[f], overlay),
                           ("degraded (flicker + dirt)", "restored", "dirt mask"),
                           strict=True):
    ax.imshow(np.clip(image, 0, 255).astype(np.uint8) if image.dtype != float else image)
    ax.set_title(name)
    ax.axis("off")
fig.suptitle(f"{title}, frame {f}")
fig.tight_layout()
plt.show()
