"""sdf(), csg() and mesh() against closed forms: box distances, a sphere's surface and volume."""

import shutil

import numpy as np
import pytest

import oclvox
from conftest import box_mesh, voxel_centres

GRID = dict(origin=(-1.0, -1.0, -1.0), voxel_size=0.125, dims=(40, 36, 32))
BAND = 3.0


def box_sdf(points, lo, hi):
    """Exact signed distance to the surface of the box [lo, hi]: negative inside."""
    lo, hi = np.asarray(lo), np.asarray(hi)
    outside = np.maximum(np.maximum(lo - points, points - hi), 0.0)
    inside = np.minimum(points - lo, hi - points).min(axis=-1)
    return np.where(inside > 0, -inside, np.linalg.norm(outside, axis=-1))


def clamp_to_band(values, voxel_size):
    return np.clip(values, -BAND * voxel_size, BAND * voxel_size)


BOX_A = ((0.1, 0.2, 0.3), (2.6, 2.4, 2.2))
BOX_B = ((1.3, -0.6, 0.9), (3.4, 1.5, 2.7))


@pytest.mark.parametrize("reference", [False, True])
def test_sdf_of_a_box_is_its_distance(reference):
    field = oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, reference=reference)
    values = field.to_numpy()
    assert values.dtype == np.float32 and values.shape == GRID["dims"]
    assert field.dims == GRID["dims"] and field.origin == GRID["origin"]
    assert field.voxel_size == GRID["voxel_size"]
    expected = clamp_to_band(box_sdf(voxel_centres(**GRID), *BOX_A), GRID["voxel_size"])
    # Float32 distances of a few-voxel-sized box: well within 1e-5 voxels of the double value.
    assert np.abs(values - expected).max() < 1e-5 * GRID["voxel_size"]
    # The samples are the field's own, shared read-only.
    assert not values.flags["OWNDATA"] and not values.flags["WRITEABLE"]


def test_sdf_device_equals_reference(spot):
    device = oclvox.sdf(*spot, 40).to_numpy()
    reference = oclvox.sdf(*spot, 40, reference=True).to_numpy()
    assert np.array_equal(device, reference)


def test_csg_of_meshes_combines_distances():
    a, b = box_mesh(*BOX_A), box_mesh(*BOX_B)
    centres = voxel_centres(**GRID)
    da, db = box_sdf(centres, *BOX_A), box_sdf(centres, *BOX_B)
    h = GRID["voxel_size"]
    for op, expected in (("union", np.minimum(da, db)), ("intersection", np.maximum(da, db)),
                         ("difference", np.maximum(da, -db))):
        field = oclvox.csg(a, op, b, **GRID, band=BAND)
        assert isinstance(field, oclvox.Field)
        # Clamping to the band commutes with min and max, so this is exact up to float rounding.
        assert np.abs(field.to_numpy() - clamp_to_band(expected, h)).max() < 1e-5 * h, op


def test_csg_of_fields_is_min_max():
    rng = np.random.default_rng(3)
    a = oclvox.Field(rng.normal(size=(5, 6, 7)), origin=(1, 2, 3), voxel_size=0.5)
    b = oclvox.Field(rng.normal(size=(5, 6, 7)), origin=(1, 2, 3), voxel_size=0.5)
    na, nb = a.to_numpy(), b.to_numpy()
    assert np.array_equal(oclvox.csg(a, "union", b).to_numpy(), np.minimum(na, nb))
    assert np.array_equal(oclvox.csg(a, "intersection", b).to_numpy(), np.maximum(na, nb))
    assert np.array_equal(oclvox.csg(a, "difference", b).to_numpy(), np.maximum(na, -nb))


def sphere_field(radius_voxels=9.3, n=26):
    h = 0.5
    origin = np.array([-n / 2 * h] * 3)
    centres = voxel_centres(origin, h, (n, n, n))
    centre = np.array([0.11, -0.07, 0.05])
    values = np.linalg.norm(centres - centre, axis=-1) - radius_voxels * h
    return oclvox.Field(values, origin=tuple(origin), voxel_size=h), centre, radius_voxels * h, h


