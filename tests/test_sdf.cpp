// Distance fields, CSG and field files, checked against analytic distances and an independent
// double-precision brute force (Ericson's Voronoi-region closest point, not the library's
// projection-or-edges formulation).
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "oclvox/sdf.hpp"
#include "openvdb_reference.hpp"
#include "sdf_internal.hpp"
#include "test_support.hpp"

namespace oclvox::test {
namespace {

Vec3d centre_of(const Grid& g, int64_t i, int64_t j, int64_t k) {
    return {g.origin[0] + (double(i) + 0.5) * g.voxel_size,
            g.origin[1] + (double(j) + 0.5) * g.voxel_size,
            g.origin[2] + (double(k) + 0.5) * g.voxel_size};
}

// Exact distance in world units from every voxel centre to the mesh, brute force in double.
std::vector<double> brute_force_distance(const Mesh& m, const Grid& g) {
    std::vector<double> out(size_t(g.voxel_count()));
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const Vec3d p = centre_of(g, i, j, k);
                double best = INFINITY;
                for (const auto& t : m.triangles)
                    best = std::min(
                        best, norm(sub(p, closest_point(p, m.positions[t[0]], m.positions[t[1]],
                                                        m.positions[t[2]]))));
                out[size_t(i + g.dims[0] * (j + g.dims[1] * k))] = best;
            }
    return out;
}

// How far the icosphere's surface can be from the sphere: R minus the smallest distance from the
// centre to a face plane (every face lies between that and R).
double icosphere_sagitta(const Mesh& m, const Vec3d& centre, double radius) {
    double nearest_plane = radius;
    for (const auto& t : m.triangles) {
        const Vec3d a = m.positions[t[0]], b = m.positions[t[1]], c = m.positions[t[2]];
        const Vec3d e0 = sub(b, a), e1 = sub(c, a);
        const Vec3d n{e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2],
                      e0[0] * e1[1] - e0[1] * e1[0]};
        nearest_plane = std::min(nearest_plane, std::abs(dot(n, sub(a, centre))) / norm(n));
    }
    return radius - nearest_plane;
}

// A grid that is not aligned with the meshes and far from the world origin, so anchors matter.
Grid offset_grid(int64_t n, double voxel_size, const Vec3d& centre) {
    Grid g;
    g.voxel_size = voxel_size;
    g.dims = {n, n + 3, n - 2};
    for (int k = 0; k < 3; ++k)
        g.origin[k] = centre[k] - 0.5 * double(g.dims[k]) * voxel_size + 0.137 * voxel_size;
    return g;
}

SdfOptions band(double voxels, bool full_grid = false) {
    SdfOptions o;
    o.band_voxels = voxels;
    o.full_grid = full_grid;
    return o;
}

// Values exactly equal, bit for bit.
void expect_identical(const ScalarField& a, const ScalarField& b) {
    ASSERT_EQ(a.values.size(), b.values.size());
    EXPECT_EQ(0, std::memcmp(a.values.data(), b.values.data(), a.values.size() * sizeof(float)));
}

const Vec3d kCentre{1000.25, -480.5, 37.75};

TEST(Sdf, BandDistancesAreExactAgainstDoubleBruteForceOnIcosphere) {
    const double vs = 0.25, radius = 3.0;
    const Mesh m = icosphere(kCentre, radius, 2);
    const Grid g = offset_grid(32, vs, kCentre);
    const SdfOptions o = band(3.0);
    const ScalarField f = unsigned_distance_reference(m, g, o);
    const std::vector<double> exact = brute_force_distance(m, g);
    const double sagitta = icosphere_sagitta(m, kCentre, radius);
    size_t in_band = 0;
    for (size_t v = 0; v < exact.size(); ++v) {
        const double d = exact[v] / vs;  // voxels
        if (d < o.band_voxels - 1e-3) {
            ++in_band;
            ASSERT_NEAR(f.values[v] / vs, d, 1e-4) << "voxel " << v;
        } else if (d > o.band_voxels + 1e-3) {
            ASSERT_EQ(f.values[v], float(o.band_voxels * vs)) << "voxel " << v;
        }
    }
    EXPECT_GT(in_band, 5000u);

    // And the analytic sphere: the mesh lies within the sagitta of it.
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const double analytic =
                    std::abs(norm(sub(centre_of(g, i, j, k), kCentre)) - radius);
                const double value = f.values[size_t(i + g.dims[0] * (j + g.dims[1] * k))];
                if (analytic < (o.band_voxels - 0.5) * vs - sagitta) {
                    ASSERT_NEAR(value, analytic, sagitta + 1e-4 * vs);
                }
            }
}

// Box [lo, hi]: outside, the length of the excess over the box; inside, the nearest face.
double box_distance(const Vec3d& p, const Vec3d& lo, const Vec3d& hi) {
    double outside2 = 0, inside = INFINITY;
    for (int k = 0; k < 3; ++k) {
        const double excess = std::max({lo[k] - p[k], p[k] - hi[k], 0.0});
        outside2 += excess * excess;
        inside = std::min({inside, p[k] - lo[k], hi[k] - p[k]});
    }
    return outside2 > 0 ? std::sqrt(outside2) : std::max(inside, 0.0);
}

TEST(Sdf, BandDistancesMatchAnalyticBoxDistance) {
    const double vs = 0.1;
    const Vec3d lo{kCentre[0] - 0.83, kCentre[1] - 0.61, kCentre[2] - 0.97};
    const Vec3d hi{kCentre[0] + 0.74, kCentre[1] + 0.88, kCentre[2] + 0.52};
    const Mesh m = box_mesh(lo, hi);
    const Grid g = offset_grid(28, vs, kCentre);
    const SdfOptions o = band(4.0);
    const ScalarField f = unsigned_distance_reference(m, g, o);
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const double d = box_distance(centre_of(g, i, j, k), lo, hi) / vs;
                const float value = f.values[size_t(i + g.dims[0] * (j + g.dims[1] * k))];
                if (d < o.band_voxels - 1e-3) {
                    ASSERT_NEAR(value / vs, d, 1e-4) << i << " " << j << " " << k;
                } else if (d > o.band_voxels + 1e-3) {
                    ASSERT_EQ(value, float(o.band_voxels * vs));
                }
            }
}

TEST(Sdf, RealMeshMatchesDoubleBruteForceAndDeviceMatchesReference) {
    const Mesh m = load_mesh(mesh_path("bunny00.off"));
    GridFit fit;
    fit.resolution = 40;
    fit.pad = 3;
    const Grid g = fit_grid(m, fit);
    const SdfOptions o = band(2.5);
    const ScalarField f = unsigned_distance(device(), m, g, o);
    expect_identical(f, unsigned_distance_reference(m, g, o));

    // A spread of 150 voxels in the band and 50 clamped ones against the brute force over all
    // 75k triangles: in the band the value is the distance, and clamped voxels really are beyond.
    const float background = float(o.band_voxels * g.voxel_size);
    size_t in_band = 0, clamped = 0;
    for (size_t v = 0; v < f.values.size(); v += 37) {
        const bool is_clamped = f.values[v] == background;
        if (is_clamped ? clamped == 50 : in_band == 150) continue;
        ++(is_clamped ? clamped : in_band);
        const int64_t i = int64_t(v) % g.dims[0], j = int64_t(v) / g.dims[0] % g.dims[1],
                      k = int64_t(v) / (g.dims[0] * g.dims[1]);
        const Vec3d p = centre_of(g, i, j, k);
        double exact = INFINITY;
        for (const auto& t : m.triangles)
            exact =
                std::min(exact, norm(sub(p, closest_point(p, m.positions[t[0]], m.positions[t[1]],
                                                          m.positions[t[2]]))));
        const double d = exact / g.voxel_size;
        if (is_clamped) {
            ASSERT_GT(d, o.band_voxels - 1e-3) << i << " " << j << " " << k;
        } else {
            ASSERT_NEAR(f.values[v] / g.voxel_size, d, 1e-3) << i << " " << j << " " << k;
        }
    }
    EXPECT_EQ(in_band, 150u);
    EXPECT_EQ(clamped, 50u);
}

// The band pass skips voxels (and blocks, and a sparse field's rows of 8) that the plane and
// bounding-sphere tests put beyond the band. Those tests only save work: checked against the
// double-precision distance on random triangles of every size, slivers and collinear ones included,
// they must keep every voxel within the band, and must actually reject some.
TEST(Sdf, CullingNeverRejectsAVoxelWithinTheBand) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    Grid grid;
    grid.voxel_size = 1.0;
    grid.dims = {48, 48, 48};
    grid.origin = {-3.71, 2.13, 0.59};
    const double band = 3.0;
    uint64_t kept = 0, rejected = 0;
    for (int n = 0; n < 300; ++n) {
        const double size = std::pow(10.0, -1.5 + 3.0 * unit(rng));  // 0.03 to 30 voxels
        Vec3d a, b, c;
        for (int k = 0; k < 3; ++k) {
            a[k] = grid.origin[k] + 24.0 + 10.0 * (unit(rng) - 0.5);
            b[k] = a[k] + size * (unit(rng) - 0.5);
            c[k] = n % 5 == 0 ? a[k] + 0.5 * (b[k] - a[k]) : a[k] + size * (unit(rng) - 0.5);
        }
        Mesh mesh;
        add_triangle(mesh, a, b, c);
        const detail::SdfTriangles prepared = detail::prepare_sdf_triangles(mesh, grid, band);
        ASSERT_EQ(prepared.triangles.size(), 1u);
        const detail::OvSdfTriangle& t = prepared.triangles[0];
        for (int k = t.lo[2]; k <= t.hi[2]; ++k)
            for (int j = t.lo[1]; j <= t.hi[1]; ++j)
                for (int i = t.lo[0]; i <= t.hi[0]; ++i) {
                    const double d = norm(sub(centre_of(grid, i, j, k),
                                              closest_point(centre_of(grid, i, j, k), a, b, c)));
                    const bool near =
                        detail::ov_voxel_near(&t, i, j, k, prepared.band) &&
                        detail::ov_block_near(&t, i / 4 * 4, j / 4 * 4, k / 4 * 4, prepared.band) &&
                        detail::ov_row_near(&t, i / 8 * 8, j, k, prepared.band);
                    if (d < band + 1e-3)
                        ASSERT_TRUE(near) << "triangle " << n << " voxel " << i << " " << j << " "
                                          << k << " at distance " << d;
                    (near ? kept : rejected) += 1;
                }
    }
    EXPECT_GT(rejected, kept / 10);
}

TEST(Sdf, NarrowBandIsClampedToExactlyTheBand) {
    const Mesh m = icosphere(kCentre, 2.0, 1);
    const Grid g = offset_grid(24, 0.25, kCentre);
    for (double b : {1.0, 2.5}) {
        const ScalarField f = unsigned_distance_reference(m, g, band(b));
        const float background = float(b * g.voxel_size);
        size_t clamped = 0;
        for (float v : f.values) {
            ASSERT_LE(v, background);
            clamped += v == background;
        }
        // Most of the grid is beyond a band this narrow.
        EXPECT_GT(clamped, f.values.size() / 2);
    }
}

TEST(Sdf, DeviceMatchesReferenceBitForBit) {
    const Mesh sphere = icosphere(kCentre, 2.6, 2);
    const Grid g = offset_grid(30, 0.2, kCentre);
    // Random triangles (including slivers and ones reaching out of the grid) in voxel units.
    const Mesh random = random_triangles(200, -4.0, 36.0, 6.0, 7);
    Grid rg;
    rg.dims = {32, 32, 32};
    for (const SdfOptions& o : {band(3.0), band(1.5), band(2.0, true)}) {
        VoxelizeStats stats;
        expect_identical(unsigned_distance(device(), sphere, g, o, &stats),
                         unsigned_distance_reference(sphere, g, o));
        EXPECT_GT(stats.work_items, 0u);
        expect_identical(unsigned_distance(device(), random, rg, o),
                         unsigned_distance_reference(random, rg, o));
    }
}

