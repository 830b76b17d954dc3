"""Every failure is an oclvox.Error subclass matching the library's, raised before work starts."""

import numpy as np
import pytest

import oclvox
from conftest import box_mesh

CUBE = box_mesh((0, 0, 0), (1, 1, 1))


def test_hierarchy():
    for cls in (oclvox.InputError, oclvox.GridError, oclvox.DeviceError, oclvox.OutputError,
                oclvox.Cancelled):
        assert issubclass(cls, oclvox.Error)
    assert issubclass(oclvox.KernelBuildError, oclvox.DeviceError)
    assert issubclass(oclvox.InputError, ValueError) and issubclass(oclvox.GridError, ValueError)
    assert issubclass(oclvox.DeviceError, RuntimeError)
    assert issubclass(oclvox.OutputError, OSError)
    assert issubclass(oclvox.Error, Exception) and not issubclass(oclvox.Cancelled, ValueError)


@pytest.mark.parametrize("vertices,faces,message", [
    (CUBE[0], CUBE[1] + 8, "refers to vertex"),                      # index past the end
    (CUBE[0], CUBE[1] - 1, "refers to vertex -1"),                   # negative index
    (CUBE[0], CUBE[1] + 2**32, "refers to vertex"),                  # would wrap to 32 bits
    (CUBE[0], CUBE[1].astype(float), "faces must be integers"),
    (CUBE[0][:, :2], CUBE[1], "vertices must have shape (N, 3)"),
    (CUBE[0].ravel(), CUBE[1], "vertices must have 2 dimensions"),
    (CUBE[0], np.zeros((0, 3), int), "no triangles"),
    (np.where(np.arange(24).reshape(8, 3) == 4, np.nan, CUBE[0]), CUBE[1], "not a finite"),
    (np.array([["a", "b", "c"]] * 8), CUBE[1], "vertices must be real numbers"),
])
def test_bad_mesh_arrays(vertices, faces, message):
    with pytest.raises(oclvox.InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        oclvox.voxelize(vertices, faces, 8)


def test_bad_mesh_files(tmp_path):
    with pytest.raises(oclvox.InputError, match="does not exist"):
        oclvox.load_mesh(tmp_path / "missing.obj")
    broken = tmp_path / "broken.obj"
    broken.write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
    with pytest.raises(oclvox.InputError, match="broken.obj"):
        oclvox.voxelize(broken, resolution=8)
    with pytest.raises(ValueError):  # InputError is a ValueError
        oclvox.load_mesh(tmp_path / "missing.stl")


@pytest.mark.parametrize("options", [
    dict(resolution=0), dict(resolution=2**21), dict(voxel_size=-1.0), dict(voxel_size=0.0),
    dict(dims=(0, 4, 4), origin=(0, 0, 0), voxel_size=1.0), dict(mode="volume"),
    dict(test="fast"), dict(inside="magic"), dict(boundary="open"), dict(brick_size=6),
    dict(pad=-1),
])
def test_bad_grids_and_options(options):
    with pytest.raises(oclvox.GridError):
        oclvox.voxelize(*CUBE, **options)


def test_bad_device():
    with pytest.raises(oclvox.DeviceError, match="no-such-device"):
        oclvox.voxelize(*CUBE, 8, device="no-such-device")
    with pytest.raises(ValueError, match="exclude"):
        oclvox.voxelize(*CUBE, 8, device="0:0", reference=True)
    with pytest.raises(TypeError):
        oclvox.voxelize(*CUBE, 8, device=0)


def test_bad_outputs(tmp_path):
    grid = oclvox.voxelize(*CUBE, 8)
    with pytest.raises(oclvox.OutputError):
        grid.save(tmp_path / "no" / "such" / "folder" / "cube.npy")
    with pytest.raises(oclvox.OutputError, match="xyz"):
        grid.save(tmp_path / "cube.xyz")
    with pytest.raises(OSError):  # OutputError is an OSError
        oclvox.save_mesh(tmp_path / "cube.unknown", *CUBE)
    assert not any(tmp_path.iterdir())  # nothing half-written left behind


def test_bad_combinations():
    field = oclvox.Field(np.zeros((4, 4, 4)))
    other = oclvox.Field(np.zeros((4, 4, 5)))
    with pytest.raises(oclvox.GridError):
        oclvox.csg(field, "union", other)
    with pytest.raises(oclvox.GridError, match="xor"):
        oclvox.csg(field, "xor", field)
    with pytest.raises(TypeError):
        oclvox.csg(field, "union", CUBE)
    with pytest.raises(ValueError, match="grid options"):
        oclvox.csg(field, "union", field, resolution=64)
    with pytest.raises(oclvox.GridError, match="dual-contouring"):
        oclvox.mesh(field, method="dual-contouring")
    with pytest.raises(TypeError, match="faces given twice"):
        oclvox.voxelize("mesh.obj", CUBE[1])
    with pytest.raises(TypeError, match="resolution given twice"):
        oclvox.voxelize("mesh.obj", 64, resolution=32)
    with pytest.raises(TypeError):
        oclvox.voxelize(42)
    with pytest.raises(oclvox.InputError):
        oclvox.Field(np.zeros((4, 4)))
    with pytest.raises(oclvox.InputError, match="not finite"):
        oclvox.mesh(oclvox.Field(np.full((4, 4, 4), np.nan)))
