// The overlap predicates (SAT and PEF, through the CPU reference) on hand-worked cases and
// against the double-precision SAT on random triangles.
#include <algorithm>

#include "test_support.hpp"

namespace oclvox::test {
namespace {

const OverlapTest kTests[] = {OverlapTest::SAT, OverlapTest::PEF};

SparseVoxels reference(const Mesh& m, const Grid& g, OverlapTest test, int brick = 8,
                       Boundary boundary = Boundary::Closed,
                       VoxelizeMode mode = VoxelizeMode::Surface) {
    VoxelizeOptions o;
    o.test = test;
    o.brick_size = brick;
    o.boundary = boundary;
    o.mode = mode;
    return voxelize_reference(m, g, o);
}

SparseVoxels half_open(const Mesh& m, const Grid& g, OverlapTest test) {
    return reference(m, g, test, 8, Boundary::HalfOpen);
}

SparseVoxels thin(const Mesh& m, const Grid& g) {
    return reference(m, g, OverlapTest::PEF, 8, Boundary::Closed, VoxelizeMode::Thin);
}

// A square [0, n]^2 in the plane x[axis] = at, as two triangles.
void add_plane(Mesh& m, int axis, double at, double n) {
    auto p = [&](double a, double b) {
        Vec3d v;
        v[axis] = at;
        v[(axis + 1) % 3] = a;
        v[(axis + 2) % 3] = b;
        return v;
    };
    add_triangle(m, p(0, 0), p(n, 0), p(n, n));
    add_triangle(m, p(0, 0), p(n, n), p(0, n));
}

bool subset(const SparseVoxels& a, const SparseVoxels& b) {
    bool inside = true;
    a.for_each([&](int64_t i, int64_t j, int64_t k) { inside = inside && b.get(i, j, k); });
    return inside;
}

std::vector<std::array<int64_t, 3>> sorted_voxels(const SparseVoxels& v) {
    std::vector<std::array<int64_t, 3>> out;
    v.for_each([&](int64_t i, int64_t j, int64_t k) { out.push_back({i, j, k}); });
    std::sort(out.begin(), out.end());
    return out;
}

class HandWorked : public ::testing::TestWithParam<OverlapTest> {};

// Triangle in the plane z = 2 (a voxel face plane): both layers k = 1 and k = 2 are set. Its
// footprint x, y >= 0.5, x + y <= 3 meets every column (i, j) in {0,1,2}^2 except (2, 2), whose
// nearest corner has x + y = 4.
TEST_P(HandWorked, FaceOnVoxelPlaneSetsBothLayers) {
    Mesh m;
    add_triangle(m, {0.5, 0.5, 2}, {2.5, 0.5, 2}, {0.5, 2.5, 2});
    const SparseVoxels v = reference(m, unit_grid(4, 4, 4), GetParam());
    EXPECT_EQ(v.count(), 16u);
    for (int k : {1, 2})
        for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i) EXPECT_EQ(v.get(i, j, k), !(i == 2 && j == 2));
    EXPECT_FALSE(v.get(0, 0, 0));
    EXPECT_FALSE(v.get(0, 0, 3));
}

// An edge on the voxel edge x = y = 2 (z from 0.5 to 2.5) touches the four columns around that
// edge in layers 0..2; the rest of the triangle stays inside column (2, 2).
TEST_P(HandWorked, EdgeOnVoxelEdgeSetsAllFourNeighbours) {
    Mesh m;
    add_triangle(m, {2, 2, 0.5}, {2, 2, 2.5}, {2.5, 2.5, 1.5});
    const SparseVoxels v = reference(m, unit_grid(4, 4, 4), GetParam());
    EXPECT_EQ(v.count(), 12u);
    for (int k = 0; k < 3; ++k)
        for (int j = 1; j <= 2; ++j)
            for (int i = 1; i <= 2; ++i) EXPECT_TRUE(v.get(i, j, k)) << i << j << k;
}

// A vertex on the voxel corner (2, 2, 2) touches all eight voxels sharing it; the small triangle
// body lies in voxel (2, 2, 2).
TEST_P(HandWorked, VertexOnVoxelCornerSetsAllEightNeighbours) {
    Mesh m;
    add_triangle(m, {2, 2, 2}, {2.3, 2.1, 2.2}, {2.1, 2.3, 2.25});
    const SparseVoxels v = reference(m, unit_grid(4, 4, 4), GetParam());
    EXPECT_EQ(v.count(), 8u);
    for (int k = 1; k <= 2; ++k)
        for (int j = 1; j <= 2; ++j)
            for (int i = 1; i <= 2; ++i) EXPECT_TRUE(v.get(i, j, k));
}

// Closed cube [1, 5]^3 in an 8^3 grid: voxels 0..5 on each axis meet the closed cube (6^3 = 216);
// the 2^3 voxels inside the open cube do not touch its surface: 208.
TEST_P(HandWorked, AxisAlignedCubeHasExactCount) {
    const SparseVoxels v =
        reference(box_mesh({1, 1, 1}, {5, 5, 5}), unit_grid(8, 8, 8), GetParam());
    EXPECT_EQ(v.count(), 208u);
    EXPECT_FALSE(v.get(2, 3, 3));
    EXPECT_TRUE(v.get(0, 0, 0));  // touches the cube's corner (1, 1, 1)
    EXPECT_FALSE(v.get(6, 6, 6));
}

// The same cube scaled by 2^-100 and moved by 2^40 voxels: grid coordinates are computed exactly
// in double, so the counts do not change.
TEST_P(HandWorked, TinyAndHugeCoordinatesGiveTheSameCube) {
    const double tiny = std::ldexp(1.0, -100);
    Grid g = unit_grid(8, 8, 8);
    g.voxel_size = tiny;
    EXPECT_EQ(reference(box_mesh({tiny, tiny, tiny}, {5 * tiny, 5 * tiny, 5 * tiny}), g, GetParam())
                  .count(),
              208u);
    const double far = std::ldexp(1.0, 40);
    Grid h = unit_grid(8, 8, 8);
    h.origin = {far, -far, far};
    EXPECT_EQ(reference(box_mesh({far + 1, -far + 1, far + 1}, {far + 5, -far + 5, far + 5}), h,
                        GetParam())
                  .count(),
              208u);
}

// Degenerate triangles are still geometry: a point, a segment (repeated vertex) and three
// collinear points along the diagonal through voxel corners (1,1,1) and (2,2,2).
TEST_P(HandWorked, DegenerateTrianglesMarkWhatTheyTouch) {
    Mesh point, point_on_face, segment, diagonal;
    add_triangle(point, {1.5, 1.5, 1.5}, {1.5, 1.5, 1.5}, {1.5, 1.5, 1.5});
    add_triangle(point_on_face, {2, 1.5, 1.5}, {2, 1.5, 1.5}, {2, 1.5, 1.5});
    add_triangle(segment, {0.5, 0.5, 0.5}, {2.5, 0.5, 0.5}, {2.5, 0.5, 0.5});
    add_triangle(diagonal, {0.5, 0.5, 0.5}, {1.5, 1.5, 1.5}, {2.5, 2.5, 2.5});
    const Grid g = unit_grid(4, 4, 4);
    EXPECT_EQ(reference(point, g, GetParam()).count(), 1u);
    EXPECT_EQ(reference(point_on_face, g, GetParam()).count(), 2u);
    const SparseVoxels s = reference(segment, g, GetParam());
    EXPECT_EQ(s.count(), 3u);
    EXPECT_TRUE(s.get(0, 0, 0) && s.get(1, 0, 0) && s.get(2, 0, 0));
    // {0,1}^3 around corner (1,1,1) and {1,2}^3 around (2,2,2) share voxel (1,1,1).
    EXPECT_EQ(reference(diagonal, g, GetParam()).count(), 15u);
}

// Three grid-aligned parallel planes at resolution N: closed boxes mark both neighbouring layers
// of each (4 layers in all), half-open boxes exactly one layer each: 3 N^2.
TEST_P(HandWorked, HalfOpenPlanesMarkExactlyOneLayer) {
    const int n = 8;
    Mesh m;
    for (double z : {1.0, 2.0, 3.0}) add_plane(m, 2, z, n);
    EXPECT_EQ(reference(m, unit_grid(n, n, n), GetParam()).count(), uint64_t(4 * n * n));
    EXPECT_EQ(half_open(m, unit_grid(n, n, n), GetParam()).count(), uint64_t(3 * n * n));
    // Three perpendicular planes: inclusion-exclusion gives 3 N^2 - 3 N + 1.
    Mesh cross;
    add_plane(cross, 0, 2, n);
    add_plane(cross, 1, 3, n);
    add_plane(cross, 2, 4, n);
    EXPECT_EQ(half_open(cross, unit_grid(n, n, n), GetParam()).count(),
              uint64_t(3 * n * n - 3 * n + 1));
}

// Cube [1, 5]^3 with half-open voxels: voxels 1..5 on each axis meet it, and those with an index
// of 1 or 5 on some axis meet its surface: 5^3 - 3^3 = 98.
TEST_P(HandWorked, HalfOpenCubeHasExactCount) {
    const SparseVoxels v =
        half_open(box_mesh({1, 1, 1}, {5, 5, 5}), unit_grid(8, 8, 8), GetParam());
    EXPECT_EQ(v.count(), 98u);
    EXPECT_TRUE(v.get(1, 1, 1) && v.get(5, 5, 5) && v.get(1, 3, 3));
    EXPECT_FALSE(v.get(0, 0, 0) || v.get(3, 3, 3));
}

// A point on a voxel face belongs to one half-open voxel, not two.
TEST_P(HandWorked, HalfOpenPointBelongsToOneVoxel) {
    Mesh m;
    add_triangle(m, {2, 1.5, 1.5}, {2, 1.5, 1.5}, {2, 1.5, 1.5});
    const SparseVoxels v = half_open(m, unit_grid(4, 4, 4), GetParam());
    EXPECT_EQ(v.count(), 1u);
    EXPECT_TRUE(v.get(2, 1, 1));
}

// A sliver from TR12J_OCC.stl at 512^3: a vertical face (normal z = -1.6e-5 of |n| = 364) whose
// projection onto z is a needle 18 voxels long and 2e-5 wide. In float, that projection's area
// cancels to exactly 0, which once oriented its edge functions backwards: PEF then dropped a run
// of voxels the face crosses by 6% of a voxel.
TEST_P(HandWorked, SliverWithCancellingProjectionIsNotDropped) {
    Mesh m;
    add_triangle(m, {177.81734807312253, 312.37235208745057, 93.8498023715415},
                 {189.84859421319169, 325.73442517910081, 114.08695652173913},
                 {177.81732491353756, 312.37232506793481, 114.08695652173913});
    Grid g = unit_grid(28, 28, 28);
    g.origin = {170, 300, 90};  // whole voxels: the float triangle is the one the 512^3 run saw
    const SparseVoxels v = reference(m, g, GetParam());
    for (int k = 10; k <= 23; ++k) EXPECT_TRUE(v.get(11, 15, k)) << "voxel 11,15," << k;
    expect_exact_up_to(v, m, 1e-4);
}

INSTANTIATE_TEST_SUITE_P(BothTests, HandWorked, ::testing::ValuesIn(kTests),
                         [](const auto& info) { return std::string(to_string(info.param)); });

class Random : public ::testing::TestWithParam<OverlapTest> {};

// Random triangles of all sizes (slivers included): within 1e-4 voxels the result is exactly the
// set of voxels the double-precision SAT finds.
TEST_P(Random, ResultIsExactUpToRounding) {
    const Grid g = unit_grid(24, 20, 22);
    for (uint32_t seed = 1; seed <= 3; ++seed) {
        const Mesh m = random_triangles(150, -2, 24, seed * 2.5, seed);
        expect_exact_up_to(reference(m, g, GetParam()), m, 1e-4);
    }
}

// Triangles whose vertices sit on a coarse lattice hit voxel faces, edges and corners exactly.
TEST_P(Random, LatticeTrianglesAreExactUpToRounding) {
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> coord(0, 32);
    Mesh m;
    for (int t = 0; t < 300; ++t) {
        Vec3d p[3];
        for (auto& v : p)
            for (double& x : v) x = coord(rng) * 0.25;
        add_triangle(m, p[0], p[1], p[2]);
    }
    expect_exact_up_to(reference(m, unit_grid(8, 8, 8), GetParam()), m, 1e-4);
}

// Every point sampled densely on every triangle lies in a set voxel (or within rounding of one).
TEST_P(Random, SampledSurfacePointsLieInSetVoxels) {
    const Grid g = unit_grid(16, 16, 16);
    const Mesh m = random_triangles(60, 0, 16, 6, 11);
    const SparseVoxels v = reference(m, g, GetParam());
    const int n = 40;
    for (const auto& tri : m.triangles)
        for (int a = 0; a <= n; ++a)
            for (int b = 0; a + b <= n; ++b) {
                Vec3d p;
                for (int k = 0; k < 3; ++k)
                    p[k] = (m.positions[tri[0]][k] * (n - a - b) + m.positions[tri[1]][k] * a +
                            m.positions[tri[2]][k] * b) /
                           n;
                bool found = false;
                for (int dz = -1; dz <= 1 && !found; ++dz)
                    for (int dy = -1; dy <= 1 && !found; ++dy)
                        for (int dx = -1; dx <= 1 && !found; ++dx) {
                            const int64_t i = int64_t(std::floor(p[0])) + dx;
                            const int64_t j = int64_t(std::floor(p[1])) + dy;
                            const int64_t k = int64_t(std::floor(p[2])) + dz;
                            const double e = 1e-5;
                            found = v.get(i, j, k) && p[0] >= i - e && p[0] <= i + 1 + e &&
                                    p[1] >= j - e && p[1] <= j + 1 + e && p[2] >= k - e &&
                                    p[2] <= k + 1 + e;
                        }
                if (p[0] < 0 || p[1] < 0 || p[2] < 0 || p[0] > 16 || p[1] > 16 || p[2] > 16)
                    continue;  // outside the grid
                ASSERT_TRUE(found) << "sample " << p[0] << "," << p[1] << "," << p[2];
            }
}

// Half-open voxels are a subset of the closed ones, and still contain every voxel the double
// test finds with the voxel shrunk by a margin.
TEST_P(Random, HalfOpenIsASubsetOfClosed) {
    const Grid g = unit_grid(20, 20, 20);
    const Mesh m = random_triangles(200, 0, 20, 4, 31);
    const SparseVoxels open = half_open(m, g, GetParam());
    EXPECT_TRUE(subset(open, reference(m, g, GetParam())));
    for_each_nearby_voxel(g, m, 0, [&](size_t t, int64_t i, int64_t j, int64_t k) {
        if (voxel_meets_triangle(g, m, t, i, j, k, -1e-4)) EXPECT_TRUE(open.get(i, j, k));
    });
}

INSTANTIATE_TEST_SUITE_P(BothTests, Random, ::testing::ValuesIn(kTests),
                         [](const auto& info) { return std::string(to_string(info.param)); });

// SAT and PEF are the same predicate in exact arithmetic: on random and on lattice triangles
// they disagree only on voxels that touch a triangle to within rounding.
TEST(SatVersusPef, DisagreeOnlyOnTouchingVoxels) {
    const Grid g = unit_grid(24, 24, 24);
    const Mesh m = random_triangles(400, 0, 24, 5, 21);
    expect_differ_only_where_touching(reference(m, g, OverlapTest::SAT),
                                      reference(m, g, OverlapTest::PEF), m, 1e-4);
}

// Vertex order within a triangle changes the float evaluation but not the set, except at
// rounding-level touching.
TEST(Permutation, VertexOrderOnlyMattersAtRounding) {
    const Grid g = unit_grid(20, 20, 20);
    const Mesh m = random_triangles(200, 0, 20, 4, 5);
    Mesh rotated = m;
    for (auto& t : rotated.triangles) t = {t[1], t[2], t[0]};
    for (OverlapTest test : kTests)
        expect_differ_only_where_touching(reference(m, g, test), reference(rotated, g, test), m,
                                          1e-4);
}

// Moving a mesh whose coordinates are multiples of 2^-10 by whole voxels moves the anchors and
// leaves the anchor-relative float triangles bit-identical, so the voxels move exactly.
TEST(Translation, WholeVoxelShiftMovesVoxelsExactly) {
    Mesh m = random_triangles(200, 5, 14, 3, 9);
    for (auto& p : m.positions)
        for (double& x : p) x = std::round(x * 1024) / 1024;
    Mesh shifted = m;
    for (auto& p : shifted.positions) {
        p[0] += 3;
        p[1] += 5;
        p[2] -= 2;
    }
    for (OverlapTest test : kTests) {
        const SparseVoxels a = reference(m, unit_grid(24, 24, 24), test);
        const SparseVoxels b = reference(shifted, unit_grid(24, 24, 24), test);
        uint64_t moved = 0;
        a.for_each([&](int64_t i, int64_t j, int64_t k) {
            // Voxels shifted out of the grid are lost; all others must reappear shifted.
            if (i + 3 < 24 && j + 5 < 24 && k - 2 >= 0) {
                EXPECT_TRUE(b.get(i + 3, j + 5, k - 2));
                ++moved;
            }
        });
        uint64_t in_b = 0;
        b.for_each([&](int64_t i, int64_t j, int64_t k) {
            if (i - 3 >= 0 && j - 5 >= 0 && k + 2 < 24) {
                EXPECT_TRUE(a.get(i - 3, j - 5, k + 2));
                ++in_b;
            }
        });
        EXPECT_GT(moved, 100u);
        EXPECT_EQ(moved, in_b);
    }
}

}  // namespace
}  // namespace oclvox::test

