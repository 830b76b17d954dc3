#!/usr/bin/env python3
"""Surface voxels, solids and signed distances: oclvox beside Open3D, same triangles, same grid.

Usage: PYTHONPATH=build/python VENV/bin/python bench/open3d_peers.py
           [--oclvox build/oclvox] [--repeat 3] [--out TABLE.md] [--classify 200]
           [--surface-meshes M ...] [--surface-res R ...]
           [--field-mesh bunny00.off] [--field-res R ...]

Open3D is not a Debian package: install it from PyPI into a virtual environment VENV that also
sees Debian's numpy (/usr/bin/python3 -m venv --system-site-packages VENV; VENV/bin/pip install
open3d; on Debian 12 it also needs libusb-1.0-0), and run this script with VENV's Python. An empty
--surface-res or --field-res leaves that part out. Both tools get the
triangles oclvox's loader reads (oclvox.load_mesh, so the same polygons and welding) and the grid
oclvox fits (its .npy sidecar: origin, voxel size, dims). Runs are interleaved repeat by repeat
and the median is reported:
  - surface: `oclvox voxelize M -r R -o X.npy --stats` (the voxelize phase; the dense .npy it
    writes is for the comparison) against Open3D's VoxelGrid.create_from_triangle_mesh_within_bounds
    on that grid (the call; its own triangle-box test on each triangle's box of voxels, one
    thread); the voxel sets are compared, and Open3D's also with oclvox's for half-open voxel
    boxes (--boundary half-open, which leaves out voxels touching a triangle only on their high
    faces);
  - solid: `oclvox voxelize --mode solid` against RaycastingScene.compute_occupancy at the voxel
    centres (Embree, all cores), the inside voxels compared;
  - signed distance in every voxel: `oclvox sdf --full` (its field phase, and the whole process)
    against RaycastingScene.compute_signed_distance at the same voxel centres (Embree, all
    cores), the distances compared (Open3D's are exact closest points in float32, signed by ray
    parity): the largest difference within 3 voxels of the surface and anywhere, in voxels, and
    the samples whose signs differ.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from peer_timing import cell, emit_table, median, run_timed, stat_seconds, timed_call


def read_npy(path):
    """The array and its sidecar (origin, voxel size, dims)."""
    with open(path + ".json") as f:
        grid = json.load(f)
    return np.load(path), grid


def voxel_centres(grid):
    """Every voxel centre, x fastest (the order of a Fortran-ordered array's ravel)."""
    origin = np.array(grid["origin"], dtype=np.float64)
    voxel = float(grid["voxel_size"])
    nx, ny, nz = grid["dims"]
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    ijk = np.stack([i.ravel(order="F"), j.ravel(order="F"), k.ravel(order="F")], axis=1)
    return (origin + (ijk + 0.5) * voxel).astype(np.float32)


def contact(vertices, faces, grid, voxels):
    """How the triangles meet each of `voxels` (i, j, k rows), counted: (interior, touching,
    near, none): some triangle meets the voxel box's interior; some meets the closed box but none
    its interior; none meets the closed box but one meets it grown by 1e-4 voxel on every side
    (oclvox's documented tolerance: its float arithmetic may set such a voxel); none meets even
    that. Decided exactly, in rationals of the world coordinates (the boxes are origin + index *
    voxel size), by the 13 separating axes; the interior counts as met when no axis separates
    even weakly."""
    from fractions import Fraction

    origin = [Fraction(x) for x in grid["origin"]]
    size = Fraction(grid["voxel_size"])
    lo_all, hi_all = vertices[faces].min(axis=1), vertices[faces].max(axis=1)
    exact = {}

    def corners(face):
        if face not in exact:
            exact[face] = [[Fraction(x) for x in vertices[v]] for v in faces[face]]
        return exact[face]

    def meets(tri, lo, hi, strict):
        # Axes: the box's normals, the triangle's normal, and edge x box-normal products.
        edges = [[tri[(e + 1) % 3][k] - tri[e][k] for k in range(3)] for e in range(3)]
        normal = [edges[0][1] * edges[1][2] - edges[0][2] * edges[1][1],
                  edges[0][2] * edges[1][0] - edges[0][0] * edges[1][2],
                  edges[0][0] * edges[1][1] - edges[0][1] * edges[1][0]]
        axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1], normal]
        for e in edges:
            axes += [[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]]
        box = [[lo[0] if a & 1 == 0 else hi[0], lo[1] if a & 2 == 0 else hi[1],
                lo[2] if a & 4 == 0 else hi[2]] for a in range(8)]
        for axis in axes:
            t = [sum(axis[k] * p[k] for k in range(3)) for p in tri]
            b = [sum(axis[k] * p[k] for k in range(3)) for p in box]
            if strict and (max(t) <= min(b) or min(t) >= max(b)):
                return False
            if not strict and (max(t) < min(b) or min(t) > max(b)):
                return False
        return True

    counts = [0, 0, 0, 0]
    grow = size / 10000
    for i, j, k in voxels:
        lo = [origin[a] + size * int(v) for a, v in enumerate((i, j, k))]
        hi = [x + size for x in lo]
        reach = float(size) * 1e-3  # candidates: triangles whose boxes meet the grown box
        near = np.nonzero(np.all((lo_all <= np.array([float(x) for x in hi]) + reach) &
                                 (hi_all >= np.array([float(x) for x in lo]) - reach), axis=1))[0]
        tris = [corners(int(f)) for f in near]
        if any(meets(t, lo, hi, True) for t in tris):
            counts[0] += 1
        elif any(meets(t, lo, hi, False) for t in tris):
            counts[1] += 1
        elif any(meets(t, [x - grow for x in lo], [x + grow for x in hi], False) for t in tris):
            counts[2] += 1
        else:
            counts[3] += 1
    return counts