// Beyond the band a full-grid field searches the tree over all the triangles, so it is exact
// everywhere: within 1e-4 voxel of a double-precision brute force, above and below. The sphere's
// interior is where jump flooding (before the tree) was 0.041 voxel off; the random triangles
// (slivers, some reaching out of the grid) make a deeper tree with boxes that overlap; 40,000 of
// them make a tree whose upper levels build in parallel (above 16,384 triangles a subtree).
TEST(Sdf, FullGridDistancesAreExactEverywhere) {
    const double vs = 0.25;
    const Mesh sphere = icosphere(kCentre, 2.0, 2);
    const Vec3d lo{kCentre[0] - 1.3, kCentre[1] - 0.4, kCentre[2] - 0.9};
    const Vec3d hi{kCentre[0] + 0.2, kCentre[1] + 1.1, kCentre[2] + 1.6};
    const Mesh box = box_mesh(lo, hi);
    const Grid g = offset_grid(36, vs, kCentre);
    Grid random_grid;
    random_grid.dims = {32, 32, 32};
    const Mesh random = random_triangles(300, 3.0, 29.0, 3.0, 11);  // all inside the grid
    Grid many_grid;
    many_grid.dims = {8, 8, 8};
    // A shell of small triangles 9 to 10 voxels around the grid's centre: every voxel is past
    // the band, and each part of the shell is the nearest for some voxels.
    Mesh many;
    std::mt19937 rng(13);
    std::normal_distribution<double> direction;
    std::uniform_real_distribution<double> radius(9.0, 10.0), offset(-0.4, 0.4);
    for (int t = 0; t < 40000; ++t) {
        Vec3d a{direction(rng), direction(rng), direction(rng)};
        const double scale = radius(rng) / std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        for (double& c : a) c = 4.0 + c * scale;
        add_triangle(many, a, {a[0] + offset(rng), a[1] + offset(rng), a[2]},
                     {a[0], a[1] + offset(rng), a[2] + offset(rng)});
    }
    for (const auto& [m, grid] :
         {std::pair{&sphere, g}, {&box, g}, {&random, random_grid}, {&many, many_grid}}) {
        const ScalarField f = unsigned_distance(device(), *m, grid, band(2.0, true));
        expect_identical(f, unsigned_distance_reference(*m, grid, band(2.0, true)));
        const std::vector<double> exact = brute_force_distance(*m, grid);
        double worst = 0;
        for (size_t v = 0; v < exact.size(); ++v)
            worst = std::max(worst, std::abs(f.values[v] - exact[v]) / grid.voxel_size);
        RecordProperty("worst_full_grid_error_voxels", std::to_string(worst));
        EXPECT_LT(worst, 1e-4);
    }
}

// A full grid is exact for a user-given grid that cuts the mesh, or misses it: triangles farther
// outside the grid than the band are kept for the search beyond the band (a narrow band drops
// them). Here a sphere lies wholly outside the grid, 9 voxels off its face, and a second one
// crosses the face.
TEST(Sdf, FullGridDistancesAreExactForMeshesOutsideTheGrid) {
    Grid g;
    g.dims = {20, 18, 16};
    Mesh m = icosphere({30, 9, 8}, 1.0, 2);
    const Mesh crossing = icosphere({-1, 4, 12}, 3.0, 1);
    for (const auto& t : crossing.triangles)
        m.triangles.push_back({t[0] + uint32_t(m.positions.size()),
                               t[1] + uint32_t(m.positions.size()),
                               t[2] + uint32_t(m.positions.size())});
    m.positions.insert(m.positions.end(), crossing.positions.begin(), crossing.positions.end());
    for (const Mesh& mesh : {icosphere({30, 9, 8}, 1.0, 2), m}) {
        const ScalarField f = unsigned_distance(device(), mesh, g, band(2.0, true));
        expect_identical(f, unsigned_distance_reference(mesh, g, band(2.0, true)));
        const std::vector<double> exact = brute_force_distance(mesh, g);
        double worst = 0;
        for (size_t v = 0; v < exact.size(); ++v)
            worst = std::max(worst, std::abs(f.values[v] - exact[v]) / g.voxel_size);
        EXPECT_LT(worst, 1e-4);
    }
}

TEST(Sdf, FarMeshLeavesTheWholeNarrowBandGridAtTheBand) {
    const Mesh m = icosphere({50, 50, 50}, 1.0, 1);
    Grid g;
    g.dims = {8, 8, 8};
    const ScalarField f = unsigned_distance(device(), m, g, band(3.0));
    for (float v : f.values) ASSERT_EQ(v, 3.0f);
}

TEST(Sdf, RejectsBadBands) {
    const Mesh m = icosphere(kCentre, 2.0, 0);
    const Grid g = offset_grid(8, 1.0, kCentre);
    for (double b : {0.0, -1.0, double(NAN), double(INFINITY)})
        EXPECT_THROW(unsigned_distance_reference(m, g, band(b)), GridError) << b;
}

// ---- sign: these need VoxelizeMode::Solid ------------------------------------------------------

TEST(SdfSign, NegativeExactlyInsideTheSphere) {
    const double vs = 0.2, radius = 2.4;
    const Mesh m = icosphere(kCentre, radius, 3);
    const Grid g = offset_grid(32, vs, kCentre);
    const double sagitta = icosphere_sagitta(m, kCentre, radius);
    for (bool full : {false, true}) {
        const ScalarField f = signed_distance(device(), m, g, band(3.0, full));
        expect_identical(f, signed_distance_reference(m, g, band(3.0, full)));
        for (int64_t k = 0; k < g.dims[2]; ++k)
            for (int64_t j = 0; j < g.dims[1]; ++j)
                for (int64_t i = 0; i < g.dims[0]; ++i) {
                    const double r = norm(sub(centre_of(g, i, j, k), kCentre));
                    const float value = f.values[size_t(i + g.dims[0] * (j + g.dims[1] * k))];
                    if (r < radius - sagitta - 1e-6) {
                        ASSERT_LT(value, 0) << i << " " << j << " " << k;
                    }
                    if (r > radius + 1e-6) {
                        ASSERT_GT(value, 0) << i << " " << j << " " << k;
                    }
                }
    }
}

TEST(SdfSign, SignedBoxMatchesAnalyticSignedDistance) {
    const double vs = 0.1;
    const Vec3d lo{kCentre[0] - 0.83, kCentre[1] - 0.61, kCentre[2] - 0.97};
    const Vec3d hi{kCentre[0] + 0.74, kCentre[1] + 0.88, kCentre[2] + 0.52};
    const Mesh m = box_mesh(lo, hi);
    const Grid g = offset_grid(28, vs, kCentre);
    const ScalarField f = signed_distance(device(), m, g, band(30.0));
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const Vec3d p = centre_of(g, i, j, k);
                bool inside = true;
                for (int a = 0; a < 3; ++a) inside = inside && p[a] > lo[a] && p[a] < hi[a];
                const double expected = (inside ? -1 : 1) * box_distance(p, lo, hi);
                ASSERT_NEAR(f.values[size_t(i + g.dims[0] * (j + g.dims[1] * k))], expected,
                            1e-4 * vs);
            }
}

// ---- layers: a field computed in pieces along z
// ---------------------------------------------------

// Fields of consecutive layer ranges (cut at layers that are not multiples of 4 or of the brick
// size) stack into the whole grid's field, sample for sample, bit for bit: signed and unsigned,
// on the device and the reference, for a mesh far from the origin and an open scan.
TEST(SdfLayers, LayerFieldsStackIntoTheWholeField) {
    const Mesh sphere = icosphere(kCentre, 2.6, 2);
    const Grid g = offset_grid(30, 0.2, kCentre);
    const std::vector<std::pair<int64_t, int64_t>> cuts{{0, 7}, {7, 13}, {13, 27}, {27, 0}};
    for (const bool reference : {false, true}) {
        SCOPED_TRACE(reference ? "reference" : "device");
        SdfOptions o = band(2.5);
        o.brick_size = 8;
        auto run = [&](const SdfOptions& options) {
            return reference ? signed_distance_reference(sphere, g, options)
                             : signed_distance(device(), sphere, g, options);
        };
        const ScalarField whole = run(o);
        std::vector<float> stacked;
        for (const auto& [first, end] : cuts) {
            SdfOptions part = o;
            part.first_layer = first;
            part.end_layer = end;
            const ScalarField f = run(part);
            const int64_t layers = (end ? end : g.dims[2]) - first;
            ASSERT_EQ(f.grid.dims[2], layers);
            EXPECT_EQ(f.grid.origin[2], g.origin[2] + double(first) * g.voxel_size);
            stacked.insert(stacked.end(), f.values.begin(), f.values.end());
        }
        ASSERT_EQ(stacked.size(), whole.values.size());
        EXPECT_EQ(0,
                  std::memcmp(stacked.data(), whole.values.data(), stacked.size() * sizeof(float)));
        EXPECT_LT(*std::min_element(stacked.begin(), stacked.end()), 0.0f);  // signed
    }

    // An open scan signed by the winding number, on the device.
    const Mesh bunny = load_mesh(mesh_path("stanford-bunny.obj"));
    GridFit fit;
    fit.resolution = 32;
    fit.pad = field_padding(2.0);
    const Grid bg = fit_grid(bunny, fit);
    SdfOptions o = band(2.0);
    const ScalarField whole = signed_distance(device(), bunny, bg, o);
    SdfOptions low = o, high = o;
    low.end_layer = 11;
    high.first_layer = 11;
    ScalarField a = signed_distance(device(), bunny, bg, low);
    const ScalarField b = signed_distance(device(), bunny, bg, high);
    a.values.insert(a.values.end(), b.values.begin(), b.values.end());
    expect_identical(a, whole);
}

// A full grid in layers: every slab searches all the triangles beyond the band, also the slabs
// that no triangle's band reaches (the sphere sits in the grid's lower third), so the slabs stack
// into the whole full-grid field bit for bit, signed and unsigned, on the device and the
// reference, and every sample is the exact distance.
TEST(SdfLayers, FullGridLayerFieldsStackIntoTheWholeFieldAlsoFarFromTheMesh) {
    const Mesh sphere = icosphere(kCentre, 1.2, 2);
    Grid g = offset_grid(16, 0.2, kCentre);
    g.dims[2] = 40;  // the sphere's band reaches layers 1 to 16 or so
    const std::vector<std::pair<int64_t, int64_t>> cuts{{0, 9}, {9, 23}, {23, 31}, {31, 0}};
    const std::vector<double> exact = brute_force_distance(sphere, g);
    for (const bool sign : {false, true})
        for (const bool reference : {false, true}) {
            SCOPED_TRACE(std::string(reference ? "reference" : "device") +
                         (sign ? " signed" : " unsigned"));
            SdfOptions o = band(2.0, true);
            o.brick_size = 8;
            VoxelizeStats stats;
            auto run = [&](const SdfOptions& options) {
                if (reference)
                    return sign ? signed_distance_reference(sphere, g, options, &stats)
                                : unsigned_distance_reference(sphere, g, options, &stats);
                return sign ? signed_distance(device(), sphere, g, options, &stats)
                            : unsigned_distance(device(), sphere, g, options, &stats);
            };
            const ScalarField whole = run(o);
            const uint64_t inside = stats.voxels_set;
            std::vector<float> stacked;
            uint64_t stacked_inside = 0;
            for (const auto& [first, end] : cuts) {
                SdfOptions part = o;
                part.first_layer = first;
                part.end_layer = end;
                const ScalarField f = run(part);
                ASSERT_EQ(f.grid.dims[2], (end ? end : g.dims[2]) - first);
                stacked.insert(stacked.end(), f.values.begin(), f.values.end());
                stacked_inside += stats.voxels_set;
            }
            ASSERT_EQ(stacked.size(), whole.values.size());
            EXPECT_EQ(0, std::memcmp(stacked.data(), whole.values.data(),
                                     stacked.size() * sizeof(float)));
            // The inside voxels each slab reports are those of its layers.
            EXPECT_EQ(stacked_inside, inside);
            EXPECT_EQ(inside, uint64_t(std::count_if(stacked.begin(), stacked.end(),
                                                     [](float v) { return std::signbit(v); })));
            if (sign) EXPECT_GT(inside, 100u);
            double worst = 0;
            for (size_t v = 0; v < stacked.size(); ++v)
                worst = std::max(worst, std::abs(std::abs(double(stacked[v])) - exact[v]));
            EXPECT_LT(worst, 1e-4 * g.voxel_size);
        }
}

