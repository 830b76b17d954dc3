#!/usr/bin/env python3
"""Whole-process timings of the `oclvox` CLI against the speed and memory targets of issues 8 and 9.

Each case runs the CLI N times and reports the wall time (min / median / max), the peak RSS of the
process (from wait4), the phase times of the median run (its --stats-json) and whether the target
holds. Needs only the Python standard library, so it also runs on a machine with nothing else (the
GPU machine of `../shared/tools/gpu/pack.sh`).

    python3 bench/targets.py [--oclvox PATH] [--meshes DIR] [--set cpu|gpu] [--repeat N]
                             [--only NAME ...] [--out TABLE.md]
"""
import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

# name, mesh file, CLI arguments after `oclvox`, output extension, wall-time target (s), peak-RSS
# target (MB), minimum kernel share of the voxelize phase. None: no target of that kind.
CPU_CASES = [
    ("surface-bunny00-8192-vdb", "bunny00.off", ["voxelize", "-r", "8192"], "vdb", 120, 4096, None),
    ("surface-bunny00-4096-vdb", "bunny00.off", ["voxelize", "-r", "4096"], "vdb", 20, None, None),
    ("surface-bunny00-1536-npy", "bunny00.off", ["voxelize", "-r", "1536"], "npy", None, 600, None),
    ("surface-buildings-1024-vdb", "buildings.obj", ["voxelize", "-r", "1024"], "vdb", None, None, None),
    ("surface-motorBike-1024-vdb", "motorBike.obj", ["voxelize", "-r", "1024"], "vdb", None, None, None),
    ("winding-scan-512-vdb", "stanford-bunny.obj",
     ["voxelize", "-r", "512", "--mode", "solid", "--inside", "winding"], "vdb", 15, None, None),
    ("sdf-bunny00-512-vdb", "bunny00.off", ["sdf", "-r", "512", "--band", "3"], "vdb", None, None, None),
    ("sdf-bunny00-2048-vdb", "bunny00.off", ["sdf", "-r", "2048", "--band", "3"], "vdb", None, 4096, None),
    # Exact distances in all 108 M voxels, computed and written a slab of layers at a time.
    ("sdf-full-bunny00-512-npy", "bunny00.off", ["sdf", "-r", "512", "--full"], "npy", None, None, None),
]
GPU_CASES = [
    ("surface-bunny-1024-binvox", "stanford-bunny.obj", ["voxelize", "-r", "1024"], "binvox", 0.3, None, 0.5),
    ("surface-bunny-4096-vdb", "stanford-bunny.obj", ["voxelize", "-r", "4096"], "vdb", 2.0, None, 0.5),
    ("surface-buildings-1024-binvox", "buildings.obj", ["voxelize", "-r", "1024"], "binvox", None, None, 0.5),
    ("surface-motorBike-1024-binvox", "motorBike.obj", ["voxelize", "-r", "1024"], "binvox", None, None, 0.5),
    ("parity-bunny00-1024-binvox", "bunny00.off",
     ["voxelize", "-r", "1024", "--mode", "solid", "--inside", "parity"], "binvox", None, None, None),
    ("winding-scan-512-vdb", "stanford-bunny.obj",
     ["voxelize", "-r", "512", "--mode", "solid", "--inside", "winding"], "vdb", 1.0, None, None),
    ("sdf-bunny00-512-vdb", "bunny00.off", ["sdf", "-r", "512", "--band", "3"], "vdb", None, None, None),
    ("sdf-bunny00-2048-vdb", "bunny00.off", ["sdf", "-r", "2048", "--band", "3"], "vdb", None, 4096, None),
    ("sdf-full-bunny00-512-npy", "bunny00.off", ["sdf", "-r", "512", "--full"], "npy", None, None, None),
]


def run_once(command):
    """Runs one process; returns (wall seconds, peak RSS in MB, exit status, its stderr)."""
    start = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stderr = process.stderr.read()
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    return wall, usage.ru_maxrss / 1024.0, os.waitstatus_to_exitcode(status), stderr.decode(errors="replace")