def check_closed_oriented(vertices, faces):
    """Every directed edge once and its reverse once: closed, manifold along edges, oriented."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    as_set = {tuple(e) for e in directed}
    assert len(as_set) == len(directed)
    assert all((b, a) in as_set for a, b in as_set)
    assert faces.min() >= 0 and faces.max() < len(vertices)


@pytest.mark.parametrize("method,tolerance", [("marching-cubes", 0.02), ("surface-nets", 0.1)])
def test_mesh_of_a_sphere(method, tolerance):
    field, centre, radius, h = sphere_field()
    vertices, faces = oclvox.mesh(field, method=method)
    assert vertices.dtype == np.float64 and faces.dtype == np.int64
    # Vertices on the sphere: exact crossings (marching cubes) to within the linear
    # interpolation's error, or their mean (surface nets), a fraction of a voxel.
    distance = np.abs(np.linalg.norm(vertices - centre, axis=1) - radius)
    assert distance.max() < tolerance * radius
    check_closed_oriented(vertices, faces)
    # Wound counter-clockwise from outside: a positive volume close to the sphere's.
    a, b, c = (vertices[faces[:, n]] for n in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert volume == pytest.approx(4 / 3 * np.pi * radius ** 3, rel=0.03)
    # The device and the host reference give the same mesh, bit for bit.
    reference = oclvox.mesh(field, method=method, reference=True)
    assert np.array_equal(vertices, reference[0]) and np.array_equal(faces, reference[1])
    # Field.mesh is the same call.
    assert np.array_equal(field.mesh(method=method)[1], faces)


def test_mesh_of_voxels_and_of_a_field_file(tmp_path):
    # A solid box of voxels meshes to a closed surface around it.
    occupancy = np.zeros((10, 12, 9), np.uint8)
    occupancy[2:7, 3:10, 1:6] = 1
    grid = oclvox.VoxelGrid.from_numpy(occupancy, origin=(0, 0, 0), voxel_size=1.0)
    vertices, faces = oclvox.mesh(grid, smoothing=0)
    check_closed_oriented(vertices, faces)
    # Without smoothing the surface runs through the faces between set and unset voxels.
    assert np.allclose(vertices.min(axis=0), [2, 3, 1]) and np.allclose(vertices.max(axis=0),
                                                                        [7, 10, 6])
    # Voxels are meshed through their smoothed field's meshing view, made a layer at a time: the
    # dense field's reference mesh, vertex for vertex.
    for smoothing in (0, 1, 2):
        layered = oclvox.mesh(grid, smoothing=smoothing)
        whole = oclvox.mesh(grid, smoothing=smoothing, reference=True)
        assert np.array_equal(layered[0], whole[0]) and np.array_equal(layered[1], whole[1])
    # A saved field reads back equal, with its grid, and meshes the same.
    field, _, _, _ = sphere_field()
    field.save(tmp_path / "sphere.npy")
    loaded = oclvox.load_field(tmp_path / "sphere.npy")
    assert np.array_equal(np.load(tmp_path / "sphere.npy"), field.to_numpy())
    assert loaded.dims == field.dims and loaded.voxel_size == field.voxel_size
    assert np.allclose(loaded.origin, field.origin)
    # The file is meshed a layer at a time (through its meshing view), the field whole: the same
    # vertices and faces, at any iso, and so is a C-order copy of the file (read whole).
    shutil.copy(tmp_path / "sphere.npy.json", tmp_path / "c_order.npy.json")
    np.save(tmp_path / "c_order.npy", np.ascontiguousarray(np.load(tmp_path / "sphere.npy")))
    for iso in (0.0, 0.3):
        whole = oclvox.mesh(field, iso=iso, reference=True)
        assert len(whole[1]) > 100
        for path in ("sphere.npy", "c_order.npy"):
            layered = oclvox.mesh(tmp_path / path, iso=iso)
            assert np.array_equal(layered[0], whole[0]) and np.array_equal(layered[1], whole[1])


@pytest.mark.parametrize("reference", [False, True])
def test_sparse_sdf_is_the_dense_sdf_and_saves_the_same_files(reference, tmp_path):
    # A box's sparse field: its dense copy is the dense field bit for bit, it holds only the
    # leaves near the surface, and its .npy file is the dense field's.
    dense = oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, reference=reference)
    sparse = oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, reference=reference, sparse=True)
    assert isinstance(sparse, oclvox.SparseField) and "leaves" in repr(sparse)
    assert sparse.dims == dense.dims and sparse.origin == dense.origin and sparse.band == BAND
    np.testing.assert_array_equal(sparse.to_field().to_numpy(), dense.to_numpy())
    leaves = np.prod([(n + 7) // 8 for n in GRID["dims"]])
    assert 0 < sparse.leaf_count < leaves
    assert sparse.stats["bricks_active"] == sparse.leaf_count
    sparse.save(tmp_path / "sparse.npy")
    dense.save(tmp_path / "dense.npy")
    np.testing.assert_array_equal(np.load(tmp_path / "sparse.npy"), dense.to_numpy())


def test_sparse_csg_of_meshes_is_the_dense_csg(tmp_path):
    a, b = box_mesh(*BOX_A), box_mesh(*BOX_B)
    for op in ("union", "intersection", "difference"):
        dense = oclvox.csg(a, op, b, band=BAND, resolution=40)
        sparse = oclvox.csg(a, op, b, band=BAND, resolution=40, sparse=True)
        np.testing.assert_array_equal(sparse.to_field().to_numpy(), dense.to_numpy())


def test_sparse_fields_on_one_lattice_combine_on_the_box_of_both(tmp_path):
    # b's grid starts 3, -5 and 9 voxels from a's and is smaller on two axes; both go through
    # .vdb files, as level sets to combine usually come.
    voxel = GRID["voxel_size"]
    offset = np.array([3, -5, 9])
    other = dict(voxel_size=voxel, dims=(30, 40, 20),
                 origin=tuple(np.array(GRID["origin"]) + offset * voxel))
    a = oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, sparse=True)
    b = oclvox.sdf(*box_mesh(*BOX_B), **other, band=BAND, sparse=True)
    a.save(tmp_path / "a.vdb")
    b.save(tmp_path / "b.vdb")
    a, b = oclvox.load_field(tmp_path / "a.vdb"), oclvox.load_field(tmp_path / "b.vdb")
    # Each field's samples placed in the box of both, +background (outside) beyond its grid.
    lo = np.minimum(0, offset)
    shape = tuple(np.maximum(GRID["dims"], offset + other["dims"]) - lo)
    background = np.float32(BAND * voxel)

    def placed(field, at):
        values = np.full(shape, background, dtype=np.float32)
        d = field.dims
        values[at[0]:at[0] + d[0], at[1]:at[1] + d[1], at[2]:at[2] + d[2]] = \
            field.to_field().to_numpy()
        return values

    va, vb = placed(a, -lo), placed(b, offset - lo)
    expected = {"union": np.minimum(va, vb), "intersection": np.maximum(va, vb),
                "difference": np.maximum(va, -vb)}
    for op, want in expected.items():
        result = oclvox.csg(a, op, b)
        assert isinstance(result, oclvox.SparseField) and result.dims == shape
        assert np.allclose(result.origin, np.array(GRID["origin"]) + lo * voxel, rtol=0,
                           atol=1e-12)
        np.testing.assert_array_equal(result.to_field().to_numpy(), want)
        assert (want < 0).sum() > 100
    # Half a voxel off a's lattice b is refused, unless read onto a's lattice (rebuilt there):
    # then the union lies on a's lattice and holds about as many inside voxels as the exact one.
    shifted = dict(other, origin=tuple(np.array(other["origin"]) + 0.5 * voxel))
    b_shifted = oclvox.sdf(*box_mesh(*BOX_B), **shifted, band=BAND, sparse=True)
    with pytest.raises(oclvox.GridError, match="lattice"):
        oclvox.csg(a, "union", b_shifted)
    b_shifted.save(tmp_path / "b_shifted.vdb")
    # (Its grid cuts the box, so its inside would be lost by the rebuild: refused. On a grid that
    # holds the box it is rebuilt.)
    with pytest.raises(oclvox.InputError, match="cut by its grid"):
        oclvox.load_field(tmp_path / "b_shifted.vdb", onto=a)
    shifted = dict(GRID, origin=tuple(np.array(GRID["origin"]) + 0.5 * voxel))
    oclvox.sdf(*box_mesh(*BOX_B), **shifted, band=BAND, sparse=True).save(tmp_path / "b_whole.vdb")
    rebuilt = oclvox.load_field(tmp_path / "b_whole.vdb", onto=a)
    union = oclvox.csg(a, "union", rebuilt)
    steps = (np.array(union.origin) - np.array(GRID["origin"])) / voxel
    assert np.allclose(steps, np.round(steps), rtol=0, atol=1e-9)
    inside = (union.to_field().to_numpy() < 0).sum()
    exact = (oclvox.csg(box_mesh(*BOX_A), "union", box_mesh(*BOX_B), **GRID, band=BAND)
             .to_numpy() < 0).sum()
    assert abs(inside - exact) < 0.03 * exact, (inside, exact)
    with pytest.raises(TypeError, match="SparseField"):
        oclvox.load_field(tmp_path / "b_whole.vdb", onto=b.to_field())
    with pytest.raises(TypeError, match="SparseFields"):
        oclvox.csg(a, "union", b.to_field())


def test_sparse_fields_refuse_full_grids_and_unaligned_layers():
    with pytest.raises(oclvox.GridError):
        oclvox.sdf(*box_mesh(*BOX_A), **GRID, full_grid=True, sparse=True)
    with pytest.raises(oclvox.GridError, match="multiple of 8"):
        oclvox.sdf(*box_mesh(*BOX_A), **GRID, layers=(0, 12), sparse=True)


def test_sparse_layer_fields_pickle_and_merge_into_the_whole_field():
    import pickle
    whole = oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, sparse=True)
    low = oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, sparse=True, layers=(0, 16))
    high = pickle.loads(pickle.dumps(
        oclvox.sdf(*box_mesh(*BOX_A), **GRID, band=BAND, sparse=True, layers=(16, 0))))
    assert 0 < low.leaf_count < whole.leaf_count and low.leaf_count + high.leaf_count == \
        whole.leaf_count
    high.merge(low)  # interleaved: the lower leaves go first
    assert high.leaf_count == whole.leaf_count
    np.testing.assert_array_equal(high.to_field().to_numpy(), whole.to_field().to_numpy())
    with pytest.raises(oclvox.GridError, match="both"):
        high.merge(low)
    other = dict(GRID, voxel_size=0.25)
    with pytest.raises(oclvox.GridError, match="same grid"):
        high.merge(oclvox.sdf(*box_mesh(*BOX_A), **other, band=BAND, sparse=True))
    state = list(whole.__getstate__())
    state[-2] = state[-2][:-1]  # a leaf's samples missing
    with pytest.raises(ValueError, match="pickled oclvox.SparseField"):
        oclvox.SparseField.__new__(oclvox.SparseField).__setstate__(tuple(state))


@pytest.mark.parametrize("method", ["marching-cubes", "surface-nets"])
def test_sparse_field_meshes_as_its_dense_copy_and_reads_back_from_vdb(method, tmp_path):
    # Meshed without a dense copy, the same vertices (in the same order) and faces as the dense
    # copy's mesh; saved as .vdb and loaded back (sparse), the same mesh again.
    sparse = oclvox.csg(box_mesh(*BOX_A), "difference", box_mesh(*BOX_B), band=BAND,
                        resolution=40, sparse=True)
    vertices, faces = sparse.mesh(method)
    dense_vertices, dense_faces = oclvox.mesh(sparse.to_field(), method=method, reference=True)
    assert len(faces) > 100
    np.testing.assert_array_equal(vertices, dense_vertices)
    np.testing.assert_array_equal(faces, dense_faces)
    sparse.save(tmp_path / "difference.vdb")
    loaded = oclvox.load_field(tmp_path / "difference.vdb")
    assert isinstance(loaded, oclvox.SparseField)
    assert loaded.dims == sparse.dims and loaded.origin == sparse.origin
    np.testing.assert_array_equal(loaded.to_field().to_numpy(), sparse.to_field().to_numpy())
    np.testing.assert_array_equal(oclvox.mesh(tmp_path / "difference.vdb", method=method)[1], faces)
    with pytest.raises(ValueError):
        sparse.mesh(method, device="any")
    (tmp_path / "bad.vdb").write_bytes(b"not a vdb")
    with pytest.raises(oclvox.InputError):
        oclvox.load_field(tmp_path / "bad.vdb")


def test_layers_written_from_a_callable_are_the_file_and_its_errors_come_back_as_they_were(
        tmp_path):
    # The writer behind sdf_sharded_to_file: layer k from a callable, x fastest; an exception the
    # callable raises comes back as itself, a wrong shape as an error naming the layer, and
    # neither leaves a file.
    write = oclvox._oclvox.write_field_layers
    write(tmp_path / "ramp.npy", (0.0, 0.0, 0.0), 1.0, (4, 5, 6), 0.0,
          lambda k: np.full((4, 5), k - 2.5) + np.arange(4)[:, None] * 0.125)
    ramp = np.load(tmp_path / "ramp.npy")
    assert ramp.shape == (4, 5, 6)
    assert np.array_equal(ramp[3, 2, :], np.arange(6) - 2.5 + 0.375)

    def failing(k):
        if k == 3:
            raise KeyError("slab lost")
        return np.zeros((4, 5), np.float32)

    with pytest.raises(KeyError, match="slab lost"):
        write(tmp_path / "failed.npy", (0.0, 0.0, 0.0), 1.0, (4, 5, 6), 0.0, failing)
    with pytest.raises(oclvox.Error, match="layer 0 must be an"):
        write(tmp_path / "failed.vdb", (0.0, 0.0, 0.0), 1.0, (4, 5, 6), 0.0,
              lambda k: np.zeros((5, 4)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ramp.npy", "ramp.npy.json"]
