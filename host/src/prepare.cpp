// Triangle preparation: grid coordinates, culling, clipping and the single rounding to float.
#include "prepare.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

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

// floor(x) as an int for the coordinates of prepared triangles, which the clip bounds to well
// within int: by truncation, as baseline x86-64 has no instruction for floor.
int floor_to_int(double x) {
    const int i = int(x);
    return x < double(i) ? i - 1 : i;
}

// The triangle rounded to float relative to its anchor, and its voxel range (ov_triangle_range,
// taken from the rounded coordinates while they are in registers: read back from the triangle
// once written, they cost a quarter of preparing, as the loads waited for the stores).
void round_to_anchor(const Vec3d& a, const Vec3d& b, const Vec3d& c, int half_open,
                     OvTriangle& triangle, OvRange& range) {
    for (int k = 0; k < 3; ++k) {
        const int anchor = floor_to_int(std::min({a[k], b[k], c[k]}));
        const float ua = float(a[k] - anchor), ub = float(b[k] - anchor), uc = float(c[k] - anchor);
        triangle.anchor[k] = anchor;
        triangle.u[k] = ua;
        triangle.u[3 + k] = ub;
        triangle.u[6 + k] = uc;
        ov_axis_range(anchor, ua, ub, uc, half_open, &range.lo[k], &range.hi[k]);
    }
}

// Throws for triangle t, which refers to a vertex the mesh lacks or does not fit grid coordinates:
// validate_mesh's error if the mesh is invalid (so the message, and the triangle it names, are
// those of checking the mesh first), else that t does not fit.
[[noreturn]] void throw_unpreparable(const Mesh& mesh, size_t t) {
    validate_mesh(mesh);
    throw InputError("triangle " + std::to_string(t) +
                     " does not fit in grid coordinates (the voxel size is too small for its "
                     "coordinates)");
}

// Triangle t's vertices in grid coordinates (voxel units), in double. Throws InputError for a
// triangle that refers to a missing vertex or (unless told that every vertex is known to be
// finite there: CheckFinite::No) does not fit grid coordinates. Checking here, on the way, spares
// a pass over the mesh that validating it first would cost.
enum class CheckFinite { No, Yes };
inline void grid_coordinates(const Mesh& mesh, const Grid& grid, double inv, size_t t, Vec3d g[3],
                             CheckFinite check = CheckFinite::Yes) {
    bool valid = true;
    for (int i = 0; i < 3; ++i) {
        const uint32_t v = mesh.triangles[t][i];
        if (v >= mesh.positions.size()) throw_unpreparable(mesh, t);
        for (int k = 0; k < 3; ++k) {
            g[i][k] = (mesh.positions[v][k] - grid.origin[k]) * inv;
            if (check == CheckFinite::Yes) valid = valid && std::isfinite(g[i][k]);
        }
    }
    if (!valid) throw_unpreparable(mesh, t);
}

// The triangles that grid triangle g prepares into: none if it misses the closed grid box, itself
// if it lies within the clip margin, else the fan of its clip to the grown grid box. Calls
// emit(a, b, c) for each and returns how many.
template <class Emit>
size_t prepared_pieces(const Vec3d g[3], const Grid& grid, Emit&& emit) {
    // Drop triangles whose box cannot touch the closed grid box.
    bool inside_margin = true, misses = false;
    for (int k = 0; k < 3; ++k) {
        const double lo = std::min({g[0][k], g[1][k], g[2][k]});
        const double hi = std::max({g[0][k], g[1][k], g[2][k]});
        misses = misses || hi < 0 || lo > double(grid.dims[k]);
        inside_margin =
            inside_margin && lo >= -kClipMargin && hi <= double(grid.dims[k]) + kClipMargin;
    }
    if (misses) return 0;
    if (inside_margin) {
        emit(g[0], g[1], g[2]);
        return 1;
    }

    // Clip the rest to the grown grid box and fan the convex remainder.
    Polygon poly{g[0], g[1], g[2]};
    for (int k = 0; k < 3 && !poly.empty(); ++k) {
        poly = clip_against(poly, k, -kClipMargin, +1);
        if (!poly.empty()) poly = clip_against(poly, k, double(grid.dims[k]) + kClipMargin, -1);
    }
    if (poly.empty()) return 0;
    if (poly.size() < 3) poly.resize(3, poly.back());  // a clipped point or segment
    for (size_t i = 1; i + 1 < poly.size(); ++i) emit(poly[0], poly[i], poly[i + 1]);
    return poly.size() - 2;
}

