"""Shared helpers: hand-made meshes and the paths the build passes in."""

import os
import pathlib

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SPOT = pathlib.Path(os.environ.get("OCLVOX_SAMPLE_DIR", REPO / "samples")) / "spot.obj"


def box_mesh(lo, hi):
    """The closed surface of the box [lo, hi]: 8 vertices, 12 triangles wound outwards."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corners = np.array([[(hi if (c >> a) & 1 else lo)[a] for a in range(3)] for c in range(8)])
    # Corner c has x from bit 0, y from bit 1, z from bit 2. Each face's corners are listed
    # counter-clockwise seen from outside and split into two triangles.
    quads = [(0, 4, 6, 2), (1, 3, 7, 5),  # x = lo, x = hi
             (0, 1, 5, 4), (2, 6, 7, 3),  # y = lo, y = hi
             (0, 2, 3, 1), (4, 5, 7, 6)]  # z = lo, z = hi
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return corners, np.array(faces, dtype=np.int64)


def voxel_boxes(origin, voxel_size, dims):
    """Lower and upper corners of every voxel, each of shape (nx, ny, nz, 3)."""
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in dims], indexing="ij"), axis=-1)
    lower = np.asarray(origin) + idx * voxel_size
    return lower, lower + voxel_size


def voxel_centres(origin, voxel_size, dims):
    lower, _ = voxel_boxes(origin, voxel_size, dims)
    return lower + 0.5 * voxel_size


@pytest.fixture(scope="session")
def spot():
    import oclvox

    return oclvox.load_mesh(SPOT)
