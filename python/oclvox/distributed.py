"""oclvox on a Dask cluster: one grid too big for one machine, or many meshes.

- ``voxelize_sharded(mesh, resolution, client=...)`` splits the grid's bricks that can hold voxels
  into shards, runs one task per shard on the workers and merges the sparse results into one
  VoxelGrid, bit for bit the one ``oclvox.voxelize`` returns.
- ``sdf_sharded(mesh, resolution, client=...)`` does the same for a signed distance field (a
  narrow band, sparse or dense, or a full grid), by slabs of z layers;
  ``sdf_sharded_to_file(mesh, path, resolution, client=...)`` writes a dense one to a file a slab
  at a time, never holding it whole.
- ``voxelize_many(paths, out_dir, resolution, client=...)`` voxelizes one mesh per task into one
  file per mesh, skips outputs already written, retries a failed task once and reports failures at
  the end.

Every worker opens its own OpenCL device (``device=``, default the worker's ``$OCLVOX_DEVICE``,
else its first GPU, else its first device). Workers need the ``oclvox`` package; for
``voxelize_many`` they also read the inputs and write the outputs, so those paths must be the same
on every machine (a shared file system).

Dask is imported only when these functions run, so ``import oclvox`` never needs it. The module is
also the back end of the CLI's ``oclvox voxelize --workers/--scheduler`` and ``oclvox batch``
(``python3 -m oclvox.distributed --help``).
"""

import argparse
import bisect
import contextlib
import dataclasses
import inspect
import json
import logging
import math
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

import oclvox

# The formats oclvox.load_mesh reads; a folder given to mesh_paths is filtered by them (it may
# hold .mtl files, READMEs, ...).
MESH_EXTENSIONS = (".obj", ".stl", ".ply", ".off", ".gltf", ".glb", ".3mf")

# voxelize's options that pass through to the workers. `progress` is voxelize_sharded's own,
# `bricks` is what it chooses, `device` is the workers'.
_PASSED_OPTIONS = frozenset(inspect.signature(oclvox.voxelize).parameters) - {
    "vertices", "faces", "resolution", "progress", "device", "bricks"}


def _distributed():
    """dask.distributed, or an ImportError that says how to get it."""
    try:
        import distributed
    except ImportError as error:
        raise ImportError("oclvox.distributed needs Dask's distributed scheduler: apt install "
                          "python3-distributed, or pip install 'dask[distributed]'") from error
    return distributed


def _check_options(options):
    unknown = sorted(set(options) - _PASSED_OPTIONS)
    if unknown:
        raise TypeError(f"unknown voxelize option(s): {', '.join(unknown)} (expected some of "
                        f"{', '.join(sorted(_PASSED_OPTIONS))})")


def _report(progress, done, total):
    """Calls a progress(done, total) callback; False from it cancels, as in oclvox.voxelize."""
    if progress is not None and progress(done, total) is False:
        raise oclvox.Cancelled("cancelled by the progress callback")


def _collect(client, futures, on_result):
    """Waits for `futures` (a dict future -> tag), passing each finished one to
    on_result(future, tag) in the order they finish, and dropping it then so that its result
    leaves the cluster as soon as it has been used. If on_result raises, the futures not yet
    finished are cancelled."""
    distributed = _distributed()
    pending = dict(futures)
    futures.clear()
    try:
        for future in distributed.as_completed(list(pending)):
            on_result(future, pending.pop(future))
    finally:
        if pending:
            client.cancel(list(pending))


# ---- one grid in shards -------------------------------------------------------------------------

def _voxelize_shard(mesh, resolution, bricks, device, options):
    """A worker's task: the voxels of the whole grid that lie in `bricks`, from the whole mesh or
    from the triangles that reach them (then `options` fix the whole run's grid and inside test)."""
    return oclvox.voxelize(mesh, resolution, bricks=bricks, device=device, **options)


