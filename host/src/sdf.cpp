// Distance fields: the host reference of the band and far passes (the same shared math and the
// same order-independent minima as kernels/sdf.cl, so the device must match it bit for bit), the
// conversion to world units, the sign from the solid voxelization, and the runs of the public
// functions (one field, or two combined by CSG) with their progress, on a device or on the host.
#include <tbb/parallel_for.h>

#include <chrono>
#include <climits>
#include <cmath>
#include <cstring>

#include "host_memory.hpp"
#include "number_text.hpp"
#include "sdf_internal.hpp"

namespace oclvox {

namespace detail {

namespace {

// Dense fields are held on the host (and on the device as 32-bit words); beyond this many
// voxels the run is refused up front instead of failing in an allocation.
constexpr uint64_t kMaxFieldVoxels = uint64_t(1) << 32;

size_t voxel_index(const Grid& grid, int i, int j, int k) {
    return size_t(i) + size_t(grid.dims[0]) * (size_t(j) + size_t(grid.dims[1]) * size_t(k));
}

// The band pass: per voxel the least squared distance below band2.
void band_pass(const SdfTriangles& prepared, const Grid& grid, std::vector<float>& distance2,
               ProgressPhases& progress, size_t phase) {
    const uint64_t items = prepared.first_item.back();
    for (size_t index = 0; index < prepared.triangles.size(); ++index) {
        const OvSdfTriangle& t = prepared.triangles[index];
        for_each_near_block(t, prepared.band, [&](int bx, int by, int bz) {
            for_each_band_sample(t, bx, by, bz, prepared.band, prepared.band2,
                                 [&](int i, int j, int k, float d2) {
                                     float& sample = distance2[voxel_index(grid, i, j, k)];
                                     sample = std::min(sample, d2);
                                 });
        });
        progress.report(phase, prepared.first_item[index + 1], items);
    }
}

// The far pass of full-grid fields, as the far_distances kernel: every voxel the band pass left
// at band2 takes its least squared distance to all the triangles, from the tree. Layer by layer,
// the rows of a layer in parallel.
void far_pass(const SdfTriangles& prepared, const Grid& grid, std::vector<float>& distance2,
              ProgressPhases& progress, size_t phase) {
    const SdfTree tree = build_sdf_tree(prepared.triangles);
    const int nx = int(grid.dims[0]), ny = int(grid.dims[1]), nz = int(grid.dims[2]);
    for (int k = 0; k < nz; ++k) {
        tbb::parallel_for(0, ny, [&](int j) {
            for (int i = 0; i < nx; ++i) {
                float& sample = distance2[voxel_index(grid, i, j, k)];
                if (!(sample < prepared.band2))
                    sample = ov_tree_distance2(tree.nodes.data(), tree.order.data(),
                                               prepared.triangles.data(), i, j, k);
            }
        });
        progress.report(phase, uint64_t(k) + 1, uint64_t(nz));
    }
}

}  // namespace

void validate_sdf_options(const Grid& grid, const SdfOptions& options) {
    validate_grid(grid);
    if (!(options.band_voxels > 0) || !std::isfinite(options.band_voxels) ||
        options.band_voxels > double(kMaxGridAxis))
        throw GridError("the distance band must be a positive number of voxels up to " +
                        std::to_string(kMaxGridAxis) + ", got " +
                        detail::number_text(options.band_voxels));
    const int64_t end = options.end_layer ? options.end_layer : grid.dims[2];
    if (options.first_layer < 0 || options.first_layer >= end || end > grid.dims[2])
        throw GridError("layers " + std::to_string(options.first_layer) + " to " +
                        std::to_string(end) + " are not a range within the grid's " +
                        std::to_string(grid.dims[2]) + " layers");
}

void validate_sdf(const Grid& grid, const SdfOptions& options, uint64_t host_bytes_per_voxel) {
    validate_sdf_options(grid, options);
    const uint64_t voxels = field_grid(grid, options).voxel_count();
    if (voxels > kMaxFieldVoxels)
        throw GridError("a dense distance field of " + std::to_string(voxels) +
                        " voxels is over the limit of " + std::to_string(kMaxFieldVoxels) +
                        ": lower the resolution");
    const Grid layers = field_grid(grid, options);
    check_host_memory(voxels * host_bytes_per_voxel, host_budget(options.host_budget_bytes),
                      "a dense distance field of " + std::to_string(layers.dims[0]) + "x" +
                          std::to_string(layers.dims[1]) + "x" + std::to_string(layers.dims[2]) +
                          " voxels (" + std::to_string(host_bytes_per_voxel) +
                          " bytes per voxel with its working copies)");
}

Grid field_grid(const Grid& grid, const SdfOptions& options) {
    Grid layers = grid;
    layers.origin[2] = grid.origin[2] + double(options.first_layer) * grid.voxel_size;
    layers.dims[2] = (options.end_layer ? options.end_layer : grid.dims[2]) - options.first_layer;
    return layers;
}

void keep_layers(SdfTriangles& prepared, const SdfOptions& options, bool onto_layers) {
    if (options.first_layer == 0 && options.end_layer == 0) return;
    const int first = int(options.first_layer);
    const int last = options.end_layer ? int(options.end_layer) - 1 : INT32_MAX;
    const int shift = onto_layers ? first : 0;
    std::vector<OvSdfTriangle> kept;
    std::vector<uint64_t> first_item{0};
    for (OvSdfTriangle t : prepared.triangles) {
        t.lo[2] = std::max(t.lo[2], first) - shift;
        t.hi[2] = std::min(t.hi[2], last) - shift;
        // A full grid's far pass searches every triangle, so those without a voxel of the
        // layers stay, with an empty range.
        if (t.lo[2] > t.hi[2] && !options.full_grid) continue;
        t.anchor[2] -= shift;
        kept.push_back(t);
        first_item.push_back(first_item.back() + item_count(t));
    }
    prepared.triangles = std::move(kept);
    prepared.first_item = std::move(first_item);
}

ScalarField distance_field(const Grid& grid, const SdfOptions& options,
                           const SdfTriangles& prepared, const std::vector<float>& distance2) {
    ScalarField field;
    field.grid = grid;
    field.values.resize(distance2.size());
    const float background = float(options.band_voxels * grid.voxel_size);
    for (size_t v = 0; v < distance2.size(); ++v) {
        const bool clamped = !options.full_grid && !(distance2[v] < prepared.band2);
        field.values[v] =
            clamped ? background : float(std::sqrt(double(distance2[v])) * grid.voxel_size);
    }
    return field;
}

uint64_t apply_sign(ScalarField& field, const SparseVoxels& inside, int64_t first_layer) {
    // Straight from the bricks' 4x4x4 block masks: no dense copy of the solid, and the work
    // follows the inside voxels, not the grid.
    const auto nbricks = inside.brick_dims();
    const int64_t size = inside.brick_size(), nb = inside.blocks_per_brick_axis();
    const int64_t nx = field.grid.dims[0], ny = field.grid.dims[1];
    const int64_t end_layer = first_layer + field.grid.dims[2];
    float* values = field.values.data();
    const size_t words = inside.blocks_per_brick();
    uint64_t negated = 0;
    for (const uint64_t index : inside.brick_indices()) {
        const uint64_t* blocks = inside.brick_blocks(index);
        const int64_t bx = int64_t(index % uint64_t(nbricks[0]));
        const int64_t by = int64_t(index / uint64_t(nbricks[0]) % uint64_t(nbricks[1]));
        const int64_t bz = int64_t(index / (uint64_t(nbricks[0]) * uint64_t(nbricks[1])));
        for (size_t w = 0; w < words; ++w) {
            const uint64_t mask = blocks[w];
            if (!mask) continue;
            const int64_t ox = bx * size + int64_t(w % nb) * 4;
            const int64_t oy = by * size + int64_t(w / nb % nb) * 4;
            const int64_t oz = bz * size + int64_t(w / (nb * nb)) * 4;
            for (int bit = 0; bit < 64; ++bit) {
                const int64_t z = oz + bit / 16;
                if (mask >> bit & 1 && z >= first_layer && z < end_layer) {
                    float& v =
                        values[(ox + bit % 4) + nx * ((oy + bit / 4 % 4) + ny * (z - first_layer))];
                    v = -v;
                    ++negated;
                }
            }
        }
    }
    return negated;
}

SdfPhases add_sdf_phases(ProgressPhases& progress, const SdfTriangles& prepared, const Grid& grid,
                         const SdfOptions& options, bool sign, bool sparse) {
    // Costs in band work items (a triangle and a 4x4x4 block), as measured through PoCL: a voxel
    // of the far pass (a walk of the tree) about five on bunny00 at 128 (band 0.23 s for 1.1 M
    // items, far pass 1.6 s for 1.6 M voxels, with the per-lane walk of 7ea7718), fewer on smaller
    // meshes, so five; the sign, whose cost follows the surface like the
    // band's, about half the band with the winding number and far less with parity, which is not
    // known before the solid voxelization picks it.
    // The leaves of a sparse field visit the band's items once more, without their samples.
    constexpr double kLeavesCost = 0.2, kFarVoxelCost = 5.0, kSignCost = 0.5;
    const double items = double(prepared.first_item.back());
    SdfPhases phases;
    if (sparse) {
        // A sparse field's sign comes before its band, so that batches of the band become signed
        // leaves as they arrive.
        phases.leaves = progress.add(kLeavesCost * items);
        if (sign) phases.sign = progress.add(kSignCost * items);
        phases.band = progress.add(items);
        return phases;
    }
    phases.band = progress.add(items);
    if (options.full_grid) phases.far = progress.add(kFarVoxelCost * double(grid.voxel_count()));
    if (sign) phases.sign = progress.add(kSignCost * items);
    return phases;
}

std::vector<float> distance2_reference(const SdfTriangles& prepared, const Grid& grid,
                                       const SdfOptions& options, ProgressPhases& progress,
                                       const SdfPhases& phases, VoxelizeStats& stats) {
    // The band; then, for full-grid fields, every voxel beyond it from the tree.
    const auto t = Clock::now();
    std::vector<float> distance2(size_t(grid.voxel_count()), prepared.band2);
    band_pass(prepared, grid, distance2, progress, phases.band);
    if (options.full_grid && !prepared.triangles.empty())
        far_pass(prepared, grid, distance2, progress, phases.far);
    stats.seconds_kernels += seconds_since(t);
    return distance2;
}

namespace {

// The Solid voxelization that signs a field: of the bricks holding the field's layers only.
VoxelizeOptions sign_options(const Grid& grid, const SdfOptions& options) {
    VoxelizeOptions solid;
    solid.mode = VoxelizeMode::Solid;
    solid.inside = options.inside;
    solid.brick_size = options.brick_size;
    solid.host_budget_bytes = options.host_budget_bytes;
    const Grid layers = field_grid(grid, options);
    if (layers.dims[2] == grid.dims[2]) return solid;
    const SparseVoxels layout(grid, options.brick_size);
    const auto nb = layout.brick_dims();
    const uint64_t per_layer = uint64_t(nb[0]) * uint64_t(nb[1]);
    const uint64_t first = uint64_t(options.first_layer / options.brick_size);
    const uint64_t last = uint64_t((options.first_layer + layers.dims[2] - 1) / options.brick_size);
    for (uint64_t brick = first * per_layer; brick < (last + 1) * per_layer; ++brick)
        solid.bricks.push_back(brick);
    return solid;
}

}  // namespace

SparseVoxels sign_voxels(Device* device, const Mesh& mesh, const Grid& grid,
                         const SdfOptions& options, ProgressPhases& progress, size_t phase,
                         VoxelizeStats& stats) {
    VoxelizeOptions solid = sign_options(grid, options);
    solid.progress = progress.forward(phase);
    VoxelizeStats solid_stats;
    SparseVoxels inside = device ? device->voxelize(mesh, grid, solid, &solid_stats)
                                 : voxelize_reference(mesh, grid, solid, &solid_stats);
    stats.seconds_binning += solid_stats.seconds_binning;
    stats.seconds_upload += solid_stats.seconds_upload;
    stats.seconds_kernels += solid_stats.seconds_kernels;
    stats.seconds_download += solid_stats.seconds_download;
    stats.allocation_retries += solid_stats.allocation_retries;
    stats.voxels_set = solid_stats.voxels_set;
    stats.inside_test = solid_stats.inside_test;
    stats.inside_test_reason = solid_stats.inside_test_reason;
    return inside;
}

void add_second_field_stats(VoxelizeStats& stats, const VoxelizeStats& b) {
    stats.triangles_in += b.triangles_in;
    stats.triangles_used += b.triangles_used;
    stats.work_items += b.work_items;
    stats.bricks_total += b.bricks_total;
    stats.bricks_active += b.bricks_active;
    stats.batches += b.batches;
    stats.seconds_binning += b.seconds_binning;
    stats.seconds_upload += b.seconds_upload;
    stats.seconds_kernels += b.seconds_kernels;
    stats.seconds_download += b.seconds_download;
    stats.allocation_retries += b.allocation_retries;
}

FieldJob plan_field(const Mesh& mesh, const Grid& grid, const SdfOptions& options, bool sign,
                    bool sparse, ProgressPhases& progress, VoxelizeStats& stats) {
    const auto t = Clock::now();
    // Prepared on the whole grid, then cut to the layers (so every sample keeps its bits); a
    // sparse field keeps the whole grid's coordinates.
    FieldJob job{
        mesh, prepare_sdf_triangles(mesh, grid, options.band_voxels, options.full_grid), {}};
    keep_layers(job.prepared, options, !sparse);
    job.phases =
        add_sdf_phases(progress, job.prepared, field_grid(grid, options), options, sign, sparse);
    stats.triangles_in = mesh.triangles.size();
    stats.triangles_used = job.prepared.triangles.size();
    stats.work_items = job.prepared.first_item.back();
    stats.seconds_binning += seconds_since(t);
    return job;
}

namespace {

// Where a run computes: the distances and the solid that signs them, on a device or both on the
// host (the reference).
struct OnDevice {
    Device& device;
    // Host bytes per voxel: the squared distances and the field made from them.
    static uint64_t host_bytes_per_voxel(const SdfOptions&) { return 8; }
    std::vector<float> distance2(const SdfTriangles& prepared, const Grid& grid,
                                 const SdfOptions& options, ProgressPhases& progress,
                                 const SdfPhases& phases, VoxelizeStats& stats) const {
        return distance2_device(device, prepared, grid, options, progress, phases, stats);
    }
    Device* solid_device() const { return &device; }
};

struct OnHost {
    // The device's.
    static uint64_t host_bytes_per_voxel(const SdfOptions&) { return 8; }
    std::vector<float> distance2(const SdfTriangles& prepared, const Grid& grid,
                                 const SdfOptions& options, ProgressPhases& progress,
                                 const SdfPhases& phases, VoxelizeStats& stats) const {
        return distance2_reference(prepared, grid, options, progress, phases, stats);
    }
    static Device* solid_device() { return nullptr; }  // voxelize_reference
};

// The job's field, signed by the solid voxelization (with options.inside) when `sign` is set;
// stats add the solid run's timings, its inside test and voxels_set = the inside voxels.
template <class Backend>
ScalarField compute_field(const Backend& backend, const FieldJob& job, const Grid& grid,
                          const SdfOptions& options, bool sign, ProgressPhases& progress,
                          VoxelizeStats& stats) {
    const Grid layers = field_grid(grid, options);
    ScalarField field = distance_field(
        layers, options, job.prepared,
        backend.distance2(job.prepared, layers, options, progress, job.phases, stats));
    if (!sign) return field;
    // The inside voxels of the field's layers (the solid covers its bricks' whole columns).
    stats.voxels_set = apply_sign(field,
                                  sign_voxels(backend.solid_device(), job.mesh, grid, options,
                                              progress, job.phases.sign, stats),
                                  options.first_layer);
    return field;
}

template <class Backend>
ScalarField distance_run(const Backend& backend, const Mesh& mesh, const Grid& grid,
                         const SdfOptions& options, bool sign, VoxelizeStats* stats_out) {
    validate_sdf(grid, options, backend.host_bytes_per_voxel(options));
    ProgressPhases progress(options.progress, sign ? "signed distance field" : "distance field");
    VoxelizeStats stats;
    const FieldJob job = plan_field(mesh, grid, options, sign, false, progress, stats);
    ScalarField field = compute_field(backend, job, grid, options, sign, progress, stats);
    progress.finish();
    if (stats_out) *stats_out = stats;
    return field;
}

template <class Backend>
ScalarField csg_run(const Backend& backend, const Mesh& a, const Mesh& b, CsgOp op,
                    const Grid& grid, const SdfOptions& options, VoxelizeStats* stats_out) {
    // Phase 1: both fields' phases, so that progress runs once over both.
    // Two fields at once.
    validate_sdf(grid, options, 2 * backend.host_bytes_per_voxel(options));
    ProgressPhases progress(options.progress, "CSG");
    VoxelizeStats stats, stats_b;
    const FieldJob job_a = plan_field(a, grid, options, true, false, progress, stats);
    const FieldJob job_b = plan_field(b, grid, options, true, false, progress, stats_b);

    // Phase 2: a's field, b's field combined into it.
    ScalarField field = compute_field(backend, job_a, grid, options, true, progress, stats);
    const ScalarField field_b =
        compute_field(backend, job_b, grid, options, true, progress, stats_b);
    combine_samples(field.values.data(), field_b.values.data(), field.values.size(), op);
    progress.finish();

    add_second_field_stats(stats, stats_b);
    if (stats_out) *stats_out = stats;
    return field;
}

}  // namespace

}  // namespace detail

int64_t field_padding(double band_voxels) {
    if (!(band_voxels > 0) || !(band_voxels < double(kMaxGridAxis)))
        throw GridError("band must be a positive number of voxels below 2^20, got " +
                        detail::number_text(band_voxels));
    return int64_t(std::ceil(band_voxels)) + 1;
}

ScalarField unsigned_distance(Device& device, const Mesh& mesh, const Grid& grid,
                              const SdfOptions& options, VoxelizeStats* stats) {
    return detail::distance_run(detail::OnDevice{device}, mesh, grid, options, false, stats);
}

ScalarField unsigned_distance_reference(const Mesh& mesh, const Grid& grid,
                                        const SdfOptions& options, VoxelizeStats* stats) {
    return detail::distance_run(detail::OnHost{}, mesh, grid, options, false, stats);
}

ScalarField signed_distance(Device& device, const Mesh& mesh, const Grid& grid,
                            const SdfOptions& options, VoxelizeStats* stats) {
    return detail::distance_run(detail::OnDevice{device}, mesh, grid, options, true, stats);
}

ScalarField signed_distance_reference(const Mesh& mesh, const Grid& grid, const SdfOptions& options,
                                      VoxelizeStats* stats) {
    return detail::distance_run(detail::OnHost{}, mesh, grid, options, true, stats);
}

ScalarField csg(Device& device, const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                const SdfOptions& options, VoxelizeStats* stats) {
    return detail::csg_run(detail::OnDevice{device}, a, b, op, grid, options, stats);
}

ScalarField csg_reference(const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                          const SdfOptions& options, VoxelizeStats* stats) {
    return detail::csg_run(detail::OnHost{}, a, b, op, grid, options, stats);
}

}  // namespace oclvox
