"""oclvox.distributed on a local Dask cluster of two worker processes.

Sharded runs are checked against the single-process run in this process (voxel for voxel, and a
.vdb read back by OpenVDB's own Python module); batches against single-process runs read back by
numpy; the CLI's cluster paths against the CLI's plain path, byte for byte.
"""

import filecmp
import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import oclvox
from conftest import SPOT

distributed = pytest.importorskip("distributed", reason="Dask (python3-distributed) not installed")
from oclvox.distributed import (  # noqa: E402
    _plan_shards, mesh_paths, sdf_sharded, sdf_sharded_to_file, shards_of, voxelize_many,
    voxelize_sharded)

CLI = os.environ.get("OCLVOX_CLI")


@pytest.fixture(scope="module")
def client():
    # Two single-threaded worker processes, as on a cluster of one-device workers. Each worker's
    # PoCL device gets one thread, so that the two share this machine's cores instead of each
    # starting a thread per core; the workers pick their device as this process does
    # ($OCLVOX_DEVICE, inherited).
    env = {"POCL_MAX_PTHREAD_COUNT": "1"}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", env=env) as cluster, \
            distributed.Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def open_spot():
    """Spot with a patch of triangles taken out: an open mesh (winding and parity differ)."""
    vertices, faces = oclvox.load_mesh(SPOT)
    centroids = vertices[faces].mean(axis=1)
    keep = np.linalg.norm(centroids - centroids[0], axis=1) > 0.15
    assert 0 < np.count_nonzero(~keep) < len(faces) // 10
    return vertices, faces[keep]


def executions(client):
    """How many tasks each worker has run (finished or failed) so far."""
    return client.run(lambda dask_worker: dask_worker.state.executed_count)


def counting_tasks(client, work):
    """Runs work(); returns its result and the tasks each worker ran meanwhile."""
    while any(client.run(lambda dask_worker: len(dask_worker.state.executing)).values()):
        time.sleep(0.05)  # tasks an earlier test cancelled, still finishing
    before = executions(client)
    result = work()
    after = executions(client)
    return result, [after[w] - before[w] for w in sorted(after)]


@pytest.mark.parametrize("resolution,options,shard_bricks", [
    (96, dict(mode="surface"), 12),
    (96, dict(mode="thin", boundary="half-open", test="pef"), 12),
    (64, dict(mode="solid", inside="parity"), 8),
    # The winding-number solid computes the whole grid in every shard: few shards, small grid.
    (40, dict(mode="filled", inside="winding"), 6),
])
def test_sharded_equals_single_process(client, open_spot, resolution, options, shard_bricks):
    options = dict(options, brick_size=16)
    single = oclvox.voxelize(open_spot, resolution, **options)
    sharded, tasks = counting_tasks(client, lambda: voxelize_sharded(
        open_spot, resolution, client=client, shard_bricks=shard_bricks, **options))
    _, shards, plan = _plan_shards(oclvox.Mesh(*open_spot), resolution, shard_bricks, client,
                                   options)
    with_triangles = len(shards) if plan.triangles is None else \
        sum(1 for t in plan.triangles if len(t))
    assert sum(tasks) == with_triangles >= 3, "too few shards to test sharding"
    if plan.triangles is not None:
        # Each shard's part of the mesh is scattered to one worker, round robin, and its task runs
        # there. (A whole mesh is on both workers, and which takes short tasks is the
        # scheduler's choice.)
        assert min(tasks) > 0, "both workers should have taken shards"
    assert single.count > 0
    assert sharded.same_voxels(single)
    assert (sharded.dims, sharded.origin, sharded.voxel_size) == \
        (single.dims, single.origin, single.voxel_size)
    assert np.array_equal(sharded.to_numpy(), single.to_numpy())