def shards_of(bricks, shard_bricks):
    """`bricks` (sorted brick indices) cut into contiguous runs of about `shard_bricks` each, the
    runs' lengths differing by at most one."""
    if shard_bricks < 1:
        raise ValueError(f"shard_bricks must be at least 1, got {shard_bricks}")
    if len(bricks) == 0:
        return []
    return np.array_split(np.asarray(bricks, dtype=np.uint64),
                          math.ceil(len(bricks) / shard_bricks))


def _auto_shard_bricks(brick_count, client):
    """About four shards per worker: a worker that finishes early takes another, so the run ends
    at most about a quarter of a worker's share after the work runs out. At least 64 bricks a
    shard, so that a shard's work outweighs the cost of a task."""
    workers = max(1, len(client.scheduler_info()["workers"]))
    return max(64, math.ceil(brick_count / (4 * workers)))


def _plan_shards(mesh, resolution, shard_bricks, client, options):
    """The candidate bricks, the shards cut from them and oclvox.selection_triangles' plan."""
    grid_options = {k: v for k, v in options.items()
                    if k in inspect.signature(oclvox.candidate_bricks).parameters}
    candidates = oclvox.candidate_bricks(mesh, resolution, **grid_options)
    if grid_options.get("mode") in ("solid", "filled"):
        # Parity reads whole brick columns (crossings below a voxel count): shards of whole
        # columns read each column's triangles in one shard, not in every shard of a z range.
        dims = oclvox._oclvox.fit_grid(mesh, oclvox._fit(
            resolution, options.get("voxel_size"), options.get("origin"), options.get("dims"),
            options.get("pad", 0), options.get("cubic", False)))[2]
        brick = grid_options.get("brick_size",
                                 inspect.signature(oclvox.voxelize).parameters["brick_size"].default)
        columns = math.ceil(dims[0] / brick) * math.ceil(dims[1] / brick)
        candidates = candidates[np.argsort(candidates % np.uint64(columns), kind="stable")]
    shards = shards_of(candidates, shard_bricks or _auto_shard_bricks(len(candidates), client))
    plan = oclvox.selection_triangles(mesh, resolution, selections=shards, **grid_options)
    return candidates, shards, plan


