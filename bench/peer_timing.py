"""Timing and reporting helpers the side-by-side benchmarks share (field_peers.py,
open3d_peers.py)."""
import re
import statistics
import subprocess
import time


def run_timed(command):
    """Whole-process wall seconds and the command's standard output."""
    start = time.perf_counter()
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    return time.perf_counter() - start, done.stdout


def stat_seconds(stdout, name):
    """A line of oclvox's --stats timing block, e.g. '  field   1.234'; NaN if it is missing."""
    match = re.search(rf"^\s*{name}\s+([0-9.]+)", stdout, re.M)
    return float(match.group(1)) if match else float("nan")


def timed_call(f):
    """Wall seconds of f() and its result."""
    start = time.perf_counter()
    result = f()
    return time.perf_counter() - start, result


def median(values):
    return statistics.median(values) if values else float("nan")


def cell(x, digits=3):
    """A table cell of seconds; '-' for NaN (a peer that did not run)."""
    return "-" if x != x else f"{x:.{digits}f}"


def emit_table(lines, out=None):
    """Prints the Markdown lines, and also writes them to `out` when given."""
    text = "\n".join(lines)
    print(text)
    if out:
        with open(out, "w") as f:
            f.write(text + "\n")