@pytest.mark.parametrize("options,whole_mesh", [
    (dict(mode="surface"), False),
    (dict(mode="filled", inside="parity"), False),
    (dict(mode="solid", inside="winding"), True),
])
def test_shards_are_sent_only_the_triangles_reaching_them(client, monkeypatch, options,
                                                          whole_mesh):
    mesh = oclvox.Mesh(*oclvox.load_mesh(SPOT))
    sent = []
    scatter = client.scatter

    def recording_scatter(data, **kwargs):
        sent.extend((part, kwargs.get("broadcast", False)) for part in data)
        return scatter(data, **kwargs)

    monkeypatch.setattr(client, "scatter", recording_scatter)
    sharded = voxelize_sharded(mesh, 64, client=client, brick_size=8, shard_bricks=16, **options)
    monkeypatch.undo()
    assert sharded.same_voxels(oclvox.voxelize(mesh, 64, brick_size=8, **options))
    triangles = [len(part.faces) for part, _ in sent]
    total = len(mesh.faces)
    if whole_mesh:
        assert triangles == [total] and sent[0][1], "the winding number needs the whole mesh"
    else:
        assert len(sent) >= 8 and not any(broadcast for _, broadcast in sent)
        assert max(triangles) < total / 3, "a shard was sent far more than its triangles"
        assert sum(triangles) < 2 * total


def test_selection_triangles_parts_give_the_shards_voxels():
    mesh = oclvox.Mesh(*oclvox.load_mesh(SPOT))
    options = dict(mode="solid", brick_size=8)
    shards = shards_of(oclvox.candidate_bricks(mesh, 48, **options), 10)
    plan = oclvox.selection_triangles(mesh, 48, selections=shards, **options)
    assert plan.inside == "parity"  # spot is closed; a part alone is open
    whole = oclvox.voxelize(mesh, 48, **options)
    merged = None
    for shard, triangles in zip(shards, plan.triangles):
        expected = oclvox.voxelize(mesh, 48, bricks=shard, **options)
        if len(triangles) == 0:
            assert expected.count == 0
            continue
        part = oclvox.voxelize(mesh.submesh(triangles), **plan.grid, inside=plan.inside,
                               bricks=shard, **options)
        assert part.same_voxels(expected)
        if merged is None:
            merged = part
        else:
            merged.merge(part)
    assert merged.same_voxels(whole)
    with pytest.raises(IndexError, match="out of range"):
        mesh.submesh([len(mesh.faces)])
    with pytest.raises(IndexError):
        mesh.submesh([-1])


def test_sharded_vdb_reads_back_as_single_process(client, tmp_path):
    pyopenvdb = pytest.importorskip("pyopenvdb", reason="python3-openvdb not installed")
    single = oclvox.voxelize(SPOT, 256, brick_size=16).to_numpy()
    candidates = len(oclvox.candidate_bricks(SPOT, 256, brick_size=16))
    assert candidates > 8 * 64  # enough that the default makes four shards per worker
    sharded, tasks = counting_tasks(
        client, lambda: voxelize_sharded(SPOT, 256, client=client, brick_size=16))
    assert sum(tasks) == 8
    sharded.save(tmp_path / "spot.vdb")
    vdb = pyopenvdb.read(str(tmp_path / "spot.vdb"), "occupancy")
    assert vdb.activeVoxelCount() == np.count_nonzero(single)
    values = np.zeros(single.shape, bool)
    vdb.copyToArray(values)
    assert np.array_equal(values, single.astype(bool))


def test_shards_of_balances_contiguous_runs():
    bricks = np.arange(10, 110, dtype=np.uint64)
    shards = shards_of(bricks, 30)
    assert [len(s) for s in shards] == [25, 25, 25, 25]
    assert np.array_equal(np.concatenate(shards), bricks)
    assert shards_of(bricks[:0], 30) == []
    with pytest.raises(ValueError):
        shards_of(bricks, 0)


def test_sharded_errors_reach_the_client(client):
    with pytest.raises(oclvox.DeviceError, match="no-such-device"):
        voxelize_sharded(SPOT, 32, client=client, device="no-such-device")
    with pytest.raises(TypeError, match="colour"):
        voxelize_sharded(SPOT, 32, client=client, colour="red")


