// oclvox scalar fields and their iso-surfaces: Naive Surface Nets and Marching Cubes, on the host
// (the reference) and on an OpenCL device (identical output), plus a mesh writer.
//
// Meshing conventions shared by both methods:
//  - a sample is inside when its value is < iso, outside when >= iso;
//  - a cell is the cube between 8 neighbouring samples; a grid edge joins two neighbouring samples
//    and "changes sign" when exactly one of them is inside;
//  - triangles are wound counter-clockwise seen from outside, so their right-hand normals point
//    from inside (negative) to outside (positive);
//  - only cells inside the grid are meshed: a surface that leaves the grid is open there. Fields
//    made by occupancy_to_field have an outside border, so their surfaces are closed;
//  - the output depends only on the field and iso (never on the brick size or the device).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "oclvox/oclvox.hpp"

namespace oclvox {

// Scalar samples at voxel CENTRES (origin + (i+0.5, j+0.5, k+0.5) * voxel_size), x fastest:
// values[i + nx*(j + ny*k)]. Negative inside, positive outside (OpenVDB's convention).
struct ScalarField {
    Grid grid;
    std::vector<float> values;
    // The sample of voxel (i, j, k); throws std::out_of_range outside the grid.
    float at(int64_t i, int64_t j, int64_t k) const;
};

// Signed conversion of a binary occupancy: -0.5 inside (set), +0.5 outside, then
// `smoothing_passes` passes of a 3x3x3 box filter (each pass averages every sample with its 26
// neighbours; samples beyond the border count as +0.5) so that meshes are not stair-stepped.
// Without smoothing the iso-surface at 0 runs exactly through the faces between set and unset
// voxels; each pass rounds it a little more (sharp corners move inwards by up to ~1 voxel per
// pass, thin features one voxel wide may vanish). The field's grid is the voxels' grid grown by
// `smoothing_passes + 1` outside voxels on every side, so surfaces are closed even where set
// voxels touch the grid border. Throws GridError for negative passes or a field too large to
// hold.
ScalarField occupancy_to_field(const SparseVoxels& voxels, int smoothing_passes = 1);

// How many samples of the grid's outer layer are inside (value < iso). Zero means no part of the
// shape reaches the grid border, so both meshing methods give a closed surface; otherwise the
// shape is cut by the grid box and its meshes are open there. Throws GridError if values.size()
// does not match the grid.
uint64_t border_samples_inside(const ScalarField& field, float iso = 0.0f);

// Naive Surface Nets: one vertex per cell whose corners change sign, at the mean of the linearly
// interpolated crossings on its sign-changing edges; one quad (two triangles) per sign-changing
// grid edge, joining the vertices of the four cells around it. Closed and manifold wherever no
// cell face has four sign changes (true for smooth fields sampled finely enough); at such faces
// the method is inherently non-manifold. Host reference.
// Both meshing functions throw GridError if values.size() does not match the grid and InputError
// for a non-finite sample or iso. `progress` is called as the work goes on, as SdfOptions::progress
// is (done / total the fraction of the estimated work, total 1,000,000, and once more at the end
// with done == total); returning false cancels (the run throws Cancelled).
Mesh surface_nets(const ScalarField& field, float iso = 0.0f,
                  const ProgressCallback& progress = {});

// Marching Cubes with face ambiguities resolved by the asymptotic decider (Nielson & Hamann
// 1991), decided from the face's four samples alone so both cells sharing a face agree: the
// output is closed, edge- and vertex-manifold and consistently oriented. One vertex per
// sign-changing edge, at the linearly interpolated crossing, shared by the cells around it; a
// contour loop that cannot be triangulated without a diagonal across a cell face (only in
// ambiguous configurations, rare on smooth fields) gets one extra vertex at the mean of its
// crossings, as in Marching Cubes 33. Body (interior) ambiguities are not resolved (no tunnels),
// which never opens the surface. The case table is derived programmatically. Host reference.
Mesh marching_cubes(const ScalarField& field, float iso = 0.0f,
                    const ProgressCallback& progress = {});

// The same meshes computed on an OpenCL device: vertex positions equal to the reference bit for
// bit, same vertex order, same triangles. Also throws DeviceError on OpenCL failures.
Mesh surface_nets(Device& device, const ScalarField& field, float iso = 0.0f,
                  const ProgressCallback& progress = {});
Mesh marching_cubes(Device& device, const ScalarField& field, float iso = 0.0f,
                    const ProgressCallback& progress = {});

// Writes a triangle mesh by extension (case-insensitive): .obj (text, exact shortest decimals),
// .ply (binary little-endian, double vertices, int indices), .stl (binary, float, facet normals).
// Written to a temporary file and renamed into place. Throws OutputError for an unknown extension,
// an invalid index, or an I/O failure.
void write_mesh(const std::string& path, const Mesh& mesh);

}  // namespace oclvox
