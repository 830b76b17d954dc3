// Triangle / axis-aligned box overlap in double precision: the 13-axis separating axis test on
// closed sets, written independently of the float kernels. The binning uses it (with a margin) to
// skip bricks a large triangle passes by, and the tests use it as the independent reference that
// decides whether a float disagreement is a touching case at rounding level.
#pragma once

#include <algorithm>
#include <array>

namespace oclvox::detail {

using Vec3d = std::array<double, 3>;

// True iff the closed triangle (a, b, c) and the closed box [lo, hi] share a point, up to the
// rounding of double arithmetic.
inline bool triangle_box_overlap_double(const Vec3d& a, const Vec3d& b, const Vec3d& c,
                                        const Vec3d& lo, const Vec3d& hi) {
    // Work relative to the box centre so the projections stay small.
    Vec3d centre, half, v[3];
    for (int k = 0; k < 3; ++k) {
        centre[k] = 0.5 * (lo[k] + hi[k]);
        half[k] = 0.5 * (hi[k] - lo[k]);
        v[0][k] = a[k] - centre[k];
        v[1][k] = b[k] - centre[k];
        v[2][k] = c[k] - centre[k];
    }
    auto separated_on = [&](const Vec3d& axis) {
        double p0 = axis[0] * v[0][0] + axis[1] * v[0][1] + axis[2] * v[0][2];
        double p1 = axis[0] * v[1][0] + axis[1] * v[1][1] + axis[2] * v[1][2];
        double p2 = axis[0] * v[2][0] + axis[1] * v[2][1] + axis[2] * v[2][2];
        double r =
            half[0] * std::abs(axis[0]) + half[1] * std::abs(axis[1]) + half[2] * std::abs(axis[2]);
        return std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r;
    };
    // Box normals.
    for (int k = 0; k < 3; ++k) {
        Vec3d axis{0, 0, 0};
        axis[k] = 1;
        if (separated_on(axis)) return false;
    }
    // Triangle edges crossed with box normals.
    Vec3d edge[3];
    for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) edge[j][k] = v[(j + 1) % 3][k] - v[j][k];
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j) {
            Vec3d axis{0, 0, 0};
            axis[(k + 1) % 3] = -edge[j][(k + 2) % 3];
            axis[(k + 2) % 3] = edge[j][(k + 1) % 3];
            if (separated_on(axis)) return false;
        }
    // Triangle normal (zero for a degenerate triangle: then the axes above decide).
    Vec3d normal{edge[0][1] * edge[1][2] - edge[0][2] * edge[1][1],
                 edge[0][2] * edge[1][0] - edge[0][0] * edge[1][2],
                 edge[0][0] * edge[1][1] - edge[0][1] * edge[1][0]};
    return !separated_on(normal);
}

}  // namespace oclvox::detail
