"""Reading and writing flow fields (Middlebury ``.flo``, KITTI PNG, ``.npy``) and images.

Every writer is atomic (temporary file + ``os.replace``).  Flow arrays follow the
package convention: shape ``(H, W, 2)`` float32, u = ``[..., 0]``, v = ``[..., 1]``,
NaN where unknown.
"""

from .flo import FlowFormatError, read_flo, write_flo
from .images import read_flow, read_image, write_flow, write_image
from .kitti_png import read_kitti_png, write_kitti_png
from .npy import read_npy_flow, write_npy_flow

__all__ = [
    "FlowFormatError",
    "read_flo",
    "write_flo",
    "read_kitti_png",
    "write_kitti_png",
    "read_npy_flow",
    "write_npy_flow",
    "read_image",
    "write_image",
    "read_flow",
    "write_flow",
]