def measure(oclvox, meshes, case, repeat, scratch):
    name, mesh, arguments, extension, _, _, _ = case
    output = os.path.join(scratch, name + "." + extension)
    stats = os.path.join(scratch, name + ".json")
    command = [oclvox] + arguments[:1] + [os.path.join(meshes, mesh)] + arguments[1:] + [
        "-o", output, "--quiet", "--stats-json", stats]
    runs = []
    for _ in range(repeat):
        wall, rss, code, stderr = run_once(command)
        if code != 0:
            last_line = (stderr.strip().splitlines() or [""])[-1]
            return {"error": "exit %d: %s" % (code, last_line)}
        with open(stats) as handle:
            runs.append((wall, rss, json.load(handle)))
        for leftover in (output, output + ".json"):
            if os.path.exists(leftover):
                os.remove(leftover)
    runs.sort(key=lambda run: run[0])
    median_run = runs[len(runs) // 2]
    return {
        "walls": [run[0] for run in runs],
        "peak_rss_mb": max(run[1] for run in runs),
        "seconds": median_run[2].get("seconds", {}),
        "device": median_run[2].get("device", {}).get("name", "?"),
    }


def verdict(case, result):
    _, _, _, _, wall_target, rss_target, kernel_share = case
    checks = []
    median = statistics.median(result["walls"])
    if wall_target is not None:
        checks.append("%s wall < %g s" % ("meets" if median < wall_target else "misses", wall_target))
    if rss_target is not None:
        checks.append("%s RSS < %d MB" % ("meets" if result["peak_rss_mb"] < rss_target else "misses", rss_target))
    seconds = result["seconds"]
    if kernel_share is not None and seconds.get("voxelize"):
        share = seconds.get("kernels", 0.0) / seconds["voxelize"]
        checks.append("kernels %.0f%% of voxelize (%s > %.0f%%)" % (
            100 * share, "meets" if share > kernel_share else "misses", 100 * kernel_share))
    return "; ".join(checks) or "-"


def phases(seconds):
    keys = ["load", "device_open", "voxelize", "binning", "kernels", "download", "field", "write"]
    return ", ".join("%s %.3f" % (key, seconds[key]) for key in keys if key in seconds)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--oclvox", default=shutil.which("oclvox") or "build/oclvox")
    parser.add_argument("--meshes", default=os.environ.get("OCLVOX_MESH_DIR", "../shared/data/meshes"))
    parser.add_argument("--set", choices=["cpu", "gpu"], default="cpu")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only", nargs="*", default=[])
    parser.add_argument("--out")
    arguments = parser.parse_args()

    cases = CPU_CASES if arguments.set == "cpu" else GPU_CASES
    cases = [case for case in cases if not arguments.only or case[0] in arguments.only]
    lines = ["machine: %s, %d cores; binary %s; device %s" % (
        platform.node(), os.cpu_count(), arguments.oclvox, os.environ.get("OCLVOX_DEVICE", "default")), "",
        "| case | whole process s (min / median / max of %d) | peak RSS MB | phases of the median run, s | target |" %
        arguments.repeat, "|---|---|---:|---|---|"]
    print("\n".join(lines), flush=True)
    with tempfile.TemporaryDirectory() as scratch:
        for case in cases:
            result = measure(arguments.oclvox, arguments.meshes, case, arguments.repeat, scratch)
            if "error" in result:
                line = "| %s | failed: %s | | | |" % (case[0], result["error"])
            else:
                walls = result["walls"]
                line = "| %s (%s) | %.3f / %.3f / %.3f | %.0f | %s | %s |" % (
                    case[0], result["device"], min(walls), statistics.median(walls), max(walls), result["peak_rss_mb"],
                    phases(result["seconds"]), verdict(case, result))
            lines.append(line)
            print(line, flush=True)
    if arguments.out:
        with open(arguments.out, "w") as handle:
            handle.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
