// oclvox distance fields: exact narrow-band (optionally full-grid) distances from a mesh sampled
// at voxel centres, their sign from the solid voxelization, CSG on fields and on voxel sets, and
// field files (.npy + JSON sidecar, OpenVDB .vdb).
#pragma once

#include <string>
#include <variant>

#include "oclvox/field.hpp"
#include "oclvox/oclvox.hpp"

// The library is built with hidden visibility; what these headers declare is its interface.
#pragma GCC visibility push(default)

namespace oclvox {

struct SdfOptions {
    // Half-width of the band of exact distances, in voxels (> 0). Narrow-band fields hold
    // +-band * voxel_size outside it.
    double band_voxels = 3.0;
    // Exact distances in every voxel, not only in the band (see signed_distance).
    bool full_grid = false;
    // How the sign decides "inside" (the Solid voxelization's test).
    InsideTest inside = InsideTest::Auto;
    // Bricks of the solid voxelization that gives the sign.
    int brick_size = 64;
    // Compute only the voxel layers first_layer <= k < end_layer of the whole grid (end_layer 0:
    // to the top). A dense field then covers just those layers (its grid starts at layer
    // first_layer), and its samples are bit for bit those of the whole grid's field there, so
    // fields of consecutive layer ranges, computed anywhere, stack into the whole field. A sparse
    // field (signed_distance_sparse; layers at multiples of 8, the leaves' size) keeps the whole
    // grid but holds only the leaves and inside voxels of those layers, the whole field's bit
    // for bit, and fields of disjoint ranges merge (SparseField::merge) into the whole field.
    // Full grids too (dense only): their search beyond the band still covers every triangle, so a
    // full grid too large to hold can be computed and written a slab of layers at a time.
    int64_t first_layer = 0, end_layer = 0;
    // Called as the work goes on (at most about every 0.05 s, and once more at the end with
    // done == total); return false to cancel (the run throws Cancelled). A run's phases (the band
    // pass, the full grid's search beyond it, the sign's solid voxelization; both fields of a CSG)
    // count in different units, so done / total is the fraction of the run's estimated work: total
    // is always 1,000,000 and done never goes back. On a device, kernels run in slices of about 0.1
    // s while a callback is set, so a cancel takes effect within about that long.
    ProgressCallback progress;
    // Host memory for the dense field and its working copies (checked before they are
    // allocated), and for the solid voxelization that gives the sign. 0: $OCLVOX_HOST_MEMORY_MIB
    // MiB if set, else half of physical memory.
    uint64_t host_budget_bytes = 0;
    // Device memory for one batch of a sparse field's leaves (signed_distance_sparse); 0: the
    // device's largest allocation, at most half its memory. The result does not depend on it.
    uint64_t device_budget_bytes = 0;
};

// Margin, in voxels on every side, for a grid fitted to a mesh whose distance field is written or
// meshed: ceil(band_voxels) + 1 (GridFit::pad). Then the whole band of exact distances lies in
// the grid, and every border sample is at least half a voxel outside the mesh's bounding box,
// where no closed mesh is inside: the zero level set does not reach the border and its meshes
// are closed. The CLI's sdf and csg pad fitted grids by this much unless told otherwise.
int64_t field_padding(double band_voxels);

// Distance in world units from each voxel centre to the nearest point of the mesh's triangles.
//
// Inside the band (distance < band_voxels voxels) the value is the exact point-to-triangle
// distance, evaluated in float on triangles stored relative to an integer anchor near them
// (so the error is a few float ulps of the triangle's size in voxels, independent of where the
// grid is), and rounded once to float in world units. Outside the band a narrow-band field holds
// band_voxels * voxel_size.
//
// full_grid: every voxel beyond the band takes its distance to the nearest of all the prepared
// triangles, found by a walk of a tree of boxes over them that passes over boxes farther than
// the nearest triangle found so far (the same float distance as in the band, so the field is
// exact everywhere, also where the nearest triangle lies outside a user-given grid).
//
// stats: triangles_in, triangles_used (those within the band of the grid; for a full grid all),
// work_items (the (triangle, 4x4x4 block) items of the band pass) and the seconds_* timings.
//
// The device result equals unsigned_distance_reference bit for bit. Throws GridError for bad
// options or a grid whose dense field (8 bytes per voxel on the host) does not fit the host
// memory budget or the device, before allocating it;
// DeviceError on OpenCL failures.
ScalarField unsigned_distance(Device& device, const Mesh& mesh, const Grid& grid,
                              const SdfOptions& options, VoxelizeStats* stats = nullptr);
ScalarField unsigned_distance_reference(const Mesh& mesh, const Grid& grid,
                                        const SdfOptions& options, VoxelizeStats* stats = nullptr);

// The unsigned distance, negated at the voxels whose centres the Solid voxelization (with
// options.inside) puts inside the mesh: negative inside, positive outside (OpenVDB's
// convention). The device version uses Device::voxelize, the reference voxelize_reference, so
// the two agree bit for bit. stats add the solid run's timings, inside_test and its reason, and
// voxels_set = the number of inside voxels (of the field's layers).
ScalarField signed_distance(Device& device, const Mesh& mesh, const Grid& grid,
                            const SdfOptions& options, VoxelizeStats* stats = nullptr);
ScalarField signed_distance_reference(const Mesh& mesh, const Grid& grid, const SdfOptions& options,
                                      VoxelizeStats* stats = nullptr);

// The narrow-band signed field as a SparseField: the band is computed only in the 8x8x8 leaves
// that a triangle's band reaches (found first, from the same 4x4x4 block culls as the band pass),
// in batches of leaves on the device, and only those leaves come back. Its to_dense() equals
// signed_distance's field bit for bit (the same prepared triangles, the same squared distances
// and the same solid for the sign), and the device result equals the reference's. Memory follows
// the surface: bunny00's field at 2048^3 took 1.8 GB (the whole process) where the dense one
// needs 27 GB. stats as signed_distance's, with bricks_total / bricks_active / batches counting
// the grid's leaves, the stored leaves and the device batches. Throws GridError for full_grid,
// layers not at multiples of 8 (see SdfOptions), or a leaf set that does not fit the host memory
// budget; DeviceError on OpenCL failures.
SparseField signed_distance_sparse(Device& device, const Mesh& mesh, const Grid& grid,
                                   const SdfOptions& options, VoxelizeStats* stats = nullptr);
SparseField signed_distance_sparse_reference(const Mesh& mesh, const Grid& grid,
                                             const SdfOptions& options,
                                             VoxelizeStats* stats = nullptr);

// ---------------------------------------------------------------------------------------------
// CSG
// ---------------------------------------------------------------------------------------------
enum class CsgOp { Union, Intersection, Difference };
const char* to_string(CsgOp op);
CsgOp csg_op_from_string(const std::string& name);  // "union" / "intersection" / "difference"

// Per sample: Union min(a, b), Intersection max(a, b), Difference (a minus b) max(a, -b). Exact
// on the zero level set; away from it the result is a bound on the distance, not the distance.
// Throws GridError unless both fields have the same grid and the right number of values.
ScalarField csg(const ScalarField& a, const ScalarField& b, CsgOp op);

// The same on occupancy: a | b, a & b, a & ~b, with a's brick size. Throws GridError unless the
// grids match.
SparseVoxels csg(const SparseVoxels& a, const SparseVoxels& b, CsgOp op);

// One grid fitted (as fit_grid(mesh, fit)) to the union of both meshes' boxes, so their fields
// can be combined.
Grid fit_grid(const Mesh& a, const Mesh& b, const GridFit& fit);

// CSG of two meshes: csg(signed_distance(a), signed_distance(b), op) on `grid` (usually
// fit_grid(a, b, fit)), holding two fields at a time rather than three. options.progress sees
// both fields as one run. stats: a's, with b's triangle and work item counts and timings added.
// The device result equals csg_reference bit for bit.
ScalarField csg(Device& device, const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                const SdfOptions& options, VoxelizeStats* stats = nullptr);
ScalarField csg_reference(const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                          const SdfOptions& options, VoxelizeStats* stats = nullptr);

// CSG of two sparse fields with the same band, leaf by leaf: the leaves of either field, combined
// sample by sample as above, and the inside voxels combined by the same operation on occupancy
// (which is what the rule gives away from both fields' leaves). On the same grid its to_dense()
// equals csg(a.to_dense(), b.to_dense(), op) bit for bit. Grids on one voxel lattice (the same
// voxel size, origins a whole number of voxels apart, as two OpenVDB level sets with one transform
// are) give a field on the box of both, where every sample beyond a field's own grid counts as
// +background (outside it). Throws GridError for other grids or bands.
SparseField csg(const SparseField& a, const SparseField& b, CsgOp op);

// CSG of two meshes through their sparse narrow-band fields (signed_distance_sparse; options as
// there, but not layers), with one progress over both. Its to_dense() equals csg's dense field of
// the same meshes bit for bit; the device result equals the reference's.
SparseField csg_sparse(Device& device, const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                       const SdfOptions& options, VoxelizeStats* stats = nullptr);
SparseField csg_sparse_reference(const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                                 const SdfOptions& options, VoxelizeStats* stats = nullptr);

// ---------------------------------------------------------------------------------------------
// Field files
// ---------------------------------------------------------------------------------------------
// By extension (case-insensitive):
//  .npy  float32, shape (nx, ny, nz), Fortran order, so arr[i, j, k] is voxel (i, j, k); plus
//        `<path>.json` with origin, voxel size, dims, where samples are (voxel centres), the sign
//        convention and the band;
//  .vdb  an OpenVDB level set (FloatGrid, class GRID_LEVEL_SET, named "sdf") in world units,
//        its transform placing voxel (i, j, k)'s sample at the centre of the voxel, background
//        band * voxel_size; only samples with |value| < background are stored.
// band_voxels <= 0 takes the band as the largest |value| / voxel_size, which is the band of a
// narrow-band field. Written to a temporary file and renamed into place; throws OutputError.
// `progress` as for write_voxels: the fraction written, the last call before the file takes its
// name, false throwing Cancelled and leaving no file.
void write_field(const std::string& path, const ScalarField& field, double band_voxels = 0,
                 const ProgressCallback& progress = {});
// The same files from a field given a layer at a time, for fields too large to hold (a full grid
// computed a slab of layers at a time, SdfOptions::first_layer): layer(k, out) puts the samples
// of layer k (grid.dims[0] * grid.dims[1], x fastest) into out, and is called for k = 0, 1, ...
// in order. band_voxels <= 0 takes the largest |value| written. The files equal those of
// write_field for the whole field; .npy holds one layer, .vdb a leaf's 8 (and its tree, which with
// band_voxels <= 0 holds every sample until the band is known).
void write_field(const std::string& path, const Grid& grid, double band_voxels,
                 const FieldLayer& layer, const ProgressCallback& progress = {});
// The same files from a sparse field, its band the field's background / voxel_size: .vdb straight
// from the leaves, .npy streamed a layer at a time (one layer in memory, never the dense field).
// Both files equal those write_field writes for field.to_dense().
void write_field(const std::string& path, const SparseField& field,
                 const ProgressCallback& progress = {});

// Reads a .npy file with its JSON sidecar `<path>.json`: a field (float32 or float64, as
// write_field writes) or an occupancy (uint8 or bool, 0 or 1, as write_voxels writes), 3-D, in
// either order. The sidecar must give origin (the corner of voxel (0,0,0)) and voxel_size; dims,
// if present, must equal the array's shape. Before anything is allocated for the data, the header
// is parsed strictly, the data length its shape implies must be exactly what the file holds, and
// the result must fit half the physical memory. Throws InputError naming the file and the
// problem, and no other exception.
std::variant<ScalarField, SparseVoxels> read_npy(const std::string& path);

// read_npy for a field only: an occupancy .npy is an InputError.
ScalarField read_field(const std::string& path);

// A .npy field read a layer at a time (k = 0, 1, ...: grid.dims[0] * grid.dims[1] samples, x
// fastest), so that a field larger than memory can be meshed (MeshingViewBuilder) or combined
// and written (write_field with a FieldLayer). Opening checks the header, the data length and the
// sidecar as read_npy does. Fortran-order files (as write_field writes them) hold each layer's
// samples together and are streamed, one layer in memory. C-order files (numpy's default) spread
// a layer over the whole file, so they are read in slabs of layers of up to a quarter of the host
// memory budget, the whole file read once per slab: a file of up to that size is read once, a
// larger one several times, with one slab in memory.
class FieldLayerReader {
  public:
    // Throws InputError naming the file and the problem, also for an occupancy .npy.
    explicit FieldLayerReader(const std::string& path);
    ~FieldLayerReader();
    FieldLayerReader(FieldLayerReader&&) noexcept;
    FieldLayerReader& operator=(FieldLayerReader&&) noexcept;