TEST(SdfLayers, BadLayerRangesAreRefused) {
    const Mesh m = icosphere(kCentre, 2.0, 0);
    const Grid g = offset_grid(8, 1.0, kCentre);
    for (const auto& [first, end] :
         std::vector<std::pair<int64_t, int64_t>>{{-1, 4}, {4, 4}, {5, 3}, {0, 9}, {8, 0}}) {
        SdfOptions o = band(2.0);
        o.first_layer = first;
        o.end_layer = end;
        EXPECT_THROW(unsigned_distance_reference(m, g, o), GridError) << first << " " << end;
        EXPECT_THROW(unsigned_distance(device(), m, g, o), GridError) << first << " " << end;
    }
}

// ---- CSG
// -----------------------------------------------------------------------------------------

// Signed distance to a sphere, built directly (not through a mesh).
ScalarField sphere_field(const Grid& g, const Vec3d& c, double r) {
    ScalarField f;
    f.grid = g;
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i)
                f.values.push_back(float(norm(sub(centre_of(g, i, j, k), c)) - r));
    return f;
}

double inside_volume(const ScalarField& f) {
    size_t n = 0;
    for (float v : f.values) n += v < 0;
    return double(n) * std::pow(f.grid.voxel_size, 3);
}

TEST(Csg, VolumesOfTwoSpheresMatchTheAnalyticLens) {
    const double r1 = 1.0, r2 = 0.8, d = 1.1;
    Grid g;
    g.voxel_size = 0.025;
    g.origin = {-1.2, -1.2, -1.2};
    g.dims = {int64_t(3.4 / g.voxel_size), 96, 96};
    const ScalarField a = sphere_field(g, {0, 0, 0}, r1), b = sphere_field(g, {d, 0, 0}, r2);
    const double pi = std::acos(-1.0);
    const double v1 = 4.0 / 3.0 * pi * r1 * r1 * r1, v2 = 4.0 / 3.0 * pi * r2 * r2 * r2;
    // Volume of the intersection of two balls (the lens), centres d apart.
    const double lens =
        pi * std::pow(r1 + r2 - d, 2) *
        (d * d + 2 * d * r2 - 3 * r2 * r2 + 2 * d * r1 + 6 * r1 * r2 - 3 * r1 * r1) / (12 * d);
    EXPECT_NEAR(inside_volume(csg(a, b, CsgOp::Union)), v1 + v2 - lens, 0.01 * (v1 + v2));
    EXPECT_NEAR(inside_volume(csg(a, b, CsgOp::Intersection)), lens, 0.01 * (v1 + v2));
    EXPECT_NEAR(inside_volume(csg(a, b, CsgOp::Difference)), v1 - lens, 0.01 * (v1 + v2));
    EXPECT_NEAR(inside_volume(csg(b, a, CsgOp::Difference)), v2 - lens, 0.01 * (v1 + v2));
}

TEST(Csg, FieldsOnDifferentGridsAreRefused) {
    Grid g;
    g.dims = {4, 4, 4};
    Grid h = g;
    h.origin[1] = 0.5;
    EXPECT_THROW(csg(sphere_field(g, {2, 2, 2}, 1), sphere_field(h, {2, 2, 2}, 1), CsgOp::Union),
                 GridError);
    EXPECT_THROW(csg(SparseVoxels(g, 4), SparseVoxels(h, 4), CsgOp::Union), GridError);
    EXPECT_THROW(csg_op_from_string("xor"), GridError);
    EXPECT_EQ(csg_op_from_string("Difference"), CsgOp::Difference);
}

TEST(Csg, OccupancyOperationsAreBitwiseSetOperations) {
    Grid g;
    g.dims = {21, 13, 17};
    std::mt19937 rng(3);
    SparseVoxels a(g, 8), b(g, 4);
    std::vector<uint8_t> da(size_t(g.voxel_count())), db(da.size());
    for (size_t v = 0; v < da.size(); ++v) {
        const int64_t i = int64_t(v) % 21, j = int64_t(v) / 21 % 13, k = int64_t(v) / (21 * 13);
        // Sparse enough that some bricks are empty in one set and not the other.
        if (rng() % 7 == 0 && i < 15) {
            da[v] = 1;
            a.set(i, j, k);
        }
        if (rng() % 5 == 0 && k > 6) {
            db[v] = 1;
            b.set(i, j, k);
        }
    }
    for (CsgOp op : {CsgOp::Union, CsgOp::Intersection, CsgOp::Difference}) {
        const std::vector<uint8_t> got = csg(a, b, op).to_dense();
        for (size_t v = 0; v < da.size(); ++v) {
            const bool expected = op == CsgOp::Union          ? (da[v] || db[v])
                                  : op == CsgOp::Intersection ? (da[v] && db[v])
                                                              : (da[v] && !db[v]);
            ASSERT_EQ(bool(got[v]), expected) << to_string(op) << " voxel " << v;
        }
    }
}

TEST(Csg, FitGridOfTwoMeshesCoversBoth) {
    const Mesh a = box_mesh({0, 0, 0}, {1, 1, 1});
    const Mesh b = box_mesh({3, -2, 0.5}, {4, -1, 2});
    GridFit fit;
    fit.resolution = 40;
    const Grid g = fit_grid(a, b, fit);
    for (const Vec3d& p : {Vec3d{0, -2, 0}, Vec3d{4, 1, 2}})
        for (int k = 0; k < 3; ++k) {
            EXPECT_LE(g.origin[k], p[k] + 1e-12);
            EXPECT_GE(g.origin[k] + double(g.dims[k]) * g.voxel_size, p[k] - 1e-12);
        }
    EXPECT_NEAR(g.voxel_size, 4.0 / 40, 1e-12);
}

// ---- progress and cancellation
// -----------------------------------------------------------------------

// Phases' counts map onto one fixed total in proportion to their weights and never go back; a
// nested run's reports are forwarded.
TEST(PhasedProgress, PhasesShareOneTotalByWeight) {
    ProgressLog log;
    log.slow = true;  // every report reaches the callback
    detail::ProgressPhases progress(log.callback(), "test run");
    const size_t first = progress.add(1), second = progress.add(3);
    progress.report(first, 1, 2);                 // half of the first quarter
    progress.report(second, 1, 4);                // a quarter of the other three
    progress.report(first, 2, 2);                 // behind what was reported: held
    EXPECT_TRUE(progress.forward(second)(3, 4));  // a nested run's report
    progress.finish();
    const uint64_t total = detail::kPhasedProgressTotal;
    const std::vector<std::pair<uint64_t, uint64_t>> expected{{total / 8, total},
                                                              {total * 7 / 16, total},
                                                              {total * 7 / 16, total},
                                                              {total * 13 / 16, total},
                                                              {total, total}};
    EXPECT_EQ(log.calls, expected);
}

TEST(PhasedProgress, ReportsAreThinnedButTheEndAlwaysArrives) {
    ProgressLog log;
    detail::ProgressPhases progress(log.callback(), "test run");
    const size_t phase = progress.add(1);
    for (uint64_t done = 1; done <= 1000; ++done) progress.report(phase, done, 1000);
    progress.finish();
    EXPECT_LT(log.calls.size(), 100u);  // 1000 reports in far less than 50 ms each
    log.expect_contract("thinned");

    detail::ProgressPhases none({}, "no callback");
    none.report(none.add(1), 1, 2);
    none.finish();
    EXPECT_FALSE(bool(none.forward(0)));
}

TEST(PhasedProgress, FalseThrowsCancelledButIsReturnedToANestedRun) {
    ProgressLog log;
    log.slow = true;
    log.cancel_from = 0;
    detail::ProgressPhases progress(log.callback(), "test run");
    const size_t phase = progress.add(1);
    EXPECT_FALSE(progress.forward(phase)(1, 2));  // the nested run throws its own Cancelled
    EXPECT_THROW(progress.report(phase, 2, 2), Cancelled);
    EXPECT_THROW(progress.finish(), Cancelled);
    EXPECT_EQ(log.calls.size(), 3u);
}

// A signed full-grid field runs every phase: band, the search beyond it, the sign. With every
// report let through, the device reports each kernel slice of each of them on one total; the
// reference reports as it goes. Slicing the kernels changes no value.
TEST(SdfProgress, EveryPhaseReportsOnOneTotalAndTheFieldIsUnchanged) {
    const Mesh sphere = icosphere(kCentre, 2.6, 2);
    const Grid g = offset_grid(24, 0.3, kCentre);
    SdfOptions o = band(2.0, true);
    const ScalarField quiet = signed_distance_reference(sphere, g, o);

    ProgressLog log;
    log.slow = true;
    o.progress = log.callback();
    expect_identical(signed_distance(device(), sphere, g, o), quiet);
    log.expect_contract("device");
    EXPECT_EQ(log.calls.back().second, detail::kPhasedProgressTotal);
    EXPECT_GE(log.steps_inside(), 2u);  // the ends of the band and of the search beyond it

    ProgressLog reference;
    o.progress = reference.callback();
    expect_identical(signed_distance_reference(sphere, g, o), quiet);
    reference.expect_contract("reference");
}

