"""voxelize() and its numpy round trips, checked against voxels worked out independently."""

import numpy as np
import pytest

import oclvox
from conftest import SPOT, box_mesh, voxel_boxes, voxel_centres

UNIT_GRID = dict(origin=(0.0, 0.0, 0.0), voxel_size=1.0, dims=(6, 6, 6))


@pytest.mark.parametrize("reference", [False, True])
def test_hand_worked_cube(reference):
    # The box [1, 4]^3 on unit voxels 0..5. Closed voxel boxes touch its surface from index 0
    # (touching x = 1) to 4 (touching x = 4); only voxel (2, 2, 2) = [2, 3]^3 lies strictly inside.
    vertices, faces = box_mesh((1, 1, 1), (4, 4, 4))
    grid = oclvox.voxelize(vertices, faces, **UNIT_GRID, reference=reference)
    occupancy = grid.to_numpy()
    assert occupancy.shape == (6, 6, 6) and occupancy.dtype == np.uint8
    expected = np.zeros((6, 6, 6), np.uint8)
    expected[0:5, 0:5, 0:5] = 1
    expected[2, 2, 2] = 0
    assert np.array_equal(occupancy, expected)
    assert grid.count == 124 and grid.dims == (6, 6, 6)
    assert grid.origin == (0.0, 0.0, 0.0) and grid.voxel_size == 1.0

    # Half-open boxes [i, i+1): the faces at 1 and 4 mark voxels 1 and 4 only; 2 and 3 are inside.
    half_open = oclvox.voxelize(vertices, faces, **UNIT_GRID, boundary="half-open",
                                reference=reference).to_numpy()
    expected = np.zeros((6, 6, 6), np.uint8)
    expected[1:5, 1:5, 1:5] = 1
    expected[2:4, 2:4, 2:4] = 0
    assert np.array_equal(half_open, expected)

    # Centres i + 0.5 inside (1, 4): indices 1, 2, 3.
    solid = oclvox.voxelize(vertices, faces, **UNIT_GRID, mode="solid",
                            reference=reference).to_numpy()
    expected = np.zeros((6, 6, 6), np.uint8)
    expected[1:4, 1:4, 1:4] = 1
    assert np.array_equal(solid, expected)
    filled = oclvox.voxelize(vertices, faces, **UNIT_GRID, mode="filled",
                             reference=reference).to_numpy()
    assert np.array_equal(filled, np.pad(np.ones((5, 5, 5), np.uint8), ((0, 1),) * 3))


@pytest.mark.parametrize("test", ["sat", "pef"])
def test_box_against_closed_form(test):
    # An off-centre box on a non-cubic grid, all coordinates dyadic so both sides compare exactly.
    # A closed voxel box touches the box's surface iff it meets the closed box and is not inside
    # its open interior; a voxel is solid iff its centre is inside.
    lo, hi = np.array([0.25, 1.0, -0.5]), np.array([2.75, 3.5, 1.25])
    origin, h, dims = (-0.5, 0.5, -1.0), 0.25, (15, 14, 11)
    vertices, faces = box_mesh(lo, hi)
    lower, upper = voxel_boxes(origin, h, dims)
    meets = np.all((lower <= hi) & (upper >= lo), axis=-1)
    inside_open = np.all((lower > lo) & (upper < hi), axis=-1)
    surface = oclvox.voxelize(vertices, faces, origin=origin, voxel_size=h, dims=dims, test=test)
    assert np.array_equal(surface.to_numpy(), (meets & ~inside_open).astype(np.uint8))
    assert surface.count == np.count_nonzero(meets & ~inside_open)

    centres = voxel_centres(origin, h, dims)
    solid = oclvox.voxelize(vertices, faces, origin=origin, voxel_size=h, dims=dims, mode="solid")
    assert np.array_equal(solid.to_numpy(), np.all((centres > lo) & (centres < hi), axis=-1))


def test_sampled_surface_points_lie_in_set_voxels(spot):
    vertices, faces = spot
    grid = oclvox.voxelize(vertices, faces, 96)
    occupancy = grid.to_numpy()
    rng = np.random.default_rng(7)
    # 20 random points per triangle plus its corners, uniform in barycentric coordinates.
    u, v = rng.random((2, len(faces), 20))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = (vertices[faces[:, n]][:, None, :] for n in range(3))
    points = np.concatenate([(a + u[..., None] * (b - a) + v[..., None] * (c - a)).reshape(-1, 3),
                             vertices[faces.ravel()]])
    index = np.floor((points - np.array(grid.origin)) / grid.voxel_size).astype(np.int64)
    # A point on the grid's upper face belongs to the last voxel.
    index = np.minimum(index, np.array(grid.dims) - 1)
    assert index.min() >= 0
    assert occupancy[index[:, 0], index[:, 1], index[:, 2]].all()


def test_fit_follows_the_mesh_box(spot):
    vertices, faces = spot
    # A power of two, so that extent / (extent / N) is exactly N (for other N the library's
    # ceil() may give the longest axis N + 1 voxels: extent / (extent / 50) rounds above 50).
    grid = oclvox.voxelize(vertices, faces, 64, pad=2)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    h = (hi - lo).max() / 64
    assert grid.voxel_size == pytest.approx(h)
    assert max(grid.dims) == 68
    assert np.allclose(grid.origin, lo - 2 * h)
    # The padding stays empty.
    occupancy = grid.to_numpy()
    assert not occupancy[:2].any() and not occupancy[-2:].any()
    cubic = oclvox.voxelize(vertices, faces, 40, cubic=True)
    assert cubic.dims == (40, 40, 40)


