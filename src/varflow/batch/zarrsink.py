"""The optional Zarr mirror of a batch run (``--zarr``): one store per input.

``OUT/<name>.zarr`` is a Zarr group written by the driver, region by region, as the
tasks of the input finish (from their output files, so the store holds exactly
what the files hold):

flow
    ``flow``: float32 ``(P, H, W, 2)``, one chunk per pair, NaN until written;
    attribute ``pairs`` lists the ``[i, j]`` frame pair of every row.
track
    ``trajectories``: float32 ``(W, F, H, W, 2)`` and ``visibility``: bool
    ``(W, F, H, W)``, one chunk per window; attributes ``windows`` (``[start,
    stop]``) and ``ref_frames``.

``written`` (bool, one entry per row) marks the rows already copied; it is set
after the data, and the manifest records the task as done after that, so a run
killed in between rewrites the row when resumed.  Zarr's local store replaces
chunk files atomically.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from .plan import BatchConfig, Task

__all__ = ["ZarrSink"]

log = logging.getLogger(__name__)


class ZarrSink:
    """Copy finished outputs into per-input Zarr stores.

    Parameters
    ----------
    out : Path
        The batch output folder.
    config : BatchConfig
    attrs : dict
        Attributes stored on every group (method, parameters, version).
    """

    def __init__(self, out: Path, config: BatchConfig, attrs: dict[str, Any]) -> None:
        self.out = out
        self.config = config
        self.attrs = attrs
        self._inputs: dict[str, tuple[str, list[Task]]] = {}
        self._groups: dict[str, Any] = {}
        self._written: dict[str, np.ndarray] = {}

    def register(self, name: str, input_path: str, tasks: list[Task]) -> None:
        """Declare the tasks of an input (their ``index`` is the row)."""
        self._inputs[name] = (input_path, tasks)

    def path(self, name: str) -> Path:
        """The store of an input."""
        return self.out / f"{name}.zarr"

    def _open(self, name: str) -> Any | None:
        """The input's group, or None if it does not exist yet."""
        if name in self._groups:
            return self._groups[name]
        import zarr

        p = self.path(name)
        if not (p / "zarr.json").is_file():
            return None
        group = zarr.open_group(store=str(p), mode="a")
        self._groups[name] = group
        if "written" in group:
            self._written[name] = np.asarray(group["written"][:], dtype=bool)
        return group

    def needs(self, task: Task) -> bool:
        """True if the task's row has not been copied yet."""
        if self._open(task.name) is None or task.name not in self._written:
            return True
        return not bool(self._written[task.name][task.index])

    def _create(self, name: str, sample: dict[str, np.ndarray]) -> Any:
        import zarr

        input_path, tasks = self._inputs[name]
        n = len(tasks)
        group = zarr.open_group(store=str(self.path(name)), mode="a")
        attrs = dict(self.attrs)
        attrs.update({"input": input_path, "name": name})
        if self.config.kind == "flow":
            attrs["pairs"] = [list(t.frames) for t in tasks]
        else:
            from varflow.multiframe.track import default_ref

            attrs["windows"] = [[t.frames[0], t.frames[-1] + 1] for t in tasks]
            attrs["ref_frames"] = [t.frames[default_ref(len(t.frames), None)] for t in tasks]
        for key, arr in sample.items():
            shape = (n, *arr.shape)
            if key in group:
                if tuple(group[key].shape) != shape:
                    raise ValueError(
                        f"{self.path(name)}: array {key!r} has shape {group[key].shape}, "
                        f"expected {shape}; remove the store or use --overwrite"
                    )
                continue
            fill = False if arr.dtype == np.bool_ else np.nan
            group.create_array(key, shape=shape, chunks=(1, *arr.shape), dtype=arr.dtype,
                               fill_value=fill)
        if "written" not in group:
            group.create_array("written", shape=(n,), chunks=(min(n, 4096),), dtype=bool,
                               fill_value=False)
        group.attrs.update(attrs)
        self._groups[name] = group
        self._written[name] = np.asarray(group["written"][:], dtype=bool)
        return group

    def _load(self, path: Path) -> dict[str, np.ndarray]:
        if self.config.kind == "track":
            from varflow.io.trajectories import read_trajectories

            traj, _, vis, _ = read_trajectories(path)
            data = {"trajectories": traj}
            if vis is not None:
                data["visibility"] = vis
            return data
        if self.config.fmt == "png":
            from varflow.io.kitti_png import read_kitti_png

            return {"flow": read_kitti_png(path)}
        from varflow.io.flo import read_flo

        return {"flow": read_flo(path)}

    def write(self, task: Task) -> None:
        """Copy a finished task's output file into its row.

        Raises
        ------
        ValueError, OSError
            When the output cannot be read or does not fit the store.
        """
        data = self._load(self.out / task.output)
        group = self._open(task.name)
        if group is None or any(k not in group for k in data) or "written" not in group:
            group = self._create(task.name, data)
        for key, arr in data.items():
            if tuple(group[key].shape[1:]) != arr.shape:
                raise ValueError(
                    f"{self.path(task.name)}: {task.output} has shape {arr.shape}, the store "
                    f"{tuple(group[key].shape[1:])}"
                )
            group[key][task.index] = arr
        group["written"][task.index] = True
        self._written[task.name][task.index] = True
        log.debug("zarr: wrote row %d of %s", task.index, self.path(task.name))