namespace oclvox::test {
namespace {

// The thin predicate in double precision on the unrounded triangle, written from Schwarz & Seidel
// 2010 independently of voxel_math.h: the voxel's box meets the triangle's box, the plane crosses
// the centre segment along the normal's dominant axis, and in each projection every edge's inner
// half-plane reaches the voxel's inscribed diamond. `margin` > 0 demands that much slack (in
// voxels), < 0 allows it.
bool thin_double(const Mesh& m, int64_t i, int64_t j, int64_t k, double margin) {
    const Vec3d p{i + 0.5, j + 0.5, k + 0.5};
    const Vec3d u[3] = {m.positions[0], m.positions[1], m.positions[2]};
    for (int a = 0; a < 3; ++a) {
        const double lo = std::min({u[0][a], u[1][a], u[2][a]});
        const double hi = std::max({u[0][a], u[1][a], u[2][a]});
        if (p[a] + 0.5 < lo + margin || p[a] - 0.5 > hi - margin) return false;
    }
    const Vec3d e0 = sub(u[1], u[0]), e1 = sub(u[2], u[0]);
    const Vec3d n{e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2],
                  e0[0] * e1[1] - e0[1] * e1[0]};
    const double dominant = std::max({std::abs(n[0]), std::abs(n[1]), std::abs(n[2])});
    if (std::abs(dot(n, sub(p, u[0]))) > dominant * (0.5 - margin)) return false;
    for (int a = 0; a < 3; ++a) {
        const int a1 = (a + 1) % 3, a2 = (a + 2) % 3;
        const double orientation = n[a] >= 0 ? 1 : -1;
        for (int e = 0; e < 3; ++e) {
            const Vec3d& from = u[e];
            const Vec3d& to = u[(e + 1) % 3];
            const double mx = -(to[a2] - from[a2]) * orientation;
            const double my = (to[a1] - from[a1]) * orientation;
            const double reach = std::max(std::abs(mx), std::abs(my));
            if (mx * (p[a1] - from[a1]) + my * (p[a2] - from[a2]) + reach * (0.5 - margin) < 0)
                return false;
        }
    }
    return true;
}

// The TR12J_OCC sliver of HandWorked.SliverWithCancellingProjectionIsNotDropped: its cancelling
// projection once turned the thin test's edge functions backwards too, dropping part of the
// 6-separating layer. Within 1e-4 voxel, the thin voxels are those the double predicate gives.
TEST(Thin, SliverWithCancellingProjectionMatchesDoublePredicate) {
    Mesh m;
    add_triangle(m, {177.81734807312253, 312.37235208745057, 93.8498023715415},
                 {189.84859421319169, 325.73442517910081, 114.08695652173913},
                 {177.81732491353756, 312.37232506793481, 114.08695652173913});
    Grid g = unit_grid(28, 28, 28);
    g.origin = {170, 300, 90};
    for (auto& p : m.positions) p = to_grid(g, p);  // whole voxels: exact
    g.origin = {0, 0, 0};
    const SparseVoxels v = thin(m, g);
    uint64_t required = 0;
    for (int64_t k = 0; k < 28; ++k)
        for (int64_t j = 0; j < 28; ++j)
            for (int64_t i = 0; i < 28; ++i) {
                if (thin_double(m, i, j, k, 1e-4)) {
                    ++required;
                    EXPECT_TRUE(v.get(i, j, k)) << "voxel " << i << "," << j << "," << k;
                }
                if (v.get(i, j, k))
                    EXPECT_TRUE(thin_double(m, i, j, k, -1e-4))
                        << "voxel " << i << "," << j << "," << k;
            }
    EXPECT_GT(required, 100u);
}

// Thin voxels are conservative voxels, and fewer of them.
TEST(Thin, IsASubsetOfConservative) {
    const Grid g = unit_grid(24, 24, 24);
    const Mesh m = random_triangles(300, 0, 24, 5, 41);
    const SparseVoxels t = thin(m, g);
    EXPECT_TRUE(subset(t, reference(m, g, OverlapTest::PEF)));
    EXPECT_LT(t.count(), reference(m, g, OverlapTest::PEF).count());
}

// Counts the voxels whose centre lies in `inside` that a 6-connected flood fill through empty
// voxels, started from the grid's border, reaches.
template <typename Inside>
uint64_t leaked_voxels(const SparseVoxels& v, Inside inside) {
    const Grid& g = v.grid();
    std::vector<uint8_t> seen(g.voxel_count(), 0);
    std::vector<std::array<int64_t, 3>> stack;
    auto index = [&](int64_t i, int64_t j, int64_t k) {
        return size_t(i + g.dims[0] * (j + g.dims[1] * k));
    };
    auto push = [&](int64_t i, int64_t j, int64_t k) {
        if (i < 0 || j < 0 || k < 0 || i >= g.dims[0] || j >= g.dims[1] || k >= g.dims[2]) return;
        if (seen[index(i, j, k)] || v.get(i, j, k)) return;
        seen[index(i, j, k)] = 1;
        stack.push_back({i, j, k});
    };
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i)
                if (i == 0 || j == 0 || k == 0 || i == g.dims[0] - 1 || j == g.dims[1] - 1 ||
                    k == g.dims[2] - 1)
                    push(i, j, k);
    uint64_t leaked = 0;
    while (!stack.empty()) {
        const auto [i, j, k] = stack.back();
        stack.pop_back();
        leaked += inside(i + 0.5, j + 0.5, k + 0.5) ? 1 : 0;
        push(i + 1, j, k);
        push(i - 1, j, k);
        push(i, j + 1, k);
        push(i, j - 1, k);
        push(i, j, k + 1);
        push(i, j, k - 1);
    }
    return leaked;
}

