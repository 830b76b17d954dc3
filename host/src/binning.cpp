// Triangle-to-brick binning. A triangle goes to every brick its voxel range overlaps, except the
// bricks that a double-precision SAT test on the brick box (grown by a margin well above float
// rounding) proves it cannot touch: a large slanted triangle then costs the bricks along its
// surface, not the whole volume of its bounding box.
#include "binning.hpp"

#include <algorithm>
#include <cmath>

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
bool brick_range(const OvRange& r, const Grid& grid, int brick_size, BrickRange& out) {
    for (int k = 0; k < 3; ++k) {
        const int64_t lo = std::max<int64_t>(r.lo[k], 0);
        const int64_t hi = std::min<int64_t>(r.hi[k], grid.dims[k] - 1);
        if (lo > hi) return false;
        out.lo[k] = lo / brick_size;
        out.hi[k] = hi / brick_size;
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

}  // namespace

Binning bin_triangles(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                      uint64_t max_pairs) {
    const int64_t nbx = (grid.dims[0] + brick_size - 1) / brick_size;
    const int64_t nby = (grid.dims[1] + brick_size - 1) / brick_size;

    // Phase 1: refuse absurd work before allocating any of it.
    uint64_t candidates = 0;
    for (const OvRange& r : prepared.ranges) {
        BrickRange b;
        if (brick_range(r, grid, brick_size, b)) candidates += b.count();
    }
    if (candidates > max_pairs)
        throw GridError("binning would examine " + std::to_string(candidates) +
                        " (triangle, brick) pairs, more than the limit of " +
                        std::to_string(max_pairs) + ": lower the resolution or use larger bricks");

    // Phase 2: (brick, triangle) pairs, culling bricks of multi-brick triangles.
    std::vector<std::pair<uint64_t, uint32_t>> pairs;
    pairs.reserve(candidates);
    for (size_t t = 0; t < prepared.ranges.size(); ++t) {
        BrickRange b;
        if (!brick_range(prepared.ranges[t], grid, brick_size, b)) continue;
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
                    pairs.emplace_back(uint64_t(bx + nbx * (by + nby * bz)), uint32_t(t));
                }
    }

    // Phase 3: group by brick (sorted, so every run is deterministic).
    std::sort(pairs.begin(), pairs.end());
    Binning out;
    out.pair_triangle.reserve(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) {
        if (i == 0 || pairs[i].first != pairs[i - 1].first) {
            out.bricks.push_back(pairs[i].first);
            out.brick_first_pair.push_back(i);
        }
        out.pair_triangle.push_back(pairs[i].second);
    }
    out.brick_first_pair.push_back(pairs.size());
    return out;
}

}  // namespace oclvox::detail
