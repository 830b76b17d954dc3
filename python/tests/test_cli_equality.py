"""The CLI and the Python package give the same voxels and fields on the same grid."""

import json
import os
import subprocess

import numpy as np
import pytest

import oclvox
from conftest import SPOT

CLI = os.environ.get("OCLVOX_CLI")
pytestmark = pytest.mark.skipif(not CLI, reason="OCLVOX_CLI (the oclvox tool) not given")


def run_cli(*args):
    subprocess.run([CLI, *map(str, args), "--quiet"], check=True)


@pytest.mark.parametrize("cli_args,options", [
    (["-r", 72], dict(resolution=72)),
    (["-r", 64, "--mode", "thin", "--boundary", "half-open", "--test", "pef"],
     dict(resolution=64, mode="thin", boundary="half-open", test="pef")),
    (["-r", 48, "--mode", "solid", "--cubic", "--pad", 3],
     dict(resolution=48, mode="solid", cubic=True, pad=3)),
    (["--voxel-size", 0.021, "--origin", "-0.3,-0.5,-0.4", "--dims", "30,41,37", "--mode",
      "filled"],
     dict(voxel_size=0.021, origin=(-0.3, -0.5, -0.4), dims=(30, 41, 37), mode="filled")),
])
def test_voxelize_matches_cli(tmp_path, cli_args, options):
    out = tmp_path / "cli.npy"
    run_cli("voxelize", SPOT, *cli_args, "-o", out)
    from_cli = np.load(out)
    sidecar = json.loads((tmp_path / "cli.npy.json").read_text())
    grid = oclvox.voxelize(SPOT, **options)
    assert from_cli.shape == grid.dims
    assert np.array_equal(grid.to_numpy(), from_cli)
    assert np.allclose(grid.origin, sidecar["origin"], rtol=0, atol=1e-12)
    assert grid.voxel_size == pytest.approx(sidecar["voxel_size"], rel=1e-15)


def test_sdf_matches_cli(tmp_path):
    out = tmp_path / "sdf.npy"
    run_cli("sdf", SPOT, "-r", 40, "--band", 2.5, "-o", out)
    field = oclvox.sdf(SPOT, 40, band=2.5)
    assert np.array_equal(field.to_numpy(), np.load(out))


def test_csg_matches_cli(tmp_path, spot):
    vertices, faces = spot
    moved = tmp_path / "moved.obj"
    oclvox.save_mesh(moved, vertices + [0.2, 0.1, 0.0], faces)
    out = tmp_path / "csg.npy"
    run_cli("csg", SPOT, "difference", moved, "-r", 40, "-o", out)
    field = oclvox.csg(SPOT, "difference", moved, 40)
    assert np.array_equal(field.to_numpy(), np.load(out))
