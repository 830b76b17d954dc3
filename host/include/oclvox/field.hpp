// oclvox scalar fields and their iso-surfaces: Naive Surface Nets and Marching Cubes, on the host
// and on an OpenCL device (identical output; the brick-tiled reference of the kernels is internal,
// meshing_reference.cpp), plus a mesh writer.
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

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "oclvox/oclvox.hpp"

// The library is built with hidden visibility; what these headers declare is its interface.
#pragma GCC visibility push(default)

namespace oclvox {

// Scalar samples at voxel CENTRES (origin + (i+0.5, j+0.5, k+0.5) * voxel_size), x fastest:
// values[i + nx*(j + ny*k)]. Negative inside, positive outside (OpenVDB's convention).
struct ScalarField {
    Grid grid;
    std::vector<float> values;
    // The sample of voxel (i, j, k); throws std::out_of_range outside the grid.
    float at(int64_t i, int64_t j, int64_t k) const;
};

// A narrow-band signed distance field stored sparsely, as OpenVDB stores a level set: the samples
// of the 8x8x8 leaves (aligned to multiples of 8 voxels) that hold a sample within the band, plus
// the inside test's voxels, which give every other sample its sign: -background inside, +background
// outside. Memory follows the surface (4 bytes per leaf sample) and the inside volume (1 bit per
// voxel), not the grid's volume, so grids far beyond a dense field's reach can be held.
// Made by signed_distance_sparse (oclvox/sdf.hpp); to_dense() gives exactly the values
// signed_distance gives for the same mesh, grid and options.
class SparseField {
  public:
    static constexpr int kLeaf = 8;
    static constexpr size_t kLeafSamples = size_t(kLeaf) * kLeaf * kLeaf;

    SparseField() = default;
    // A field of `grid` with no leaves yet: every sample +-background by `inside`'s voxels, the
    // background band_voxels * voxel_size rounded to float (as narrow-band fields hold it).
    // Throws GridError unless inside's grid is `grid` and the band is finite and positive.
    SparseField(const Grid& grid, double band_voxels, SparseVoxels inside);

    const Grid& grid() const { return grid_; }
    double band_voxels() const { return band_voxels_; }
    float background() const { return background_; }
    std::array<int64_t, 3> leaf_dims() const;  // leaves along each axis (ceil)
    // The minimum voxel of leaf lx + nlx*(ly + nly*lz): (lx, ly, lz) * kLeaf.
    std::array<int64_t, 3> leaf_origin(uint64_t leaf_index) const;
    size_t leaf_count() const { return leaf_keys_.size(); }
    // The linear indices lx + nlx*(ly + nly*lz) of the stored leaves, in increasing order.
    const std::vector<uint64_t>& leaf_indices() const { return leaf_keys_; }
    // The kLeafSamples samples of the n-th stored leaf, x fastest; samples of a leaf beyond the
    // grid's far faces are +-background and belong to no voxel.
    const float* leaf_samples(size_t n) const { return &samples_[n * kLeafSamples]; }
    // The inside test's voxels: they sign every sample outside the leaves.
    const SparseVoxels& inside() const { return inside_; }
    // Appends a leaf with leaf index above every stored one; its samples are copied. Throws
    // GridError for an index out of order or outside the grid.
    void append_leaf(uint64_t leaf_index, const float* samples);
    // Adds other's leaves and inside voxels: fields of disjoint layer ranges of one grid
    // (signed_distance_sparse with layers) merge into the whole grid's field. Throws GridError
    // unless other has the same grid, band and brick size, or if a leaf is stored in both. Leaves
    // all after this field's are appended without moving the stored ones.
    void merge(const SparseField& other);
    // Room for this many leaves in all, so appending them never copies the stored samples.
    void reserve_leaves(size_t leaves) {
        leaf_keys_.reserve(leaves);
        samples_.reserve(leaves * kLeafSamples);
    }

    // The sample of voxel (i, j, k); throws std::out_of_range outside the grid.
    float at(int64_t i, int64_t j, int64_t k) const;
    // The samples of the box [lo, hi) into out, x fastest (hi - lo samples per row): one lookup
    // per leaf the box touches plus one step per sample. Throws GridError for a box not inside the
    // grid.
    void copy_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi,
                  float* out) const;
    // The kLeafSamples samples of leaf `leaf_index` (below the product of leaf_dims()), stored or
    // not, x fastest; samples beyond the grid's far faces are +background.
    void copy_leaf(uint64_t leaf_index, float* samples) const;
    // The dense field; throws GridError if it does not fit the host memory budget.
    ScalarField to_dense() const;

  private:
    Grid grid_{};
    double band_voxels_ = 0;
    float background_ = 0;
    SparseVoxels inside_;
    std::vector<uint64_t> leaf_keys_;
    std::vector<float> samples_;
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

// occupancy_to_field's samples a layer at a time (k = 0, 1, ... of its grown grid), bit for bit,
// holding three layers per smoothing pass instead of the field: with MeshingViewBuilder, voxels
// whose field would not fit in memory can still be meshed. `voxels` must outlive it. Throws as
// occupancy_to_field, and GridError past the last layer.
class OccupancyFieldLayers {
  public:
    OccupancyFieldLayers(const SparseVoxels& voxels, int smoothing_passes = 1);
    ~OccupancyFieldLayers();
    OccupancyFieldLayers(const OccupancyFieldLayers&) = delete;
    OccupancyFieldLayers& operator=(const OccupancyFieldLayers&) = delete;