def voxelize_sharded(mesh, resolution=256, *, client, shard_bricks=None, device=None,
                     progress=None, **options):
    """Voxelizes one mesh on a Dask cluster; returns the VoxelGrid oclvox.voxelize returns.

    mesh: as for oclvox.voxelize (a path is read here, on the client). options: voxelize's
    (mode, test, inside, boundary, grid options, brick_size, device_memory, host_memory,
    reference). The bricks that can hold set voxels (oclvox.candidate_bricks, computed here
    without a device) are cut into shards of about `shard_bricks` bricks (default: about four
    shards per worker, at least 64 bricks each); each shard is one task,
    oclvox.voxelize(..., bricks=shard), on the device `device` names on that worker (default: the
    worker's $OCLVOX_DEVICE, else its first GPU, else its first device). The shards' results are
    merged as they arrive, so the client holds the result and at most one shard's. The result is
    bit for bit the single-process one: each brick is computed by exactly one shard, by the same
    code on the same grid.

    Surface, thin and parity solid (and filled) shards get only the triangles that reach their
    bricks (oclvox.selection_triangles, one pass over the mesh here), so a shard's work and the
    data sent to it follow its share of the surface, and a shard with none is no task. A
    winding-number solid (inside="winding", or "auto" on an open mesh) needs the whole mesh in
    every shard: the mesh is sent to every worker once, and each shard computes the whole grid
    and keeps its bricks, so it gains nothing from sharding; run it with oclvox.voxelize or with
    few shards.

    progress: called as progress(bricks_done, bricks_total) as shards finish; returning False
    cancels the shards not yet done and raises oclvox.Cancelled.
    """
    _check_options(options)
    # Phase 1: the mesh, read once; the bricks worth a task, in shards, and each shard's triangles.
    mesh = oclvox._as_mesh(mesh)
    candidates, shards, plan = _plan_shards(mesh, resolution, shard_bricks, client, options)

    # Phase 2: one task per shard that has triangles. A part of the mesh would fit another grid
    # and could choose another inside test, so its tasks are given the whole run's.
    tasks = []  # (mesh or its future, options, shard)
    if plan.triangles is None:
        [mesh_on_workers] = client.scatter([mesh], broadcast=True)
        tasks = [(mesh_on_workers, options, shard) for shard in shards]
    else:
        part_options = {k: v for k, v in options.items()
                        if k not in ("voxel_size", "origin", "dims", "pad", "cubic")}
        part_options.update(plan.grid, inside=plan.inside)
        parts = [(mesh.submesh(triangles), shard)
                 for triangles, shard in zip(plan.triangles, shards) if len(triangles)]
        # Scattered rather than inlined in the tasks: each part goes to one worker, once.
        futures = client.scatter([part for part, _ in parts], hash=False) if parts else []
        tasks = [(future, part_options, shard) for future, (_, shard) in zip(futures, parts)]
        del parts
    if not tasks:
        # No brick can hold a voxel, so any selection gives the empty whole grid; brick 0 alone
        # costs least (an empty selection would mean every brick).
        [mesh_on_worker] = client.scatter([mesh])
        tasks = [(mesh_on_worker, options, np.zeros(1, np.uint64))]
    futures = {client.submit(_voxelize_shard, part, resolution, shard, device, part_options):
               len(shard) if len(candidates) else 0 for part, part_options, shard in tasks}

    # Phase 3: merge the shards as they finish.
    merged = []
    done = [len(candidates) - sum(futures.values())]  # shards without triangles: no task

    def merge(future, brick_count):
        shard = future.result()
        if merged:
            merged[0].merge(shard)
        else:
            merged.append(shard)
        done[0] += brick_count
        _report(progress, done[0], len(candidates))

    _collect(client, futures, merge)
    return merged[0]


# ---- a distance field in layers ------------------------------------------------------------------

_SDF_OPTIONS = frozenset(inspect.signature(oclvox.sdf).parameters) - {
    "vertices", "faces", "resolution", "device", "layers"}


def _sdf_layers(mesh, resolution, layers, device, options):
    """A worker's task: the whole field's samples in voxel layers layers[0] <= k < layers[1], as
    an array, or with options["sparse"] as a SparseField of the whole grid holding those layers'
    leaves."""
    field = oclvox.sdf(mesh, resolution, layers=layers, device=device, **options)
    return field if options.get("sparse") else np.array(field.to_numpy(), order="F")


def sdf_sharded(mesh, resolution=256, *, client, shard_layers=None, device=None, progress=None,
                **options):
    """The signed distance field of one mesh on a Dask cluster; returns what oclvox.sdf returns
    (narrow band: a Field, or with sparse=True a SparseField), bit for bit.

    options: sdf's (band, full_grid, inside, grid options, brick_size, reference, sparse; a full
    grid is dense, not sparse: every slab still searches all the triangles beyond the band, so its
    distances are the whole field's). The grid's z layers
    are cut into slabs of `shard_layers` layers (default: about four slabs per worker, a multiple
    of brick_size so that no brick of the sign's solid is computed twice, and with sparse=True of
    8, the leaves' size, which shard_layers must then be too); each slab is one task,
    oclvox.sdf(..., layers=(first, end)), whose samples are the whole field's there. Each slab's
    sign comes from a solid voxelization of its whole columns of bricks.
    Dense: the client copies each slab into the whole field as it arrives, and needs the memory
    of the field twice at the end (4 bytes a voxel, once for the slabs, once in the Field);
    sdf_sharded_to_file writes it instead, never holding it whole.
    Sparse: each slab comes back as its leaves and inside voxels, and the client merges the slabs
    in z order as they become contiguous (SparseField.merge): memory follows the surface, as for
    oclvox.sdf(..., sparse=True), plus the slabs that arrived ahead of their turn.
    progress: called as progress(layers_done, layers_total) as slabs arrive; returning False
    cancels (oclvox.Cancelled), and the slabs not yet finished are cancelled on the cluster.
    """
    slabs = _submit_sdf_slabs(mesh, resolution, client, shard_layers, device, options)
    done = [0]

    def report(first):
        done[0] += slabs.cuts[slabs.cuts.index(first) + 1] - first
        _report(progress, done[0], slabs.dims[2])

    if options.get("sparse", False):
        return _merge_slabs(client, slabs.futures, slabs.cuts, report)
    values = np.empty(slabs.dims, np.float32, order="F")

    def place(future, first):
        slab = future.result()
        values[:, :, first:first + slab.shape[2]] = slab
        report(first)

    _collect(client, slabs.futures, place)
    return oclvox.Field(values, slabs.origin, slabs.voxel_size, slabs.band)