    const Grid& grid() const;
    // Fills `samples` with the next layer. Throws InputError naming the file when the file ends
    // early (it changed since it was opened) or after the last layer.
    void read_layer(float* samples);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The meshing view at iso (MeshingViewBuilder, oclvox/field.hpp) of a .npy field read a layer at a
// time: surface_nets and marching_cubes of it give the field's mesh bit for bit, with memory for
// the view (the leaves near the iso-surface, the inside bits) instead of the field. Throws as
// FieldLayerReader and MeshingViewBuilder do; `progress` as for write_field (the fraction of the
// layers read; false throws Cancelled).
SparseField read_meshing_view(const std::string& path, float iso,
                              const ProgressCallback& progress = {});

// Whether a .npy file holds a field (float samples) rather than an occupancy (uint8), from its
// header alone. Throws InputError as read_npy does for a file it cannot read.
bool npy_holds_field(const std::string& path);

// Reads an OpenVDB level set (.vdb) as a sparse field, without a dense copy: the FloatGrid named
// "sdf" (as write_field writes), else the file's only float grid of class level set. Its leaves
// become the field's leaves (every value, active or not), its tiles below zero and its leaves'
// values below zero the inside voxels, and the band is its background / voxel size. Files
// write_field wrote keep their grid (from their oclvox metadata), so a field written and read
// back meshes to the same surface; for other files the grid is the box of the leaves and inside
// tiles, one voxel wider on every side, aligned to their leaves, with the file's voxel size and
// placement. Throws InputError naming the file and the problem: not a readable .vdb, no such grid,
// a transform other than axis-aligned cubic voxels, a background that is not positive, active
// tiles, non-finite values, or a field beyond the host memory budget.
SparseField read_sparse_field(const std::string& path);
// The same level set on the voxel lattice of `lattice` (its voxel size, and voxel centres a whole
// number of voxels from its own) with a band of band_voxels of those voxels, so that it combines
// with the fields there (csg). A level set already on that lattice with that background is read
// as above; any other is rebuilt there by OpenVDB's tools::levelSetRebuild (its zero level set
// polygonized, one point per cell at the mean of its edge crossings, and the exact narrow band of
// that polygon surface taken on the lattice), so its values are no longer exact distances to the
// file's surface: the polygonization moves a convex surface inwards by about h^2 / (2 R) for the
// file's voxel size h and a radius of curvature R (on a sphere of 10.6 voxels' radius, within 1.5
// voxels of the surface: 0.036 of the file's voxels on average, 0.13 at worst). Throws as
// read_sparse_field, and GridError for an invalid lattice or band.
SparseField read_sparse_field(const std::string& path, const Grid& lattice, double band_voxels);

}  // namespace oclvox

#pragma GCC visibility pop
