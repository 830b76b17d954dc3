// Fans over an open mesh's holes; see winding_fans.hpp.
#include "winding_fans.hpp"

#include <algorithm>
#include <cmath>
#include <map>

#include "solid_internal.hpp"
#include "winding_tree.hpp"

namespace oclvox::detail {

namespace {

// A solid angle's bound from its triangle's area and least distance d: at most area / d^2, and
// at most 2 pi (also where d is not positive).
double solid_angle_bound(double area, double d) {
    return d > 0 ? std::min(2 * M_PI, area / (d * d)) : 2 * M_PI;
}

}  // namespace

double BoundaryFans::weighted_solid_angle(size_t t, const Vec3d& p) const {
    return weight[t] *
           solid_angle_double(&triangles[t][0], &triangles[t][3], &triangles[t][6], p.data());
}

double BoundaryFans::winding(const Vec3d& p) const {
    double sum = 0;
    for (size_t t = 0; t < triangles.size(); ++t) sum += weighted_solid_angle(t, p);
    return sum / (4 * M_PI);
}

BoundaryFans::Estimate BoundaryFans::winding_estimate(const Vec3d& p) const {
    double sum = 0, error = 0;
    for (size_t i = 0; i < nodes.size();) {
        const WindingNode& c = nodes[i];
        const Vec3d d{c.centre[0] - p[0], c.centre[1] - p[1], c.centre[2] - p[2]};
        const double r = distance(c.centre, p), gap = r - c.radius;
        if (gap > kFarRadii * c.radius) {
            // The solid angle's kernel n.(x - p)/|x - p|^3 to first order in x about the centre,
            // integrated over each triangle: its area vector seen from the centre, plus its
            // moment through the kernel's gradient, I/r^3 - 3 d d^T/r^5.
            const double r2 = r * r, r3 = r2 * r, r5 = r3 * r2;
            double dmd = 0;
            for (int a = 0; a < 3; ++a)
                for (int b = 0; b < 3; ++b) dmd += d[a] * c.moment[3 * a + b] * d[b];
            const double trace = c.moment[0] + c.moment[4] + c.moment[8];
            sum +=
                (c.area_normal[0] * d[0] + c.area_normal[1] * d[1] + c.area_normal[2] * d[2]) / r3 +
                trace / r3 - 3 * dmd / r5;
            error += 3 * c.area * c.radius * c.radius / (gap * gap * gap * gap);
            i = c.skip;
            continue;
        }
        if (c.leaf)
            for (size_t t = c.first; t < c.first + c.count; ++t) sum += weighted_solid_angle(t, p);
        ++i;  // a leaf's next node is past it; an inner node's is its first child
    }
    // Plus the rounding of this sum and of winding(p)'s, generously: a sum of n terms in double
    // is within n 2^-53 of the sum of their magnitudes, each solid angle at most 2 pi times its
    // weight, and atan2 and the terms' arithmetic add a few ulps each.
    return {sum / (4 * M_PI),
            error / (4 * M_PI) + 1e-15 * double(triangles.size() + 1) * (1 + total_weight)};
}

double BoundaryFans::bound(const Vec3d& p, double reach) const {
    return sum_over_ball(
        p, reach, [](double area, double gap) { return area / (gap * gap); }, solid_angle_bound);
}

double BoundaryFans::gradient_bound(const Vec3d& p, double reach) const {
    return sum_over_ball(
        p, reach, [](double area, double gap) { return 2 * area / (gap * gap * gap); },
        [](double area, double d) {
            return d > 0 ? std::min(2 * area / (d * d * d), 4 * M_PI / d) : INFINITY;
        });
}

bool BoundaryFans::below_half_at(const Vec3d& p) const {
    const double limit = 0.5 * 4 * M_PI;
    double sum = 0;
    for (size_t i = 0; i < nodes.size() && sum < limit;) {
        const WindingNode& c = nodes[i];
        const double gap = distance(p, c.centre) - c.radius;
        if (gap > c.radius) {
            sum += c.area / (gap * gap);
            i = c.skip;
        } else if (c.leaf) {
            for (size_t t = c.first; t < c.first + c.count; ++t)
                sum += weight[t] * solid_angle_bound(area_of(t), least_distance(t, p) * (1 - 1e-9));
            i = c.skip;
        } else {
            ++i;
        }
    }
    return sum < limit;
}

double BoundaryFans::least_distance(size_t t, const Vec3d& p) const {
    const auto& v = triangles[t];
    const Vec3d a{v[0], v[1], v[2]}, b{v[3], v[4], v[5]}, c{v[6], v[7], v[8]};
    auto sub = [](const Vec3d& x, const Vec3d& y) {
        return Vec3d{x[0] - y[0], x[1] - y[1], x[2] - y[2]};
    };
    auto dot = [](const Vec3d& x, const Vec3d& y) {
        return x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    };
    auto cross = [](const Vec3d& x, const Vec3d& y) {
        return Vec3d{x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2],
                     x[0] * y[1] - x[1] * y[0]};
    };
    // Within the prism over the triangle, the distance to its plane.
    const Vec3d n = cross(sub(b, a), sub(c, a));
    const double nn = dot(n, n);
    if (nn > 0 && dot(cross(sub(b, a), sub(p, a)), n) >= 0 &&
        dot(cross(sub(c, b), sub(p, b)), n) >= 0 && dot(cross(sub(a, c), sub(p, c)), n) >= 0)
        return std::fabs(dot(sub(p, a), n)) / std::sqrt(nn);
    // Elsewhere (and for a degenerate triangle), the distance to the nearest edge.
    auto segment = [&](const Vec3d& x, const Vec3d& y) {
        const Vec3d e = sub(y, x), q = sub(p, x);
        const double ee = dot(e, e);
        const double s = ee > 0 ? std::clamp(dot(q, e) / ee, 0.0, 1.0) : 0.0;
        const Vec3d r{q[0] - s * e[0], q[1] - s * e[1], q[2] - s * e[2]};
        return std::sqrt(dot(r, r));
    };
    return std::min({segment(a, b), segment(b, c), segment(c, a)});
}