def interleaved(command, stat, peer, repeat):
    """Runs `command` (oclvox, writing the .npy at its "-o") and then times `peer(grid)` on the
    grid it wrote, `repeat` times by turns. Returns the medians (the process, its --stats line
    `stat`, the peer's call) and the last run's array, grid and peer result."""
    npy = command[command.index("-o") + 1]
    t = {k: [] for k in ("process", "stat", "peer")}
    for _ in range(repeat):
        seconds, out = run_timed(command)
        t["process"].append(seconds)
        t["stat"].append(stat_seconds(out, stat))
        ours, grid = read_npy(npy)
        seconds, theirs = timed_call(lambda: peer(grid))
        t["peer"].append(seconds)
    return {k: median(v) for k, v in t.items()}, ours, grid, theirs


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--oclvox", default="build/oclvox")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", help="also write the Markdown tables here")
    parser.add_argument("--classify", type=int, default=200,
                        help="voxels only oclvox sets that are classified exactly, per case")
    meshes = "../shared/data/meshes/"
    parser.add_argument("--surface-meshes", nargs="+", default=[
        meshes + "stanford-bunny.obj", meshes + "buildings.obj", meshes + "motorBike.obj"])
    parser.add_argument("--surface-res", type=int, nargs="*", default=[256, 1024])
    parser.add_argument("--field-mesh", default=meshes + "bunny00.off")
    parser.add_argument("--field-res", type=int, nargs="*", default=[64, 128])
    args = parser.parse_args()

    try:
        import open3d as o3d
    except ImportError as e:
        sys.exit(f"open3d_peers.py: Open3D cannot be imported ({e}); see the usage")
    import oclvox

    cores = len(os.sched_getaffinity(0))
    print(f"Open3D {o3d.__version__}, {cores} cores, oclvox {args.oclvox}", file=sys.stderr)

    def open3d_mesh(path):
        vertices, faces = oclvox.load_mesh(path)
        return o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                         o3d.utility.Vector3iVector(faces.astype(np.int32)))

    def scene_of(mesh):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
        return scene

    surface_rows, solid_rows, field_rows = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        npy = os.path.join(tmp, "out.npy")

        # Surface voxels.
        for path in args.surface_meshes:
            mesh = open3d_mesh(path)
            for res in args.surface_res:
                command = [args.oclvox, "voxelize", path, "-r", str(res), "-o", npy, "--quiet",
                           "--stats"]

                def voxel_grid(grid):
                    origin = np.array(grid["origin"], dtype=np.float64)
                    voxel = float(grid["voxel_size"])
                    top = origin + np.array(grid["dims"]) * voxel
                    return o3d.geometry.VoxelGrid.create_from_triangle_mesh_within_bounds(
                        mesh, voxel, origin, top)

                m, ours, grid, theirs = interleaved(command, "voxelize", voxel_grid, args.repeat)
                index = np.array([v.grid_index for v in theirs.get_voxels()], dtype=np.int64)
                index = index[np.all((index >= 0) & (index < np.array(grid["dims"])), axis=1)]
                theirs_dense = np.zeros(ours.shape, dtype=bool)
                theirs_dense[index[:, 0], index[:, 1], index[:, 2]] = True
                ours = ours.astype(bool)
                # The same grid with half-open voxel boxes (a voxel that only touches a triangle
                # on its high faces is left out), not timed.
                subprocess.run(command[:-1] + ["--boundary", "half-open"], check=True)
                half_open = read_npy(npy)[0].astype(bool)
                # A sample of the voxels only oclvox sets, classified exactly.
                only = np.argwhere(ours & ~theirs_dense)
                sample = only[np.random.default_rng(1).permutation(len(only))[:args.classify]]
                met = contact(np.asarray(mesh.vertices), np.asarray(mesh.triangles), grid,
                              sample)
                surface_rows.append((os.path.basename(path), res, m,
                                     int(ours.sum()), int(theirs_dense.sum()),
                                     int((ours & ~theirs_dense).sum()),
                                     int((theirs_dense & ~ours).sum()),
                                     int((half_open != theirs_dense).sum()),
                                     " / ".join(map(str, met)) + f" of {len(sample)}"))
                print(surface_rows[-1], file=sys.stderr)

        # Solids and signed distances of one closed mesh.
        mesh = open3d_mesh(args.field_mesh)
        scene = scene_of(mesh)
        for res in args.field_res:
            solid = [args.oclvox, "voxelize", args.field_mesh, "-r", str(res), "--mode", "solid",
                     "-o", npy, "--quiet", "--stats"]
            m, ours, grid, theirs = interleaved(
                solid, "voxelize",
                lambda grid: scene.compute_occupancy(voxel_centres(grid)).numpy(), args.repeat)
            ours = ours.astype(bool).ravel(order="F")
            theirs = theirs.astype(bool)
            solid_rows.append((res, "x".join(map(str, grid["dims"])), m, int(ours.sum()),
                               int(theirs.sum()), int((ours != theirs).sum())))
            print(solid_rows[-1], file=sys.stderr)

            sdf = [args.oclvox, "sdf", args.field_mesh, "-r", str(res), "--full", "-o", npy,
                   "--quiet", "--stats"]
            m, ours, grid, theirs = interleaved(
                sdf, "field",
                lambda grid: scene.compute_signed_distance(voxel_centres(grid)).numpy(),
                args.repeat)
            voxel = float(grid["voxel_size"])
            ours = ours.ravel(order="F") / voxel
            theirs = theirs / voxel
            near = np.abs(theirs) <= 3
            field_rows.append((res, "x".join(map(str, grid["dims"])), m,
                               float(np.abs(np.abs(ours[near]) - np.abs(theirs[near])).max()),
                               float(np.abs(np.abs(ours) - np.abs(theirs)).max()),
                               int((np.sign(ours) != np.sign(theirs)).sum())))
            print(field_rows[-1], file=sys.stderr)

    table = [
        f"Open3D {o3d.__version__} beside oclvox, {cores} cores, median of {args.repeat} "
        "interleaved runs, seconds",
        "",
        "| mesh | R | oclvox voxelize phase | Open3D create_from_triangle_mesh_within_bounds | "
        "voxels oclvox / Open3D | only oclvox | only Open3D | differ from oclvox "
        "--boundary half-open | a sample of the only-oclvox voxels (exact): interior met / only "
        "touched / within 1e-4 voxel / farther |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, res, m, n_ours, n_theirs, only_ours, only_theirs, half_open, met in surface_rows:
        table.append(f"| {name} | {res} | {cell(m['stat'])} | {cell(m['peer'])} | "
                     f"{n_ours} / {n_theirs} | {only_ours} | {only_theirs} | {half_open} | "
                     f"{met} |")
    name = os.path.basename(args.field_mesh)
    table += [
        "",
        f"| {name} solid | grid | oclvox voxelize phase | oclvox whole process | Open3D "
        "compute_occupancy | inside oclvox / Open3D | voxels that differ |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for res, dims, m, n_ours, n_theirs, differ in solid_rows:
        table.append(f"| {res} | {dims} | {cell(m['stat'])} | {cell(m['process'])} | "
                     f"{cell(m['peer'])} | {n_ours} / {n_theirs} | {differ} |")
    table += [
        "",
        f"| {name} SDF, every voxel | grid | oclvox sdf --full field phase | oclvox whole process"
        " | Open3D compute_signed_distance | largest difference of the distances within 3 voxels"
        " of the surface / anywhere (voxels) | signs that differ |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for res, dims, m, near, anywhere, signs in field_rows:
        table.append(f"| {res} | {dims} | {cell(m['stat'])} | {cell(m['process'])} | "
                     f"{cell(m['peer'])} | {near:.2g} / {anywhere:.2g} | {signs} |")
    emit_table(table, args.out)


if __name__ == "__main__":
    main()
