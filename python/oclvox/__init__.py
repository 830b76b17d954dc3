"""oclvox: conservative mesh voxelization, signed distance fields, CSG and meshing on OpenCL.

Meshes are given as ``(vertices, faces)`` arrays, as a file path, or as any object with
``.vertices`` and ``.faces`` (a trimesh.Trimesh, an oclvox.Mesh). Volumes come back as numpy arrays
shaped ``(nx, ny, nz)`` with axes x, y, z: ``arr[i, j, k]`` is voxel (i, j, k), whose box is
``origin + (i, j, k) * voxel_size`` to ``origin + (i + 1, j + 1, k + 1) * voxel_size``.

Work runs on an OpenCL device (``device=``: "P:D" indices from ``devices()`` or part of a
device/platform name; default ``$OCLVOX_DEVICE``, else the first GPU, else the first device), or
on the bit-identical CPU reference with ``reference=True``. Devices are opened once and kept. The
GIL is released while work runs. Errors are ``oclvox.Error`` subclasses.
"""

import collections
import numbers
import os

from ._oclvox import (
    Cancelled,
    DeviceError,
    Error,
    Field,
    GridError,
    InputError,
    KernelBuildError,
    Mesh,
    OutputError,
    SparseField,
    VoxelGrid,
)
from . import _oclvox

__all__ = [
    "load_mesh", "save_mesh", "voxelize", "candidate_bricks", "selection_triangles", "sdf", "csg", "mesh", "devices", "load_field",
    "Mesh", "VoxelGrid", "Field", "SparseField", "Error", "InputError",
    "GridError", "DeviceError", "KernelBuildError", "OutputError", "Cancelled",
]


def _as_mesh(mesh):
    """An oclvox.Mesh from a path, a mesh object or a (vertices, faces) pair."""
    if isinstance(mesh, Mesh):
        return mesh
    if isinstance(mesh, (str, os.PathLike)):
        return _oclvox.load_mesh(mesh)
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        return Mesh(mesh.vertices, mesh.faces)
    if isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        return Mesh(mesh[0], mesh[1])
    raise TypeError("a mesh is (vertices, faces) arrays, a file path, or an object with "
                    f".vertices and .faces; got {type(mesh).__name__}")


def _mesh_and_resolution(vertices, faces, resolution):
    """The mesh from the first two positional arguments, and the resolution.

    voxelize(vertices, faces, 128) and voxelize(mesh, 128) both work: after a mesh given as one
    object (path, mesh object, pair), an integer in the second place is the resolution.
    """
    if faces is None:
        return _as_mesh(vertices), resolution
    if isinstance(faces, numbers.Integral) and _is_mesh(vertices):
        if resolution != 256:
            raise TypeError("resolution given twice")
        return _as_mesh(vertices), int(faces)
    if isinstance(vertices, (str, os.PathLike, Mesh)) or hasattr(vertices, "faces"):
        raise TypeError("faces given twice: the first argument is already a mesh")
    return Mesh(vertices, faces), resolution


def _is_mesh(value):
    """Whether `value` is a whole mesh in one object (not a vertex array)."""
    return (isinstance(value, (str, os.PathLike, Mesh))
            or (isinstance(value, (tuple, list)) and len(value) == 2)
            or (hasattr(value, "vertices") and hasattr(value, "faces")))


def _fit(resolution, voxel_size, origin, dims, pad, cubic):
    return _oclvox.GridFit(resolution=resolution, voxel_size=voxel_size, origin=origin, dims=dims,
                           pad=pad, cubic=cubic)


def _selector(device):
    if device is not None and not isinstance(device, str):
        raise TypeError("device must be a selector string such as '0:0' or 'pocl', or None")
    return device


def load_mesh(path, *, progress=None):
    """Reads OBJ, STL, PLY, OFF, glTF or 3MF: returns (vertices float64 (N, 3), faces int64 (M, 3)).
    progress: as for sdf."""
    loaded = _oclvox.load_mesh(path, progress=progress)
    return loaded.vertices, loaded.faces


def save_mesh(path, vertices, faces=None, *, progress=None):
    """Writes a triangle mesh by extension: .obj, .ply or .stl. progress: as for sdf (False
    cancels and leaves no file)."""
    _mesh_and_resolution(vertices, faces, 256)[0].save(path, progress=progress)