// 6-separating: on a closed surface no 6-connected path of empty voxels joins outside to inside.
// A sphere of radius 9.3 off the voxel lattice, and a tilted cube.
TEST(Thin, ClosedSurfacesLeaveNoSixConnectedGap) {
    const Vec3d c{12.2, 11.7, 12.45};
    const Mesh sphere = icosphere(c, 9.3, 3);
    const SparseVoxels s = thin(sphere, unit_grid(25, 25, 25));
    EXPECT_EQ(leaked_voxels(s,
                            [&](double x, double y, double z) {
                                return std::hypot(x - c[0], y - c[1], z - c[2]) < 9.3 * 0.98 - 0.01;
                            }),
              0u);
    // The inside is really there: the flood fill without the surface reaches it.
    EXPECT_GT(leaked_voxels(SparseVoxels(s.grid(), 8),
                            [&](double x, double y, double z) {
                                return std::hypot(x - c[0], y - c[1], z - c[2]) < 9.0;
                            }),
              1000u);

    // A cube rotated about two axes.
    Mesh cube = box_mesh({-6, -6, -6}, {6, 6, 6});
    const double a = 0.5, b = 0.3;
    for (auto& p : cube.positions) {
        const double x = p[0] * std::cos(a) - p[1] * std::sin(a);
        const double y = p[0] * std::sin(a) + p[1] * std::cos(a);
        const double z = p[2];
        p = {12.3 + x, 12.1 + y * std::cos(b) - z * std::sin(b),
             12.2 + y * std::sin(b) + z * std::cos(b)};
    }
    const SparseVoxels t = thin(cube, unit_grid(25, 25, 25));
    EXPECT_EQ(leaked_voxels(t,
                            [&](double x, double y, double z) {
                                // Undo the rotation and ask whether the centre is well inside the
                                // cube.
                                const double dx = x - 12.3, dy = y - 12.1, dz = z - 12.2;
                                const double y1 = dy * std::cos(b) + dz * std::sin(b);
                                const double z1 = -dy * std::sin(b) + dz * std::cos(b);
                                const double x0 = dx * std::cos(a) + y1 * std::sin(a);
                                const double y0 = -dx * std::sin(a) + y1 * std::cos(a);
                                return std::max({std::abs(x0), std::abs(y0), std::abs(z1)}) < 5.9;
                            }),
              0u);
    EXPECT_LT(t.count(), reference(cube, unit_grid(25, 25, 25), OverlapTest::PEF).count());
}