def test_device_equals_reference_and_modes_nest(spot):
    vertices, faces = spot
    results = {}
    for mode in ("surface", "thin", "solid", "filled"):
        device = oclvox.voxelize(vertices, faces, 48, mode=mode)
        reference = oclvox.voxelize(vertices, faces, 48, mode=mode, reference=True)
        assert np.array_equal(device.to_numpy(), reference.to_numpy()), mode
        assert reference.device == "reference" and device.device != "reference"
        results[mode] = device.to_numpy().astype(bool)
    assert not (results["thin"] & ~results["surface"]).any()
    assert np.array_equal(results["filled"], results["surface"] | results["solid"])
    assert oclvox.voxelize(vertices, faces, 48, mode="solid").stats["inside_test"] == "parity"


def test_downloads_bring_back_the_same_voxels(spot):
    # The compact download brings back 12 bytes per non-empty 4^3 block (counted here from the
    # voxels) and a 4-byte count per 64 blocks.
    vertices, faces = spot
    for mode in ("surface", "solid"):
        whole = oclvox.voxelize(vertices, faces, 64, mode=mode, inside="parity", download="whole")
        blocks = oclvox.voxelize(vertices, faces, 64, mode=mode, inside="parity",
                                 download="blocks")
        dense = whole.to_numpy()
        assert np.array_equal(blocks.to_numpy(), dense), mode
        n = tuple(-(-d // 4) * 4 for d in dense.shape)
        padded = np.zeros(n, dtype=bool)
        padded[:dense.shape[0], :dense.shape[1], :dense.shape[2]] = dense
        non_empty = padded.reshape(n[0] // 4, 4, n[1] // 4, 4, n[2] // 4, 4).any(axis=(1, 3, 5))
        compact = blocks.stats["bytes_downloaded"]
        assert 12 * non_empty.sum() <= compact <= 12 * non_empty.sum() + \
            whole.stats["bytes_downloaded"] // 128 + 4 * blocks.stats["batches"], mode
    with pytest.raises(ValueError, match="download"):
        oclvox.voxelize(vertices, faces, 16, download="some")


def test_mesh_given_every_way(spot, tmp_path):
    vertices, faces = spot
    expected = oclvox.voxelize(vertices, faces, 40).to_numpy()

    class TrimeshLike:  # what trimesh.Trimesh offers: .vertices and .faces arrays
        def __init__(self, v, f):
            self.vertices, self.faces = v, f

    as_lists = TrimeshLike(vertices.tolist(), faces.astype(np.int32).tolist())
    for mesh in (TrimeshLike(vertices, faces), as_lists, str(SPOT), SPOT, (vertices, faces),
                 oclvox.Mesh(vertices, faces)):
        assert np.array_equal(oclvox.voxelize(mesh, resolution=40).to_numpy(), expected)
    # Other layouts and integer dtypes are converted.
    assert np.array_equal(oclvox.voxelize(np.asfortranarray(vertices), faces.astype(np.uint32),
                                          40).to_numpy(), expected)


def test_load_mesh_round_trip(tmp_path):
    vertices, faces = box_mesh((-1, 0, 2), (3, 0.5, 2.25))
    path = tmp_path / "box.obj"
    oclvox.save_mesh(path, vertices, faces)
    loaded_vertices, loaded_faces = oclvox.load_mesh(path)
    assert loaded_vertices.dtype == np.float64 and loaded_vertices.shape == (8, 3)
    assert loaded_faces.dtype == np.int64 and loaded_faces.shape == (12, 3)
    # Same triangles by position (the loader may renumber vertices).
    assert np.array_equal(np.sort(loaded_vertices[loaded_faces].reshape(12, -1), axis=0),
                          np.sort(vertices[faces].reshape(12, -1), axis=0))
    # The vertices array is the mesh's own storage, not a copy.
    assert not loaded_vertices.flags["OWNDATA"]


def test_save_and_from_numpy_round_trip(spot, tmp_path):
    vertices, faces = spot
    grid = oclvox.voxelize(vertices, faces, 40)
    occupancy = grid.to_numpy()
    grid.save(tmp_path / "spot.npy")
    assert np.array_equal(np.load(tmp_path / "spot.npy"), occupancy)

    rebuilt = oclvox.VoxelGrid.from_numpy(occupancy * 7.5, origin=grid.origin,
                                          voxel_size=grid.voxel_size, brick_size=16)
    assert rebuilt.count == grid.count and rebuilt.dims == grid.dims
    assert np.array_equal(rebuilt.to_numpy(), occupancy)


def test_csg_of_voxel_grids_is_bitwise(spot):
    vertices, faces = spot
    grid = dict(origin=(-0.5, -0.8, -0.7), voxel_size=0.03, dims=(34, 52, 50))
    a = oclvox.voxelize(vertices, faces, **grid, mode="solid")
    b = oclvox.voxelize(vertices + [0.1, 0.05, 0.0], faces, **grid)
    na, nb = a.to_numpy().astype(bool), b.to_numpy().astype(bool)
    for op, expected in (("union", na | nb), ("intersection", na & nb),
                         ("difference", na & ~nb)):
        assert np.array_equal(oclvox.csg(a, op, b).to_numpy(), expected), op
