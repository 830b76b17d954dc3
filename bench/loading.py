#!/usr/bin/env python3
"""Mesh loading speed per format, in fresh processes.

The bundled OBJ meshes (buildings, motorBike, stanford-bunny) are written once more as binary STL
and binary PLY (oclvox.save_mesh) and as ASCII PLY and OFF (written here), then each file is
loaded by `oclvox voxelize FILE --reference -r 16 --json` (the reference, so that no device
opens beside the load) REPEAT times; the table gives the median of the run's "load" phase (parse,
triangulation, checks and welding) and the file's megabytes per second.

    PYTHONPATH=build/python /usr/bin/python3 bench/loading.py [--repeat N] [--oclvox PATH]
        [--meshes DIR] [--out TABLE.md]

A second oclvox (another commit's build, or the same CLI with another library through
LD_LIBRARY_PATH: --compare-env 'LD_LIBRARY_PATH=/tmp/libold') is timed in turn with the first
when --compare-env is given, run by run, so that both see the same machine.
"""
import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile

import oclvox


def write_ascii_ply(path, vertices, faces):
    with open(path, "w") as out:
        out.write(f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\n"
                  "property float x\nproperty float y\nproperty float z\n"
                  f"element face {len(faces)}\nproperty list uchar int vertex_indices\n"
                  "end_header\n")
        out.writelines(f"{x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist())
        out.writelines(f"3 {a} {b} {c}\n" for a, b, c in faces.tolist())


def write_off(path, vertices, faces):
    with open(path, "w") as out:
        out.write(f"OFF\n{len(vertices)} {len(faces)} 0\n")
        out.writelines(f"{x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist())
        out.writelines(f"3 {a} {b} {c}\n" for a, b, c in faces.tolist())


def load_seconds(oclvox_path, mesh, env):
    run = subprocess.run([oclvox_path, "voxelize", mesh, "--reference", "-r", "16", "-o",
                          mesh + ".binvox", "--json"],
                         capture_output=True, text=True, env=env, check=True)
    return json.loads(run.stdout)["seconds"]["load"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--oclvox", default="build/oclvox")
    parser.add_argument("--meshes", default="../shared/data/meshes")
    parser.add_argument("--compare-env", default=None,
                        help="VAR=VALUE[,VAR=VALUE]: also time the CLI under this environment")
    parser.add_argument("--out", default=None)
    args = parser.parse_args()

    envs = [("this build", dict(os.environ))]
    if args.compare_env:
        other = dict(os.environ)
        for pair in args.compare_env.split(","):
            name, value = pair.split("=", 1)
            other[name] = value
        envs.append((args.compare_env, other))

    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name in ("buildings", "motorBike", "stanford-bunny"):
            source = os.path.join(args.meshes, name + ".obj")
            vertices, faces = oclvox.load_mesh(source)
            files = {"obj": os.path.join(folder, name + ".obj")}  # outputs go beside inputs
            with open(source, "rb") as src, open(files["obj"], "wb") as dst:
                dst.write(src.read())
            for ext in ("stl", "ply"):
                files["binary " + ext] = os.path.join(folder, f"{name}.{ext}")
                oclvox.save_mesh(files["binary " + ext], vertices, faces)
            files["ascii ply"] = os.path.join(folder, name + "-ascii.ply")
            write_ascii_ply(files["ascii ply"], vertices, faces)
            files["off"] = os.path.join(folder, name + ".off")
            write_off(files["off"], vertices, faces)
            for kind, path in files.items():
                times = {label: [] for label, _ in envs}
                for _ in range(args.repeat):
                    for label, env in envs:
                        times[label].append(load_seconds(args.oclvox, path, env))
                megabytes = os.path.getsize(path) / 1e6
                rows.append((name, kind, megabytes, len(faces),
                             [statistics.median(times[label]) for label, _ in envs]))

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                if line.startswith("model name")), platform.processor())
    lines = [f"machine: {cpu}, {os.cpu_count()} cores; commit {commit}; "
             f"median of {args.repeat} fresh processes each",
             "",
             "| mesh | format | MB | triangles | " +
             " | ".join(f"load s ({label})" for label, _ in envs) + " | MB/s |",
             "|---|---|---:|---:|" + "---:|" * len(envs) + "---:|"]
    for name, kind, megabytes, triangles, medians in rows:
        lines.append(f"| {name} | {kind} | {megabytes:.1f} | {triangles} | " +
                     " | ".join(f"{m:.4f}" for m in medians) + f" | {megabytes / medians[0]:.0f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        with open(args.out, "w") as out:
            out.write(text)


if __name__ == "__main__":
    sys.exit(main())