// Whether every vertex lies in the closed grid box (in grid coordinates): then no triangle misses
// the grid or reaches beyond the clip margin, so each prepares into exactly itself. Non-finite
// grid coordinates are not in the box.
bool every_vertex_in_grid(const Mesh& mesh, const Grid& grid, double inv) {
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, mesh.positions.size(), 16384), true,
        [&](const tbb::blocked_range<size_t>& vertices, bool in) {
            for (size_t v = vertices.begin(); in && v < vertices.end(); ++v)
                for (int k = 0; k < 3; ++k) {
                    const double g = (mesh.positions[v][k] - grid.origin[k]) * inv;
                    in = in && g >= 0 && g <= double(grid.dims[k]);
                }
            return in;
        },
        [](bool a, bool b) { return a && b; });
}

}  // namespace

PreparedTriangles prepare_triangles(const Mesh& mesh, const Grid& grid, Boundary boundary) {
    if (mesh.triangles.empty()) validate_mesh(mesh);  // throws: no triangles
    validate_grid(grid);
    // Triangles are independent, so fixed chunks of them are prepared in parallel. A first pass
    // counts each chunk's pieces, so the second writes them straight to their place: the result,
    // and the triangle an error names (the first that fails), do not depend on the threads, and
    // no per-chunk copy is made (at hundreds of thousands of triangles the copies and their page
    // faults cost more than the preparation).
    constexpr size_t kChunk = 8192;
    const double inv = 1.0 / grid.voxel_size;
    const size_t chunks = (mesh.triangles.size() + kChunk - 1) / kChunk;
    auto for_each_chunk = [&](auto&& body) {
        std::vector<std::exception_ptr> errors(chunks);
        tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
            try {
                body(c, c * kChunk, std::min(mesh.triangles.size(), (c + 1) * kChunk));
            } catch (...) {
                errors[c] = std::current_exception();
            }
        });
        for (const std::exception_ptr& error : errors)
            if (error) std::rethrow_exception(error);
    };

    // Pass 1: pieces per chunk. A grid fitted to the mesh holds every vertex, and then every
    // triangle is one piece: a pass over the vertices says so, cheaper than one over the triangles.
    std::vector<size_t> offset(chunks + 1, 0);
    const bool one_piece_each = every_vertex_in_grid(mesh, grid, inv);
    if (one_piece_each) {
        for (size_t c = 0; c < chunks; ++c)
            offset[c + 1] = std::min(mesh.triangles.size(), (c + 1) * kChunk);
    } else {
        for_each_chunk([&](size_t c, size_t begin, size_t end) {
            Vec3d g[3];
            for (size_t t = begin; t < end; ++t) {
                grid_coordinates(mesh, grid, inv, t, g);
                offset[c + 1] +=
                    prepared_pieces(g, grid, [](const Vec3d&, const Vec3d&, const Vec3d&) {});
            }
        });
        for (size_t c = 0; c < chunks; ++c) offset[c + 1] += offset[c];
    }

    // Pass 2: each chunk's pieces, rounded once to float, with their voxel ranges (and their
    // sources, unless each triangle is its own piece).
    PreparedTriangles out;
    out.triangles.resize(offset[chunks]);
    if (!one_piece_each) out.source.resize(offset[chunks]);
    out.ranges.resize(offset[chunks]);
    const int half_open = boundary == Boundary::HalfOpen;
    for_each_chunk([&](size_t c, size_t begin, size_t end) {
        Vec3d g[3];
        if (one_piece_each) {  // piece t is triangle t, with no clip or finiteness test to make
            for (size_t t = begin; t < end; ++t) {
                grid_coordinates(mesh, grid, inv, t, g, CheckFinite::No);
                round_to_anchor(g[0], g[1], g[2], half_open, out.triangles[t], out.ranges[t]);
            }
            return;
        }
        size_t next = offset[c];
        for (size_t t = begin; t < end; ++t) {
            grid_coordinates(mesh, grid, inv, t, g);
            prepared_pieces(g, grid, [&](const Vec3d& p0, const Vec3d& p1, const Vec3d& p2) {
                round_to_anchor(p0, p1, p2, half_open, out.triangles[next], out.ranges[next]);
                out.source[next++] = uint32_t(t);
            });
        }
    });
    return out;
}

}  // namespace oclvox::detail
