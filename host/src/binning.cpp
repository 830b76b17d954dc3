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

// The grid's bricks, with what every triangle's binning needs worked out once (two 64-bit
// divisions per triangle were a sixth of binning's time).
struct BrickGrid {
    BrickGrid(const Grid& grid, int brick_size)
        : grid(grid),
          size(brick_size),
          divider(brick_size),
          nbx((grid.dims[0] + brick_size - 1) / brick_size),
          nby((grid.dims[1] + brick_size - 1) / brick_size) {}
    uint64_t index(int64_t bx, int64_t by, int64_t bz) const {
        return uint64_t(bx + nbx * (by + nby * bz));
    }
    const Grid& grid;
    int size;
    BrickDivider divider;
    int64_t nbx, nby;
};

// Bricks overlapped by the triangle's voxel range clipped to the grid; false if it misses the grid.
bool brick_range(const OvRange& r, const BrickGrid& bricks, BrickRange& out) {
    for (int k = 0; k < 3; ++k) {
        const int64_t lo = std::max<int64_t>(r.lo[k], 0);
        const int64_t hi = std::min<int64_t>(r.hi[k], bricks.grid.dims[k] - 1);
        if (lo > hi) return false;
        out.lo[k] = bricks.divider(uint32_t(lo));
        out.hi[k] = bricks.divider(uint32_t(hi));
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

// Whether the triangle of voxel range r, whose bricks b span several bricks along one axis only,
// meets every one of them, so that the cull would keep them all. It does when its voxel range
// along the other two axes lies within the grid (unclipped): then the triangle lies within that
// row of bricks across those axes (a voxel range starts at or below the triangle's minimum and
// ends less than one voxel below its maximum), and, being connected, it meets every slab of the
// row along the spanning axis that its range reaches. Most multi-brick triangles just cross one
// brick face, and the cull was half of binning them.
bool meets_every_brick_of_row(const OvRange& r, const BrickRange& b, const Grid& grid) {
    int spanning = 0;
    bool within = true;
    for (int k = 0; k < 3; ++k) {
        if (b.lo[k] != b.hi[k])
            ++spanning;
        else
            within = within && r.lo[k] >= 0 && r.hi[k] <= grid.dims[k] - 1;
    }
    return spanning == 1 && within;
}

// Calls f(brick index) for every brick triangle t may touch: those its voxel range overlaps, less
// (for a triangle spanning several bricks, unless it spans a row that it meets every brick of)
// those the double-precision test on the brick box grown by cull_margin proves it misses.
template <class F>
void for_each_brick_of(const PreparedTriangles& prepared, size_t t, const BrickGrid& bricks,
                       F&& f) {
    BrickRange b;
    if (!brick_range(prepared.ranges[t], bricks, b)) return;
    if (b.count() == 1) {  // most triangles: nothing to cull
        f(bricks.index(b.lo[0], b.lo[1], b.lo[2]));
        return;
    }
    if (meets_every_brick_of_row(prepared.ranges[t], b, bricks.grid)) {
        for (int64_t bz = b.lo[2]; bz <= b.hi[2]; ++bz)
            for (int64_t by = b.lo[1]; by <= b.hi[1]; ++by)
                for (int64_t bx = b.lo[0]; bx <= b.hi[0]; ++bx) f(bricks.index(bx, by, bz));
        return;
    }
    const OvTriangle& tri = prepared.triangles[t];
    Vec3d v[3];
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) v[i][k] = double(tri.anchor[k]) + double(tri.u[3 * i + k]);
    const double margin = cull_margin(tri);
    const int brick_size = bricks.size;
    for (int64_t bz = b.lo[2]; bz <= b.hi[2]; ++bz)
        for (int64_t by = b.lo[1]; by <= b.hi[1]; ++by)
            for (int64_t bx = b.lo[0]; bx <= b.hi[0]; ++bx) {
                const Vec3d lo{double(bx * brick_size) - margin, double(by * brick_size) - margin,
                               double(bz * brick_size) - margin};
                const Vec3d hi{double((bx + 1) * brick_size) + margin,
                               double((by + 1) * brick_size) + margin,
                               double((bz + 1) * brick_size) + margin};
                if (triangle_box_overlap_double(v[0], v[1], v[2], lo, hi))
                    f(bricks.index(bx, by, bz));
            }
}

// The (triangle, brick) pairs of the triangles' brick ranges, counted per chunk of kChunk
// triangles (in parallel: a sum of integers is the same in any order); throws GridError if their
// total is over max_pairs. A triangle's range meets at most every brick of the grid, so when
// triangles x bricks is within max_pairs the limit cannot be passed: then nothing is counted and
// the result is empty (the count is a pass over every range: at 1024^3 a quarter of binning
// buildings' 400k triangles).
constexpr size_t kChunk = 8192;

std::vector<uint64_t> candidate_pairs(const PreparedTriangles& prepared, const Grid& grid,
                                      int brick_size, uint64_t max_pairs) {
    uint64_t bricks = 1;
    for (int k = 0; k < 3; ++k) bricks *= uint64_t((grid.dims[k] + brick_size - 1) / brick_size);
    if (bricks <= max_pairs / std::max<uint64_t>(prepared.ranges.size(), 1)) return {};
    const size_t chunks = (prepared.ranges.size() + kChunk - 1) / kChunk;
    std::vector<uint64_t> candidates(chunks, 0);
    const BrickGrid brick_grid(grid, brick_size);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        const size_t end = std::min(prepared.ranges.size(), (c + 1) * kChunk);
        for (size_t t = c * kChunk; t < end; ++t) {
            BrickRange b;
            if (brick_range(prepared.ranges[t], brick_grid, b)) candidates[c] += b.count();
        }
    });
    uint64_t total = 0;
    for (const uint64_t n : candidates) total += n;
    if (total > max_pairs)
        throw GridError("binning would examine " + std::to_string(total) +
                        " (triangle, brick) pairs, more than the limit of " +
                        std::to_string(max_pairs) + ": lower the resolution or use larger bricks");
    return candidates;
}

