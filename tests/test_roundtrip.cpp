// Round trip mesh -> signed distance field -> mesh: the surfaces that Surface Nets and Marching
// Cubes extract from a device SDF stay within about one voxel of the mesh the field was made
// from, are closed, and do not depend on the brick size of the solid pass that signs the field.
//
// The distance between the meshes is measured here, independently of the library: points sampled
// densely on each mesh's triangles, their exact double-precision distance to the other mesh's
// triangles (Ericson's closest point), looked up through a simple uniform grid of triangles.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "oclvox/sdf.hpp"
#include "test_support.hpp"

namespace oclvox::test {
namespace {

Vec3d mad(const Vec3d& o, const Vec3d& e, double t) {
    return {o[0] + t * e[0], o[1] + t * e[1], o[2] + t * e[2]};
}

// Distance queries against one mesh, exact up to `reach`: every triangle is listed in each cell
// of a uniform grid that its box grown by `reach` touches, so any triangle within `reach` of a
// point is listed in the point's cell. Farther than that the answer is just "at least reach",
// which is all a bound of one voxel needs.
class DistanceGrid {
  public:
    DistanceGrid(const Mesh& mesh, double cell, double reach)
        : mesh_(mesh), cell_(cell), reach_(reach) {
        lo_ = {INFINITY, INFINITY, INFINITY};
        Vec3d hi{-INFINITY, -INFINITY, -INFINITY};
        for (const auto& p : mesh.positions)
            for (int k = 0; k < 3; ++k) {
                lo_[k] = std::min(lo_[k], p[k] - reach);
                hi[k] = std::max(hi[k], p[k] + reach);
            }
        for (int k = 0; k < 3; ++k) dims_[k] = int64_t((hi[k] - lo_[k]) / cell) + 1;
        cells_.resize(size_t(dims_[0] * dims_[1] * dims_[2]));
        for (uint32_t t = 0; t < mesh.triangles.size(); ++t) {
            int64_t a[3], b[3];
            for (int k = 0; k < 3; ++k) {
                double mn = INFINITY, mx = -INFINITY;
                for (uint32_t v : mesh.triangles[t]) {
                    mn = std::min(mn, mesh.positions[v][k]);
                    mx = std::max(mx, mesh.positions[v][k]);
                }
                a[k] = cell_of(mn - reach, k);
                b[k] = cell_of(mx + reach, k);
            }
            for (int64_t z = a[2]; z <= b[2]; ++z)
                for (int64_t y = a[1]; y <= b[1]; ++y)
                    for (int64_t x = a[0]; x <= b[0]; ++x)
                        cells_[size_t(x + dims_[0] * (y + dims_[1] * z))].push_back(t);
        }
    }

    // min(exact distance to the mesh, reach)
    double distance(const Vec3d& p) const {
        int64_t c[3];
        for (int k = 0; k < 3; ++k) {
            c[k] = int64_t(std::floor((p[k] - lo_[k]) / cell_));
            if (c[k] < 0 || c[k] >= dims_[k]) return reach_;
        }
        double best = reach_;
        for (uint32_t t : cells_[size_t(c[0] + dims_[0] * (c[1] + dims_[1] * c[2]))]) {
            const auto& tri = mesh_.triangles[t];
            best = std::min(
                best, norm(sub(p, closest_point(p, mesh_.positions[tri[0]], mesh_.positions[tri[1]],
                                                mesh_.positions[tri[2]]))));
        }
        return best;
    }

  private:
    int64_t cell_of(double x, int k) const {
        return std::clamp<int64_t>(int64_t(std::floor((x - lo_[k]) / cell_)), 0, dims_[k] - 1);
    }

