"""Pieces of one grid from Python. Brick selections: voxelize(..., bricks=...) over the shards of candidate_bricks
merges into the unrestricted result, and VoxelGrid and Mesh survive pickling (how Dask moves
them between processes) with every voxel and coordinate intact."""

import pickle

import numpy as np
import pytest

import oclvox


@pytest.mark.parametrize("mode", ["surface", "thin", "solid", "filled"])
def test_shards_merge_into_the_whole(spot, mode):
    whole = oclvox.voxelize(spot, 40, mode=mode, brick_size=8)
    candidates = oclvox.candidate_bricks(spot, 40, mode=mode, brick_size=8)
    assert candidates.dtype == np.uint64
    assert set(whole.brick_indices()) <= set(candidates)
    merged = None
    for shard in np.array_split(candidates, 3):
        part = oclvox.voxelize(spot, 40, mode=mode, brick_size=8, bricks=shard)
        assert set(part.brick_indices()) <= set(shard)
        if merged is None:
            merged = part
        else:
            merged.merge(part)
    assert merged.same_voxels(whole)
    assert merged.count == whole.count
    assert np.array_equal(merged.to_numpy(), whole.to_numpy())


def test_merge_refuses_another_grid(spot):
    a = oclvox.voxelize(spot, 24)
    b = oclvox.voxelize(spot, 25)
    with pytest.raises(oclvox.GridError):
        a.merge(b)


def test_brick_outside_the_grid_is_an_error(spot):
    with pytest.raises(oclvox.GridError, match="outside the grid"):
        oclvox.voxelize(spot, 16, brick_size=8, bricks=[10**6])
    with pytest.raises(ValueError):
        oclvox.voxelize(spot, 16, brick_size=8, bricks=[[1, 2]])


def test_voxel_grid_pickles_sparsely(spot):
    grid = oclvox.voxelize(spot, 48, brick_size=16)
    data = pickle.dumps(grid)
    # The set 4^3 blocks travel (a word each) and a bit per block of the stored bricks, not the
    # dense grid and not the bricks' empty blocks. Blocks counted here from the dense array.
    dense = grid.to_numpy()
    padded = np.pad(dense, [(0, -n % 4) for n in dense.shape])
    set_blocks = np.count_nonzero(padded.reshape(
        padded.shape[0] // 4, 4, padded.shape[1] // 4, 4, padded.shape[2] // 4, 4).any(
            axis=(1, 3, 5)))
    mask_bytes = grid.brick_count * (16 // 4)**3 // 8
    assert set_blocks * 8 + mask_bytes < len(data) < set_blocks * 8 + mask_bytes + 4096
    assert len(data) < grid.brick_count * 16**3 // 8 / 2  # under half of the bricks' bits
    back = pickle.loads(data)
    assert back.same_voxels(grid)
    assert (back.origin, back.voxel_size, back.dims, back.brick_size) == \
        (grid.origin, grid.voxel_size, grid.dims, grid.brick_size)
    assert np.array_equal(back.to_numpy(), grid.to_numpy())


def test_damaged_voxel_grid_state_is_refused(spot):
    state = oclvox.voxelize(spot, 32, brick_size=8).__getstate__()
    for bad in (state[:6] + (state[6][:-1],) + state[7:],   # a word missing
                state[:6] + (np.append(state[6], 1),) + state[7:],  # one too many
                state[:5] + (state[5][:, :-1],) + state[6:],  # masks of the wrong width
                state[:7]):
        empty = oclvox.VoxelGrid.__new__(oclvox.VoxelGrid)
        with pytest.raises(ValueError, match="not a pickled oclvox.VoxelGrid"):
            empty.__setstate__(bad)


def test_mesh_pickles_exactly(spot):
    mesh = oclvox.Mesh(*spot)
    back = pickle.loads(pickle.dumps(mesh))
    assert np.array_equal(back.vertices, mesh.vertices)
    assert np.array_equal(back.faces, mesh.faces)


@pytest.mark.parametrize("full_grid", [False, True])
def test_sdf_layers_stack_into_the_whole_field(spot, full_grid):
    whole = oclvox.sdf(spot, 40, band=2.0, brick_size=8, full_grid=full_grid)
    nz = whole.dims[2]
    cuts = [0, 5, 17, 30, nz]
    parts = [oclvox.sdf(spot, 40, band=2.0, brick_size=8, layers=(a, b), full_grid=full_grid)
             for a, b in zip(cuts, cuts[1:])]
    stacked = np.concatenate([p.to_numpy() for p in parts], axis=2)
    assert np.array_equal(stacked.view(np.uint32), whole.to_numpy().view(np.uint32))
    assert parts[1].origin[2] == whole.origin[2] + 5 * whole.voxel_size
    # A full grid's slabs hold distances far beyond the band, a narrow band's none.
    assert (np.abs(stacked).max() > 5 * 2.0 * whole.voxel_size) == full_grid
    with pytest.raises(oclvox.GridError):
        oclvox.sdf(spot, 40, full_grid=full_grid, layers=(5, 5))
