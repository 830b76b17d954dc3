// Triangle-to-brick binning. A triangle goes to every brick its voxel range overlaps, except the
// bricks that a double-precision SAT test on the brick box (grown by a margin well above float
// rounding) proves it cannot touch: a large slanted triangle then costs the bricks along its
// surface, not the whole volume of its bounding box.
#include "binning.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "mesh_bounds.hpp"
#include "overlap_double.hpp"

namespace oclvox::detail {

namespace {

struct BrickRange {
    int64_t lo[3], hi[3];
    uint64_t count() const {
        uint64_t n = 1;
        for (int k = 0; k < 3; ++k) n *= uint64_t(hi[k] - lo[k] + 1);
        return n;
    }
};

// Bricks overlapped by the triangle's voxel range clipped to the grid; false if it misses the grid.
bool brick_range(const OvRange& r, const Grid& grid, const BrickDivider& brick, BrickRange& out) {
    for (int k = 0; k < 3; ++k) {
        const int64_t lo = std::max<int64_t>(r.lo[k], 0);
        const int64_t hi = std::min<int64_t>(r.hi[k], grid.dims[k] - 1);
        if (lo > hi) return false;
        out.lo[k] = brick(uint32_t(lo));
        out.hi[k] = brick(uint32_t(hi));
    }
    return true;
}

// The float kernels may set a voxel that touches the triangle only within their rounding, which
// grows with the size of the anchor-relative coordinates; the margin covers that with room.
double cull_margin(const OvTriangle& t) {
    float largest = 0;
    for (float u : t.u) largest = std::max(largest, std::abs(u));
    return 1e-3 + 1e-5 * double(largest);
}

// Calls f(brick index) for every brick triangle t may touch: those its voxel range overlaps, less
// (for a triangle spanning several bricks) those the double-precision test on the brick box
// grown by cull_margin proves it misses.
template <class F>
void for_each_brick_of(const PreparedTriangles& prepared, size_t t, const Grid& grid,
                       int brick_size, const BrickDivider& divider, F&& f) {
    BrickRange b;
    if (!brick_range(prepared.ranges[t], grid, divider, b)) return;
    const int64_t nbx = (grid.dims[0] + brick_size - 1) / brick_size;
    const int64_t nby = (grid.dims[1] + brick_size - 1) / brick_size;
    const bool cull = b.count() > 1;
    const OvTriangle& tri = prepared.triangles[t];
    Vec3d v[3];
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) v[i][k] = double(tri.anchor[k]) + double(tri.u[3 * i + k]);
    const double margin = cull ? cull_margin(tri) : 0;
    for (int64_t bz = b.lo[2]; bz <= b.hi[2]; ++bz)
        for (int64_t by = b.lo[1]; by <= b.hi[1]; ++by)
            for (int64_t bx = b.lo[0]; bx <= b.hi[0]; ++bx) {
                if (cull) {
                    const Vec3d lo{double(bx * brick_size) - margin,
                                   double(by * brick_size) - margin,
                                   double(bz * brick_size) - margin};
                    const Vec3d hi{double((bx + 1) * brick_size) + margin,
                                   double((by + 1) * brick_size) + margin,
                                   double((bz + 1) * brick_size) + margin};
                    if (!triangle_box_overlap_double(v[0], v[1], v[2], lo, hi)) continue;
                }
                f(uint64_t(bx + nbx * (by + nby * bz)));
            }
}

// The (triangle, brick) pairs of the triangles' brick ranges; throws GridError over max_pairs.
uint64_t candidate_pairs(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                         uint64_t max_pairs) {
    uint64_t candidates = 0;
    const BrickDivider brick(brick_size);
    for (const OvRange& r : prepared.ranges) {
        BrickRange b;
        if (brick_range(r, grid, brick, b)) candidates += b.count();
    }
    if (candidates > max_pairs)
        throw GridError("binning would examine " + std::to_string(candidates) +
                        " (triangle, brick) pairs, more than the limit of " +
                        std::to_string(max_pairs) + ": lower the resolution or use larger bricks");
    return candidates;
}

}  // namespace

