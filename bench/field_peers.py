#!/usr/bin/python3
"""Distance fields and meshing, oclvox beside its peers, on the same mesh, grid and cores.

Usage: /usr/bin/python3 bench/field_peers.py (Debian's Python, which sees the Debian peers)
       [--oclvox build/oclvox] [--mesh MESH.off|MESH.obj] [--band 3]
                                    [--repeat 3] [--out TABLE.md] RES [RES ...]

For each resolution R it runs, interleaved repeat by repeat (ours, then each peer, again and
again, so a machine whose speed drifts slows every column alike), and reports the median:
  - oclvox sdf MESH -r R --band B -o X.vdb       whole process, and its own "field" time;
  - OpenVDB FloatGrid.createLevelSetFromPolygons  the call alone, same voxel size, sample
                                                  positions and half width;
  - oclvox mesh X.vdb --mesher surface-nets / marching-cubes: the "mesh" time of the level set
    oclvox wrote (read sparse, meshed on the host's cores), and the whole process;
  - OpenVDB convertToPolygons (volumeToMesh) of that same .vdb;
  - scikit-image measure.marching_cubes of that same field, read from oclvox's .npy.
Peers that are not installed (Debian python3-openvdb, python3-skimage) are named and skipped.
OpenVDB runs on all the cores this process may use (TBB), oclvox's distance field on its OpenCL
device (PoCL uses the same cores) and its sparse meshing on the host's cores (TBB), scikit-image
on one core.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from peer_timing import cell, emit_table, median, run_timed, stat_seconds, timed_call


def read_off(path):
    """Vertices (float64, n x 3) and triangles (int32, m x 3) of an OFF file (polygons fanned)."""
    with open(path) as f:
        words = f.read().split()
    if not words or not words[0].endswith("OFF"):
        sys.exit(f"{path}: not an OFF file")
    nv, nf = int(words[1]), int(words[2])
    at = 4
    points = np.array(words[at:at + 3 * nv], dtype=np.float64).reshape(nv, 3)
    at += 3 * nv
    triangles = []
    for _ in range(nf):
        n = int(words[at])
        face = [int(w) for w in words[at + 1:at + 1 + n]]
        at += 1 + n
        triangles += [(face[0], face[i], face[i + 1]) for i in range(1, n - 1)]
    return points, np.array(triangles, dtype=np.int32)


def read_obj(path):
    """Vertices and triangles of an OBJ file's `v` and `f` lines (polygons fanned; texture and
    normal indices and negative, relative indices as the format allows)."""
    points, triangles = [], []
    with open(path) as f:
        for line in f:
            words = line.split()
            if not words:
                continue
            if words[0] == "v":
                points.append([float(w) for w in words[1:4]])
            elif words[0] == "f":
                face = [int(w.split("/")[0]) for w in words[1:]]
                face = [i - 1 if i > 0 else len(points) + i for i in face]
                triangles += [(face[0], face[i], face[i + 1]) for i in range(1, len(face) - 1)]
    return np.array(points, dtype=np.float64), np.array(triangles, dtype=np.int32)


def read_mesh(path):
    """An OFF or OBJ mesh, by its extension, as OpenVDB's arrays."""
    if path.lower().endswith(".obj"):
        return read_obj(path)
    if path.lower().endswith(".off"):
        return read_off(path)
    sys.exit(f"{path}: field_peers.py reads .off and .obj meshes")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("resolutions", type=int, nargs="+")
    parser.add_argument("--oclvox", default="build/oclvox")
    parser.add_argument("--mesh", default="../shared/data/meshes/bunny00.off")
    parser.add_argument("--band", type=float, default=3.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", help="also write the Markdown table here")
    args = parser.parse_args()

    try:
        import pyopenvdb as openvdb  # Debian's python3-openvdb
    except ImportError:
        try:
            import openvdb
        except ImportError:
            openvdb = None
    try:
        from skimage import measure
    except ImportError:
        measure = None
    found = [name for name, module in (("OpenVDB", openvdb), ("scikit-image", measure)) if module]
    missing = [name for name, module in (("OpenVDB", openvdb), ("scikit-image", measure))
               if not module]
    print(f"peers found: {', '.join(found) or 'none'}"
          + (f"; not installed: {', '.join(missing)}" if missing else ""), file=sys.stderr)

    points, triangles = read_mesh(args.mesh)
    cores = len(os.sched_getaffinity(0))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        vdb, npy, ply = (os.path.join(tmp, "field" + e) for e in (".vdb", ".npy", ".ply"))
        for res in args.resolutions:
            sdf = [args.oclvox, "sdf", args.mesh, "-r", str(res), "--band", str(args.band)]
            # The field the meshers share, and its grid for OpenVDB's transform.
            subprocess.run(sdf + ["-o", npy, "--quiet"], check=True)
            with open(npy + ".json") as f:
                grid = json.load(f)
            field = np.load(npy)
            voxel = float(grid["voxel_size"])
            origin = np.array(grid["origin"], dtype=np.float64)
            dims = "x".join(str(d) for d in field.shape)

            t = {k: [] for k in ("sdf_proc", "sdf_field", "vdb_ls", "sn", "sn_proc", "mc",
                                 "mc_proc", "vdb_mesh", "skimage")}
            for _ in range(args.repeat):
                seconds, out = run_timed(sdf + ["-o", vdb, "--quiet", "--stats"])
                t["sdf_proc"].append(seconds)
                t["sdf_field"].append(stat_seconds(out, "field"))
                if openvdb:
                    # Voxel (i, j, k)'s sample at origin + (i + 0.5) * voxel, as oclvox's.
                    xf = openvdb.createLinearTransform(voxelSize=voxel)
                    xf.translate(tuple(origin + 0.5 * voxel))
                    seconds, _ = timed_call(lambda: openvdb.FloatGrid.createLevelSetFromPolygons(
                        points, triangles=triangles, transform=xf, halfWidth=args.band))
                    t["vdb_ls"].append(seconds)
                for mesher, key in (("surface-nets", "sn"), ("marching-cubes", "mc")):
                    seconds, out = run_timed([args.oclvox, "mesh", vdb, "-o", ply, "--mesher",
                                              mesher, "--quiet", "--stats"])
                    t[key + "_proc"].append(seconds)
                    t[key].append(stat_seconds(out, "mesh"))
                if openvdb:
                    level_set = openvdb.read(vdb, "sdf")
                    seconds, _ = timed_call(lambda: level_set.convertToPolygons(isovalue=0.0))
                    t["vdb_mesh"].append(seconds)
                if measure:
                    seconds, _ = timed_call(lambda: measure.marching_cubes(field, 0.0))
                    t["skimage"].append(seconds)
            rows.append((res, dims, {k: median(v) for k, v in t.items()}))

    table = [
        f"{os.path.basename(args.mesh)}, band {args.band:g}, {cores} cores, median of "
        f"{args.repeat} interleaved runs, seconds",
        "",
        "| R | grid | oclvox sdf → .vdb (process) | oclvox field | OpenVDB createLevelSetFromPolygons"
        " | oclvox Surface Nets | oclvox Marching Cubes | OpenVDB volumeToMesh | scikit-image"
        " marching_cubes (1 core) |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for res, dims, m in rows:
        table.append(f"| {res} | {dims} | {cell(m['sdf_proc'])} | {cell(m['sdf_field'])} | "
                     f"{cell(m['vdb_ls'])} | {cell(m['sn'])} | {cell(m['mc'])} | "
                     f"{cell(m['vdb_mesh'])} | {cell(m['skimage'])} |")
    table.append("")
    table.append("oclvox meshing columns are the mesh phase of `oclvox mesh field.vdb` (the same "
                 "file OpenVDB meshes, read sparse); its whole processes took " + ", ".join(
                     f"{res}: SN {cell(m['sn_proc'])} / MC {cell(m['mc_proc'])}"
                     for res, _, m in rows) + " s (reading the .vdb and writing the .ply "
                 "included).")
    emit_table(table, args.out)


if __name__ == "__main__":
    main()
