"""Running voxelization tasks beyond one process: recipes other processes rebuild a surface from, and tasks on Dask
or a pool."""

from ..common.moved import forward


def __getattr__(name: str):  # the 0.2 module implc.cluster's names, for one release
    return forward(__name__, ("tasks", "recipe"), name)