Binning bin_triangles(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                      const BrickSelection& selection, uint64_t max_pairs) {
    // Phase 1: refuse absurd work before allocating any of it.
    const uint64_t candidates = candidate_pairs(prepared, grid, brick_size, max_pairs);

    // Phase 2: (brick, triangle) pairs of the selected bricks, culling bricks of multi-brick
    // triangles. Triangles are independent, so fixed chunks of them are binned in parallel and
    // their pairs joined in chunk order: the pairs stay in ascending triangle order, whatever the
    // threads.
    constexpr size_t kChunk = 8192;
    const size_t chunks = (prepared.ranges.size() + kChunk - 1) / kChunk;
    std::vector<std::vector<std::pair<uint64_t, uint32_t>>> chunk_pairs(chunks);
    const BrickDivider divider(brick_size);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        auto& out = chunk_pairs[c];
        const size_t end = std::min(prepared.ranges.size(), (c + 1) * kChunk);
        for (size_t t = c * kChunk; t < end; ++t)
            for_each_brick_of(prepared, t, grid, brick_size, divider, [&](uint64_t brick) {
                if (selection.contains(brick)) out.emplace_back(brick, uint32_t(t));
            });
    });
    std::vector<std::pair<uint64_t, uint32_t>> pairs;
    pairs.reserve(selection.everything() ? candidates : 0);
    for (auto& chunk : chunk_pairs) {
        pairs.insert(pairs.end(), chunk.begin(), chunk.end());
        std::vector<std::pair<uint64_t, uint32_t>>().swap(chunk);
    }

    // Phase 3: group by brick in ascending brick order, triangles ascending within a brick: the
    // order sorting the pairs would give, so every run is deterministic. The pairs come in
    // ascending triangle order, so a stable counting sort over the few distinct bricks gives it
    // in linear time. Consecutive pairs mostly share a brick (meshes are stored coherently), so
    // the last brick's slot is remembered before the map is asked.
    std::unordered_map<uint64_t, uint32_t> slot_of_brick;
    std::vector<uint32_t> slot_of_pair(pairs.size());
    uint64_t last_brick = 0;
    uint32_t last_slot = 0;
    for (size_t i = 0; i < pairs.size(); ++i) {
        if (i == 0 || pairs[i].first != last_brick) {
            last_brick = pairs[i].first;
            last_slot =
                slot_of_brick.try_emplace(last_brick, uint32_t(slot_of_brick.size())).first->second;
        }
        slot_of_pair[i] = last_slot;
    }
    Binning out;
    out.bricks.reserve(slot_of_brick.size());
    for (const auto& brick_slot : slot_of_brick) out.bricks.push_back(brick_slot.first);
    std::sort(out.bricks.begin(), out.bricks.end());
    // Slots were numbered by first appearance; renumber them by brick order, then count.
    std::vector<uint32_t> rank(slot_of_brick.size());
    for (size_t b = 0; b < out.bricks.size(); ++b) rank[slot_of_brick[out.bricks[b]]] = uint32_t(b);
    out.brick_first_pair.assign(out.bricks.size() + 1, 0);
    for (uint32_t& slot : slot_of_pair) {
        slot = rank[slot];
        ++out.brick_first_pair[slot + 1];
    }
    for (size_t b = 0; b < out.bricks.size(); ++b)
        out.brick_first_pair[b + 1] += out.brick_first_pair[b];
    out.pair_triangle.resize(pairs.size());
    std::vector<uint64_t> next(out.brick_first_pair.begin(), out.brick_first_pair.end() - 1);
    for (size_t i = 0; i < pairs.size(); ++i)
        out.pair_triangle[next[slot_of_pair[i]]++] = pairs[i].second;
    return out;
}

void for_each_triangle_brick(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                             const std::function<void(uint32_t, uint64_t)>& f, uint64_t max_pairs) {
    candidate_pairs(prepared, grid, brick_size, max_pairs);
    const BrickDivider divider(brick_size);
    for (size_t t = 0; t < prepared.ranges.size(); ++t)
        for_each_brick_of(prepared, t, grid, brick_size, divider,
                          [&](uint64_t brick) { f(uint32_t(t), brick); });
}

std::vector<uint64_t> touched_bricks(const PreparedTriangles& prepared, const Grid& grid,
                                     int brick_size, uint64_t max_pairs) {
    std::vector<uint64_t> bricks;
    for_each_triangle_brick(
        prepared, grid, brick_size, [&](uint32_t, uint64_t brick) { bricks.push_back(brick); },
        max_pairs);
    std::sort(bricks.begin(), bricks.end());
    bricks.erase(std::unique(bricks.begin(), bricks.end()), bricks.end());
    return bricks;
}

}  // namespace oclvox::detail

namespace oclvox {

std::vector<uint64_t> candidate_bricks(const Mesh& mesh, const Grid& grid,
                                       const VoxelizeOptions& options) {
    const SparseVoxels layout(grid, options.brick_size);  // validates the brick size
    if (options.mode == VoxelizeMode::Surface || options.mode == VoxelizeMode::Thin)
        return detail::touched_bricks(detail::prepare_triangles(mesh, grid, options.boundary), grid,
                                      options.brick_size);

    // Solid voxels have their centres inside the mesh (and Filled's surface voxels touch it), so
    // they lie in the voxels meeting its bounding box; one voxel more on each side covers the
    // rounding of the box to voxels.
    validate_mesh(mesh);
    validate_grid(grid);
    std::array<double, 3> lo, hi;
    detail::used_bounds(mesh, lo, hi);
    int64_t first[3], last[3];
    uint64_t count = 1;
    for (int k = 0; k < 3; ++k) {
        const double a = std::floor((lo[k] - grid.origin[k]) / grid.voxel_size) - 1;
        const double b = std::floor((hi[k] - grid.origin[k]) / grid.voxel_size) + 1;
        if (b < 0 || a > double(grid.dims[k] - 1)) return {};
        first[k] = int64_t(std::max(a, 0.0)) / options.brick_size;
        last[k] = int64_t(std::min(b, double(grid.dims[k] - 1))) / options.brick_size;
        count *= uint64_t(last[k] - first[k] + 1);
    }
    if (count > uint64_t(1) << 31)
        throw GridError("the mesh's bounding box meets " + std::to_string(count) +
                        " bricks, more than 2^31: use larger bricks");
    const auto nb = layout.brick_dims();
    std::vector<uint64_t> bricks;
    bricks.reserve(count);
    for (int64_t bz = first[2]; bz <= last[2]; ++bz)
        for (int64_t by = first[1]; by <= last[1]; ++by)
            for (int64_t bx = first[0]; bx <= last[0]; ++bx)
                bricks.push_back(uint64_t(bx + nb[0] * (by + nb[1] * bz)));
    return bricks;
}

}  // namespace oclvox
