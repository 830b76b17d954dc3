// Triangles for the distance field: voxel units, band culling, one rounding to float relative
// to an integer anchor, and the per-triangle constants that keep division and square roots out
// of the shared math (they are computed here once, in double, from the rounded vertices).
#include <algorithm>
#include <cmath>

#include "sdf_internal.hpp"

namespace oclvox::detail {

namespace {

using Vec3 = std::array<double, 3>;

// Anchors and voxel indices are ints in the kernels; vertices this far out are refused rather
// than silently wrapped.
constexpr double kMaxVoxelCoordinate = double(1 << 30);

Vec3 sub(const Vec3& a, const Vec3& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
double dot(const Vec3& a, const Vec3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// Constants of the triangle whose anchor and float vertices are already set in t.
void set_constants(OvSdfTriangle& t) {
    Vec3 v[3], e[3];
    for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) v[j][k] = double(t.vertex[j][k]);
    double longest2 = 0;
    for (int j = 0; j < 3; ++j) {
        e[j] = sub(v[(j + 1) % 3], v[j]);
        const double len2 = dot(e[j], e[j]);
        longest2 = std::max(longest2, len2);
        for (int k = 0; k < 3; ++k) t.edge[j][k] = float(e[j][k]);
        t.inv_len2[j] = len2 > 0 ? float(1.0 / len2) : 0.0f;
    }
    // A sliver whose area is below 1e-9 of its longest edge squared is treated as its edges: the
    // distance changes by at most its width, while its normal would be mostly rounding noise.
    const Vec3 n = cross(e[0], e[1]);
    const double area2 = std::sqrt(dot(n, n));
    t.has_face = area2 > 1e-9 * longest2;
    Vec3 unit{0, 0, 0};
    if (t.has_face)
        for (int k = 0; k < 3; ++k) unit[k] = n[k] / area2;
    for (int k = 0; k < 3; ++k) t.normal[k] = float(unit[k]);
    for (int j = 0; j < 3; ++j) {
        const Vec3 side = cross(e[j], unit);
        for (int k = 0; k < 3; ++k) t.side[j][k] = float(side[k]);
    }
    // The bounding sphere about the vertices' mean; the radius is measured from the float centre
    // and rounded up, so the sphere holds the float triangle.
    for (int k = 0; k < 3; ++k) t.centre[k] = float((v[0][k] + v[1][k] + v[2][k]) / 3.0);
    double radius = 0;
    for (int j = 0; j < 3; ++j) {
        const Vec3 r = sub(v[j], {double(t.centre[0]), double(t.centre[1]), double(t.centre[2])});
        radius = std::max(radius, std::sqrt(dot(r, r)));
    }
    t.radius = std::nextafter(float(radius), INFINITY);
}

}  // namespace

SdfTriangles prepare_sdf_triangles(const Mesh& mesh, const Grid& grid, double band_voxels,
                                   bool every_triangle) {
    validate_mesh(mesh);
    validate_grid(grid);
    SdfTriangles out;
    out.band = float(band_voxels);
    out.band2 = out.band * out.band;
    out.first_item.push_back(0);

    const double inv = 1.0 / grid.voxel_size;
    for (size_t index = 0; index < mesh.triangles.size(); ++index) {
        // Phase 1: voxel units, in double.
        Vec3 g[3];
        for (int i = 0; i < 3; ++i)
            for (int k = 0; k < 3; ++k) {
                g[i][k] = (mesh.positions[mesh.triangles[index][i]][k] - grid.origin[k]) * inv;
                if (!(std::abs(g[i][k]) < kMaxVoxelCoordinate))
                    throw InputError("triangle " + std::to_string(index) +
                                     " lies more than 2^30 voxels from the grid origin: use a "
                                     "larger voxel size or a mesh closer to the grid");
            }

        // Phase 2: voxels whose centre c = i + 0.5 is within the band of the triangle's box,
        // i in [ceil(lo - band - 0.5), floor(hi + band - 0.5)], clipped to the grid. Centres
        // outside that range are farther than the band from the triangle.
        OvSdfTriangle t{};
        bool empty = false;
        for (int k = 0; k < 3; ++k) {
            const double lo = std::min({g[0][k], g[1][k], g[2][k]});
            const double hi = std::max({g[0][k], g[1][k], g[2][k]});
            const double first = std::max(0.0, std::ceil(lo - band_voxels - 0.5));
            const double last =
                std::min(double(grid.dims[k] - 1), std::floor(hi + band_voxels - 0.5));
            empty = empty || first > last;
            t.lo[k] = int(first);
            t.hi[k] = int(last);
            t.anchor[k] = int(std::floor(lo));
        }
        if (empty && !every_triangle) continue;

        // Phase 3: the single rounding to float, then the constants.
        for (int i = 0; i < 3; ++i)
            for (int k = 0; k < 3; ++k) t.vertex[i][k] = float(g[i][k] - double(t.anchor[k]));
        set_constants(t);

        out.triangles.push_back(t);
        out.first_item.push_back(out.first_item.back() + item_count(t));
    }
    return out;
}

}  // namespace oclvox::detail