def voxelize(vertices, faces=None, resolution=256, *, mode="surface", test="sat", inside="auto",
             boundary="closed", voxel_size=None, origin=None, dims=None, pad=0, cubic=False,
             brick_size=64, device_memory=None, host_memory=None, download="auto", device=None,
             reference=False, progress=None, bricks=None):
    """Voxelizes a mesh; returns a VoxelGrid.

    mode: "surface" (conservative: every voxel whose closed box touches a triangle), "thin"
    (6-separating), "solid" (voxels whose centre is inside) or "filled" (solid and surface).
    test: "sat" or "pef". inside (solid modes): "auto", "parity" or "winding".
    boundary: "closed" or "half-open".
    Grid: `resolution` voxels along the longest axis of the mesh box, or `voxel_size`; `origin`
    (x, y, z) and `dims` (nx, ny, nz) fix the grid instead of fitting it; `pad` adds empty voxels
    on every side; `cubic` makes a resolution^3 grid with the mesh centred (binvox convention).
    brick_size: voxels per brick edge (multiple of 4); device_memory / host_memory: MiB budgets.
    download: how the device's voxels come back: "auto" (only the non-empty 4^3 blocks from a
    device with memory of its own, whole batches read in place on CPUs), "whole" or "blocks";
    the voxels are the same.
    progress: called as progress(bricks_done, bricks_total) after each batch; returning False
    cancels the run, which raises oclvox.Cancelled (an exception it raises is passed on).
    bricks: compute only these bricks of the whole grid (linear indices bx + nbx * (by + nby * bz)
    of brick_size bricks, nb = ceil(dims / brick_size)); the result holds exactly the whole run's
    voxels in them, so results over disjoint selections merge (VoxelGrid.merge) into the whole.
    Surface, thin and parity solid do only those bricks' work; the winding number does the whole
    grid's and keeps the selected bricks. See candidate_bricks and oclvox.distributed.
    """
    options = dict(mode=mode, test=test, inside=inside, boundary=boundary, brick_size=brick_size,
                   device_memory=device_memory, host_memory=host_memory, download=download)
    mesh, resolution = _mesh_and_resolution(vertices, faces, resolution)
    return _oclvox.voxelize(mesh, _fit(resolution, voxel_size, origin, dims, pad, cubic), **options,
                            device=_selector(device), reference=reference, progress=progress,
                            bricks=bricks)


def candidate_bricks(vertices, faces=None, resolution=256, *, mode="surface", inside="auto",
                     boundary="closed", voxel_size=None, origin=None, dims=None, pad=0,
                     cubic=False, brick_size=64):
    """The bricks that voxelize with these options can set voxels in: a sorted uint64 array of
    linear brick indices, a superset of the result's bricks, found on the host (no device).
    Surface and thin: the bricks the binning gives triangles; solid and filled: every brick meeting
    the mesh's bounding box. Split it to run voxelize(..., bricks=part) in pieces."""
    mesh, resolution = _mesh_and_resolution(vertices, faces, resolution)
    return _oclvox.candidate_bricks(mesh, _fit(resolution, voxel_size, origin, dims, pad, cubic),
                                    mode=mode, inside=inside, boundary=boundary,
                                    brick_size=brick_size)


SelectionTriangles = collections.namedtuple("SelectionTriangles", "grid inside triangles")
SelectionTriangles.__doc__ = """What selection_triangles returns.

grid: the whole run's grid as voxelize's keyword arguments (origin, voxel_size, dims), because a
part of the mesh would fit a different one. inside: the whole run's inside test ("parity" or
"winding" for solid and filled, with "auto" resolved on the whole mesh; else the one given).
triangles: per selection, a sorted uint32 array of triangle indices; None when every selection
needs the whole mesh (the winding number: every triangle counts in every voxel)."""


def selection_triangles(vertices, faces=None, resolution=256, *, selections, mode="surface",
                        inside="auto", boundary="closed", voxel_size=None, origin=None,
                        dims=None, pad=0, cubic=False, brick_size=64):
    """For each brick selection, the triangles that voxelize(..., bricks=selection) reads, so that
    a machine running that selection needs only them: voxelize(mesh.submesh(plan.triangles[s]),
    **plan.grid, inside=plan.inside, bricks=selections[s], <the other options>) gives exactly the
    voxels of voxelize(mesh, ..., bricks=selections[s]); a selection with no triangles has none.
    One pass over the triangles and the (triangle, brick) pairs the binning makes, on the host.
    Returns a SelectionTriangles (grid, inside, triangles)."""
    mesh, resolution = _mesh_and_resolution(vertices, faces, resolution)
    fit = _fit(resolution, voxel_size, origin, dims, pad, cubic)
    origin, voxel_size, dims = _oclvox.fit_grid(mesh, fit)
    selections = list(selections)
    chosen, whole_mesh, triangles = _oclvox.selection_triangles(
        mesh, fit, mode=mode, inside=inside, boundary=boundary, brick_size=brick_size,
        selections=selections)
    return SelectionTriangles(dict(origin=origin, voxel_size=voxel_size, dims=dims), chosen,
                              None if whole_mesh else triangles)


