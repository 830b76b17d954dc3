// Triangle preparation: grid coordinates, culling, clipping and the single rounding to float.
#include "prepare.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <exception>

#include "overlap_double.hpp"

namespace oclvox::detail {

namespace {

// Triangles are clipped to the grid box grown by this many voxels on every side. The margin keeps
// the clip's new edges away from every voxel of the grid, so clipping never changes which grid
// voxels a triangle touches.
constexpr double kClipMargin = 1.0;

using Polygon = std::vector<Vec3d>;

// Sutherland-Hodgman against the half-space x[axis] >= bound (sign +1) or <= bound (sign -1).
Polygon clip_against(const Polygon& in, int axis, double bound, double sign) {
    Polygon out;
    for (size_t i = 0; i < in.size(); ++i) {
        const Vec3d& a = in[i];
        const Vec3d& b = in[(i + 1) % in.size()];
        const double da = sign * (a[axis] - bound), db = sign * (b[axis] - bound);
        if (da >= 0) out.push_back(a);
        if ((da >= 0) != (db >= 0)) {
            const double t = da / (da - db);
            Vec3d p;
            for (int k = 0; k < 3; ++k) p[k] = a[k] + t * (b[k] - a[k]);
            p[axis] = bound;  // exactly on the plane, whatever the rounding of t
            out.push_back(p);
        }
    }
    return out;
}

OvTriangle round_to_anchor(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    OvTriangle t;
    for (int k = 0; k < 3; ++k) {
        const double anchor = std::floor(std::min({a[k], b[k], c[k]}));
        t.anchor[k] = int(anchor);
        t.u[k] = float(a[k] - anchor);
        t.u[3 + k] = float(b[k] - anchor);
        t.u[6 + k] = float(c[k] - anchor);
    }
    return t;
}

// Prepares triangle t of the mesh into `out` (none if it misses the grid, several if clipping
// fans it). Throws InputError for a triangle that does not fit grid coordinates.
void prepare_one(const Mesh& mesh, const Grid& grid, double inv, size_t t, PreparedTriangles& out) {
    // Phase 1: grid coordinates, in voxel units, in double.
    Vec3d g[3];
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) {
            g[i][k] = (mesh.positions[mesh.triangles[t][i]][k] - grid.origin[k]) * inv;
            if (!std::isfinite(g[i][k]))
                throw InputError("triangle " + std::to_string(t) +
                                 " does not fit in grid coordinates (the voxel size is too "
                                 "small for its coordinates)");
        }

    // Phase 2: drop triangles whose box cannot touch the closed grid box.
    bool inside_margin = true, misses = false;
    for (int k = 0; k < 3; ++k) {
        const double lo = std::min({g[0][k], g[1][k], g[2][k]});
        const double hi = std::max({g[0][k], g[1][k], g[2][k]});
        misses = misses || hi < 0 || lo > double(grid.dims[k]);
        inside_margin =
            inside_margin && lo >= -kClipMargin && hi <= double(grid.dims[k]) + kClipMargin;
    }
    if (misses) return;
    if (inside_margin) {
        out.triangles.push_back(round_to_anchor(g[0], g[1], g[2]));
        out.source.push_back(uint32_t(t));
        return;
    }

    // Phase 3: clip the rest to the grown grid box and fan the convex remainder.
    Polygon poly{g[0], g[1], g[2]};
    for (int k = 0; k < 3 && !poly.empty(); ++k) {
        poly = clip_against(poly, k, -kClipMargin, +1);
        if (!poly.empty()) poly = clip_against(poly, k, double(grid.dims[k]) + kClipMargin, -1);
    }
    if (poly.empty()) return;
    if (poly.size() < 3) poly.resize(3, poly.back());  // a clipped point or segment
    for (size_t i = 1; i + 1 < poly.size(); ++i) {
        out.triangles.push_back(round_to_anchor(poly[0], poly[i], poly[i + 1]));
        out.source.push_back(uint32_t(t));
    }
}

}  // namespace

PreparedTriangles prepare_triangles(const Mesh& mesh, const Grid& grid, Boundary boundary) {
    validate_mesh(mesh);
    validate_grid(grid);
    // Triangles are independent, so fixed chunks of them are prepared in parallel and joined in
    // chunk order: the result, and the triangle an error names (the first that fails), do not
    // depend on the threads.
    constexpr size_t kChunk = 8192;
    const double inv = 1.0 / grid.voxel_size;
    const size_t chunks = (mesh.triangles.size() + kChunk - 1) / kChunk;
    std::vector<PreparedTriangles> parts(chunks);
    std::vector<std::exception_ptr> errors(chunks);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        try {
            const size_t end = std::min(mesh.triangles.size(), (c + 1) * kChunk);
            for (size_t t = c * kChunk; t < end; ++t) prepare_one(mesh, grid, inv, t, parts[c]);
        } catch (...) {
            errors[c] = std::current_exception();
        }
    });
    for (const std::exception_ptr& error : errors)
        if (error) std::rethrow_exception(error);

    // Joined in chunk order at their offsets, with each triangle's voxel range, in parallel too.
    std::vector<size_t> offset(chunks + 1, 0);
    for (size_t c = 0; c < chunks; ++c) offset[c + 1] = offset[c] + parts[c].triangles.size();
    PreparedTriangles out;
    out.triangles.resize(offset[chunks]);
    out.source.resize(offset[chunks]);
    out.ranges.resize(offset[chunks]);
    const int half_open = boundary == Boundary::HalfOpen;
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        const PreparedTriangles& part = parts[c];
        std::copy(part.triangles.begin(), part.triangles.end(), &out.triangles[offset[c]]);
        std::copy(part.source.begin(), part.source.end(), &out.source[offset[c]]);
        for (size_t i = 0; i < part.triangles.size(); ++i)
            out.ranges[offset[c] + i] = ov_triangle_range(part.triangles[i], half_open);
    });
    return out;
}

}  // namespace oclvox::detail