// Cancelling at any point stops the run with Cancelled, and nothing is reported after the false
// answer: at the first report, in the band, in the search beyond it, in the sign's solid
// voxelization (parity and winding number, forwarded) and at the end. Every device report is let
// through (the device reports once per kernel slice); the reference, which reports per triangle and
// per slice of voxels, runs at full speed and cancels at the first report that reaches the
// callback.
TEST(SdfProgress, FalseAnywhereCancels) {
    const Mesh sphere = icosphere(kCentre, 2.6, 2);
    const Grid g = offset_grid(24, 0.3, kCentre);
    struct Case {
        bool full;
        InsideTest inside;
        double at;              // fraction of the total at which the callback answers false
        const char* device_by;  // what the device run's Cancelled names
    };
    // Narrow band: the band pass is 2/3 of the estimated work, the sign the last third; the sign's
    // solid voxelization throws its own Cancelled.
    const std::vector<Case> cases{{false, InsideTest::Parity, 0.0, "signed distance field"},
                                  {false, InsideTest::Parity, 0.5, "signed distance field"},
                                  {false, InsideTest::Parity, 0.9, "solid voxelization"},
                                  {false, InsideTest::Winding, 0.9, "solid voxelization"},
                                  {true, InsideTest::Parity, 0.5, "signed distance field"},
                                  {true, InsideTest::Parity, 1.0, "solid voxelization"}};
    for (const Case& c : cases)
        for (bool on_device : {true, false}) {
            SdfOptions o = band(2.0, c.full);
            o.inside = c.inside;
            ProgressLog log;
            log.slow = on_device;
            log.cancel_from = c.at;
            o.progress = log.callback();
            const std::string what = std::string(on_device ? "device" : "reference") +
                                     (c.full ? " full " : " band ") + to_string(c.inside) + " at " +
                                     std::to_string(c.at);
            try {
                on_device ? signed_distance(device(), sphere, g, o)
                          : signed_distance_reference(sphere, g, o);
                ADD_FAILURE() << what << ": not cancelled";
            } catch (const Cancelled& e) {
                if (on_device)
                    EXPECT_NE(std::string(e.what()).find(c.device_by), std::string::npos)
                        << what << ": " << e.what();
            }
            ASSERT_TRUE(log.cancelled) << what;
            for (size_t i = 0; i + 1 < log.calls.size(); ++i)
                ASSERT_LT(double(log.calls[i].first), c.at * double(log.calls[i].second))
                    << what << ": call " << i << " should have cancelled";
        }
    SdfOptions o = band(2.0);
    o.progress = [](uint64_t, uint64_t) { return false; };
    EXPECT_THROW(unsigned_distance(device(), sphere, g, o), Cancelled);
    EXPECT_THROW(unsigned_distance_reference(sphere, g, o), Cancelled);
}

// CSG of two meshes is the CSG of their signed fields, on the device as on the host, with one
// progress over both fields; a false answer in either field cancels it.
TEST(CsgProgress, MeshCsgIsTheCsgOfTheFieldsWithOneProgress) {
    const Mesh a = icosphere(kCentre, 2.0, 2);
    const Mesh b = box_mesh({kCentre[0] - 0.4, kCentre[1] - 0.3, kCentre[2] - 2.5},
                            {kCentre[0] + 2.7, kCentre[1] + 0.6, kCentre[2] + 2.5});
    GridFit fit;
    fit.resolution = 40;
    fit.pad = 3;
    const Grid g = fit_grid(a, b, fit);
    for (CsgOp op : {CsgOp::Union, CsgOp::Difference}) {
        SdfOptions o = band(2.0);
        const ScalarField expected =
            csg(signed_distance_reference(a, g, o), signed_distance_reference(b, g, o), op);
        ProgressLog log;
        log.slow = true;
        o.progress = log.callback();
        VoxelizeStats stats;
        expect_identical(csg(device(), a, b, op, g, o, &stats), expected);
        log.expect_contract("csg on the device");
        EXPECT_EQ(stats.triangles_in, a.triangles.size() + b.triangles.size());
        ProgressLog reference;
        o.progress = reference.callback();
        expect_identical(csg_reference(a, b, op, g, o), expected);
        reference.expect_contract("csg reference");
    }
    for (bool on_device : {true, false})
        for (double at : {0.0, 0.6, 1.0}) {
            SdfOptions o = band(2.0);
            ProgressLog log;
            log.slow = on_device && at > 0;
            log.cancel_from = at;
            o.progress = log.callback();
            EXPECT_THROW(on_device ? csg(device(), a, b, CsgOp::Union, g, o)
                                   : csg_reference(a, b, CsgOp::Union, g, o),
                         Cancelled)
                << on_device << " " << at;
            EXPECT_TRUE(log.cancelled);
        }
}

// ---- files
// ---------------------------------------------------------------------------------------

std::string temp_path(const std::string& name) {
    return (::testing::TempDir() + "oclvox_sdf_" + std::to_string(getpid()) + "_" + name);
}

ScalarField sample_field() {
    Grid g;
    g.voxel_size = 0.5;
    g.origin = {-3.25, 1.5, 10.0};
    g.dims = {11, 7, 5};
    ScalarField f = sphere_field(g, {-0.5, 3.0, 11.2}, 1.3);
    for (float& v : f.values) v = std::clamp(v, -1.0f, 1.0f);  // a narrow band of 2 voxels
    return f;
}

TEST(FieldFiles, NpyRoundTripsAndIsFortranOrderedFloat32) {
    const ScalarField f = sample_field();
    const std::string path = temp_path("field.npy");
    write_field(path, f);
    const ScalarField back = read_field(path);
    EXPECT_EQ(back.grid.origin, f.grid.origin);
    EXPECT_EQ(back.grid.voxel_size, f.grid.voxel_size);
    EXPECT_EQ(back.grid.dims, f.grid.dims);
    expect_identical(back, f);

    // The bytes: header says float32, Fortran order, shape (nx, ny, nz); the data is x fastest.
    std::ifstream in(path, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const size_t data = bytes.size() - f.values.size() * 4;
    EXPECT_EQ(data % 64, 0u);
    const std::string header = bytes.substr(10, data - 10);
    EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos) << header;
    EXPECT_NE(header.find("'fortran_order': True"), std::string::npos);
    EXPECT_NE(header.find("'shape': (11, 7, 5)"), std::string::npos);
    float sample;
    std::memcpy(&sample, bytes.data() + data + 4 * (3 + 11 * (2 + 7 * 4)), 4);
    EXPECT_EQ(sample, f.values[3 + 11 * (2 + 7 * 4)]);

    std::ifstream sidecar_in(path + ".json");
    const nlohmann::json sidecar = nlohmann::json::parse(sidecar_in);
    EXPECT_EQ(sidecar.at("band_voxels").get<double>(), 2.0);
    EXPECT_NE(sidecar.at("sample_position").get<std::string>().find("voxel centres"),
              std::string::npos);
    EXPECT_NE(sidecar.at("sign_convention").get<std::string>().find("negative inside"),
              std::string::npos);
    std::remove(path.c_str());
    std::remove((path + ".json").c_str());
}

std::string file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

// Two .npy fields: the same bytes, and sidecars that differ only in the file they name.
void expect_same_npy(const std::string& path_a, const std::string& path_b) {
    EXPECT_EQ(file_bytes(path_a), file_bytes(path_b));
    nlohmann::json a = nlohmann::json::parse(file_bytes(path_a + ".json"));
    nlohmann::json b = nlohmann::json::parse(file_bytes(path_b + ".json"));
    a.erase("file");
    b.erase("file");
    EXPECT_EQ(a, b);
}

// Two .vdb level sets read back through OpenVDB: the same active voxels and values (inactive
// signs included) over the grid and a voxel around it, background, transform and band metadata.
void expect_same_level_set(const std::string& path_a, const std::string& path_b, const Grid& g) {
    openvdb::initialize();
    auto read = [](const std::string& path) {
        openvdb::io::File file(path);
        file.open();
        auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("sdf"));
        file.close();
        return grid;
    };
    const auto a = read(path_a), b = read(path_b);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->activeVoxelCount(), b->activeVoxelCount());
    EXPECT_GT(a->activeVoxelCount(), 0u);
    EXPECT_EQ(a->tree().leafCount(), b->tree().leafCount());
    EXPECT_EQ(a->background(), b->background());
    EXPECT_EQ(a->transform(), b->transform());
    EXPECT_EQ(a->metaValue<double>("oclvox_band_voxels"),
              b->metaValue<double>("oclvox_band_voxels"));
    const auto access_a = a->getConstAccessor(), access_b = b->getConstAccessor();
    for (int64_t k = -1; k <= g.dims[2]; ++k)
        for (int64_t j = -1; j <= g.dims[1]; ++j)
            for (int64_t i = -1; i <= g.dims[0]; ++i) {
                const openvdb::Coord at{int(i), int(j), int(k)};
                ASSERT_EQ(access_a.isValueOn(at), access_b.isValueOn(at));
                ASSERT_EQ(access_a.getValue(at), access_b.getValue(at))
                    << i << " " << j << " " << k;
            }
}

// A field written a layer at a time (as `sdf --full` writes one slab after another) gives the
// whole field's files, with its band given or found from the samples as they pass (the whole
// field's writer finds it before): the same .npy bytes and sidecar, and a .vdb with the same
// voxels, values, background and band. Each layer is asked for once, in order.
TEST(FieldFiles, LayerByLayerFilesEqualTheWholeFieldsFiles) {
    Grid g;
    g.voxel_size = 0.25;
    g.origin = {-2.0, -1.5, -3.0};
    g.dims = {13, 11, 21};  // 21 layers: two whole leaves of 8 and a part
    const ScalarField f = sphere_field(g, {-0.4, 0.1, -0.7}, 1.1);
    const size_t per_layer = size_t(g.dims[0] * g.dims[1]);
    for (const std::string extension : {".npy", ".vdb"})
        for (const double band : {0.0, 2.0}) {
            SCOPED_TRACE(extension + " band " + std::to_string(band));
            const std::string whole = temp_path("whole" + extension);
            const std::string layers = temp_path("layers" + extension);
            write_field(whole, f, band);
            int64_t next = 0;
            write_field(layers, g, band, [&](int64_t k, float* out) {
                EXPECT_EQ(k, next++);
                std::copy_n(&f.values[size_t(k) * per_layer], per_layer, out);
            });
            EXPECT_EQ(next, g.dims[2]);
            // Without a band, the largest |value|, as the whole field's writer infers it.
            float largest = 0;
            for (float v : f.values) largest = std::max(largest, std::abs(v));
            const double expected_band = band > 0 ? band : double(largest) / g.voxel_size;
            if (extension == ".npy") {
                expect_same_npy(whole, layers);
                EXPECT_EQ(nlohmann::json::parse(file_bytes(layers + ".json"))
                              .at("band_voxels")
                              .get<double>(),
                          expected_band);
                std::remove((whole + ".json").c_str());
                std::remove((layers + ".json").c_str());
            } else {
                expect_same_level_set(whole, layers, g);
                EXPECT_EQ(read_sparse_field(layers).band_voxels(), expected_band);
            }
            std::remove(whole.c_str());
            std::remove(layers.c_str());
        }
}

TEST(FieldFiles, COrderNpyIsTransposedOnRead) {
    // A 2x3x4 float64 array in C order (z fastest) written by hand, value = 100 i + 10 j + k.
    const std::string path = temp_path("c_order.npy");
    std::string dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3, 4), }";
    dict += std::string((64 - (10 + dict.size() + 1) % 64) % 64, ' ') + "\n";
    {
        std::ofstream out(path, std::ios::binary);
        out.write("\x93NUMPY\x01\x00", 8);
        out.put(char(dict.size() & 0xff));
        out.put(char(dict.size() >> 8));
        out << dict;
        for (int i = 0; i < 2; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 4; ++k) {
                    const double v = 100 * i + 10 * j + k;
                    out.write(reinterpret_cast<const char*>(&v), 8);
                }
        std::ofstream(path + ".json") << R"({"origin": [1, 2, 3], "voxel_size": 0.5})";
    }
    const ScalarField f = read_field(path);
    EXPECT_EQ(f.grid.dims, (std::array<int64_t, 3>{2, 3, 4}));
    EXPECT_EQ(f.grid.origin, (std::array<double, 3>{1, 2, 3}));
    for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 4; ++k)
                EXPECT_EQ(f.values[size_t(i + 2 * (j + 3 * k))], 100 * i + 10 * j + k);
    std::remove((path + ".json").c_str());
    EXPECT_THROW(read_field(path), InputError);  // no sidecar
    std::remove(path.c_str());
    EXPECT_THROW(read_field(path), InputError);  // no file
}