// Thin voxels follow the boundary rule too: three parallel grid-aligned planes mark two layers
// each when closed (4 N^2 in all) and exactly one layer each when half-open (3 N^2), and the
// half-open thin sphere is still 6-separating.
TEST(Thin, HalfOpenPlanesMarkExactlyOneLayer) {
    const int n = 8;
    Mesh m;
    for (double z : {1.0, 2.0, 3.0}) add_plane(m, 2, z, n);
    const Grid g = unit_grid(n, n, n);
    EXPECT_EQ(thin(m, g).count(), uint64_t(4 * n * n));
    const SparseVoxels open =
        reference(m, g, OverlapTest::PEF, 8, Boundary::HalfOpen, VoxelizeMode::Thin);
    EXPECT_EQ(open.count(), uint64_t(3 * n * n));
    for (int k : {1, 2, 3}) EXPECT_TRUE(open.get(3, 4, k));

    const Vec3d c{12.2, 11.7, 12.45};
    const SparseVoxels s = reference(icosphere(c, 9.3, 3), unit_grid(25, 25, 25), OverlapTest::PEF,
                                     8, Boundary::HalfOpen, VoxelizeMode::Thin);
    EXPECT_TRUE(subset(s, thin(icosphere(c, 9.3, 3), unit_grid(25, 25, 25))));
    EXPECT_EQ(leaked_voxels(s,
                            [&](double x, double y, double z) {
                                return std::hypot(x - c[0], y - c[1], z - c[2]) < 9.3 * 0.98 - 0.01;
                            }),
              0u);
}

}  // namespace
}  // namespace oclvox::test