double BoundaryFans::area_of(size_t t) const {
    const auto& v = triangles[t];
    const double e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
    const double e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
    const double n[3] = {(e1[1] * e2[2] - e1[2] * e2[1]) / 2, (e1[2] * e2[0] - e1[0] * e2[2]) / 2,
                         (e1[0] * e2[1] - e1[1] * e2[0]) / 2};
    return std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

double BoundaryFans::distance(const Vec3d& p, const Vec3d& q) {
    return std::sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                     (p[2] - q[2]) * (p[2] - q[2]));
}

namespace {

constexpr size_t kFanTrianglesPerLeaf = 16;

}  // namespace

BoundaryFans boundary_fans(const Mesh& mesh, const Grid& grid) {
    const WeldedEdges welded = weld_edges(mesh);
    // Boundary edges (net count != 0), and their connected components by union-find.
    std::vector<std::pair<std::pair<uint32_t, uint32_t>, int64_t>> edges;
    for (const auto& [edge, uses] : welded.uses)
        if (uses[0] != uses[1]) edges.push_back({edge, int64_t(uses[0]) - int64_t(uses[1])});
    BoundaryFans fans;
    if (edges.empty()) return fans;
    std::vector<uint32_t> parent(welded.positions.size());
    for (size_t v = 0; v < parent.size(); ++v) parent[v] = uint32_t(v);
    auto find = [&](uint32_t v) {
        while (parent[v] != v) v = parent[v] = parent[parent[v]];
        return v;
    };
    for (const auto& [edge, net] : edges) parent[find(edge.first)] = find(edge.second);
    // Apex per component: the mean of its vertices (each edge end counted once per edge).
    std::map<uint32_t, std::array<double, 4>> apex;
    for (const auto& [edge, net] : edges)
        for (uint32_t v : {edge.first, edge.second}) {
            auto& a = apex[find(v)];
            for (int k = 0; k < 3; ++k) a[k] += welded.positions[v][k];
            a[3] += 1;
        }
    auto to_grid = [&](const std::array<double, 3>& p, int k) {
        return (p[k] - grid.origin[k]) / grid.voxel_size;
    };
    for (const auto& [edge, net] : edges) {
        const auto& a = apex[find(edge.first)];
        const std::array<double, 3> centre{a[0] / a[3], a[1] / a[3], a[2] / a[3]};
        // The fan triangle's boundary runs low -> high `net` times, like the mesh's.
        const uint32_t from = net > 0 ? edge.first : edge.second;
        const uint32_t to = net > 0 ? edge.second : edge.first;
        std::array<double, 9> t;
        for (int k = 0; k < 3; ++k) {
            t[k] = to_grid(centre, k);
            t[3 + k] = to_grid(welded.positions[from], k);
            t[6 + k] = to_grid(welded.positions[to], k);
        }
        fans.triangles.push_back(t);
        fans.weight.push_back(double(net > 0 ? net : -net));
    }
    // Store the triangles in the tree's order.
    WindingNodes tree = build_winding_nodes(fans.triangles, fans.weight, kFanTrianglesPerLeaf);
    BoundaryFans sorted;
    sorted.nodes = std::move(tree.nodes);
    for (uint32_t i : tree.order) {
        sorted.triangles.push_back(fans.triangles[i]);
        sorted.weight.push_back(fans.weight[i]);
        sorted.total_weight += fans.weight[i];
    }
    return sorted;
}

}  // namespace oclvox::detail