TEST(FieldFiles, VdbIsALevelSetWithCentreSampledTransform) {
    const ScalarField f = sample_field();
    const Grid& g = f.grid;
    const std::string path = temp_path("field.vdb");
    write_field(path, f, 2.0);

    openvdb::initialize();
    openvdb::io::File file(path);
    file.open();
    const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("sdf"));
    file.close();
    ASSERT_TRUE(grid);
    EXPECT_EQ(grid->getGridClass(), openvdb::GRID_LEVEL_SET);
    EXPECT_FLOAT_EQ(grid->background(), float(2.0 * g.voxel_size));
    EXPECT_NEAR(grid->voxelSize()[0], g.voxel_size, 1e-12);
    // Index (i, j, k) is the centre of voxel (i, j, k) in world space.
    const openvdb::Vec3d world = grid->indexToWorld(openvdb::Coord(3, 2, 4));
    const Vec3d centre = centre_of(g, 3, 2, 4);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(world[k], centre[k], 1e-9);

    const auto access = grid->getConstAccessor();
    size_t active = 0;
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const float v = f.values[size_t(i + g.dims[0] * (j + g.dims[1] * k))];
                const openvdb::Coord c{int(i), int(j), int(k)};
                if (std::abs(v) < 1.0f) {
                    ++active;
                    EXPECT_EQ(access.getValue(c), v);
                    EXPECT_TRUE(access.isValueOn(c));
                } else {
                    EXPECT_FALSE(access.isValueOn(c));
                }
            }
    EXPECT_GT(active, 0u);
    EXPECT_EQ(grid->activeVoxelCount(), active);
    std::remove(path.c_str());
}

TEST(FieldFiles, UnknownExtensionIsAnOutputError) {
    EXPECT_THROW(write_field(temp_path("field.txt"), sample_field()), OutputError);
}

// ---- sparse narrow-band fields ----------------------------------------------------------------

// The meshes of the sparse tests: a closed sphere off the origin (parity sign), the closed scan
// (parity) and open random triangles (winding-number sign, leaves at the grid's faces).
struct SparseCase {
    const char* name;
    Mesh mesh;
    Grid grid;
};

std::vector<SparseCase> sparse_cases() {
    std::vector<SparseCase> cases;
    cases.push_back({"sphere", icosphere(kCentre, 2.6, 3), offset_grid(37, 0.2, kCentre)});
    const Mesh bunny = load_mesh(mesh_path("bunny00.off"));
    GridFit fit;
    fit.resolution = 45;
    fit.pad = 4;
    cases.push_back({"bunny00", bunny, fit_grid(bunny, fit)});
    Grid rg;
    rg.dims = {29, 34, 27};
    cases.push_back({"random", random_triangles(120, -3.0, 33.0, 5.0, 11), rg});
    // Triangles without a face, whose distance is their edges': collinear ones, ones with two
    // corners at one point, and points.
    Mesh degenerate = random_triangles(60, 2.0, 25.0, 4.0, 5);
    for (size_t t = 0; t < degenerate.triangles.size(); ++t) {
        const auto& tri = degenerate.triangles[t];
        const Vec3d a = degenerate.positions[tri[0]], b = degenerate.positions[tri[1]];
        Vec3d& c = degenerate.positions[tri[2]];
        for (int k = 0; k < 3; ++k)
            c[k] = t % 3 == 0 ? a[k] + 0.375 * (b[k] - a[k]) : t % 3 == 1 ? b[k] : a[k];
        if (t % 3 == 2) degenerate.positions[tri[1]] = a;
    }
    cases.push_back({"degenerate", degenerate, rg});
    return cases;
}

TEST(SparseSdf, ToDenseIsTheDenseFieldBitForBitOnDeviceAndReference) {
    for (const SparseCase& c : sparse_cases())
        for (const SdfOptions& o : {band(3.0), band(1.25)}) {
            SCOPED_TRACE(std::string(c.name) + " band " + std::to_string(o.band_voxels));
            VoxelizeStats stats;
            const SparseField sparse = signed_distance_sparse(device(), c.mesh, c.grid, o, &stats);
            const SparseField reference = signed_distance_sparse_reference(c.mesh, c.grid, o);
            EXPECT_EQ(sparse.leaf_indices(), reference.leaf_indices());
            EXPECT_EQ(stats.bricks_active, sparse.leaf_count());
            EXPECT_GT(sparse.leaf_count(), 0u);
            const ScalarField dense = signed_distance(device(), c.mesh, c.grid, o);
            expect_identical(sparse.to_dense(), dense);
            expect_identical(sparse.to_dense(), reference.to_dense());
            expect_identical(reference.to_dense(), signed_distance_reference(c.mesh, c.grid, o));
            EXPECT_EQ(border_samples_inside(sparse), border_samples_inside(dense));
        }
}

// Sparse and dense band fields as a GPU computes them (device_used_as_a_gpu: uploads, leaves
// downloaded from the device's memory), in one batch of leaves and in many, are this device's
// fields sample for sample.
TEST(SparseSdf, FieldsComputedAsOnAGpuEqualThisDevicesFields) {
    Device& gpu = device_used_as_a_gpu();
    for (const SparseCase& c : sparse_cases()) {
        SCOPED_TRACE(c.name);
        SdfOptions o = band(2.0);
        const ScalarField expected = signed_distance(device(), c.mesh, c.grid, o);
        expect_identical(signed_distance(gpu, c.mesh, c.grid, o), expected);
        expect_identical(signed_distance_sparse(gpu, c.mesh, c.grid, o).to_dense(), expected);
        o.device_budget_bytes = 7 * SparseField::kLeafSamples * 4;  // seven leaves a batch
        VoxelizeStats stats;
        expect_identical(signed_distance_sparse(gpu, c.mesh, c.grid, o, &stats).to_dense(),
                         expected);
        EXPECT_GT(stats.batches, 1u);
    }
}

TEST(SparseSdf, BatchBudgetAndBrickSizeDoNotChangeAnySample) {
    const SparseCase c = sparse_cases()[1];
    const SdfOptions o = band(2.0);
    VoxelizeStats one_batch;
    const ScalarField expected =
        signed_distance_sparse(device(), c.mesh, c.grid, o, &one_batch).to_dense();
    EXPECT_EQ(one_batch.batches, 1u);
    SdfOptions small = o;
    small.device_budget_bytes = 7 * SparseField::kLeafSamples * 4;  // seven leaves a batch
    small.brick_size = 16;
    // Progress over all batches on one total, never going back, ending at the total.
    uint64_t last = 0, calls = 0;
    bool monotonic = true;
    small.progress = [&](uint64_t done, uint64_t total) {
        monotonic = monotonic && done >= last && done <= total;
        last = done;
        ++calls;
        return true;
    };
    VoxelizeStats many;
    const SparseField batched = signed_distance_sparse(device(), c.mesh, c.grid, small, &many);
    EXPECT_EQ(many.batches, (batched.leaf_count() + 6) / 7);
    expect_identical(batched.to_dense(), expected);
    EXPECT_TRUE(monotonic);
    // Reports are at most one per 50 ms after the first, so a fast device (an H200 here) may
    // make only the first and the last.
    EXPECT_GE(calls, 2u);
    EXPECT_EQ(last, 1000000u);
}

TEST(SparseSdf, LeavesFollowTheSurface) {
    // Every stored leaf is within the band (plus the leaf's half diagonal) of the sphere, and
    // every voxel that close to it lies in a stored leaf: leaves are where the surface is.
    const double vs = 0.05, radius = 2.0;
    const Mesh m = icosphere(kCentre, radius, 4);
    const Grid g = offset_grid(100, vs, kCentre);
    const SparseField f = signed_distance_sparse(device(), m, g, band(3.0));
    const auto n = f.leaf_dims();
    const double reach =
        3.0 * vs + icosphere_sagitta(m, kCentre, radius) + std::sqrt(3.0) * SparseField::kLeaf * vs;
    for (uint64_t leaf : f.leaf_indices()) {
        const int64_t x = int64_t(leaf % uint64_t(n[0])) * 8 + 4,
                      y = int64_t(leaf / uint64_t(n[0]) % uint64_t(n[1])) * 8 + 4,
                      z = int64_t(leaf / uint64_t(n[0] * n[1])) * 8 + 4;
        const double r = norm(sub(centre_of(g, x, y, z), kCentre));
        ASSERT_LT(std::abs(r - radius), reach) << leaf;
    }
    // A shell of leaves, far fewer samples than the grid.
    const double shell = 4 * M_PI * radius * radius / (vs * vs) * 6;  // area times band width
    EXPECT_LT(double(f.leaf_count() * SparseField::kLeafSamples), 4 * shell);
}

TEST(SparseSdf, GridBeyondTheDenseBudgetCompletesSparse) {
    // 640^3 voxels: the dense field (4 bytes a voxel) is refused by a 256 MiB budget, the sparse
    // one is not, and its samples are the sphere's distances.
    const double vs = 0.1, radius = 1.5;
    const Mesh m = icosphere(kCentre, radius, 3);
    Grid g = offset_grid(640, vs, kCentre);
    g.dims = {640, 640, 640};
    SdfOptions o = band(3.0);
    o.host_budget_bytes = uint64_t(256) << 20;
    EXPECT_THROW(signed_distance(device(), m, g, o), GridError);
    const SparseField f = signed_distance_sparse(device(), m, g, o);
    const double sagitta = icosphere_sagitta(m, kCentre, radius);
    const Vec3d c = to_grid(g, kCentre);
    size_t checked = 0;
    for (int64_t d = -20; d <= 20; ++d) {
        const int64_t i = int64_t(c[0]) + d, j = int64_t(c[1]), k = int64_t(c[2]);
        const double r = norm(sub(centre_of(g, i, j, k), kCentre));
        const double expected = (r - radius) / vs;  // signed, in voxels, up to the sagitta
        const float value = f.at(i, j, k) / float(vs);
        if (std::abs(expected) < 3.0 - sagitta / vs - 1e-3) {
            EXPECT_NEAR(value, expected, sagitta / vs + 1e-3) << d;
            ++checked;
        } else if (std::abs(expected) > 3.0 + 1e-3) {
            EXPECT_EQ(std::abs(value), 3.0f) << d;
            EXPECT_EQ(value < 0, expected < 0) << d;
        }
    }
    EXPECT_GT(checked, 8u);
    EXPECT_EQ(f.at(0, 0, 0), f.background());
    EXPECT_EQ(f.at(int64_t(c[0]), int64_t(c[1]), int64_t(c[2])), -f.background());
}