// One chunk's pairs in ascending triangle order, as their triangles and the slots of their
// bricks among the chunk's distinct bricks, which are kept in order of first appearance with their
// pair counts. Consecutive pairs mostly share a brick (meshes are stored coherently), so the last
// brick's slot is remembered before the map is asked.
struct ChunkPairs {
    std::vector<uint32_t> triangles;
    std::vector<uint32_t> slots;
    std::vector<uint64_t> bricks;
    std::vector<uint64_t> counts;

    void add(uint64_t brick, uint32_t triangle) {
        if (triangles.empty() || brick != last_brick) {
            const auto [it, fresh] = slot_of_brick.try_emplace(brick, uint32_t(bricks.size()));
            if (fresh) {
                bricks.push_back(brick);
                counts.push_back(0);
            }
            last_brick = brick;
            last_slot = it->second;
        }
        triangles.push_back(triangle);
        slots.push_back(last_slot);
        ++counts[last_slot];
    }

  private:
    std::unordered_map<uint64_t, uint32_t> slot_of_brick;
    uint64_t last_brick = 0;
    uint32_t last_slot = 0;
};

}  // namespace

Binning bin_triangles(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                      const BrickSelection& selection, uint64_t max_pairs) {
    // Phase 1: refuse absurd work before allocating any of it.
    const std::vector<uint64_t> candidates = candidate_pairs(prepared, grid, brick_size, max_pairs);

    // Phase 2: each chunk's (brick, triangle) pairs in the selected bricks, culling bricks of
    // multi-brick triangles, and its distinct bricks; chunks in parallel.
    const size_t chunks = (prepared.ranges.size() + kChunk - 1) / kChunk;
    std::vector<ChunkPairs> chunk(chunks);
    const BrickGrid bricks(grid, brick_size);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        ChunkPairs& out = chunk[c];
        // Room for the usual pairs (pages not written cost nothing); the candidates of large
        // triangles can be far more than the pairs their cull keeps, and a selection keeps fewer
        // still.
        const size_t room =
            candidates.empty() ? 2 * kChunk : size_t(std::min<uint64_t>(candidates[c], 2 * kChunk));
        out.triangles.reserve(room);
        out.slots.reserve(room);
        const size_t end = std::min(prepared.ranges.size(), (c + 1) * kChunk);
        for (size_t t = c * kChunk; t < end; ++t)
            for_each_brick_of(prepared, t, bricks, [&](uint64_t brick) {
                if (selection.everything() || selection.contains(brick))
                    out.add(brick, uint32_t(t));
            });
    });

    // Phase 3: the active bricks in ascending order, and where each chunk's pairs of each brick
    // go: bricks in order, and within a brick chunk after chunk, so triangles stay ascending (the
    // order sorting the pairs would give, whatever the threads). Only the chunks' few distinct
    // bricks are visited here.
    Binning out;
    for (const ChunkPairs& part : chunk)
        out.bricks.insert(out.bricks.end(), part.bricks.begin(), part.bricks.end());
    std::sort(out.bricks.begin(), out.bricks.end());
    out.bricks.erase(std::unique(out.bricks.begin(), out.bricks.end()), out.bricks.end());
    auto rank = [&](uint64_t brick) {
        return size_t(std::lower_bound(out.bricks.begin(), out.bricks.end(), brick) -
                      out.bricks.begin());
    };
    out.brick_first_pair.assign(out.bricks.size() + 1, 0);
    for (const ChunkPairs& part : chunk)
        for (size_t i = 0; i < part.bricks.size(); ++i)
            out.brick_first_pair[rank(part.bricks[i]) + 1] += part.counts[i];
    for (size_t b = 0; b < out.bricks.size(); ++b)
        out.brick_first_pair[b + 1] += out.brick_first_pair[b];
    // chunk_next[c][i]: where chunk c's next pair of its i-th distinct brick goes.
    std::vector<std::vector<uint64_t>> chunk_next(chunks);
    std::vector<uint64_t> next(out.brick_first_pair.begin(), out.brick_first_pair.end() - 1);
    for (size_t c = 0; c < chunks; ++c)
        for (size_t i = 0; i < chunk[c].bricks.size(); ++i) {
            uint64_t& brick_next = next[rank(chunk[c].bricks[i])];
            chunk_next[c].push_back(brick_next);
            brick_next += chunk[c].counts[i];
        }

    // Phase 4: every chunk writes its triangles to their places, in parallel.
    out.pair_triangle.resize(out.brick_first_pair.back());
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        const ChunkPairs& part = chunk[c];
        std::vector<uint64_t>& place = chunk_next[c];
        for (size_t p = 0; p < part.triangles.size(); ++p)
            out.pair_triangle[place[part.slots[p]]++] = part.triangles[p];
    });
    return out;
}

void for_each_triangle_brick(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                             const std::function<void(uint32_t, uint64_t)>& f, uint64_t max_pairs) {
    candidate_pairs(prepared, grid, brick_size, max_pairs);
    const BrickGrid bricks(grid, brick_size);
    for (size_t t = 0; t < prepared.triangles.size(); ++t)
        for_each_brick_of(prepared, t, bricks, [&](uint64_t brick) { f(uint32_t(t), brick); });
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