def _field_pad(pad, band, origin, dims):
    """The CLI's rule: a fitted field grid gets field_padding(band) voxels on every side (so the
    zero level set closes inside it) unless pad, origin or dims place the grid."""
    if pad is not None:
        return pad
    return 0 if origin is not None or dims is not None else _oclvox.field_padding(band)


def sdf(vertices, faces=None, resolution=256, *, band=3.0, full_grid=False, inside="auto",
        voxel_size=None, origin=None, dims=None, pad=None, cubic=False, brick_size=64, device=None,
        reference=False, progress=None, layers=None, sparse=False):
    """Signed distance field (negative inside) at voxel centres; returns a Field.

    Exact within `band` voxels of the surface, clamped to +-band * voxel_size beyond it, or
    propagated to every voxel with full_grid=True. Grid options as for voxelize, except that
    `pad` defaults to ceil(band) + 1 when neither origin nor dims is given, as on the CLI.
    progress: called as progress(done, total) as the work goes on (at most about every 0.05 s,
    and at the end with done == total); done / total is the fraction of the estimated work
    (total is 1,000,000). Returning False cancels the run, which raises oclvox.Cancelled (an
    exception it raises is passed on).
    layers=(first, end): only the voxel layers first <= k < end of the whole grid (end 0: to the
    top), bit for bit the whole field's samples there; stacked along z, consecutive ranges give
    the whole field (also full grids, whose slabs still search every triangle beyond the band).
    The sign's solid still does its whole columns' work.
    sparse=True: a narrow band of the whole grid kept as a SparseField (the 8x8x8 leaves the band
    reaches and the inside voxels as bits), for grids whose dense field would not fit; its
    .save() writes .vdb from the leaves or .npy a layer at a time, .to_field() gives the Field
    (bit for bit the sparse=False result). With layers (first and end multiples of 8, or end the
    top) it keeps the whole grid but holds only those layers' leaves and inside voxels, and
    SparseField.merge joins the fields of disjoint ranges into the whole field; SparseFields
    pickle as their leaves and inside voxels.
    """
    mesh, resolution = _mesh_and_resolution(vertices, faces, resolution)
    pad = _field_pad(pad, band, origin, dims)
    return _oclvox.sdf(mesh, _fit(resolution, voxel_size, origin, dims, pad, cubic), band=band,
                       full_grid=full_grid, inside=inside, brick_size=brick_size,
                       device=_selector(device), reference=reference, progress=progress,
                       layers=layers, sparse=sparse)


def csg(a, op, b, resolution=256, *, band=3.0, full_grid=False, inside="auto", voxel_size=None,
        origin=None, dims=None, pad=None, cubic=False, brick_size=64, device=None, reference=False,
        progress=None, sparse=False):
    """Combines two shapes; op is "union", "intersection" or "difference" (a minus b).

    - two meshes: their signed distance fields on one grid fitted around both (grid and SDF
      options, and progress over both fields, as for sdf), combined by min / max / max(a, -b);
      returns a Field, or with sparse=True a SparseField combined leaf by leaf (as sdf's);
    - two Fields on the same grid: returns a Field;
    - two SparseFields (from sdf(sparse=True) or load_field of .vdb level sets) with the same
      band, on the same grid or on grids of one voxel lattice (the same voxel size, origins a
      whole number of voxels apart, as OpenVDB level sets with one transform are): returns a
      SparseField on the box of both, where a field counts as outside beyond its own grid;
    - two VoxelGrids on the same grid: a | b, a & b, a & ~b; returns a VoxelGrid.
    """
    if (isinstance(a, Field) and isinstance(b, Field)) or \
            (isinstance(a, SparseField) and isinstance(b, SparseField)):
        _no_grid_options(resolution, voxel_size, origin, dims, pad, cubic)
        return _oclvox.csg_fields(a, op, b)
    if isinstance(a, VoxelGrid) and isinstance(b, VoxelGrid):
        _no_grid_options(resolution, voxel_size, origin, dims, pad, cubic)
        return _oclvox.csg_voxels(a, op, b)
    if _is_mesh(a) and _is_mesh(b):
        pad = _field_pad(pad, band, origin, dims)
        return _oclvox.csg_meshes(_as_mesh(a), op, _as_mesh(b),
                                  _fit(resolution, voxel_size, origin, dims, pad, cubic),
                                  band=band, full_grid=full_grid, inside=inside,
                                  brick_size=brick_size, device=_selector(device),
                                  reference=reference, progress=progress, sparse=sparse)
    raise TypeError("csg takes two meshes, two Fields, two SparseFields or two VoxelGrids; got "
                    f"{type(a).__name__} and {type(b).__name__}")