// Sparse fields of layer ranges (cut at multiples of 8, not of the brick size) hold the whole
// field's leaves of those layers, sample for sample, and merged in either order (appended, or
// interleaved) they are the whole field: leaves, samples and inside voxels. Device and reference,
// a closed sphere (parity), the scan and open random triangles (winding number).
TEST(SparseSdf, LayerFieldsMergeIntoTheWholeField) {
    for (const SparseCase& c : sparse_cases())
        for (const bool reference : {false, true}) {
            SCOPED_TRACE(std::string(c.name) + (reference ? " reference" : " device"));
            SdfOptions o = band(2.0);
            o.brick_size = 12;
            auto run = [&](const SdfOptions& options) {
                return reference ? signed_distance_sparse_reference(c.mesh, c.grid, options)
                                 : signed_distance_sparse(device(), c.mesh, c.grid, options);
            };
            const SparseField whole = run(o);
            const auto n = whole.leaf_dims();
            const uint64_t per_layer = uint64_t(n[0]) * uint64_t(n[1]);
            std::vector<SparseField> parts;
            for (const auto& [first, end] :
                 std::vector<std::pair<int64_t, int64_t>>{{0, 8}, {8, 24}, {24, 0}}) {
                SdfOptions part = o;
                part.first_layer = first;
                part.end_layer = end;
                parts.push_back(run(part));
                // Its leaves are the whole field's in leaf layers first / 8 up to end / 8.
                const uint64_t lo = uint64_t(first / 8) * per_layer,
                               hi = end ? uint64_t(end / 8) * per_layer : UINT64_MAX;
                std::vector<uint64_t> expected;
                for (const uint64_t leaf : whole.leaf_indices())
                    if (leaf >= lo && leaf < hi) expected.push_back(leaf);
                EXPECT_EQ(parts.back().leaf_indices(), expected) << first;
                EXPECT_GT(expected.size(), 0u) << first;
            }
            SparseField forward = parts[0];
            forward.merge(parts[1]);
            forward.merge(parts[2]);
            SparseField backward = parts[2];
            backward.merge(parts[0]);
            backward.merge(parts[1]);
            for (const SparseField* merged : {&forward, &backward}) {
                EXPECT_EQ(merged->leaf_indices(), whole.leaf_indices());
                expect_identical(merged->to_dense(), whole.to_dense());
                EXPECT_TRUE(merged->inside().same_voxels(whole.inside()));
            }
        }
}

TEST(SparseSdf, FullGridUnalignedLayersAndLayeredCsgAreRefused) {
    const SparseCase c = sparse_cases()[0];
    EXPECT_THROW(signed_distance_sparse(device(), c.mesh, c.grid, band(2.0, true)), GridError);
    for (const auto& [first, end] :
         std::vector<std::pair<int64_t, int64_t>>{{3, 0}, {0, 12}, {8, 8}, {0, 40}}) {
        SdfOptions layers = band(2.0);
        layers.first_layer = first;
        layers.end_layer = end;
        EXPECT_THROW(signed_distance_sparse_reference(c.mesh, c.grid, layers), GridError) << first;
        EXPECT_THROW(signed_distance_sparse(device(), c.mesh, c.grid, layers), GridError) << first;
    }
    EXPECT_THROW(signed_distance_sparse(device(), c.mesh, c.grid, band(-1.0)), GridError);
    SdfOptions layers = band(2.0);
    layers.end_layer = 16;
    EXPECT_THROW(csg_sparse(device(), c.mesh, c.mesh, CsgOp::Union, c.grid, layers), GridError);
}

// Merging needs one grid, band and brick size, and leaves stored in only one of the fields.
TEST(SparseField, MergeRefusesOtherGridsAndSharedLeaves) {
    const SparseCase c = sparse_cases()[0];
    SparseField f = signed_distance_sparse(device(), c.mesh, c.grid, band(2.0));
    EXPECT_THROW(f.merge(f), GridError);
    Grid other = c.grid;
    other.origin[0] += c.grid.voxel_size;
    EXPECT_THROW(f.merge(signed_distance_sparse(device(), c.mesh, other, band(2.0))), GridError);
    EXPECT_THROW(f.merge(signed_distance_sparse(device(), c.mesh, c.grid, band(2.5))), GridError);
    SdfOptions bricks = band(2.0);
    bricks.brick_size = 16;
    EXPECT_THROW(f.merge(signed_distance_sparse(device(), c.mesh, c.grid, bricks)), GridError);
    const size_t leaves = f.leaf_count();
    f.merge(SparseField(c.grid, 2.0, SparseVoxels(c.grid, 64)));  // nothing to add
    EXPECT_EQ(f.leaf_count(), leaves);
}

TEST(SparseSdf, FilesEqualTheDenseFieldsFiles) {
    // The .npy samples are the same bytes; the .vdb read back through OpenVDB has the same active
    // voxels, values, inactive signs and transform.
    const SparseCase c = sparse_cases()[1];
    const SdfOptions o = band(2.5);
    const SparseField sparse = signed_distance_sparse(device(), c.mesh, c.grid, o);
    const ScalarField dense = signed_distance(device(), c.mesh, c.grid, o);
    const std::string sparse_npy = temp_path("sparse.npy"), dense_npy = temp_path("dense.npy");
    write_field(sparse_npy, sparse);
    write_field(dense_npy, dense, o.band_voxels);
    expect_same_npy(sparse_npy, dense_npy);

    const std::string sparse_vdb = temp_path("sparse.vdb"), dense_vdb = temp_path("dense.vdb");
    write_field(sparse_vdb, sparse);
    write_field(dense_vdb, dense, o.band_voxels);
    expect_same_level_set(sparse_vdb, dense_vdb, c.grid);
    for (const auto& path : {sparse_npy, dense_npy, sparse_vdb, dense_vdb})
        std::remove(path.c_str());
    std::remove((sparse_npy + ".json").c_str());
    std::remove((dense_npy + ".json").c_str());
}

// What OpenVDB's own writer makes of a field: a FloatGrid "sdf" of class level set, a voxel
// active where |value(i, j, k)| < background (set voxel by voxel through OpenVDB's API), every
// other value signed by OpenVDB's signed flood fill, our grid's transform and metadata, written by
// io::Stream with active-mask compression. OpenVDB adds "file_delayed_load" metadata (an index
// for its delayed loading of leaves, which its readers do without); it is cut out of the bytes.
std::string openvdb_written_level_set(
    const Grid& g, float background, double band_voxels,
    const std::function<float(int64_t, int64_t, int64_t)>& value) {
    openvdb::initialize();
    const openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
    place_as_our_vdb_files_do(*grid, g, "sdf", openvdb::GRID_LEVEL_SET);
    grid->insertMeta("oclvox_band_voxels", openvdb::DoubleMetadata(band_voxels));
    openvdb::FloatGrid::Accessor access = grid->getAccessor();
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const float v = value(i, j, k);
                if (std::abs(v) < background)
                    access.setValueOn(openvdb::Coord(int(i), int(j), int(k)), v);
            }
    openvdb::tools::signedFloodFill(grid->tree());
    std::string bytes = written_by_openvdb(grid);

    auto int32_at = [&](size_t at) {
        int32_t v;
        std::memcpy(&v, &bytes[at], 4);
        return v;
    };
    auto named = [](const std::string& name) {
        const int32_t size = int32_t(name.size());
        return std::string(reinterpret_cast<const char*>(&size), 4) + name;
    };
    const size_t entry = bytes.find(named("file_delayed_load"));
    if (entry == std::string::npos) return bytes;
    size_t end = entry + 4 + 17;
    end += 4 + size_t(int32_at(end));                     // its type name
    end += 4 + size_t(int32_at(end));                     // its value
    const size_t count = bytes.find(named("class")) - 4;  // the first entry follows the count
    const int32_t entries = int32_at(count) - 1;
    bytes.replace(count, 4, reinterpret_cast<const char*>(&entries), 4);
    bytes.erase(entry, end - entry);
    return bytes;
}

// A sparse field's file, and the dense field's with the band given and with the band found from
// the samples (the largest |value|, the background then: samples at it are inactive).
void expect_level_set_bytes_of_openvdbs_writer(const SparseField& field) {
    const Grid& g = field.grid();
    const auto at = [&](int64_t i, int64_t j, int64_t k) { return field.at(i, j, k); };
    const std::string path = temp_path("bytes.vdb");
    write_field(path, field);
    expect_vdb_bytes_equal_but_uuid(
        file_bytes(path),
        openvdb_written_level_set(g, field.background(), field.band_voxels(), at));

    const ScalarField dense = field.to_dense();
    write_field(path, dense, field.band_voxels());
    expect_vdb_bytes_equal_but_uuid(
        file_bytes(path),
        openvdb_written_level_set(g, field.background(), field.band_voxels(), at));
    const size_t per_layer = size_t(g.dims[0]) * size_t(g.dims[1]);
    write_field(path, g, 0.0, [&](int64_t k, float* out) {
        std::copy_n(&dense.values[size_t(k) * per_layer], per_layer, out);
    });
    float largest = 0;
    for (const float v : dense.values) largest = std::max(largest, std::abs(v));
    expect_vdb_bytes_equal_but_uuid(
        file_bytes(path),
        openvdb_written_level_set(g, largest, double(largest) / g.voxel_size, at));
    std::remove(path.c_str());
}

// The bytes of a field's .vdb, sparse or dense, are those of OpenVDB's writer for the same level
// set (but for the UUID and OpenVDB's delayed-load index): the leaves' masks and values, the
// flood fill's signs in leaves, nodes and root tiles, their compression and the statistics.
TEST(LevelSetFiles, VdbIsByteForByteWhatOpenVdbsWriterMakesOfTheSameLevelSet) {
    for (const SparseCase& c : sparse_cases()) {
        SCOPED_TRACE(c.name);
        expect_level_set_bytes_of_openvdbs_writer(
            signed_distance_sparse_reference(c.mesh, c.grid, band(2.5)));
    }
    {
        SCOPED_TRACE("no leaves");
        const Grid g = unit_grid(9, 9, 9);
        expect_level_set_bytes_of_openvdbs_writer(SparseField(g, 2.0, SparseVoxels(g, 8)));
    }
    // Three upper nodes along z (4096 voxels each) with the middle one empty: the flood fill
    // makes it an inside tile of the root, between two inside leaves. In the last, beside an
    // inside leaf, a leaf of both signs reaching past the grid's x face, which signs the tiles
    // after it outside; in the middle a stored leaf with no sample in the band (no leaf).
    SCOPED_TRACE("root tiles");
    const Grid g = unit_grid(12, 8, 8200);
    SparseField field(g, 2.0, SparseVoxels(g, 8));
    const float bg = field.background();
    std::vector<float> samples(SparseField::kLeafSamples);
    std::fill(samples.begin(), samples.end(), -0.5f * bg);
    field.append_leaf(0, samples.data());  // leaf (0, 0, 0)
    std::fill(samples.begin(), samples.end(), bg);
    field.append_leaf(1024, samples.data());  // leaf (0, 0, 512): z 4096, nothing in the band
    std::fill(samples.begin(), samples.end(), -0.25f * bg);
    field.append_leaf(2048, samples.data());  // leaf (0, 0, 1024): z 8192
    for (int z = 0; z < 8; ++z)
        for (int y = 0; y < 8; ++y)
            for (int x = 0; x < 8; ++x)
                samples[size_t(x + 8 * (y + 8 * z))] =
                    x < 4 ? 0.35f * bg * float(x - 2 * y + z - 1) : bg;
    field.append_leaf(2049, samples.data());  // leaf (1, 0, 1024): x 8..11 in the grid
    expect_level_set_bytes_of_openvdbs_writer(field);

    // And OpenVDB reads the gap as inside, from our file.
    const std::string path = temp_path("root_tiles.vdb");
    write_field(path, field);
    openvdb::io::File file(path);
    file.open();
    const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("sdf"));
    file.close();
    ASSERT_TRUE(grid);
    EXPECT_EQ(grid->tree().getValue(openvdb::Coord(3, 3, 6000)), -bg);
    EXPECT_EQ(grid->tree().getValue(openvdb::Coord(3, 3, 9000)), bg);
    std::remove(path.c_str());
}

// ---- level sets read from .vdb ------------------------------------------------------------------