def sdf_sharded_to_file(mesh, path, resolution=256, *, client, shard_layers=None, device=None,
                        progress=None, **options):
    """sdf_sharded's dense field (a full grid, or a narrow band without sparse=True) written to
    `path` (.npy or .vdb) a layer at a time in z order: the client waits for each slab in turn,
    so it holds one slab, never the whole field (for .vdb OpenVDB's tree of it). The file holds
    what sdf_sharded(...).save(path) writes (.npy byte for byte). Returns the grid as (origin,
    voxel_size, dims). progress: progress(layers_written, layers_total), False cancelling with no
    file left. Options as for sdf_sharded, but not sparse."""
    if options.get("sparse"):
        raise ValueError("sdf_sharded_to_file writes dense slabs; save a sparse sdf_sharded result")
    slabs = _submit_sdf_slabs(mesh, resolution, client, shard_layers, device, options)
    by_first = {first: future for future, first in slabs.futures.items()}
    slabs.futures.clear()
    held = {"first": None, "values": None}

    def layer(k):
        first = slabs.cuts[bisect.bisect_right(slabs.cuts, k) - 1]
        if held["first"] != first:
            held["values"] = None  # before the next slab arrives
            held["values"], held["first"] = by_first.pop(first).result(), first
        return held["values"][:, :, k - first]

    try:
        oclvox._oclvox.write_field_layers(os.fspath(path), slabs.origin, slabs.voxel_size,
                                          slabs.dims, slabs.band, layer, progress)
    finally:
        if by_first:
            client.cancel(list(by_first.values()))
    return slabs.origin, slabs.voxel_size, slabs.dims


@dataclasses.dataclass
class _SdfSlabs:
    """What _submit_sdf_slabs starts: the whole grid, the field's band as Field keeps it (0 for a
    full grid: taken from the values when written), the slabs' first layers, and their futures."""
    origin: tuple
    voxel_size: float
    dims: tuple
    band: float
    cuts: list
    futures: dict  # future -> first layer


