"""Benchmark of oclvox.distributed on local Dask clusters: what sharding and batching cost and gain.

    PYTHONPATH=build/python /usr/bin/python3 bench/dask_bench.py [--mesh M] [--resolution 4096]
        [--shard-bricks K] [--batch 50] [--batch-resolution 256] [--project 32768] [--out F.md]

Measures, each with the load average beside it (other jobs on a shared machine show there):
- scheduling overhead: a trivial task's round trip, one at a time, and per task when 1000 are
  queued at once;
- one grid (--mesh at --resolution, surface): the single-process call on one core, then
  voxelize_sharded on 1 and 2 workers, each a process whose PoCL device has one thread (so that
  1 worker = 1 core): wall time, shards, compute time summed over shards (Dask's task stream),
  result size (pickled, as it travels);
- a shard's voxelize call on the whole mesh against on the triangles that reach it;
- a batch: --batch scaled and moved copies of the mesh through voxelize_many on 1 and 2 workers;
- a projection for --project^3 on 100 workers from the measured per-brick cost and result bytes
  (oclvox.candidate_bricks gives the brick count at that size without voxelizing);
- one distance field (--mesh at --sdf-resolution, band 3) through sdf_sharded on 2 workers, dense
  and sparse: wall time, what the client holds, and the two compared sample for sample.
--sdf-only runs the last section alone. Prints a Markdown report (and writes it to --out).
"""

import argparse
import os
import pathlib
import pickle
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import distributed
import oclvox
from oclvox.distributed import sdf_sharded, voxelize_many, voxelize_sharded

MESHES = pathlib.Path(os.environ.get("OCLVOX_MESH_DIR", "/work/shared/data/meshes"))
# One PoCL thread per worker process: a worker is one core, as it would be one device.
ONE_CORE = {"POCL_MAX_PTHREAD_COUNT": "1"}


def load():
    return "%.1f" % os.getloadavg()[0]


def cluster(workers):
    return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                    dashboard_address=":0", env=ONE_CORE)


def warm_up(client, mesh):
    """Opens each worker's device and loads its kernels, so that no timing includes them; starts
    the scheduler's task stream, which records only from its first use."""
    client.run(lambda: oclvox.voxelize(mesh, 64).count)
    client.get_task_stream()


def noop(x):
    return x


def overhead(lines):
    with cluster(1) as c, distributed.Client(c) as client:
        client.submit(noop, 0).result()
        trips = []
        for i in range(200):
            start = time.perf_counter()
            client.submit(noop, i, pure=False).result()
            trips.append(time.perf_counter() - start)
        start = time.perf_counter()
        client.gather(client.map(noop, range(1000), pure=False))
        queued = (time.perf_counter() - start) / 1000
    lines.append(f"- one trivial task's round trip, one at a time: median "
                 f"{statistics.median(trips) * 1e3:.1f} ms (load {load()})")
    lines.append(f"- 1000 trivial tasks queued at once: {queued * 1e3:.2f} ms per task "
                 f"(load {load()})")


def single_process_seconds(mesh, resolution):
    """oclvox.voxelize in a fresh process on one PoCL thread; the call alone (device open and
    kernels loaded by a warm-up call first)."""
    script = ("import sys, time, oclvox\n"
              "m = oclvox.load_mesh(sys.argv[1]); oclvox.voxelize(m, 64)\n"
              "t = time.perf_counter(); g = oclvox.voxelize(m, int(sys.argv[2]))\n"
              "print(time.perf_counter() - t, g.brick_count, g.count)\n")
    out = subprocess.run([sys.executable, "-c", script, str(mesh), str(resolution)],
                         env=dict(os.environ, **ONE_CORE), check=True, capture_output=True,
                         text=True).stdout.split()
    return float(out[0]), int(out[1]), int(out[2])


def compute_times(stream, prefix):
    """Per task of `prefix`: (start, stop) of its compute on the worker, from Dask's task stream."""
    return [next((s["start"], s["stop"]) for s in t["startstops"] if s["action"] == "compute")
            for t in stream.data if t["key"].startswith(prefix)]