    const Grid& grid() const;  // the voxels' grid grown by smoothing_passes + 1 on every side
    // The next layer's grid().dims[0] * grid().dims[1] samples, x fastest.
    void next_layer(float* samples);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The meshing view at iso (MeshingViewBuilder) of occupancy_to_field(voxels, smoothing_passes),
// made a layer at a time (OccupancyFieldLayers): it meshes as that field does, with memory for the
// view instead of the field.
SparseField occupancy_meshing_view(const SparseVoxels& voxels, int smoothing_passes = 1,
                                   float iso = 0.0f);

// How many samples of the grid's outer layer are inside (value < iso). Zero means no part of the
// shape reaches the grid border, so both meshing methods give a closed surface; otherwise the
// shape is cut by the grid box and its meshes are open there. Throws GridError if values.size()
// does not match the grid.
uint64_t border_samples_inside(const ScalarField& field, float iso = 0.0f);
uint64_t border_samples_inside(const SparseField& field, float iso = 0.0f);

// One layer of a field given a layer at a time: fills `samples` with the grid.dims[0] *
// grid.dims[1] samples of layer k, x fastest.
using FieldLayer = std::function<void(int64_t k, float* samples)>;
// Those of border_samples_inside(field) that lie in layer k (`samples`, as FieldLayer gives it)
// of a field on `grid`: summed over every layer, the field's count.
uint64_t border_samples_inside(const Grid& grid, int64_t k, const float* samples, float iso = 0.0f);

// Naive Surface Nets: one vertex per cell whose corners change sign, at the mean of the linearly
// interpolated crossings on its sign-changing edges; one quad (two triangles) per sign-changing
// grid edge, joining the vertices of the four cells around it. Closed and manifold wherever no
// cell face has four sign changes (true for smooth fields sampled finely enough); at such faces
// the method is inherently non-manifold. On the host's cores (TBB), visiting only the 8x8x8
// blocks whose samples change side (through the field's meshing view, as for SparseField below).
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
// which never opens the surface. The case table is derived programmatically. On the host's cores,
// as surface_nets.
Mesh marching_cubes(const ScalarField& field, float iso = 0.0f,
                    const ProgressCallback& progress = {});

// The same meshes computed on an OpenCL device: vertex positions equal to the host's bit for bit,
// same vertex order, same triangles. Also throws DeviceError on OpenCL failures.
Mesh surface_nets(Device& device, const ScalarField& field, float iso = 0.0f,
                  const ProgressCallback& progress = {});
Mesh marching_cubes(Device& device, const ScalarField& field, float iso = 0.0f,
                    const ProgressCallback& progress = {});

// The same meshes of a sparse narrow-band field, on the host, without a dense copy: equal bit for
// bit to meshing field.to_dense() (the same vertices in the same order, the same triangles), also
// where the inside voxels change away from the leaves (holes an inside test closed). Work and
// memory follow the surface: the 8x8x8 blocks that reach a leaf or a change of the inside voxels,
// three slabs of them at a time, plus the mesh. Throws InputError for a non-finite sample or iso,
// GridError when the mesh exceeds 32-bit indices or the host memory budget.
Mesh surface_nets(const SparseField& field, float iso = 0.0f,
                  const ProgressCallback& progress = {});
Mesh marching_cubes(const SparseField& field, float iso = 0.0f,
                    const ProgressCallback& progress = {});

// The sparse field that meshes at `iso` exactly as a dense field does (surface_nets and
// marching_cubes of it give the dense field's mesh bit for bit, and its samples below iso are the
// dense field's), built from the dense field given a layer at a time, so that a field too large
// to hold whole (a full-grid distance field computed a slab of layers at a time, a large .npy) can
// still be meshed and previewed. It keeps the 8x8x8 leaves holding a corner of a cell with samples
// on both sides of iso, and elsewhere only each sample's side, as inside voxels under a background
// beyond iso. Memory holds 16 layers, the inside voxels and the kept leaves. The dense meshing
// functions above mesh through it.
class MeshingViewBuilder {
  public:
    // Throws GridError for an invalid grid or when 16 of its layers exceed the host memory
    // budget, InputError for a non-finite iso.
    MeshingViewBuilder(const Grid& grid, float iso);
    ~MeshingViewBuilder();
    MeshingViewBuilder(MeshingViewBuilder&&) noexcept;
    MeshingViewBuilder& operator=(MeshingViewBuilder&&) noexcept;

    // Adds the next layer (k = 0, 1, ... in order): grid.dims[0] * grid.dims[1] samples, x
    // fastest. Throws InputError naming a non-finite sample, GridError after the last layer or
    // when the kept leaves exceed the host memory budget.
    void add_layer(const float* samples);
    // The view, once every layer is added (GridError before); the builder is then empty.
    SparseField finish();

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Writes a triangle mesh by extension (case-insensitive): .obj (text, exact shortest decimals),
// .ply (binary little-endian, double vertices, int indices), .stl (binary, float, facet normals).
// Written to a temporary file and renamed into place. Throws OutputError for an unknown extension,
// an invalid index, or an I/O failure. `progress` as for write_field: the fraction written, the
// last call before the file takes its name, false throwing Cancelled and leaving no file.
void write_mesh(const std::string& path, const Mesh& mesh, const ProgressCallback& progress = {});

}  // namespace oclvox

#pragma GCC visibility pop