def _submit_sdf_slabs(mesh, resolution, client, shard_layers, device, options):
    """Phases 1 and 2 of sdf_sharded: the checks, the grid oclvox.sdf fits, and one task per slab
    of layers (the mesh sent to every worker once)."""
    if options.get("full_grid") and options.get("sparse"):
        raise ValueError("full_grid=True gives a dense field: sparse=True holds narrow bands only")
    unknown = sorted(set(options) - _SDF_OPTIONS)
    if unknown:
        raise TypeError(f"unknown sdf option(s): {', '.join(unknown)}")
    mesh = oclvox._as_mesh(mesh)
    defaults = inspect.signature(oclvox.sdf).parameters
    band = options.get("band", defaults["band"].default)
    options["pad"] = oclvox._field_pad(options.get("pad"), band, options.get("origin"),
                                       options.get("dims"))
    origin, voxel_size, dims = oclvox._oclvox.fit_grid(mesh, oclvox._fit(
        resolution, options.get("voxel_size"), options.get("origin"), options.get("dims"),
        options["pad"], options.get("cubic", False)))
    brick = options.get("brick_size", defaults["brick_size"].default)
    sparse = options.get("sparse", False)
    unit = math.lcm(brick, 8) if sparse else brick
    if shard_layers is None:
        workers = max(1, len(client.scheduler_info()["workers"]))
        shard_layers = unit * max(1, math.ceil(dims[2] / (4 * workers * unit)))
    if shard_layers < 1 or (sparse and shard_layers % 8):
        raise ValueError(f"shard_layers must be at least 1{' and a multiple of 8' if sparse else ''}"
                         f", got {shard_layers}")
    cuts = list(range(0, dims[2], shard_layers)) + [dims[2]]
    [mesh_on_workers] = client.scatter([mesh], broadcast=True)
    futures = {client.submit(_sdf_layers, mesh_on_workers, resolution, (first, end), device,
                             options): first
               for first, end in zip(cuts, cuts[1:])}
    return _SdfSlabs(tuple(origin), voxel_size, tuple(dims),
                     0.0 if options.get("full_grid") else band, cuts, futures)


def _merge_slabs(client, futures, cuts, report):
    """The SparseField of slab futures (keyed by their first layer, cuts in z order): each merged
    in z order once the slabs below it are in, so that merging only appends leaves."""
    held, whole, turn = {}, [None], [0]

    def merge(future, first):
        held[first] = future.result()
        while turn[0] < len(cuts) - 1 and cuts[turn[0]] in held:
            slab = held.pop(cuts[turn[0]])
            if whole[0] is None:
                whole[0] = slab
            else:
                whole[0].merge(slab)
            turn[0] += 1
        report(first)

    _collect(client, futures, merge)
    return whole[0]


# ---- many meshes --------------------------------------------------------------------------------

@dataclasses.dataclass
class BatchSummary:
    """What voxelize_many did: outputs written by this run, outputs already there (skipped), and
    the inputs that failed twice, each with its error message."""
    written: list = dataclasses.field(default_factory=list)
    skipped: list = dataclasses.field(default_factory=list)
    failed: dict = dataclasses.field(default_factory=dict)

    @property
    def ok(self):
        return not self.failed


def mesh_paths(source):
    """The meshes a batch names: a folder's mesh files (not recursive; by extension, see
    MESH_EXTENSIONS), or a list file's lines (one path each; blank lines and lines starting with
    # are skipped; relative paths are relative to the list file's folder). Sorted by name."""
    source = pathlib.Path(source)
    if source.is_dir():
        return sorted(p for p in source.iterdir()
                      if p.is_file() and p.suffix.lower() in MESH_EXTENSIONS)
    if not source.is_file():
        raise oclvox.InputError(f"'{source}' is neither a folder of meshes nor a list file")
    lines = (line.strip() for line in source.read_text().splitlines())
    return [source.parent / line for line in lines if line and not line.startswith("#")]


def _extension(ext):
    """"binvox" or ".BINVOX" -> ".binvox"."""
    ext = ext.lower()
    return ext if ext.startswith(".") else "." + ext


def _output_files(output):
    """The files that make `output` complete: a .npy has its .json sidecar, written after it."""
    return [output, output.with_name(output.name + ".json")] if output.suffix == ".npy" \
        else [output]


def _check_output_format(out_dir, ext):
    """Writes a one-voxel grid in format `ext` into out_dir and removes it: an unknown format or a
    folder that cannot be written is found before any task runs, by the library's own writer."""
    with tempfile.TemporaryDirectory(dir=out_dir, prefix=".oclvox-probe-") as probe:
        oclvox.VoxelGrid.from_numpy(np.ones((1, 1, 1), np.uint8)).save(
            os.path.join(probe, "probe" + ext))