    const Mesh& mesh_;
    double cell_, reach_;
    Vec3d lo_{};
    int64_t dims_[3]{};
    std::vector<std::vector<uint32_t>> cells_;
};

// One-sided Hausdorff estimate max_{p on from} d(p, to), in units of `spacing`: every triangle of
// `from` is sampled on a barycentric lattice fine enough that samples are at most spacing/8
// apart, so the estimate is below the true value by at most that much. Distances are exact up to
// 1.5 voxels and reported as 1.5 beyond, which still fails a bound of one voxel.
double one_sided_hausdorff(const Mesh& from, const Mesh& to, double spacing) {
    const DistanceGrid grid(to, 0.75 * spacing, 1.5 * spacing);
    double worst = 0;
    for (const auto& t : from.triangles) {
        const Vec3d& a = from.positions[t[0]];
        const Vec3d& b = from.positions[t[1]];
        const Vec3d& c = from.positions[t[2]];
        const double longest = std::max({norm(sub(b, a)), norm(sub(c, b)), norm(sub(a, c))});
        const int n = std::max(1, int(std::ceil(longest / (spacing / 6))));
        for (int64_t i = 0; i <= n; ++i)
            for (int64_t j = 0; i + j <= n; ++j) {
                const Vec3d p = mad(mad(a, sub(b, a), double(i) / n), sub(c, a), double(j) / n);
                worst = std::max(worst, grid.distance(p));
            }
    }
    return worst / spacing;
}

// Closed: no undirected edge lies on a border (used by an odd number of triangles). Manifold as
// well: every edge is used by exactly two triangles. Surface Nets is documented to be
// non-manifold (an edge shared by four triangles) at cell faces with four sign changes, so for
// it only closedness is required on real meshes; the count of such edges is printed.
void expect_closed(const Mesh& m, const char* what, bool require_manifold) {
    ASSERT_FALSE(m.triangles.empty()) << what;
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (const auto& t : m.triangles)
        for (int e = 0; e < 3; ++e) {
            const uint32_t u = t[e], v = t[(e + 1) % 3];
            ASSERT_NE(u, v) << what << ": triangle with a repeated vertex";
            ++uses[{std::min(u, v), std::max(u, v)}];
        }
    size_t border = 0, non_manifold = 0;
    for (const auto& [edge, count] : uses) {
        border += count % 2 != 0;
        non_manifold += count != 2;
        if ((count % 2 != 0 || (require_manifold && count != 2)) && border + non_manifold < 6)
            ADD_FAILURE() << what << ": edge " << edge.first << "-" << edge.second << " used "
                          << count << " times";
    }
    std::printf("[ measured ] %s: %zu edges, %zu border, %zu used more than twice\n", what,
                uses.size(), border, non_manifold);
    EXPECT_EQ(border, 0u) << what;
    if (require_manifold) {
        EXPECT_EQ(non_manifold, 0u) << what;
    }
}

void expect_same_mesh(const Mesh& a, const Mesh& b, const char* what) {
    EXPECT_TRUE(a.positions == b.positions) << what << ": vertex positions differ";
    EXPECT_TRUE(a.triangles == b.triangles) << what << ": triangles differ";
}

SdfOptions band3(int brick_size) {
    SdfOptions o;
    o.band_voxels = 3.0;
    o.brick_size = brick_size;
    return o;
}

// The whole round trip for one mesh on one grid: both directions of the Hausdorff distance for
// both meshing methods within `bound` voxels, closed outputs, brick size without effect.
void check_round_trip(const char* name, const Mesh& mesh, const Grid& grid, double bound,
                      bool nets_manifold) {
    const ScalarField f64 = signed_distance(device(), mesh, grid, band3(64));
    const ScalarField f16 = signed_distance(device(), mesh, grid, band3(16));
    ASSERT_TRUE(f64.values == f16.values) << name << ": the field depends on the brick size";

    const Mesh nets = surface_nets(device(), f64), cubes = marching_cubes(device(), f64);
    expect_same_mesh(nets, surface_nets(device(), f16), "surface nets, bricks 64 vs 16");
    expect_same_mesh(cubes, marching_cubes(device(), f16), "marching cubes, bricks 64 vs 16");
    expect_closed(nets, "surface nets", nets_manifold);
    expect_closed(cubes, "marching cubes", true);

    for (const auto& [method, out] :
         {std::pair{"surface nets", &nets}, {"marching cubes", &cubes}}) {
        const double to_original = one_sided_hausdorff(*out, mesh, grid.voxel_size);
        const double to_output = one_sided_hausdorff(mesh, *out, grid.voxel_size);
        std::printf(
            "[ measured ] %s, %s: %zu triangles, Hausdorff output->original %.3f, "
            "original->output %.3f voxels\n",
            name, method, out->triangles.size(), to_original, to_output);
        EXPECT_LE(to_original, bound) << name << ", " << method << ": output -> original";
        EXPECT_LE(to_output, bound) << name << ", " << method << ": original -> output";
    }
}

TEST(RoundTrip, SphereMeshesStayWithinOneVoxelAreClosedAndIgnoreBrickSize) {
    // Radius 15 voxels, centre off the voxel lattice so no crossing lands on a sample.
    const Mesh sphere = icosphere({0.31, -0.17, 0.23}, 1.5, 3);
    Grid g;
    g.voxel_size = 0.1;
    g.origin = {-1.93, -1.87, -1.91};
    g.dims = {40, 40, 40};
    check_round_trip("sphere", sphere, g, 1.0, true);
}

TEST(RoundTrip, SpotMeshesStayWithinOneVoxelAreClosedAndIgnoreBrickSize) {
    const Mesh spot = load_mesh(mesh_path("spot.obj"));
    GridFit fit;
    fit.resolution = 48;
    fit.pad = 4;  // beyond the band, so the surface never reaches the grid border
    check_round_trip("spot", spot, fit_grid(spot, fit), 1.0, false);
}

// The measure itself must be able to fail: a copy of the sphere moved by 1.25 voxels is more
// than one voxel away from the original in both directions (exactly 1.25 along the shift).
TEST(RoundTrip, HausdorffEstimateSeesAShiftOfOneAndAQuarterVoxels) {
    const Mesh a = icosphere({0, 0, 0}, 1.5, 3), b = icosphere({0.125, 0, 0}, 1.5, 3);
    EXPECT_NEAR(one_sided_hausdorff(a, b, 0.1), 1.25, 0.03);
    EXPECT_NEAR(one_sided_hausdorff(b, a, 0.1), 1.25, 0.03);
    EXPECT_NEAR(one_sided_hausdorff(a, a, 0.1), 0.0, 1e-9);
}

// ---- field meshes are closed: padded grids and Marching Cubes (what sdf and csg do) -------------
// A grid fitted to the mesh(es) and padded by field_padding(band) has no inside sample on its
// border, and Marching Cubes of the field is then a closed, consistently oriented, vertex-manifold
// surface with the input's Euler characteristic and number of parts. The unpadded fit (the old
// default) cuts the surface, and Surface Nets (the old default mesher) is non-manifold on CSG
// results; both are measured and printed.

GridFit padded_fit(int64_t resolution) {
    GridFit fit;
    fit.resolution = resolution;
    fit.pad = field_padding(band3(64).band_voxels);
    return fit;
}

void expect_closed_manifold(const Mesh& out, int64_t euler, int64_t components,
                            const std::string& what) {
    const Topology t = topology(out);
    std::printf("[ measured ] %s: %lld triangles, Euler characteristic %lld, %lld part(s)\n",
                what.c_str(), (long long)t.faces, (long long)t.euler(), (long long)t.components);
    EXPECT_TRUE(t.closed_and_oriented) << what;
    EXPECT_TRUE(t.vertex_manifold) << what;
    EXPECT_EQ(t.unused_vertices, 0) << what;
    EXPECT_EQ(t.euler(), euler) << what;
    EXPECT_EQ(t.components, components) << what;
}

// Undirected edges not used by exactly two triangles.
size_t non_manifold_edges(const Mesh& m) {
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (const auto& t : m.triangles)
        for (int e = 0; e < 3; ++e)
            ++uses[{std::min(t[e], t[(e + 1) % 3]), std::max(t[e], t[(e + 1) % 3])}];
    return size_t(
        std::count_if(uses.begin(), uses.end(), [](const auto& u) { return u.second != 2; }));
}

TEST(FieldMeshes, RealMeshFieldsOnPaddedGridsMeshToClosedManifoldsOfTheInputsTopology) {
    for (const char* name : {"bunny00.off", "spot.obj"}) {
        const Mesh mesh = load_mesh(mesh_path(name));
        const Topology input = topology(welded(mesh));
        ASSERT_TRUE(input.closed_and_oriented && input.vertex_manifold) << name;

        const ScalarField field =
            signed_distance(device(), mesh, fit_grid(mesh, padded_fit(64)), band3(64));
        EXPECT_EQ(border_samples_inside(field), 0u) << name;
        std::printf("[ measured ] %s input: Euler characteristic %lld, %lld part(s)\n", name,
                    (long long)input.euler(), (long long)input.components);
        expect_closed_manifold(marching_cubes(device(), field), input.euler(), input.components,
                               std::string(name) + ", marching cubes, padded grid");

        GridFit unpadded = padded_fit(64);
        unpadded.pad = 0;
        const ScalarField cut =
            signed_distance(device(), mesh, fit_grid(mesh, unpadded), band3(64));
        const uint64_t border = border_samples_inside(cut);
        std::printf(
            "[ measured ] %s, unpadded grid: %llu border samples inside, marching cubes "
            "closed: %d\n",
            name, (unsigned long long)border,
            int(topology(marching_cubes(device(), cut)).closed_and_oriented));
        EXPECT_GT(border, 0u) << name << ": the unpadded fit should cut the surface";
    }
}

TEST(FieldMeshes, CsgOfOverlappingSpheresAndBoxesMeshesToClosedGenusZeroManifolds) {
    const std::pair<Mesh, Mesh> shapes[] = {
        {icosphere({0.0, 0.0, 0.0}, 1.0, 3), icosphere({0.83, 0.31, -0.27}, 0.8, 3)},
        {box_mesh({0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}),
         box_mesh({0.61, 0.23, 0.29}, {1.37, 0.71, 1.43})}};
    for (const auto& [a, b] : shapes) {
        const Grid grid = fit_grid(a, b, padded_fit(40));
        const ScalarField fa = signed_distance(device(), a, grid, band3(64));
        const ScalarField fb = signed_distance(device(), b, grid, band3(64));
        for (const CsgOp op : {CsgOp::Union, CsgOp::Difference, CsgOp::Intersection}) {
            const std::string what =
                std::string(&a == &shapes[0].first ? "spheres " : "boxes ") + to_string(op);
            const ScalarField c = csg(fa, fb, op);
            EXPECT_EQ(border_samples_inside(c), 0u) << what;
            expect_closed_manifold(marching_cubes(device(), c), 2, 1, what + ", marching cubes");
            std::printf(
                "[ measured ] %s, surface nets: %zu edges not shared by exactly two "
                "triangles\n",
                what.c_str(), non_manifold_edges(surface_nets(device(), c)));
        }
    }
}

// The border count against a direct enumeration on a small non-cubic field.
TEST(FieldMeshes, BorderSamplesInsideCountsExactlyTheOuterLayer) {
    ScalarField field;
    field.grid.dims = {4, 5, 6};
    field.values.assign(4 * 5 * 6, 1.0f);
    std::mt19937 rng(3);
    uint64_t expected = 0;
    for (int k = 0; k < 6; ++k)
        for (int j = 0; j < 5; ++j)
            for (int i = 0; i < 4; ++i)
                if (rng() % 3 == 0) {
                    field.values[size_t(i + 4 * (j + 5 * k))] = -0.5f;
                    expected += i == 0 || j == 0 || k == 0 || i == 3 || j == 4 || k == 5;
                }
    ASSERT_GT(expected, 0u);
    EXPECT_EQ(border_samples_inside(field), expected);
    EXPECT_EQ(border_samples_inside(field, -1.0f), 0u);  // nothing is below -1
    field.grid.dims = {1, 1, 1};
    field.values = {-2.0f};
    EXPECT_EQ(border_samples_inside(field), 1u);
    field.values = {};
    EXPECT_THROW(border_samples_inside(field), GridError);
}

}  // namespace
}  // namespace oclvox::test