def test_sharded_progress_counts_bricks_and_can_cancel(client):
    calls = []
    voxelize_sharded(SPOT, 128, client=client, brick_size=16, shard_bricks=20,
                     progress=lambda done, total: calls.append((done, total)))
    total = len(oclvox.candidate_bricks(SPOT, 128, brick_size=16))
    assert len(calls) == len(shards_of(np.arange(total), 20)) > 1
    assert all(t == total for _, t in calls) and calls[-1][0] == total
    assert all(a[0] < b[0] for a, b in zip(calls, calls[1:]))
    with pytest.raises(oclvox.Cancelled):
        voxelize_sharded(SPOT, 128, client=client, brick_size=16, shard_bricks=20,
                         progress=lambda done, total: False)


def test_sharded_without_candidate_bricks_is_the_empty_whole_grid(client):
    # A grid placed away from the mesh: no brick can hold a voxel.
    grid = dict(origin=(10.0, 10.0, 10.0), voxel_size=0.1, dims=(30, 20, 10), brick_size=8)
    assert len(oclvox.candidate_bricks(SPOT, **grid)) == 0
    sharded = voxelize_sharded(SPOT, client=client, **grid)
    assert sharded.count == 0 and sharded.dims == (30, 20, 10)
    assert sharded.same_voxels(oclvox.voxelize(SPOT, **grid))


@pytest.mark.parametrize("extension", [".npy", ".vdb"])
def test_full_grid_sdf_sharded_to_file_writes_the_single_process_file(client, tmp_path, extension):
    # Written a layer at a time as the slabs are waited for in turn: the file the single
    # process's field saves (.npy byte for byte, .vdb the same level set); a cancel from the
    # progress callback leaves no file.
    options = dict(band=1.0, brick_size=8, full_grid=True)
    single = oclvox.sdf(SPOT, 40, **options)
    single.save(tmp_path / f"single{extension}")
    written = []
    grid = sdf_sharded_to_file(SPOT, tmp_path / f"sharded{extension}", 40, client=client,
                               shard_layers=8, progress=lambda done, total: written.append(done),
                               **options)
    assert grid == (single.origin, single.voxel_size, single.dims)
    assert written and written[-1] == max(written)
    if extension == ".npy":
        assert filecmp.cmp(tmp_path / "single.npy", tmp_path / "sharded.npy", shallow=False)
    else:  # the same level set read back (its band found as the layers passed, then pruned)
        a, b = (oclvox.load_field(tmp_path / f"{n}.vdb") for n in ("single", "sharded"))
        assert (a.dims, a.origin, a.band, a.leaf_count) == (b.dims, b.origin, b.band, b.leaf_count)
        assert np.array_equal(a.to_field().to_numpy().view(np.uint32),
                              b.to_field().to_numpy().view(np.uint32))
    with pytest.raises(oclvox.Cancelled):
        sdf_sharded_to_file(SPOT, tmp_path / f"cancelled{extension}", 40, client=client,
                            shard_layers=8, progress=lambda done, total: False, **options)
    assert not any(p.name.startswith("cancelled") for p in tmp_path.iterdir())
    with pytest.raises(ValueError, match="sparse"):
        sdf_sharded_to_file(SPOT, tmp_path / "x.npy", 24, client=client, sparse=True)


@pytest.mark.parametrize("mesh,options", [
    ("spot", dict(band=2.0)),
    ("open", dict(band=1.5, inside="winding", pad=1)),
])
def test_sdf_sharded_equals_single_process(client, open_spot, mesh, options):
    mesh = SPOT if mesh == "spot" else open_spot
    options = dict(options, brick_size=8)
    single = oclvox.sdf(mesh, 40, **options)
    sharded, slabs = counting_tasks(client, lambda: sdf_sharded(mesh, 40, client=client,
                                                                 **options))
    # The slabs ran on the workers; which worker took which is the scheduler's choice (the mesh is
    # on both, and slabs of a few milliseconds may all go to one), unlike the voxelize shards.
    assert sum(slabs) >= 4
    assert (sharded.dims, sharded.origin, sharded.voxel_size, sharded.band) == \
        (single.dims, single.origin, single.voxel_size, single.band)
    assert np.array_equal(sharded.to_numpy().view(np.uint32), single.to_numpy().view(np.uint32))
    inside = single.to_numpy() < 0
    assert inside.any() and (~inside).any()