def _voxelize_file(path, output, resolution, device, options):
    """A worker's task: one mesh file into one voxel file (written atomically by the library)."""
    start = time.perf_counter()
    grid = oclvox.voxelize(path, resolution, device=device, **options)
    grid.save(output)
    return {"voxels": grid.count, "seconds": time.perf_counter() - start}


def voxelize_many(paths, out_dir, resolution=256, *, client, ext=".binvox", device=None,
                  progress=None, **options):
    """Voxelizes each mesh file into out_dir/<stem><ext>, one Dask task per mesh; returns a
    BatchSummary (written, skipped, failed {path: message}).

    Resumable: an output that exists is complete, because the library writes every file to a
    temporary name and renames it when done (a .npy counts when its .json sidecar, written after
    it, exists too); such inputs are skipped, whatever options made them, so delete an output to
    redo it. A task that fails is retried once (on any worker); one that fails again is reported
    in the summary while the others go on. Inputs and out_dir must be the same paths on every
    worker (a shared file system). options: as for oclvox.voxelize; device: as for
    voxelize_sharded. progress: called as progress(meshes_done, meshes_total) as tasks finish
    (failed ones included); returning False cancels the rest and raises oclvox.Cancelled.
    """
    _check_options(options)
    # Phase 1: the outputs, checked before any work.
    ext = _extension(ext)
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _check_output_format(out_dir, ext)
    outputs = {}
    for path in map(pathlib.Path, paths):
        output = out_dir / (path.stem + ext)
        if output in outputs.values():
            other = next(p for p, o in outputs.items() if o == output)
            raise oclvox.InputError(f"'{path}' and '{other}' would both be written to '{output}'")
        outputs[path] = output

    # Phase 2: what is left to do.
    summary = BatchSummary()
    todo = {}
    for path, output in outputs.items():
        if all(f.exists() for f in _output_files(output)):
            summary.skipped.append(str(output))
        else:
            todo[path] = output

    # Phase 3: one task per mesh, each retried once.
    futures = {client.submit(_voxelize_file, str(path), str(output), resolution, device, options,
                             retries=1): path
               for path, output in todo.items()}

    # Phase 4: collect, failures included.
    def collect(future, path):
        if future.status == "finished":
            summary.written.append(str(todo[path]))
        else:
            error = future.exception()
            summary.failed[str(path)] = f"{type(error).__name__}: {error}"
        _report(progress, len(summary.written) + len(summary.failed), len(todo))

    _collect(client, futures, collect)
    summary.written.sort()
    return summary


# ---- command line -------------------------------------------------------------------------------

@contextlib.contextmanager
def _cluster_client(args):
    """A Client of the scheduler at --scheduler, or of a local cluster of --workers processes
    (closed on the way out, its worker processes ended)."""
    distributed = _distributed()
    if args.scheduler:
        with distributed.Client(args.scheduler) as client:
            yield client
        return
    # One thread per worker: a worker is one device, which runs one call at a time. The workers'
    # own logs (a failed task's traceback) would repeat what the summary says. The scheduler's
    # HTTP server (the dashboard, with bokeh) on a free port, so that clusters can run side by side.
    with distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=logging.ERROR) as cluster, \
            distributed.Client(cluster) as client:
        yield client


def _progress_line(what, quiet):
    """A progress(done, total) callback drawing one line on stderr (none when quiet or when
    stderr is not a terminal)."""
    if quiet or not sys.stderr.isatty():
        return None

    def draw(done, total):
        sys.stderr.write(f"\r{what}: {done}/{total}" + ("\n" if done == total else ""))
        sys.stderr.flush()
    return draw


