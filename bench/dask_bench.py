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
- a batch: --batch scaled and moved copies of the mesh through voxelize_many on 1 and 2 workers;
- a projection for --project^3 on 100 workers from the measured per-brick cost and result bytes
  (oclvox.candidate_bricks gives the brick count at that size without voxelizing).
Prints a Markdown report (and writes it to --out).
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
from oclvox.distributed import voxelize_many, voxelize_sharded

MESHES = pathlib.Path(os.environ.get("OCLVOX_MESH_DIR", "/work/shared/data/meshes"))
# One PoCL thread per worker process: a worker is one core, as it would be one device.
ONE_CORE = {"POCL_MAX_PTHREAD_COUNT": "1"}


def load():
    return "%.1f" % os.getloadavg()[0]


def cluster(workers):
    return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                    dashboard_address=None, env=ONE_CORE)


def warm_up(client, mesh):
    """Opens each worker's device and loads its kernels, so that no timing includes them."""
    client.run(lambda: oclvox.voxelize(mesh, 64).count)


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


def sharded(mesh, resolution, shard_bricks, workers):
    with cluster(workers) as c, distributed.Client(c) as client:
        warm_up(client, mesh)
        before = load()
        with distributed.get_task_stream(client) as stream:
            start = time.perf_counter()
            grid = voxelize_sharded(mesh, resolution, client=client, shard_bricks=shard_bricks)
            wall = time.perf_counter() - start
    computes = [sum(s["stop"] - s["start"] for s in t["startstops"] if s["action"] == "compute")
                for t in stream.data if t["key"].startswith("_voxelize_shard")]
    return dict(wall=wall, shards=len(computes), compute=sum(computes),
                shard_median=statistics.median(computes), bytes=len(pickle.dumps(grid)),
                bricks=grid.brick_count, count=grid.count, load=f"{before}/{load()}")


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
    computes = [sum(s["stop"] - s["start"] for s in t["startstops"] if s["action"] == "compute")
                for t in stream.data if t["key"].startswith("_voxelize_file")]
    return dict(wall=wall, compute=sum(computes), load=f"{before}/{load()}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mesh", default=str(MESHES / "bunny00.off"))
    parser.add_argument("--resolution", type=int, default=4096)
    parser.add_argument("--shard-bricks", type=int, default=256)
    parser.add_argument("--batch", type=int, default=50)
    parser.add_argument("--batch-resolution", type=int, default=256)
    parser.add_argument("--project", type=int, default=32768)
    parser.add_argument("--out")
    args = parser.parse_args()
    mesh = pathlib.Path(args.mesh)
    lines = [f"# oclvox on local Dask clusters ({mesh.name})", "",
             f"{os.cpu_count()} cores; each worker a process with a one-thread PoCL device; "
             f"load average (1 min) shown as before/after each run.", "", "## Scheduling", ""]
    overhead(lines)

    # One grid.
    r = args.resolution
    alone, _, _ = single_process_seconds(mesh, r)
    runs = {w: sharded(mesh, r, args.shard_bricks, w) for w in (1, 2)}
    lines += ["", f"## One grid: {r}^3 surface, shards of {args.shard_bricks} bricks (64^3)", "",
              f"- single process, one core, the voxelize call alone: {alone:.2f} s "
              f"(load {load()})", "",
              "| workers | wall s | shards | compute s (sum over shards) | median shard s | "
              "speed-up vs 1 worker | load |", "|---:|---:|---:|---:|---:|---:|---|"]
    for w, run in runs.items():
        lines.append(f"| {w} | {run['wall']:.2f} | {run['shards']} | {run['compute']:.2f} | "
                     f"{run['shard_median']:.3f} | {runs[1]['wall'] / run['wall']:.2f} | "
                     f"{run['load']} |")
    one = runs[1]
    candidates = len(oclvox.candidate_bricks(mesh, r))
    per_brick = one["compute"] / candidates
    per_result_brick = one["bytes"] / one["bricks"]
    lines += ["", f"- {candidates} candidate bricks, {one['bricks']} in the result, "
                  f"{one['count']} voxels set; result {one['bytes'] / 2**20:.1f} MiB pickled "
                  f"({per_result_brick / 1024:.1f} KiB per result brick)",
              f"- compute per candidate brick: {per_brick * 1e3:.2f} ms (1 worker); "
              f"wall - compute on 1 worker: {one['wall'] - one['compute']:.2f} s "
              f"({(one['wall'] - one['compute']) / one['shards'] * 1e3:.1f} ms per shard)"]

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
    big = len(oclvox.candidate_bricks(mesh, args.project))
    lines += ["", f"## Projection: {args.project}^3 on 100 workers", "",
              f"- candidate bricks at {args.project}^3: {big} (oclvox.candidate_bricks)",
              f"- compute: {big} x {per_brick * 1e3:.2f} ms / 100 = "
              f"{big * per_brick / 100:.1f} s per worker (one PoCL core each)",
              f"- result: at most {big} x {per_result_brick / 1024:.1f} KiB = "
              f"{big * per_result_brick / 2**30:.1f} GiB gathered into the client"]
    report = "\n".join(lines) + "\n"
    print(report)
    if args.out:
        pathlib.Path(args.out).write_text(report)


if __name__ == "__main__":
    main()