def _no_grid_options(resolution, voxel_size, origin, dims, pad, cubic):
    if (resolution != 256 or voxel_size is not None or origin is not None or dims is not None
            or pad not in (None, 0) or cubic):
        raise ValueError("grid options apply to mesh inputs only (fields and voxel grids "
                         "keep their own grid)")


def mesh(field, iso=0.0, method="marching-cubes", *, smoothing=1, device=None, reference=False,
         progress=None):
    """Triangulates a field's iso-surface; returns (vertices float64 (N, 3), faces int64 (M, 3)).

    field: a Field, a SparseField, a field file (a .npy field, read a layer at a time unless a
    device or the reference is asked for, or a .vdb level set, read sparse), or a VoxelGrid (turned
    into a field with `smoothing` box-filter passes). method: "marching-cubes"
    or "surface-nets". Samples < iso are inside; triangles are wound counter-clockwise seen from
    outside. progress: as for sdf. A SparseField is meshed on the host's cores, without a dense
    copy, into the mesh its dense copy gives (so `device` and `reference` apply to dense fields
    only, and naming a device for a SparseField is an error).
    """
    if isinstance(field, VoxelGrid):
        # Its smoothed field a layer at a time into the samples and sides the meshers read,
        # unless a device or the reference meshes the dense field.
        use_view = device is None and not reference
        field = (field.meshing_view(smoothing, iso) if use_view
                 else field.to_field(smoothing=smoothing))
    elif (isinstance(field, (str, os.PathLike)) and os.fspath(field).lower().endswith(".npy")
          and device is None and not reference):
        # Read a layer at a time into the samples and sides the meshers read (its meshing
        # view), so memory follows the surface, not the field's volume.
        field = _oclvox.load_meshing_view(field, iso=iso, progress=progress)
    elif isinstance(field, (str, os.PathLike)):
        field = load_field(field)
    if isinstance(field, SparseField):
        if device is not None:
            raise ValueError("a SparseField is meshed on the host; device applies to dense "
                             "fields (SparseField.to_field() gives one)")
        surface = _oclvox.mesh_sparse(field, iso=iso, method=method, progress=progress)
        return surface.vertices, surface.faces
    if not isinstance(field, Field):
        raise TypeError(f"mesh takes a Field, a SparseField, a VoxelGrid or a field path; got "
                        f"{type(field).__name__}")
    surface = _oclvox.mesh(field, iso=iso, method=method, device=_selector(device),
                           reference=reference, progress=progress)
    return surface.vertices, surface.faces


def _field_mesh(self, method="marching-cubes", iso=0.0, *, device=None, reference=False,
                progress=None):
    """This field's iso-surface: (vertices, faces), as oclvox.mesh."""
    return mesh(self, iso=iso, method=method, device=device, reference=reference,
                progress=progress)


def _grid_mesh(self, method="marching-cubes", *, smoothing=1, device=None, reference=False,
               progress=None):
    """The surface of these voxels (through a smoothed field): (vertices, faces), as oclvox.mesh."""
    return mesh(self, method=method, smoothing=smoothing, device=device, reference=reference,
                progress=progress)


Field.mesh = _field_mesh
SparseField.mesh = _field_mesh
VoxelGrid.mesh = _grid_mesh


def load_field(path, *, onto=None):
    """Reads a field file: a .npy field (with its JSON sidecar) as a Field, a .vdb level set
    (ours, or any OpenVDB narrow-band level set) as a SparseField, without a dense copy.

    onto: a SparseField whose voxel lattice and band a .vdb level set is read onto, so the two
    combine in csg(); one on another lattice is rebuilt there by OpenVDB's levelSetRebuild (its
    values are then distances to a polygonization of its surface, within a fraction of a voxel).
    """
    if os.fspath(path).lower().endswith(".vdb"):
        if onto is not None:
            if not isinstance(onto, SparseField):
                raise TypeError(f"onto must be a SparseField, got {type(onto).__name__}")
            return _oclvox.load_sparse_field_onto(path, onto)
        return _oclvox.load_sparse_field(path)
    if onto is not None:
        raise ValueError("onto applies to .vdb level sets only")
    return _oclvox.load_field(path)


def devices():
    """Every OpenCL device: a list of dicts (id, platform, name, vendor, version, type, ...)."""
    return _oclvox.devices()