TEST(LevelSetFiles, OurVdbReadsBackToTheSameGridAndSamples) {
    // write_field keeps the grid in metadata and the signs by flood fill, so reading back gives
    // the same dense samples (and so the same meshes), whatever leaves had no band sample.
    for (const SparseCase& c : sparse_cases()) {
        if (std::string(c.name) == "random") continue;  // open: no flood-fill signs to keep
        SCOPED_TRACE(c.name);
        const SparseField field = signed_distance_sparse_reference(c.mesh, c.grid, band(2.5));
        const std::string path = temp_path("read_back.vdb");
        write_field(path, field);
        const SparseField read = read_sparse_field(path);
        EXPECT_TRUE(same_grid(read.grid(), c.grid));
        EXPECT_EQ(read.background(), field.background());
        EXPECT_LE(read.leaf_count(), field.leaf_count());
        expect_identical(read.to_dense(), field.to_dense());
        std::remove(path.c_str());
    }
}

// A level set OpenVDB made itself, at negative indices, with a translation that is not a multiple
// of the voxel: every sample of the field read is the grid's value at the same world position,
// the tree lies inside the grid with an outside border, and the surface meshes closed.
TEST(LevelSetFiles, ForeignLevelSetSamplesAreOpenVdbsValuesAtTheSamePlaces) {
    openvdb::initialize();
    const double voxel = 0.37;
    auto vdb = openvdb::FloatGrid::create(float(3 * voxel));
    vdb->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    vdb->transform().postTranslate(openvdb::Vec3d(-5.11, 2.03, 7.5));
    vdb->setGridClass(openvdb::GRID_LEVEL_SET);
    vdb->setName("surface");
    // A sphere of radius 8.1 (22 voxels, so its inside holds whole tiles) at world (-9, 1, 3):
    // index centre about (-10.5, -2.8, -12.2).
    const openvdb::Vec3d centre(-9.0, 1.0, 3.0);
    const double radius = 8.1;
    auto access = vdb->getAccessor();
    for (int k = -40; k < 20; ++k)
        for (int j = -30; j < 30; ++j)
            for (int i = -40; i < 20; ++i) {
                const openvdb::Coord at(i, j, k);
                const double d = (vdb->indexToWorld(at) - centre).length() - radius;
                if (std::abs(d) < 3 * voxel) access.setValue(at, float(d));
            }
    openvdb::tools::signedFloodFill(vdb->tree());
    const std::string path = temp_path("foreign.vdb");
    {
        openvdb::io::File file(path);
        file.write({vdb});
    }
    const SparseField field = read_sparse_field(path);
    const Grid& g = field.grid();
    EXPECT_NEAR(g.voxel_size, voxel, 1e-15);
    EXPECT_EQ(field.background(), vdb->background());
    const auto read = vdb->getConstAccessor();
    size_t negative = 0;
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) {
                const openvdb::Vec3d world(g.origin[0] + (double(i) + 0.5) * voxel,
                                           g.origin[1] + (double(j) + 0.5) * voxel,
                                           g.origin[2] + (double(k) + 0.5) * voxel);
                const openvdb::Vec3d index = vdb->worldToIndex(world);
                const openvdb::Coord at(int(std::lround(index[0])), int(std::lround(index[1])),
                                        int(std::lround(index[2])));
                ASSERT_NEAR((index - at.asVec3d()).length(), 0.0, 1e-9);
                ASSERT_EQ(field.at(i, j, k), read.getValue(at)) << i << " " << j << " " << k;
                negative += field.at(i, j, k) < 0;
            }
    EXPECT_GT(negative, 1000u);  // the inside tiles became inside voxels
    EXPECT_EQ(border_samples_inside(field), 0u);
    openvdb::CoordBBox active = vdb->evalActiveVoxelBoundingBox();
    EXPECT_GE(uint64_t(g.dims[0]), uint64_t(active.dim()[0]) + 2);
    const test::Topology t = test::topology(marching_cubes(field));
    EXPECT_TRUE(t.closed_and_oriented);
    EXPECT_EQ(t.components, 1);
    std::remove(path.c_str());
}