def test_full_grid_sdf_sharded_equals_single_process(client):
    # Dense slabs of a full grid, each searching every triangle beyond the band: the single
    # process's field bit for bit. (Its slabs are quick, so which workers run them is left to the
    # scheduler.)
    options = dict(band=1.0, brick_size=8, full_grid=True)
    single = oclvox.sdf(SPOT, 40, **options)
    sharded, slabs = counting_tasks(client, lambda: sdf_sharded(SPOT, 40, client=client,
                                                                 **options))
    assert sum(slabs) >= 4
    assert (sharded.dims, sharded.origin, sharded.voxel_size, sharded.band) == \
        (single.dims, single.origin, single.voxel_size, single.band)
    assert np.array_equal(sharded.to_numpy().view(np.uint32), single.to_numpy().view(np.uint32))
    values = single.to_numpy()
    assert (values < 0).any() and np.abs(values).max() > 5 * options["band"] * single.voxel_size


@pytest.mark.parametrize("mesh,options", [
    ("spot", dict(band=2.0)),
    ("open", dict(band=1.5, inside="winding", pad=1)),
])
def test_sparse_sdf_sharded_equals_single_process(client, open_spot, mesh, options):
    # The slabs travel as SparseFields (pickled leaves and inside voxels) and merge into the
    # single process's sparse field: the same leaves and, densely, the same bits.
    mesh = SPOT if mesh == "spot" else open_spot
    options = dict(options, brick_size=12, sparse=True)
    single = oclvox.sdf(mesh, 40, **options)
    sharded, slabs = counting_tasks(client, lambda: sdf_sharded(mesh, 40, client=client,
                                                                 shard_layers=8, **options))
    # The slabs ran on the workers; which worker took which is the scheduler's choice (the mesh is
    # on both, and slabs of a few milliseconds may all go to one), unlike the voxelize shards.
    assert sum(slabs) >= 4
    assert isinstance(sharded, oclvox.SparseField)
    assert (sharded.dims, sharded.origin, sharded.voxel_size, sharded.band, sharded.leaf_count) \
        == (single.dims, single.origin, single.voxel_size, single.band, single.leaf_count)
    dense = single.to_field().to_numpy()
    assert np.array_equal(sharded.to_field().to_numpy().view(np.uint32), dense.view(np.uint32))
    assert (dense < 0).any() and (dense > 0).any()


def test_sdf_sharded_refuses_sparse_full_grids_and_unaligned_sparse_slabs(client):
    with pytest.raises(ValueError, match="dense"):
        sdf_sharded(SPOT, 24, client=client, full_grid=True, sparse=True)
    with pytest.raises(ValueError, match="multiple of 8"):
        sdf_sharded(SPOT, 24, client=client, sparse=True, shard_layers=12)


