// Shared helpers for the voxelization tests: small meshes built by hand, and the independent
// double-precision checks that every result is measured against.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <random>
#include <string>

#include "oclvox/oclvox.hpp"
#include "overlap_double.hpp"

namespace oclvox::test {

using detail::Vec3d;

// The OpenCL device the tests run on: $OCLVOX_DEVICE, else the library's default choice. Opened
// once per test process.
inline Device& device() {
    static Device d =
        Device::open(std::getenv("OCLVOX_DEVICE") ? std::getenv("OCLVOX_DEVICE") : "");
    return d;
}

inline Grid unit_grid(int64_t nx, int64_t ny, int64_t nz) {
    Grid g;
    g.dims = {nx, ny, nz};
    return g;
}

inline void add_triangle(Mesh& m, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const auto base = uint32_t(m.positions.size());
    m.positions.push_back(a);
    m.positions.push_back(b);
    m.positions.push_back(c);
    m.triangles.push_back({base, base + 1, base + 2});
}

// Closed box [lo, hi] as 12 outward-facing triangles over 8 shared vertices.
inline Mesh box_mesh(const Vec3d& lo, const Vec3d& hi) {
    Mesh m;
    for (int i = 0; i < 8; ++i)
        m.positions.push_back(
            {i & 1 ? hi[0] : lo[0], i & 2 ? hi[1] : lo[1], i & 4 ? hi[2] : lo[2]});
    const uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                  {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& q : quads) {
        m.triangles.push_back({q[0], q[1], q[2]});
        m.triangles.push_back({q[0], q[2], q[3]});
    }
    return m;
}

// A closed sphere: an octahedron subdivided `levels` times, vertices pushed onto the sphere.
inline Mesh sphere_mesh(const Vec3d& centre, double radius, int levels) {
    std::vector<std::array<Vec3d, 3>> tris;
    const Vec3d px{1, 0, 0}, nx{-1, 0, 0}, py{0, 1, 0}, ny{0, -1, 0}, pz{0, 0, 1}, nz{0, 0, -1};
    tris = {{px, py, pz}, {py, nx, pz}, {nx, ny, pz}, {ny, px, pz},
            {py, px, nz}, {nx, py, nz}, {ny, nx, nz}, {px, ny, nz}};
    auto unit_mid = [](const Vec3d& a, const Vec3d& b) {
        Vec3d m{a[0] + b[0], a[1] + b[1], a[2] + b[2]};
        const double l = std::sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        return Vec3d{m[0] / l, m[1] / l, m[2] / l};
    };
    for (int level = 0; level < levels; ++level) {
        std::vector<std::array<Vec3d, 3>> finer;
        for (const auto& t : tris) {
            const Vec3d ab = unit_mid(t[0], t[1]), bc = unit_mid(t[1], t[2]),
                        ca = unit_mid(t[2], t[0]);
            finer.push_back({t[0], ab, ca});
            finer.push_back({ab, t[1], bc});
            finer.push_back({ca, bc, t[2]});
            finer.push_back({ab, bc, ca});
        }
        tris.swap(finer);
    }
    Mesh m;
    for (const auto& t : tris) {
        Vec3d p[3];
        for (int i = 0; i < 3; ++i)
            for (int k = 0; k < 3; ++k) p[i][k] = centre[k] + radius * t[i][k];
        add_triangle(m, p[0], p[1], p[2]);
    }
    return m;
}

// Triangles with vertices uniform in [lo, hi)^3, each of size up to `span`.
inline Mesh random_triangles(int count, double lo, double hi, double span, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> where(lo, hi), offset(-span, span);
    Mesh m;
    for (int t = 0; t < count; ++t) {
        const Vec3d a{where(rng), where(rng), where(rng)};
        Vec3d b = a, c = a;
        for (int k = 0; k < 3; ++k) {
            b[k] += offset(rng);
            c[k] += offset(rng);
        }
        add_triangle(m, a, b, c);
    }
    return m;
}

inline Vec3d to_grid(const Grid& g, const Vec3d& p) {
    return {(p[0] - g.origin[0]) / g.voxel_size, (p[1] - g.origin[1]) / g.voxel_size,
            (p[2] - g.origin[2]) / g.voxel_size};
}

// Does the closed voxel box, grown (eps > 0) or shrunk (eps < 0) by |eps| voxels, meet the
// triangle in double precision?
inline bool voxel_meets_triangle(const Grid& g, const Mesh& m, size_t t, int64_t i, int64_t j,
                                 int64_t k, double eps) {
    const Vec3d a = to_grid(g, m.positions[m.triangles[t][0]]);
    const Vec3d b = to_grid(g, m.positions[m.triangles[t][1]]);
    const Vec3d c = to_grid(g, m.positions[m.triangles[t][2]]);
    const Vec3d lo{double(i) - eps, double(j) - eps, double(k) - eps};
    const Vec3d hi{double(i + 1) + eps, double(j + 1) + eps, double(k + 1) + eps};
    return detail::triangle_box_overlap_double(a, b, c, lo, hi);
}

// Calls f(t, i, j, k) for every triangle t and grid voxel within `pad` voxels of its box.
template <typename F>
void for_each_nearby_voxel(const Grid& g, const Mesh& m, int pad, F f) {
    for (size_t t = 0; t < m.triangles.size(); ++t) {
        int64_t lo[3], hi[3];
        for (int k = 0; k < 3; ++k) {
            double mn = INFINITY, mx = -INFINITY;
            for (uint32_t v : m.triangles[t]) {
                const double x = to_grid(g, m.positions[v])[k];
                mn = std::min(mn, x);
                mx = std::max(mx, x);
            }
            lo[k] = std::max<int64_t>(0, int64_t(std::floor(mn)) - pad);
            hi[k] = std::min<int64_t>(g.dims[k] - 1, int64_t(std::floor(mx)) + pad);
        }
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
            for (int64_t y = lo[1]; y <= hi[1]; ++y)
                for (int64_t x = lo[0]; x <= hi[0]; ++x) f(t, x, y, z);
    }
}

// The two halves of "exact up to rounding", against the double-precision SAT on the original
// (unrounded) triangles:
//  - conservative: every voxel that a triangle meets even after shrinking the voxel by eps is set;
//  - no false positives: every set voxel meets some triangle once the voxel is grown by eps.
inline void expect_exact_up_to(const SparseVoxels& v, const Mesh& m, double eps) {
    const Grid& g = v.grid();
    SparseVoxels justified(g, v.brick_size());
    uint64_t missing = 0;
    for_each_nearby_voxel(g, m, 1, [&](size_t t, int64_t i, int64_t j, int64_t k) {
        if (voxel_meets_triangle(g, m, t, i, j, k, eps)) justified.set(i, j, k);
        if (voxel_meets_triangle(g, m, t, i, j, k, -eps) && !v.get(i, j, k) && missing++ < 5)
            ADD_FAILURE() << "voxel " << i << "," << j << "," << k << " meets triangle " << t
                          << " but is not set";
    });
    uint64_t unjustified = 0;
    v.for_each([&](int64_t i, int64_t j, int64_t k) {
        if (!justified.get(i, j, k) && unjustified++ < 5)
            ADD_FAILURE() << "voxel " << i << "," << j << "," << k
                          << " is set but no triangle comes within " << eps << " voxels of it";
    });
    EXPECT_EQ(missing, 0u);
    EXPECT_EQ(unjustified, 0u);
}

// Voxels set in exactly one of a and b must all be touching cases: within eps of some triangle,
// and not met by any triangle once shrunk by eps.
inline uint64_t expect_differ_only_where_touching(const SparseVoxels& a, const SparseVoxels& b,
                                                  const Mesh& m, double eps) {
    const Grid& g = a.grid();
    SparseVoxels near(g, a.brick_size()), solid(g, a.brick_size());
    for_each_nearby_voxel(g, m, 1, [&](size_t t, int64_t i, int64_t j, int64_t k) {
        if (voxel_meets_triangle(g, m, t, i, j, k, eps)) near.set(i, j, k);
        if (voxel_meets_triangle(g, m, t, i, j, k, -eps)) solid.set(i, j, k);
    });
    uint64_t differing = 0;
    auto check = [&](const SparseVoxels& x, const SparseVoxels& y) {
        x.for_each([&](int64_t i, int64_t j, int64_t k) {
            if (y.get(i, j, k)) return;
            ++differing;
            EXPECT_TRUE(near.get(i, j, k) && !solid.get(i, j, k))
                << "voxel " << i << "," << j << "," << k << " differs but is not a touching case";
        });
    };
    check(a, b);
    check(b, a);
    return differing;
}

inline std::string mesh_path(const std::string& name) {
    return std::string(OCLVOX_MESH_DIR) + "/" + name;
}

}  // namespace oclvox::test