def sharded(mesh, resolution, shard_bricks, workers):
    """One voxelize_sharded run; returns its figures and the grid."""
    with cluster(workers) as c, distributed.Client(c) as client:
        warm_up(client, mesh)
        before = load()
        with distributed.get_task_stream(client) as stream:
            start = time.perf_counter()
            grid = voxelize_sharded(mesh, resolution, client=client, shard_bricks=shard_bricks)
            wall = time.perf_counter() - start
    spans = compute_times(stream, "_voxelize_shard")
    computes = [stop - start for start, stop in spans]
    return dict(wall=wall, shards=len(spans), compute=sum(computes),
                span=max(s for _, s in spans) - min(s for s, _ in spans),
                shard_median=statistics.median(computes), load=f"{before}/{load()}"), grid


def receive_cost(mesh, resolution, shard_bricks):
    """Wall seconds per MiB for the client to take one finished shard from a worker (Dask's
    transfer: serialization, compression, TCP, deserialization) and merge it into another: the
    part of voxelize_sharded that one client does for every shard."""
    from oclvox.distributed import _voxelize_shard
    bricks = oclvox.candidate_bricks(mesh, resolution)
    with cluster(1) as c, distributed.Client(c) as client:
        warm_up(client, mesh)
        [on_worker] = client.scatter([oclvox._as_mesh(mesh)], broadcast=True)
        first, second = (client.submit(_voxelize_shard, on_worker, resolution,
                                       bricks[i * shard_bricks:(i + 1) * shard_bricks], None, {})
                         for i in range(2))
        distributed.wait([first, second])
        merged = first.result()
        start = time.perf_counter()
        merged.merge(second.result())
        seconds = time.perf_counter() - start
        mib = len(pickle.dumps(second.result(), protocol=5)) / 2**20
    return seconds / mib


# Run in a fresh process on one PoCL thread: one worker's view of a shard.
SHARD_PREPARATION = """
import statistics, sys, time
import numpy as np
import oclvox
from oclvox.distributed import shards_of
mesh = oclvox.Mesh(*oclvox.load_mesh(sys.argv[1]))
resolution, shard_bricks, sampled = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
oclvox.voxelize(mesh, 64)  # device open, kernels loaded
start = time.perf_counter()
shards = shards_of(oclvox.candidate_bricks(mesh, resolution), shard_bricks)
plan = oclvox.selection_triangles(mesh, resolution, selections=shards)
planning = time.perf_counter() - start
whole, part, sizes = [], [], []
for i in np.linspace(0, len(shards) - 1, sampled).astype(int):
    start = time.perf_counter()
    expected = oclvox.voxelize(mesh, resolution, bricks=shards[i])
    whole.append(time.perf_counter() - start)
    start = time.perf_counter()
    got = oclvox.voxelize(mesh.submesh(plan.triangles[i]), **plan.grid, bricks=shards[i])
    part.append(time.perf_counter() - start)
    sizes.append(len(plan.triangles[i]))
    assert got.same_voxels(expected)
print(len(shards), planning, statistics.median(whole), statistics.median(part),
      statistics.median(sizes))
"""


def shard_preparation(mesh, resolution, shard_bricks, sampled=5):
    """A shard's voxelize call on the whole mesh (it prepares every triangle) against on the
    triangles selection_triangles gives it (submesh included), median over `sampled` shards spread
    over the grid, in one process on one PoCL thread; plus the client's one planning pass."""
    out = subprocess.run([sys.executable, "-c", SHARD_PREPARATION, str(mesh), str(resolution),
                          str(shard_bricks), str(sampled)],
                         env=dict(os.environ, **ONE_CORE), check=True, capture_output=True,
                         text=True).stdout.split()
    shards, planning, whole, part, size = (float(x) for x in out)
    return dict(shards=int(shards), planning=planning, whole=whole, part=part,
                triangles=int(size))


def batch(mesh, count, resolution, workers, folder):
    out = folder / f"out{workers}"
    with cluster(workers) as c, distributed.Client(c) as client:
        warm_up(client, mesh)
        before = load()
        paths = sorted(folder.glob("*.ply"))[:count]
        with distributed.get_task_stream(client) as stream:
            start = time.perf_counter()
            summary = voxelize_many(paths, out, resolution, client=client)
            wall = time.perf_counter() - start
    assert summary.ok and len(summary.written) == count, summary
    spans = compute_times(stream, "_voxelize_file")
    return dict(wall=wall, compute=sum(stop - start for start, stop in spans),
                load=f"{before}/{load()}")