# ---- many meshes --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def mesh_folder(tmp_path_factory):
    """20 meshes: scaled and moved copies of spot, and one corrupt file among them."""
    folder = tmp_path_factory.mktemp("meshes")
    vertices, faces = oclvox.load_mesh(SPOT)
    rng = np.random.default_rng(12)
    for i in range(19):
        scale, shift = rng.uniform(0.5, 2.0, 3), rng.uniform(-5, 5, 3)
        oclvox.save_mesh(folder / f"spot{i:02d}.obj", vertices * scale + shift, faces)
    (folder / "corrupt.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
    (folder / "notes.txt").write_text("not a mesh: not in the batch\n")
    return folder


def test_voxelize_many_resumes_and_reports_failures(client, mesh_folder, tmp_path):
    paths = mesh_paths(mesh_folder)
    assert len(paths) == 20
    out = tmp_path / "out"
    calls = []
    first, tasks = counting_tasks(client, lambda: voxelize_many(
        paths, out, 24, client=client, ext="npy", mode="solid",
        progress=lambda done, total: calls.append((done, total))))
    assert calls == [(i, 20) for i in range(1, 21)]

    # 19 outputs, each the single-process voxels (read back by numpy); one failure, named.
    assert len(first.written) == 19 and first.skipped == []
    assert list(first.failed) == [str(mesh_folder / "corrupt.obj")]
    assert "corrupt.obj" in first.failed[str(mesh_folder / "corrupt.obj")]
    for path in (p for p in paths if p.name != "corrupt.obj"):
        expected = oclvox.voxelize(path, 24, mode="solid").to_numpy()
        assert np.array_equal(np.load(out / (path.stem + ".npy")), expected), path
    # The corrupt mesh was tried twice (one retry), every other mesh once.
    assert sum(tasks) == 19 + 2

    # A rerun writes nothing again; an output without its sidecar is not complete and is redone.
    stamps = {f: f.stat().st_mtime_ns for f in out.iterdir()}
    (out / "spot03.npy.json").unlink()
    second = voxelize_many(paths, out, 24, client=client, ext=".npy", mode="solid")
    assert second.written == [str(out / "spot03.npy")]
    assert len(second.skipped) == 18 and list(second.failed) == list(first.failed)
    for f, stamp in stamps.items():
        if f.name not in ("spot03.npy", "spot03.npy.json"):
            assert f.stat().st_mtime_ns == stamp, f
    third = voxelize_many(paths, out, 24, client=client, ext=".npy", mode="solid")
    assert third.written == [] and len(third.skipped) == 19 and not third.ok


def test_voxelize_many_checks_outputs_before_work(client, mesh_folder, tmp_path):
    with pytest.raises(oclvox.OutputError, match="unknown extension"):
        voxelize_many(mesh_paths(mesh_folder), tmp_path, 24, client=client, ext="xyz")
    twins = [mesh_folder / "spot00.obj", tmp_path / "spot00.stl"]
    with pytest.raises(oclvox.InputError, match="both be written"):
        voxelize_many(twins, tmp_path, 24, client=client)


def test_list_file_paths_are_relative_to_its_folder(mesh_folder, tmp_path):
    listing = mesh_folder / "list.txt"
    listing.write_text("# two of them\nspot01.obj\n\n" + str(mesh_folder / "spot02.obj") + "\n")
    assert mesh_paths(listing) == [mesh_folder / "spot01.obj", mesh_folder / "spot02.obj"]
    listing.unlink()
    with pytest.raises(oclvox.InputError, match="neither a folder"):
        mesh_paths(tmp_path / "missing")


# ---- the CLI ------------------------------------------------------------------------------------

def run_cli(*args, check=True, **env):
    # The CLI runs the Python back end with the interpreter running these tests.
    environment = dict(os.environ, OCLVOX_PYTHON=sys.executable)
    environment.update(env)
    return subprocess.run([CLI, *map(str, args), "--quiet"], env=environment, check=check,
                          capture_output=True, text=True)


@pytest.mark.skipif(not CLI, reason="OCLVOX_CLI (the oclvox tool) not given")
def test_cli_cluster_paths_write_the_plain_paths_files(mesh_folder, tmp_path):
    batch = run_cli("batch", mesh_folder, "-o", tmp_path / "batch", "-r", 20, "--mode", "filled",
                    "--download", "blocks", "--workers", 2, check=False)
    # A failed mesh: exit code 1, the file named; the others written.
    assert batch.returncode == 1 and "corrupt.obj" in batch.stderr, batch.stderr
    assert len(list((tmp_path / "batch").iterdir())) == 19
    for i in range(3):
        plain = tmp_path / f"plain{i}.binvox"
        run_cli("voxelize", mesh_folder / f"spot0{i}.obj", "-r", 20, "--mode", "filled", "-o",
                plain)
        assert filecmp.cmp(plain, tmp_path / "batch" / f"spot0{i}.binvox", shallow=False)

    grid = ["-r", 100, "--brick-size", 16, "--mode", "thin", "--pad", 2]
    run_cli("voxelize", SPOT, *grid, "-o", tmp_path / "plain.npy")
    run_cli("voxelize", SPOT, *grid, "--workers", 2, "--shard-bricks", 10, "--download",
            "blocks", "-o", tmp_path / "sharded.npy")
    assert filecmp.cmp(tmp_path / "plain.npy", tmp_path / "sharded.npy", shallow=False)
    sidecars = [json.loads((tmp_path / f"{name}.npy.json").read_text())
                for name in ("plain", "sharded")]
    assert sidecars[0].pop("file") == "plain.npy" and sidecars[1].pop("file") == "sharded.npy"
    assert sidecars[0] == sidecars[1]

    # A distance field in slabs of layers, kept sparse, written as the plain run writes it.
    field = ["-r", 40, "--band", 2, "--inside", "winding"]
    run_cli("sdf", SPOT, *field, "-o", tmp_path / "plain_sdf.npy")
    run_cli("sdf", SPOT, *field, "--workers", 2, "-o", tmp_path / "sharded_sdf.npy")
    assert filecmp.cmp(tmp_path / "plain_sdf.npy", tmp_path / "sharded_sdf.npy", shallow=False)
    sidecars = [json.loads((tmp_path / f"{name}_sdf.npy.json").read_text())
                for name in ("plain", "sharded")]
    assert sidecars[0].pop("file") == "plain_sdf.npy"
    assert sidecars[1].pop("file") == "sharded_sdf.npy"
    assert sidecars[0] == sidecars[1]

    # A full grid: dense slabs on the cluster, the plain run's slabs written as computed.
    run_cli("sdf", SPOT, *field, "--full", "-o", tmp_path / "plain_full.npy")
    run_cli("sdf", SPOT, *field, "--full", "--workers", 2, "-o", tmp_path / "sharded_full.npy")
    assert filecmp.cmp(tmp_path / "plain_full.npy", tmp_path / "sharded_full.npy", shallow=False)
    sidecars = [json.loads((tmp_path / f"{name}_full.npy.json").read_text())
                for name in ("plain", "sharded")]
    assert sidecars[0].pop("file") == "plain_full.npy"
    assert sidecars[1].pop("file") == "sharded_full.npy"
    assert sidecars[0] == sidecars[1] and sidecars[0]["band_voxels"] > 10


@pytest.mark.skipif(not CLI, reason="OCLVOX_CLI (the oclvox tool) not given")
def test_cli_cluster_paths_fail_clearly(mesh_folder, tmp_path):
    # A Python without the package (an `oclvox` that is not this one shadows it).
    (tmp_path / "oclvox").mkdir()
    (tmp_path / "oclvox" / "__init__.py").write_text("")
    missing = run_cli("batch", mesh_folder, "-o", tmp_path / "out", check=False,
                      PYTHONPATH=str(tmp_path))
    assert missing.returncode == 1
    assert "the distributed path needs the Python package: pip install ." in missing.stderr
    no_python = run_cli("batch", mesh_folder, "-o", tmp_path / "out", check=False,
                        OCLVOX_PYTHON=str(tmp_path / "no-python"))
    assert no_python.returncode == 1 and "OCLVOX_PYTHON" in no_python.stderr
    for refused in (["--stats"], ["--cubic=min"], ["--preview", tmp_path / "p.png"]):
        run = run_cli("voxelize", SPOT, "-o", tmp_path / "x.vdb", "--workers", 2, *refused,
                      check=False)
        assert run.returncode == 2 and "not available with --workers" in run.stderr, refused
    for refused in (["--mesh", tmp_path / "m.obj"], ["--json"]):
        run = run_cli("sdf", SPOT, "-o", tmp_path / "x.vdb", "--workers", 2, *refused,
                      check=False)
        assert run.returncode == 2 and "not available with --workers" in run.stderr, refused