// A level set on another lattice (another voxel size, voxel centres off A's) is rebuilt on A's
// lattice with A's band: its grid lies on that lattice exactly, its background is A's (so the two
// combine), and its samples are the exact distances A's lattice has for the same sphere to within
// a small fraction of a voxel. One already on the lattice with that band is read unchanged, and
// another band on the same lattice is rebuilt to it.
TEST(LevelSetFiles, LevelSetsOnAnotherLatticeAreRebuiltOnItCloseToTheExactDistances) {
    const Vec3d centre{1.3, -0.7, 2.1};
    const Mesh sphere = test::icosphere(centre, 1.45, 5);
    Grid a;
    a.voxel_size = 0.1;
    a.origin = {-0.43, -2.52, 0.31};
    a.dims = {40, 42, 41};
    Grid b;
    b.voxel_size = 0.137;
    b.origin = {-0.61, -2.73, 0.17};
    b.dims = {32, 31, 33};
    const SparseField exact = signed_distance_sparse_reference(sphere, a, band(3.0));
    const std::string path = temp_path("other_lattice.vdb");
    write_field(path, signed_distance_sparse_reference(sphere, b, band(3.0)));

    const SparseField rebuilt = read_sparse_field(path, a, exact.band_voxels());
    const Grid& g = rebuilt.grid();
    EXPECT_EQ(g.voxel_size, a.voxel_size);
    EXPECT_EQ(rebuilt.background(), exact.background());
    int64_t offset[3];
    for (int k = 0; k < 3; ++k) {
        const double voxels = (g.origin[k] - a.origin[k]) / a.voxel_size;
        offset[k] = std::llround(voxels);
        EXPECT_NEAR(voxels, double(offset[k]), 1e-9);
    }
    // OpenVDB's rebuild polygonizes the surface with one point per cell at the mean of its edge
    // crossings, which moves a convex surface inwards by about h^2 / (2 R) (h the file's voxel,
    // R the radius: 0.065 of A's voxels here); half a voxel off the lattice would be 0.5.
    double worst = 0, sum = 0;
    size_t compared = 0;
    for (int64_t k = 0; k < a.dims[2]; ++k)
        for (int64_t j = 0; j < a.dims[1]; ++j)
            for (int64_t i = 0; i < a.dims[0]; ++i) {
                const float want = exact.at(i, j, k);
                const int64_t at[3] = {i - offset[0], j - offset[1], k - offset[2]};
                if (!(std::abs(want) < 1.5 * a.voxel_size) || at[0] < 0 || at[1] < 0 || at[2] < 0 ||
                    at[0] >= g.dims[0] || at[1] >= g.dims[1] || at[2] >= g.dims[2])
                    continue;
                const double d = double(rebuilt.at(at[0], at[1], at[2])) - want;
                worst = std::max(worst, std::abs(d));
                sum += d;
                ++compared;
            }
    ASSERT_GT(compared, 5000u);
    EXPECT_LT(worst, 0.25 * a.voxel_size) << worst / a.voxel_size << " voxels";
    EXPECT_LT(std::abs(sum / double(compared)), 0.1 * a.voxel_size)
        << sum / double(compared) / a.voxel_size << " voxels";
    EXPECT_NO_THROW(csg(exact, rebuilt, CsgOp::Union));

    const SparseField as_written = read_sparse_field(path);
    const SparseField unchanged = read_sparse_field(path, b, as_written.band_voxels());
    EXPECT_TRUE(same_grid(unchanged.grid(), as_written.grid()));
    expect_identical(unchanged.to_dense(), as_written.to_dense());
    const SparseField wider = read_sparse_field(path, b, 5.0);
    EXPECT_EQ(wider.background(), float(5.0 * b.voxel_size));
    const ScalarField wide = wider.to_dense();
    EXPECT_TRUE(std::any_of(wide.values.begin(), wide.values.end(), [&](float v) {
        return std::abs(v) > 3.5 * b.voxel_size && std::abs(v) < 4.5 * b.voxel_size;
    }));
    EXPECT_THROW(read_sparse_field(path, a, 0.0), GridError);
    // A surface its grid cuts cannot be signed again after the rebuild: refused, naming the file.
    Grid cut = b;
    cut.dims[0] = 16;
    write_field(path, signed_distance_sparse_reference(sphere, cut, band(3.0)));
    try {
        read_sparse_field(path, a, 3.0);
        ADD_FAILURE() << "a cut surface was rebuilt";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("cut by its grid"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
    std::remove(path.c_str());
}

TEST(LevelSetFiles, FilesThatAreNotNarrowBandLevelSetsAreInputErrorsNamingTheFile) {
    openvdb::initialize();
    auto expect_refused = [](const std::string& path, const std::string& why) {
        try {
            read_sparse_field(path);
            ADD_FAILURE() << why << ": no error";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
        }
    };
    expect_refused(temp_path("field.npy"), "not a .vdb");
    const std::string garbage = temp_path("garbage.vdb");
    std::ofstream(garbage) << "not a vdb file at all";
    expect_refused(garbage, "garbage");
    expect_refused(temp_path("missing.vdb"), "missing");

    auto write = [](const std::string& path, const openvdb::GridBase::Ptr& grid) {
        openvdb::io::File file(path);
        file.write({grid});
    };
    auto level_set = [] {
        auto g = openvdb::FloatGrid::create(1.0f);
        g->setGridClass(openvdb::GRID_LEVEL_SET);
        g->tree().setValueOn(openvdb::Coord(3, 4, 5), -0.5f);
        return g;
    };
    const std::string path = temp_path("bad.vdb");
    auto fog = level_set();
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    write(path, fog);
    expect_refused(path, "a fog volume");
    auto tiles = level_set();
    tiles->tree().addTile(1, openvdb::Coord(128, 0, 0), -1.0f, true);
    write(path, tiles);
    expect_refused(path, "an active tile");
    auto rotated = level_set();
    openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(0.5);
    transform->postRotate(0.3, openvdb::math::Z_AXIS);
    rotated->setTransform(transform);
    write(path, rotated);
    expect_refused(path, "a rotated transform");
    auto nan = level_set();
    nan->tree().setValueOn(openvdb::Coord(3, 4, 6), NAN);
    write(path, nan);
    expect_refused(path, "a NaN");
    auto negative = openvdb::FloatGrid::create(-1.0f);
    negative->setGridClass(openvdb::GRID_LEVEL_SET);
    negative->tree().setValueOn(openvdb::Coord(1, 1, 1), 0.5f);
    write(path, negative);
    expect_refused(path, "a negative background");
    auto empty = openvdb::FloatGrid::create(1.0f);
    empty->setGridClass(openvdb::GRID_LEVEL_SET);
    write(path, empty);
    expect_refused(path, "no leaves");
    for (const auto& p : {garbage, path}) std::remove(p.c_str());
}

// The outer layer of a 2^20 x 2^20 x 16 grid holds 2^41 samples: counted from the leaves and the
// inside voxels without reading a face whole.
TEST(SparseField, BorderCountOfAHugeGridReadsNoFaceWhole) {
    Grid g;
    g.dims = {int64_t(1) << 20, int64_t(1) << 20, 16};
    SparseVoxels inside(g, 32);
    inside.set_box({0, 0, 0}, {10, 20, 16});  // reaches the faces x = 0, y = 0, z = 0 and z = 15
    SparseField f(g, 2.0, inside);
    const std::vector<float> leaf(SparseField::kLeafSamples, -0.25f);
    f.append_leaf(1000 / 8, leaf.data());  // voxels [1000, 1008) x [0, 8) x [0, 8)
    // Inside voxels on the border: all 3200 of the box but its 9 x 19 x 14 interior; the leaf's
    // border samples (y = 0 or z = 0): 64 + 64 - 8.
    EXPECT_EQ(border_samples_inside(f), 3200u - 9u * 19u * 14u + 120u);
    EXPECT_EQ(border_samples_inside(f, -3.0f), 0u);  // below every value
    const uint64_t n[3] = {uint64_t(1) << 20, uint64_t(1) << 20, 16};
    EXPECT_EQ(border_samples_inside(f, 3.0f),  // above every value: the whole layer
              n[0] * n[1] * n[2] - (n[0] - 2) * (n[1] - 2) * (n[2] - 2));
}

TEST(SparseField, BoxesAndSamplesReadTheLeavesAndTheInsideVoxels) {
    // A hand-built field: one leaf, inside voxels in and out of it.
    Grid g;
    g.dims = {20, 11, 9};
    SparseVoxels inside(g, 8);
    inside.set(1, 1, 1);    // in the leaf: its stored sample wins
    inside.set(17, 10, 8);  // outside every leaf: -background
    SparseField f(g, 2.0, inside);
    std::vector<float> leaf(SparseField::kLeafSamples);
    for (size_t v = 0; v < leaf.size(); ++v) leaf[v] = 0.001f * float(v);
    const auto n = f.leaf_dims();
    EXPECT_EQ(n, (std::array<int64_t, 3>{3, 2, 2}));
    f.append_leaf(uint64_t(2 + 3 * 1), leaf.data());  // leaf (2, 1, 0): voxels 16.., 8.., 0..
    EXPECT_THROW(f.append_leaf(1, leaf.data()), GridError);
    EXPECT_THROW(f.append_leaf(12, leaf.data()), GridError);
    EXPECT_EQ(f.at(16, 8, 0), 0.0f);
    EXPECT_EQ(f.at(19, 10, 7), 0.001f * float(3 + 8 * (2 + 8 * 7)));
    EXPECT_EQ(f.at(17, 10, 8), -2.0f);
    EXPECT_EQ(f.at(1, 1, 1), -2.0f);
    EXPECT_EQ(f.at(0, 0, 0), 2.0f);
    EXPECT_THROW(f.at(20, 0, 0), std::out_of_range);
    const ScalarField dense = f.to_dense();
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i) ASSERT_EQ(dense.at(i, j, k), f.at(i, j, k));
    std::vector<float> box(3 * 4 * 2);
    f.copy_box({15, 7, 6}, {18, 11, 8}, box.data());
    for (int64_t k = 0; k < 2; ++k)
        for (int64_t j = 0; j < 4; ++j)
            for (int64_t i = 0; i < 3; ++i)
                EXPECT_EQ(box[size_t(i + 3 * (j + 4 * k))], f.at(15 + i, 7 + j, 6 + k));
    EXPECT_THROW(f.copy_box({0, 0, 0}, {21, 1, 1}, box.data()), GridError);
    EXPECT_EQ(border_samples_inside(f), border_samples_inside(dense));
    EXPECT_EQ(border_samples_inside(f), 1u);  // (17, 10, 8) only
}

TEST(SparseCsg, ToDenseIsTheDenseCsgBitForBitForEveryOperation) {
    // Two overlapping spheres of different sizes on one grid: every operation of the sparse
    // fields equals the operation of the dense fields, on the device and the reference, and the
    // CSG of sparse fields equals the CSG of their dense copies.
    const Mesh a = icosphere(kCentre, 1.6, 3);
    const Mesh b = icosphere({kCentre[0] + 1.1, kCentre[1] - 0.3, kCentre[2] + 0.2}, 1.0, 3);
    GridFit fit;
    fit.resolution = 40;
    fit.pad = 4;
    const Grid g = fit_grid(a, b, fit);
    const SdfOptions o = band(2.5);
    const SparseField sa = signed_distance_sparse(device(), a, g, o);
    const SparseField sb = signed_distance_sparse(device(), b, g, o);
    for (CsgOp op : {CsgOp::Union, CsgOp::Intersection, CsgOp::Difference}) {
        SCOPED_TRACE(to_string(op));
        const ScalarField dense = csg(device(), a, b, op, g, o);
        VoxelizeStats stats;
        const SparseField sparse = csg_sparse(device(), a, b, op, g, o, &stats);
        expect_identical(sparse.to_dense(), dense);
        expect_identical(csg_sparse_reference(a, b, op, g, o).to_dense(),
                         csg_reference(a, b, op, g, o));
        expect_identical(csg(sa, sb, op).to_dense(), csg(sa.to_dense(), sb.to_dense(), op));
        EXPECT_EQ(stats.bricks_active, sa.leaf_count() + sb.leaf_count());
        EXPECT_LE(sparse.leaf_count(), sa.leaf_count() + sb.leaf_count());
    }
    // Different bands or grids are refused.
    SdfOptions wide = o;
    wide.band_voxels = 3.0;
    EXPECT_THROW(csg(sa, signed_distance_sparse(device(), b, g, wide), CsgOp::Union), GridError);
    Grid moved = g;
    moved.origin[0] += 0.5 * g.voxel_size;
    try {
        csg(sa, signed_distance_sparse(device(), b, moved, o), CsgOp::Union);
        ADD_FAILURE() << "fields half a voxel apart were combined";
    } catch (const GridError& e) {
        EXPECT_NE(std::string(e.what()).find("lattice"), std::string::npos) << e.what();
    }
}

// Fields on grids of one lattice (origins whole voxels apart, different sizes) combine on the
// box of both, and every sample of the result is the operation on the two fields' own samples
// there, +background beyond a field's grid: by voxel moves (offsets not multiples of 4) and by
// 64-bit block moves (multiples of 4), and with the grids either way round.
TEST(SparseCsg, FieldsOnOneLatticeCombineOnTheBoxOfBoth) {
    const Mesh a = icosphere(kCentre, 1.6, 3);
    const Mesh b = icosphere({kCentre[0] + 1.1, kCentre[1] - 0.3, kCentre[2] + 0.2}, 1.0, 3);
    GridFit fit;
    fit.resolution = 32;
    fit.pad = 3;
    const Grid ga = fit_grid(a, fit);
    const SdfOptions o = band(2.5);
    const SparseField fa = signed_distance_sparse(device(), a, ga, o);
    for (const std::array<int64_t, 3> offset :
         {std::array<int64_t, 3>{3, -5, 7}, {8, -16, 4}, {0, 0, 0}}) {
        SCOPED_TRACE(::testing::PrintToString(offset));
        Grid gb = ga;
        for (int k = 0; k < 3; ++k) gb.origin[k] += double(offset[k]) * ga.voxel_size;
        gb.dims = {ga.dims[0] - 6, ga.dims[1] + 5, ga.dims[2] - 9};
        const SparseField fb = signed_distance_sparse(device(), b, gb, o);
        for (const bool swap : {false, true}) {
            const SparseField& x = swap ? fb : fa;
            const SparseField& y = swap ? fa : fb;
            for (CsgOp op : {CsgOp::Union, CsgOp::Intersection, CsgOp::Difference}) {
                SCOPED_TRACE(std::string(to_string(op)) + (swap ? " swapped" : ""));
                const SparseField r = csg(x, y, op);
                const Grid& g = r.grid();
                std::array<int64_t, 3> sx, sy;  // each field's voxel (0, 0, 0) in the result
                for (int k = 0; k < 3; ++k) {
                    EXPECT_EQ(g.origin[k], std::min(x.grid().origin[k], y.grid().origin[k]));
                    sx[k] = std::llround((x.grid().origin[k] - g.origin[k]) / g.voxel_size);
                    sy[k] = std::llround((y.grid().origin[k] - g.origin[k]) / g.voxel_size);
                    EXPECT_EQ(g.dims[k],
                              std::max(sx[k] + x.grid().dims[k], sy[k] + y.grid().dims[k]));
                }
                auto sample = [](const SparseField& f, const std::array<int64_t, 3>& shift,
                                 int64_t i, int64_t j, int64_t k) {
                    const std::array<int64_t, 3> p = {i - shift[0], j - shift[1], k - shift[2]};
                    for (int a = 0; a < 3; ++a)
                        if (p[a] < 0 || p[a] >= f.grid().dims[a]) return f.background();
                    return f.at(p[0], p[1], p[2]);
                };
                const ScalarField dense = r.to_dense();
                size_t inside = 0;
                for (int64_t k = 0; k < g.dims[2]; ++k)
                    for (int64_t j = 0; j < g.dims[1]; ++j)
                        for (int64_t i = 0; i < g.dims[0]; ++i) {
                            float want = sample(x, sx, i, j, k);
                            const float other = sample(y, sy, i, j, k);
                            detail::combine_samples(&want, &other, 1, op);
                            ASSERT_EQ(dense.at(i, j, k), want) << i << " " << j << " " << k;
                            inside += want < 0;
                        }
                EXPECT_GT(inside, 100u);
            }
        }
    }
}

// Two level sets OpenVDB made with one transform (so their leaf boxes differ) combine as
// OpenVDB's own CSG combines them, sample for sample over the whole result grid.
TEST(LevelSetFiles, TwoOpenVdbLevelSetsOnOneTransformCombineAsOpenVdbsCsg) {
    openvdb::initialize();
    const float voxel = 0.1f, half_width = 3.0f;
    auto sphere = [&](float radius, const openvdb::Vec3f& centre, const std::string& name) {
        auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius, centre, voxel,
                                                                             half_width);
        const std::string path = temp_path(name);
        openvdb::io::File file(path);
        file.write({grid});
        file.close();
        return std::make_pair(grid, path);
    };
    const auto [va, pa] = sphere(1.3f, {0.2f, -0.4f, 0.1f}, "lattice_a.vdb");
    const auto [vb, pb] = sphere(0.9f, {1.5f, 0.3f, -0.6f}, "lattice_b.vdb");
    const SparseField a = read_sparse_field(pa), b = read_sparse_field(pb);
    EXPECT_FALSE(same_grid(a.grid(), b.grid()));
    for (CsgOp op : {CsgOp::Union, CsgOp::Intersection, CsgOp::Difference}) {
        SCOPED_TRACE(to_string(op));
        openvdb::FloatGrid::Ptr want;
        switch (op) {
            case CsgOp::Union:
                want = openvdb::tools::csgUnionCopy(*va, *vb);
                break;
            case CsgOp::Intersection:
                want = openvdb::tools::csgIntersectionCopy(*va, *vb);
                break;
            case CsgOp::Difference:
                want = openvdb::tools::csgDifferenceCopy(*va, *vb);
                break;
        }
        const SparseField r = csg(a, b, op);
        const Grid& g = r.grid();
        const auto read = want->getConstAccessor();
        size_t inside = 0;
        for (int64_t k = 0; k < g.dims[2]; ++k)
            for (int64_t j = 0; j < g.dims[1]; ++j)
                for (int64_t i = 0; i < g.dims[0]; ++i) {
                    const openvdb::Vec3d index = want->worldToIndex(
                        openvdb::Vec3d(g.origin[0] + (double(i) + 0.5) * g.voxel_size,
                                       g.origin[1] + (double(j) + 0.5) * g.voxel_size,
                                       g.origin[2] + (double(k) + 0.5) * g.voxel_size));
                    const openvdb::Coord at(int(std::lround(index[0])), int(std::lround(index[1])),
                                            int(std::lround(index[2])));
                    ASSERT_NEAR((index - at.asVec3d()).length(), 0.0, 1e-6);
                    ASSERT_EQ(r.at(i, j, k), read.getValue(at)) << i << " " << j << " " << k;
                    inside += r.at(i, j, k) < 0;
                }
        EXPECT_GT(inside, 100u);
    }
    std::remove(pa.c_str());
    std::remove(pb.c_str());
}

}  // namespace
}  // namespace oclvox::test
