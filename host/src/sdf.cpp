// Distance fields: the host reference of the band and jump-flooding passes (the same shared math
// and the same order-independent minima as kernels/sdf.cl, so the device must match it bit for
// bit), the conversion to world units, and the sign from the solid voxelization.
#include <chrono>
#include <cmath>
#include <cstring>

#include "host_memory.hpp"
#include "sdf_internal.hpp"

namespace oclvox {

namespace detail {

namespace {

// Dense fields are held on the host (and on the device as 32-bit words); beyond this many
// voxels the run is refused up front instead of failing in an allocation.
constexpr uint64_t kMaxFieldVoxels = uint64_t(1) << 32;

double seconds_since(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

size_t voxel_index(const Grid& grid, int i, int j, int k) {
    return size_t(i) + size_t(grid.dims[0]) * (size_t(j) + size_t(grid.dims[1]) * size_t(k));
}

// The band pass: per voxel the least squared distance below band2 and, for full-grid fields,
// the lowest triangle index attaining it (what band_distance and band_nearest leave behind).
void band_pass(const SdfTriangles& prepared, const Grid& grid, std::vector<float>& distance2,
               std::vector<uint32_t>* nearest) {
    for (size_t index = 0; index < prepared.triangles.size(); ++index) {
        const OvSdfTriangle& t = prepared.triangles[index];
        for (int bz = t.lo[2] / 4 * 4; bz <= t.hi[2]; bz += 4)
            for (int by = t.lo[1] / 4 * 4; by <= t.hi[1]; by += 4)
                for (int bx = t.lo[0] / 4 * 4; bx <= t.hi[0]; bx += 4) {
                    if (!ov_block_near(&t, bx, by, bz, prepared.band)) continue;
                    for (int k = std::max(bz, t.lo[2]); k <= std::min(bz + 3, t.hi[2]); ++k)
                        for (int j = std::max(by, t.lo[1]); j <= std::min(by + 3, t.hi[1]); ++j)
                            for (int i = std::max(bx, t.lo[0]); i <= std::min(bx + 3, t.hi[0]);
                                 ++i) {
                                if (!ov_voxel_near(&t, i, j, k, prepared.band)) continue;
                                const float d2 = ov_voxel_distance2(&t, i, j, k);
                                if (!(d2 < prepared.band2)) continue;
                                const size_t v = voxel_index(grid, i, j, k);
                                if (d2 < distance2[v]) {
                                    distance2[v] = d2;
                                    if (nearest) (*nearest)[v] = uint32_t(index);
                                } else if (nearest && d2 == distance2[v]) {
                                    (*nearest)[v] = std::min((*nearest)[v], uint32_t(index));
                                }
                            }
                }
    }
}

// One jump-flooding pass, as the jump kernel: the nearest (lowest index on ties) of the triangles
// known to the voxel itself and to its 26 neighbours `step` voxels away.
void jump_pass(const SdfTriangles& prepared, const Grid& grid, int step,
               const std::vector<uint32_t>& nearest_in, std::vector<uint32_t>& nearest_out,
               std::vector<float>& distance2) {
    const int nx = int(grid.dims[0]), ny = int(grid.dims[1]), nz = int(grid.dims[2]);
    for (int k = 0; k < nz; ++k)
        for (int j = 0; j < ny; ++j)
            for (int i = 0; i < nx; ++i) {
                const size_t v = voxel_index(grid, i, j, k);
                uint32_t best = nearest_in[v];
                float best_d2 = INFINITY;
                if (best != kNoTriangle)
                    best_d2 = ov_voxel_distance2(&prepared.triangles[best], i, j, k);
                for (int dz = -1; dz <= 1; ++dz)
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            const int a = i + dx * step, b = j + dy * step, c = k + dz * step;
                            if (a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz) continue;
                            const uint32_t candidate = nearest_in[voxel_index(grid, a, b, c)];
                            if (candidate == kNoTriangle || candidate == best) continue;
                            const float d2 =
                                ov_voxel_distance2(&prepared.triangles[candidate], i, j, k);
                            if (d2 < best_d2 || (d2 == best_d2 && candidate < best)) {
                                best = candidate;
                                best_d2 = d2;
                            }
                        }
                nearest_out[v] = best;
                if (best != kNoTriangle) distance2[v] = best_d2;
            }
}

}  // namespace

void validate_sdf(const Grid& grid, const SdfOptions& options, uint64_t host_bytes_per_voxel) {
    validate_grid(grid);
    if (!(options.band_voxels > 0) || !std::isfinite(options.band_voxels) ||
        options.band_voxels > double(kMaxGridAxis))
        throw GridError("the distance band must be a positive number of voxels up to " +
                        std::to_string(kMaxGridAxis) + ", got " +
                        std::to_string(options.band_voxels));
    if (grid.voxel_count() > kMaxFieldVoxels)
        throw GridError("a dense distance field of " + std::to_string(grid.voxel_count()) +
                        " voxels is over the limit of " + std::to_string(kMaxFieldVoxels) +
                        ": lower the resolution");
    check_host_memory(
        grid.voxel_count() * host_bytes_per_voxel, host_budget(options.host_budget_bytes),
        "a dense distance field of " + std::to_string(grid.dims[0]) + "x" +
            std::to_string(grid.dims[1]) + "x" + std::to_string(grid.dims[2]) + " voxels (" +
            std::to_string(host_bytes_per_voxel) + " bytes per voxel with its working copies)");
}

std::vector<int> jump_steps(const Grid& grid) {
    const int64_t longest = std::max({grid.dims[0], grid.dims[1], grid.dims[2]});
    int step = 1;
    while (int64_t(step) * 2 < longest) step *= 2;
    std::vector<int> steps;
    for (; step >= 1; step /= 2) steps.push_back(step);
    steps.push_back(1);
    return steps;
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

void apply_sign(ScalarField& field, const SparseVoxels& inside) {
    // Straight from the bricks' 4x4x4 block masks: no dense copy of the solid, and the work
    // follows the inside voxels, not the grid.
    const auto nbricks = inside.brick_dims();
    const int64_t size = inside.brick_size(), nb = inside.blocks_per_brick_axis();
    const int64_t nx = field.grid.dims[0], ny = field.grid.dims[1];
    float* values = field.values.data();
    for (const auto& [index, blocks] : inside.bricks()) {
        const int64_t bx = int64_t(index % uint64_t(nbricks[0]));
        const int64_t by = int64_t(index / uint64_t(nbricks[0]) % uint64_t(nbricks[1]));
        const int64_t bz = int64_t(index / (uint64_t(nbricks[0]) * uint64_t(nbricks[1])));
        for (size_t w = 0; w < blocks.size(); ++w) {
            const uint64_t mask = blocks[w];
            if (!mask) continue;
            const int64_t ox = bx * size + int64_t(w % nb) * 4;
            const int64_t oy = by * size + int64_t(w / nb % nb) * 4;
            const int64_t oz = bz * size + int64_t(w / (nb * nb)) * 4;
            for (int bit = 0; bit < 64; ++bit)
                if (mask >> bit & 1) {
                    float& v =
                        values[(ox + bit % 4) + nx * ((oy + bit / 4 % 4) + ny * (oz + bit / 16))];
                    v = -v;
                }
        }
    }
}

}  // namespace detail

int64_t field_padding(double band_voxels) {
    if (!(band_voxels > 0) || !(band_voxels < double(kMaxGridAxis)))
        throw GridError("band must be a positive number of voxels below 2^20, got " +
                        std::to_string(band_voxels));
    return int64_t(std::ceil(band_voxels)) + 1;
}

ScalarField unsigned_distance_reference(const Mesh& mesh, const Grid& grid,
                                        const SdfOptions& options, VoxelizeStats* stats_out) {
    VoxelizeStats stats;
    // Phase 1: validate and prepare. The squared distances and the field made from them, and for
    // full-grid fields two buffers of nearest triangles, are held at once.
    auto t = std::chrono::steady_clock::now();
    detail::validate_sdf(grid, options, options.full_grid ? 16 : 8);
    const detail::SdfTriangles prepared =
        detail::prepare_sdf_triangles(mesh, grid, options.band_voxels);
    stats.triangles_in = mesh.triangles.size();
    stats.triangles_used = prepared.triangles.size();
    stats.work_items = prepared.first_item.back();
    stats.seconds_binning = detail::seconds_since(t);

    // Phase 2: the band; then, for full-grid fields, the jump flood from it.
    t = std::chrono::steady_clock::now();
    std::vector<float> distance2(size_t(grid.voxel_count()), prepared.band2);
    std::vector<uint32_t> nearest, scratch;
    if (options.full_grid) nearest.assign(distance2.size(), detail::kNoTriangle);
    detail::band_pass(prepared, grid, distance2, options.full_grid ? &nearest : nullptr);
    if (options.full_grid) {
        scratch.resize(nearest.size());
        for (int step : detail::jump_steps(grid)) {
            detail::jump_pass(prepared, grid, step, nearest, scratch, distance2);
            nearest.swap(scratch);
        }
    }
    stats.seconds_kernels = detail::seconds_since(t);

    if (stats_out) *stats_out = stats;
    return detail::distance_field(grid, options, prepared, distance2);
}

ScalarField signed_distance_reference(const Mesh& mesh, const Grid& grid, const SdfOptions& options,
                                      VoxelizeStats* stats_out) {
    VoxelizeStats stats, solid_stats;
    ScalarField field = unsigned_distance_reference(mesh, grid, options, &stats);
    VoxelizeOptions solid;
    solid.mode = VoxelizeMode::Solid;
    solid.inside = options.inside;
    solid.brick_size = options.brick_size;
    solid.host_budget_bytes = options.host_budget_bytes;
    detail::apply_sign(field, voxelize_reference(mesh, grid, solid, &solid_stats));
    stats.seconds_binning += solid_stats.seconds_binning;
    stats.seconds_kernels += solid_stats.seconds_kernels;
    stats.voxels_set = solid_stats.voxels_set;
    stats.inside_test = solid_stats.inside_test;
    stats.inside_test_reason = solid_stats.inside_test_reason;
    if (stats_out) *stats_out = stats;
    return field;
}

ScalarField signed_distance(Device& device, const Mesh& mesh, const Grid& grid,
                            const SdfOptions& options, VoxelizeStats* stats_out) {
    VoxelizeStats stats, solid_stats;
    ScalarField field = unsigned_distance(device, mesh, grid, options, &stats);
    VoxelizeOptions solid;
    solid.mode = VoxelizeMode::Solid;
    solid.inside = options.inside;
    solid.brick_size = options.brick_size;
    solid.host_budget_bytes = options.host_budget_bytes;
    detail::apply_sign(field, device.voxelize(mesh, grid, solid, &solid_stats));
    stats.seconds_binning += solid_stats.seconds_binning;
    stats.seconds_upload += solid_stats.seconds_upload;
    stats.seconds_kernels += solid_stats.seconds_kernels;
    stats.seconds_download += solid_stats.seconds_download;
    stats.allocation_retries += solid_stats.allocation_retries;
    stats.voxels_set = solid_stats.voxels_set;
    stats.inside_test = solid_stats.inside_test;
    stats.inside_test_reason = solid_stats.inside_test_reason;
    if (stats_out) *stats_out = stats;
    return field;
}

}  // namespace oclvox
