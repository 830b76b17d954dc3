// numpy arrays in and out of the library's value types. Arrays given to oclvox are checked and
// copied once into the library's storage (it owns its meshes and fields); arrays handed back share
// the library's storage wherever its layout is already what numpy needs.
//
// Volumes are shaped (nx, ny, nz) with axes x, y, z, so arr[i, j, k] is voxel (i, j, k). The
// library stores them x fastest, which is numpy's Fortran order, so no reordering is needed.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <array>
#include <oclvox/field.hpp>
#include <oclvox/oclvox.hpp>

namespace oclvox_python {

// A mesh from vertices (N, 3), any real dtype, and faces (M, 3), any integer dtype, each index in
// [0, N). Throws oclvox::InputError naming what is wrong.
oclvox::Mesh mesh_from_arrays(pybind11::handle vertices, pybind11::handle faces);

// The mesh's vertices as a float64 (N, 3) array over its own storage, kept alive by `owner`.
pybind11::array_t<double> vertices_view(oclvox::Mesh& mesh, pybind11::handle owner);
// The mesh's faces as a new int64 (M, 3) array (numpy's default integer, as trimesh uses).
pybind11::array_t<int64_t> faces_array(const oclvox::Mesh& mesh);

// The dense occupancy as a new uint8 (nx, ny, nz) array of 0 and 1. The dense copy is built with
// the GIL released. Throws oclvox::GridError if it cannot fit in memory.
pybind11::array_t<uint8_t> occupancy_array(const oclvox::SparseVoxels& voxels);
// Set voxels from a (nx, ny, nz) array: every non-zero element is set.
oclvox::SparseVoxels voxels_from_array(pybind11::handle occupancy, const oclvox::Grid& grid_base,
                                       int brick_size);

// The field's samples as a read-only float32 (nx, ny, nz) view, kept alive by `owner`.
pybind11::array_t<float> field_view(const oclvox::ScalarField& field, pybind11::handle owner);
// A field with samples from a real (nx, ny, nz) array (copied, in float32).
oclvox::ScalarField field_from_array(pybind11::handle values, const oclvox::Grid& grid_base);

}  // namespace oclvox_python