def _parse_args(argv):
    parser = argparse.ArgumentParser(
        prog="python3 -m oclvox.distributed",
        description="oclvox on a Dask cluster (the back end of `oclvox voxelize --workers/"
                    "--scheduler`, `oclvox sdf --workers/--scheduler` and `oclvox batch`).")
    commands = parser.add_subparsers(dest="command", required=True)
    sharded = commands.add_parser("voxelize", help="one mesh, its bricks in shards")
    sharded.add_argument("input")
    sharded.add_argument("-o", "--output", required=True)
    sharded.add_argument("--shard-bricks", type=int,
                         help="bricks per task (default: about four tasks per worker)")
    field = commands.add_parser("sdf", help="one mesh's distance field, in slabs: a narrow band "
                                            "kept sparse, or (full_grid) every voxel, dense")
    field.add_argument("input")
    field.add_argument("-o", "--output", required=True, help=".vdb or .npy")
    batch = commands.add_parser("batch", help="one output per mesh of a folder or list file")
    batch.add_argument("input", help="a folder of meshes or a list file (one path a line)")
    batch.add_argument("-o", "--output", required=True, help="output folder")
    batch.add_argument("--output-format", default="binvox")
    for command in (sharded, field, batch):
        where = command.add_mutually_exclusive_group()
        where.add_argument("--scheduler", help="address of a running scheduler, tcp://host:8786")
        where.add_argument("--workers", type=int, default=1,
                           help="worker processes of a local cluster (default 1)")
        command.add_argument("-r", "--resolution", type=int, default=256)
        command.add_argument("--device", help="OpenCL device selector on the workers (default: "
                                              "each worker's $OCLVOX_DEVICE, else its first GPU)")
        command.add_argument("--options", default="{}",
                             help="oclvox.voxelize's (sdf: oclvox.sdf's) keyword options as a "
                                  "JSON object, e.g. '{\"mode\": \"solid\", \"pad\": 2}'")
        command.add_argument("-q", "--quiet", action="store_true")
    return parser.parse_args(argv)


def main(argv=None):
    """The command line; returns the exit code (0 done, 1 an error or a failed mesh)."""
    args = _parse_args(argv)
    try:
        options = json.loads(args.options)
        with _cluster_client(args) as client:
            start = time.perf_counter()
            if args.command in ("voxelize", "sdf"):
                result = None
                if args.command == "voxelize":
                    result = voxelize_sharded(
                        args.input, args.resolution, client=client,
                        shard_bricks=args.shard_bricks, device=args.device,
                        progress=_progress_line("bricks", args.quiet), **options)
                    made = f"{result.count} voxels set"
                elif options.get("full_grid", False):
                    # A full grid is dense: written a slab at a time as the slabs come in.
                    _, _, dims = sdf_sharded_to_file(
                        args.input, args.output, args.resolution, client=client,
                        device=args.device, progress=_progress_line("layers", args.quiet),
                        **options)
                    made = "every voxel"
                else:
                    # A narrow band kept sparse.
                    result = sdf_sharded(args.input, args.resolution, client=client,
                                         device=args.device, sparse=True,
                                         progress=_progress_line("layers", args.quiet), **options)
                    made = f"{result.leaf_count} leaves"
                if result is not None:
                    result.save(args.output)
                    dims = result.dims
                if not args.quiet:
                    print(f"{args.output}: {made} in {'x'.join(map(str, dims))}, "
                          f"{time.perf_counter() - start:.2f} s", file=sys.stderr)
                return 0
            summary = voxelize_many(mesh_paths(args.input), args.output, args.resolution,
                                    client=client, ext=args.output_format, device=args.device,
                                    progress=_progress_line("meshes", args.quiet), **options)
    except (oclvox.Error, ImportError, OSError, TypeError, ValueError) as error:
        print(f"oclvox: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("oclvox: cancelled by SIGINT", file=sys.stderr)
        return 130
    for path, message in summary.failed.items():
        print(f"oclvox: failed: {path}: {message}", file=sys.stderr)
    if not args.quiet or summary.failed:
        print(f"{len(summary.written)} written, {len(summary.skipped)} skipped (already there), "
              f"{len(summary.failed)} failed, {time.perf_counter() - start:.2f} s",
              file=sys.stderr)
    return 0 if summary.ok else 1


if __name__ == "__main__":
    sys.exit(main())