def sharded_fields(mesh, resolution, workers=2):
    """sdf_sharded dense and sparse (band 3) on one cluster: wall seconds, the bytes the client
    ends up holding, and whether the two fields are the same samples."""
    with cluster(workers) as c, distributed.Client(c) as client:
        warm_up(client, mesh)
        runs = {}
        for sparse in (False, True):
            before = load()
            start = time.perf_counter()
            field = sdf_sharded(mesh, resolution, client=client, band=3.0, sparse=sparse)
            wall = time.perf_counter() - start
            held = len(pickle.dumps(field, protocol=5)) if sparse else field.to_numpy().nbytes
            runs[sparse] = dict(wall=wall, held=held, load=f"{before}/{load()}", field=field)
    dense, sparse = runs[False]["field"], runs[True]["field"]
    same = np.array_equal(sparse.to_field().to_numpy().view(np.uint32),
                          dense.to_numpy().view(np.uint32))
    return runs, same, sparse.leaf_count, dense.dims


def sdf_section(mesh, resolution):
    runs, same, leaves, dims = sharded_fields(mesh, resolution)
    lines = ["", f"## One distance field: {resolution} (grid {dims[0]}x{dims[1]}x{dims[2]}), "
             "band 3, sdf_sharded on 2 workers", "",
             "| field | wall s | the client holds | load |", "|---|---:|---:|---|"]
    for sparse, run in runs.items():
        what = (f"{run['held'] / 2**20:.1f} MiB ({leaves} leaves and the inside bits, pickled)"
                if sparse else f"{run['held'] / 2**20:.1f} MiB (4 bytes a voxel; twice that "
                               "while the slabs are copied in)")
        lines.append(f"| {'sparse' if sparse else 'dense'} | {run['wall']:.2f} | {what} | "
                     f"{run['load']} |")
    lines += ["", f"- sparse == dense, sample for sample: {same}"]
    assert same
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mesh", default=str(MESHES / "bunny00.off"))
    parser.add_argument("--resolution", type=int, default=4096)
    parser.add_argument("--shard-bricks", type=int,
                        help="bricks per shard (default: 8 shards, the split voxelize_sharded "
                             "makes by default on 2 workers; the same for both runs)")
    parser.add_argument("--batch", type=int, default=50)
    parser.add_argument("--batch-resolution", type=int, default=256)
    parser.add_argument("--project", type=int, default=32768)
    parser.add_argument("--sdf-resolution", type=int, default=512)
    parser.add_argument("--sdf-only", action="store_true")
    parser.add_argument("--out")
    args = parser.parse_args()
    mesh = pathlib.Path(args.mesh)
    if args.sdf_only:
        report([f"# oclvox on local Dask clusters ({mesh.name})"] +
               sdf_section(mesh, args.sdf_resolution), args.out)
        return
    lines = [f"# oclvox on local Dask clusters ({mesh.name})", "",
             f"{os.cpu_count()} cores; each worker a process with a one-thread PoCL device; "
             f"load average (1 min) shown as before/after each run.", "", "## Scheduling", ""]
    overhead(lines)

    # One grid.
    r = args.resolution
    candidates = len(oclvox.candidate_bricks(mesh, r))
    shard_bricks = args.shard_bricks or -(-candidates // 8)
    alone, _, alone_count = single_process_seconds(mesh, r)
    runs = {}
    for w in (1, 2):
        runs[w], grid = sharded(mesh, r, shard_bricks, w)
    # The sharded result is the single-process one (checked in full, voxel for voxel).
    assert grid.count == alone_count and grid.same_voxels(oclvox.voxelize(mesh, r))
    result_bytes = len(pickle.dumps(grid, protocol=5))
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        grid.save(os.path.join(tmp, "grid.vdb"))
        vdb_seconds = time.perf_counter() - start
    receiving = receive_cost(mesh, r, shard_bricks)
    lines += ["", f"## One grid: {r}^3 surface, shards of {shard_bricks} bricks (64^3)", "",
              f"- single process, one core, the voxelize call alone: {alone:.2f} s "
              f"(load {load()})", "",
              "| workers | wall s | shards | compute s (sum over shards) | compute span s | "
              "median shard s | speed-up (wall) vs 1 worker | load |",
              "|---:|---:|---:|---:|---:|---:|---:|---|"]
    for w, run in runs.items():
        lines.append(f"| {w} | {run['wall']:.2f} | {run['shards']} | {run['compute']:.2f} | "
                     f"{run['span']:.2f} | {run['shard_median']:.3f} | "
                     f"{runs[1]['wall'] / run['wall']:.2f} | {run['load']} |")
    one = runs[1]
    per_brick = one["compute"] / candidates
    per_result_brick = result_bytes / grid.brick_count
    lines += ["", f"- sharded == single process: {grid.count} voxels set, same voxels",
              f"- {candidates} candidate bricks, {grid.brick_count} in the result; result "
              f"{result_bytes / 2**20:.1f} MiB pickled ({per_result_brick / 1024:.1f} KiB per "
              f"result brick)",
              f"- compute per candidate brick: {per_brick * 1e3:.2f} ms (1 worker, sum over "
              f"shards / candidate bricks)",
              f"- taking a finished shard from a worker and merging it: {receiving * 1e3:.1f} ms "
              f"per MiB, wall (load {load()})",
              f"- writing the merged result as one .vdb: {vdb_seconds:.2f} s (load {load()})"]

    # What a shard costs on the whole mesh and on its own triangles.
    triangles = len(oclvox.load_mesh(mesh)[1])
    lines += ["", f"## A shard on the whole mesh and on its triangles ({triangles} triangles)",
              "", "One process on one PoCL thread; the voxelize call of one shard, median of 5 "
              "shards spread over the grid; planning: candidate_bricks, shards_of and "
              "selection_triangles for all shards, once, on the client.", "",
              "| grid | bricks per shard | shards | planning s | shard s, whole mesh | "
              "shard s, its triangles | its triangles (median) | load |",
              "|---|---:|---:|---:|---:|---:|---:|---|"]
    for resolution, bricks in ((1024, 8), (4096, 64), (r, shard_bricks)):
        run = shard_preparation(mesh, resolution, bricks)
        lines.append(f"| {resolution}^3 | {bricks} | {run['shards']} | {run['planning']:.3f} | "
                     f"{run['whole']:.4f} | {run['part']:.4f} | {run['triangles']} | {load()} |")

    # A batch.
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        vertices, faces = oclvox.load_mesh(mesh)
        rng = np.random.default_rng(50)
        for i in range(args.batch):
            oclvox.save_mesh(folder / f"m{i:03d}.ply",
                             vertices * rng.uniform(0.5, 2, 3) + rng.uniform(-1, 1, 3), faces)
        batches = {w: batch(mesh, args.batch, args.batch_resolution, w, folder) for w in (1, 2)}
    lines += ["", f"## A batch: {args.batch} copies at {args.batch_resolution}, .binvox", "",
              "| workers | wall s | compute s (sum) | per mesh s | speed-up | load |",
              "|---:|---:|---:|---:|---:|---|"]
    for w, run in batches.items():
        lines.append(f"| {w} | {run['wall']:.2f} | {run['compute']:.2f} | "
                     f"{run['wall'] / args.batch:.3f} | {batches[1]['wall'] / run['wall']:.2f} | "
                     f"{run['load']} |")

    # The projection.
    n = args.project
    big = len(oclvox.candidate_bricks(mesh, n))
    gib = big * per_result_brick / 2**30
    compute = big * per_brick / 100
    receive = gib * 1024 * receiving
    write = vdb_seconds * big / grid.brick_count
    lines += ["", f"## Projection: {n}^3 on 100 workers", "",
              f"- candidate bricks at {n}^3: {big} (oclvox.candidate_bricks; "
              f"{big / candidates:.0f}x those at {r}^3)",
              f"- compute: {big} x {per_brick * 1e3:.2f} ms / 100 workers = {compute:.1f} s per "
              f"worker (one PoCL core each, as measured)",
              f"- result: {big} x {per_result_brick / 1024:.1f} KiB = {gib:.1f} GiB into the "
              f"client",
              f"- client: {gib * 1024:.0f} MiB x {receiving * 1e3:.1f} ms/MiB = {receive:.0f} s "
              f"of taking and merging shards, one process",
              f"- one .vdb: {vdb_seconds:.2f} s x {big / grid.brick_count:.0f} = {write:.0f} s "
              f"(scaled by result bricks from the {r}^3 write)"]
    report(lines + sdf_section(mesh, args.sdf_resolution), args.out)


def report(lines, out):
    text = "\n".join(lines) + "\n"
    print(text)
    if out:
        pathlib.Path(out).write_text(text)


if __name__ == "__main__":
    main()
