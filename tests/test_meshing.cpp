// Surface Nets and Marching Cubes: topology against Euler's formula and hand-worked cases,
// geometry against analytic surfaces, brick-size invariance, device == host reference, and the
// mesh writers read back by small independent readers.
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <sstream>

#include "meshing.hpp"
#include "meshing_math.h"
#include "oclvox/field.hpp"
#include "oclvox/sdf.hpp"
#include "opencl_runtime.hpp"
#include "test_support.hpp"

namespace oclvox {
namespace {

using Vec3 = std::array<double, 3>;

using test::device;
using test::device_used_as_a_gpu;

// ---- fields
// --------------------------------------------------------------------------------------

// Samples f at the voxel centres of an n^3-voxel grid of unit voxels at the origin.
ScalarField sample_field(int64_t nx, int64_t ny, int64_t nz,
                         const std::function<double(const Vec3&)>& f) {
    ScalarField field;
    field.grid.dims = {nx, ny, nz};
    for (int64_t k = 0; k < nz; ++k)
        for (int64_t j = 0; j < ny; ++j)
            for (int64_t i = 0; i < nx; ++i)
                field.values.push_back(float(f({i + 0.5, j + 0.5, k + 0.5})));
    return field;
}

double sphere_distance(const Vec3& p, const Vec3& c, double r) {
    return std::sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                     (p[2] - c[2]) * (p[2] - c[2])) -
           r;
}

// Torus around the z axis through c: tube radius r at distance R from the axis.
double torus_distance(const Vec3& p, const Vec3& c, double R, double r) {
    const double x = p[0] - c[0], y = p[1] - c[1], z = p[2] - c[2];
    const double ring = std::sqrt(x * x + y * y) - R;
    return std::sqrt(ring * ring + z * z) - r;
}

const Vec3 kSphereCentre{20.3, 19.6, 20.1};
constexpr double kSphereRadius = 14.2;
ScalarField sphere_field() {
    return sample_field(
        40, 40, 40, [](const Vec3& p) { return sphere_distance(p, kSphereCentre, kSphereRadius); });
}

const Vec3 kTorusCentre{20.2, 19.7, 8.1};
constexpr double kTorusR = 12.0, kTorusTube = 4.5;
ScalarField torus_field() {
    return sample_field(40, 40, 16, [](const Vec3& p) {
        return torus_distance(p, kTorusCentre, kTorusR, kTorusTube);
    });
}

// Uniform noise in [-1, 1] (many ambiguous faces) inside an outside border, so surfaces close.
ScalarField noise_field(int n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> value(-1.0f, 1.0f);
    ScalarField field = sample_field(n, n, n, [](const Vec3&) { return 1.0; });
    for (int k = 1; k < n - 1; ++k)
        for (int j = 1; j < n - 1; ++j)
            for (int i = 1; i < n - 1; ++i) field.values[size_t(i + n * (j + n * k))] = value(rng);
    return field;
}

// ---- topology (independent of the meshing code) -----------------------------------------------

void expect_closed_surface(const Mesh& mesh, int64_t euler, int64_t components) {
    const test::Topology t = test::topology(mesh);
    EXPECT_TRUE(t.closed_and_oriented);
    EXPECT_TRUE(t.vertex_manifold);
    EXPECT_EQ(t.unused_vertices, 0);
    EXPECT_EQ(t.euler(), euler);
    EXPECT_EQ(t.components, components);
}

double signed_volume(const Mesh& mesh) {
    double volume = 0;
    for (const auto& tri : mesh.triangles) {
        const Vec3& a = mesh.positions[tri[0]];
        const Vec3& b = mesh.positions[tri[1]];
        const Vec3& c = mesh.positions[tri[2]];
        volume += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                   a[2] * (b[0] * c[1] - b[1] * c[0])) /
                  6.0;
    }
    return volume;
}

// Sign-changing grid edges counted straight from the samples.
int64_t sign_changing_edges(const ScalarField& f, float iso) {
    const auto& n = f.grid.dims;
    int64_t count = 0;
    for (int64_t k = 0; k < n[2]; ++k)
        for (int64_t j = 0; j < n[1]; ++j)
            for (int64_t i = 0; i < n[0]; ++i) {
                const bool in = f.at(i, j, k) < iso;
                if (i + 1 < n[0] && (f.at(i + 1, j, k) < iso) != in) ++count;
                if (j + 1 < n[1] && (f.at(i, j + 1, k) < iso) != in) ++count;
                if (k + 1 < n[2] && (f.at(i, j, k + 1) < iso) != in) ++count;
            }
    return count;
}

void expect_identical(const Mesh& a, const Mesh& b) {
    ASSERT_EQ(a.positions.size(), b.positions.size());
    ASSERT_EQ(a.triangles.size(), b.triangles.size());
    EXPECT_TRUE(a.positions == b.positions) << "vertex positions differ";
    EXPECT_TRUE(a.triangles == b.triangles) << "triangles differ";
}

// ---- analytic surfaces -----------------------------------------------------------------------

TEST(Meshing, SphereIsOneClosedOrientedGenusZeroSurfaceForBothMethods) {
    const ScalarField field = sphere_field();
    for (const Mesh& mesh : {marching_cubes(field), surface_nets(field)}) {
        expect_closed_surface(mesh, 2, 1);
        // Outward normals give a positive volume close to the ball's.
        const double ball = 4.0 / 3.0 * M_PI * std::pow(kSphereRadius, 3);
        EXPECT_NEAR(signed_volume(mesh), ball, 0.01 * ball);
    }
}

TEST(Meshing, TorusIsOneClosedSurfaceOfGenusOne) {
    const ScalarField field = torus_field();
    for (const Mesh& mesh : {marching_cubes(field), surface_nets(field)}) {
        expect_closed_surface(mesh, 0, 1);
        const double volume = 2 * M_PI * M_PI * kTorusR * kTorusTube * kTorusTube;
        EXPECT_NEAR(signed_volume(mesh), volume, 0.02 * volume);
    }
}

TEST(Meshing, VerticesLieWithinASmallFractionOfAVoxelOfTheAnalyticSurface) {
    const ScalarField field = sphere_field();
    auto worst = [](const Mesh& mesh) {
        double error = 0;
        for (const Vec3& p : mesh.positions)
            error = std::max(error, std::abs(sphere_distance(p, kSphereCentre, kSphereRadius)));
        return error;
    };
    // Marching Cubes interpolates the exact distance along edges: only the curvature within one
    // edge and float rounding remain. Surface Nets averages crossings across a cell, which
    // pulls the vertex inside by up to about diagonal^2 / (8 R).
    EXPECT_LT(worst(marching_cubes(field)), 0.01);
    EXPECT_LT(worst(surface_nets(field)), 3.0 / (8 * kSphereRadius));
}

// Euler's formula fixes the sizes: a closed triangle mesh has E = 3F/2, so V = F/2 + chi. Surface
// Nets has one quad (2 triangles) per sign-changing edge, Marching Cubes one vertex per
// sign-changing edge; so on a sphere V_sn = E_cross + 2 and F_mc = 2 E_cross - 4. Both methods
// thus have about the same vertex AND triangle counts; Surface Nets is not vertex-cheaper.
TEST(Meshing, VertexAndTriangleCountsFollowEulersFormulaForBothMethods) {
    const ScalarField field = sphere_field();
    const int64_t crossing = sign_changing_edges(field, 0.0f);
    const Mesh mc = marching_cubes(field), sn = surface_nets(field);
    EXPECT_EQ(int64_t(sn.triangles.size()), 2 * crossing);
    EXPECT_EQ(int64_t(sn.positions.size()), crossing + 2);
    EXPECT_EQ(int64_t(mc.positions.size()), crossing);  // smooth field: no centre vertices
    EXPECT_EQ(int64_t(mc.triangles.size()), 2 * crossing - 4);
}

// ---- hand-worked cases --------------------------------------------------------------------------

// A single set voxel, unsmoothed: samples are -0.5 there and +0.5 around, so every crossing is
// half-way between sample centres, i.e. on a face of the voxel.
TEST(Meshing, SingleVoxelGivesAnOctahedronThroughItsFaceCentresAndASurfaceNetsCube) {
    Grid grid;
    grid.origin = {10, 20, 30};
    grid.voxel_size = 2;
    grid.dims = {3, 3, 3};
    SparseVoxels voxels(grid, 4);
    voxels.set(1, 1, 1);
    const ScalarField field = occupancy_to_field(voxels, 0);
    EXPECT_EQ(field.grid.dims, (std::array<int64_t, 3>{5, 5, 5}));
    EXPECT_EQ(field.at(2, 2, 2), -0.5f);
    EXPECT_EQ(field.at(1, 2, 2), 0.5f);

    const Mesh mc = marching_cubes(field);
    ASSERT_EQ(mc.positions.size(), 6u);
    EXPECT_EQ(mc.triangles.size(), 8u);
    // Voxel (1,1,1) spans [12, 14] x [22, 24] x [32, 34]; its centre is (13, 23, 33).
    std::vector<Vec3> expected{{12, 23, 33}, {14, 23, 33}, {13, 22, 33},
                               {13, 24, 33}, {13, 23, 32}, {13, 23, 34}};
    for (const Vec3& p : mc.positions)
        EXPECT_NE(std::find(expected.begin(), expected.end(), p), expected.end())
            << p[0] << " " << p[1] << " " << p[2];
    expect_closed_surface(mc, 2, 1);
    EXPECT_NEAR(signed_volume(mc), 4.0 / 3.0, 1e-12);  // octahedron of "radius" 1: 4/3

    // Surface Nets: 8 cells around the sample, each vertex the mean of the 3 face centres it
    // sees, half a voxel out along one axis each: centre +-1/6 voxel = +-1/3 world units per
    // axis; 6 edges x 2 triangles.
    const Mesh sn = surface_nets(field);
    ASSERT_EQ(sn.positions.size(), 8u);
    EXPECT_EQ(sn.triangles.size(), 12u);
    for (const Vec3& p : sn.positions)
        for (int k = 0; k < 3; ++k)
            EXPECT_NEAR(std::abs(p[k] - (13.0 + 10.0 * k)), 1.0 / 3.0, 1e-6);
    expect_closed_surface(sn, 2, 1);
}

// One face with two inside samples on a diagonal, A = C = -1, and two outside ones, B = D = b.
// The bilinear saddle is (AC - BD) / (A + C - B - D) = (1 - b^2) / (-2 - 2b): inside (the two
// samples connect into one blob) for b < 1, outside (two separate blobs) for b > 1.
TEST(Meshing, AsymptoticDeciderJoinsOrSeparatesAnAmbiguousFaceLikeTheBilinearSaddle) {
    for (const float b : {0.5f, 2.0f}) {
        ScalarField field = sample_field(4, 4, 4, [](const Vec3&) { return 1.0; });
        auto at = [&](int i, int j, int k) -> float& {
            return field.values[size_t(i + 4 * (j + 4 * k))];
        };
        at(1, 1, 1) = -1;
        at(2, 2, 1) = -1;
        at(2, 1, 1) = b;
        at(1, 2, 1) = b;
        const Mesh mesh = marching_cubes(field);
        if (b < 1)
            expect_closed_surface(mesh, 2, 1);
        else
            expect_closed_surface(mesh, 4, 2);
    }
}

// Every corner pattern of one cell, alone in an outside field: each 6-connected group of inside
// corners is a ball (ties in the decider separate), so the surface is one sphere per group.
TEST(Meshing, EveryMarchingCubesCornerCaseIsClosedWithOneSpherePerInsideGroup) {
    for (int mask = 1; mask < 256; ++mask) {
        ScalarField field = sample_field(4, 4, 4, [](const Vec3&) { return 1.0; });
        for (int c = 0; c < 8; ++c)
            if (mask >> c & 1)
                field
                    .values[size_t((1 + (c & 1)) + 4 * ((1 + (c >> 1 & 1)) + 4 * (1 + (c >> 2))))] =
                    -1;
        // Groups of corners joined by cube edges.
        int groups = 0, seen = 0;
        for (int c = 0; c < 8; ++c) {
            if (!(mask >> c & 1) || (seen >> c & 1)) continue;
            ++groups;
            std::vector<int> stack{c};
            seen |= 1 << c;
            while (!stack.empty()) {
                const int at = stack.back();
                stack.pop_back();
                for (int axis = 0; axis < 3; ++axis) {
                    const int next = at ^ (1 << axis);
                    if ((mask >> next & 1) && !(seen >> next & 1)) {
                        seen |= 1 << next;
                        stack.push_back(next);
                    }
                }
            }
        }
        SCOPED_TRACE("mask " + std::to_string(mask));
        expect_closed_surface(marching_cubes(field), 2 * groups, groups);
    }
}

// Noise has ambiguous faces everywhere (and needs centre vertices); Marching Cubes must still be
// closed, consistently oriented and manifold.
TEST(Meshing, MarchingCubesStaysClosedAndManifoldOnNoiseFullOfAmbiguousFaces) {
    for (uint32_t seed = 1; seed <= 4; ++seed) {
        const Mesh mesh = marching_cubes(noise_field(14, seed));
        const test::Topology t = test::topology(mesh);
        EXPECT_TRUE(t.closed_and_oriented) << "seed " << seed;
        EXPECT_TRUE(t.vertex_manifold) << "seed " << seed;
        EXPECT_EQ(t.unused_vertices, 0);
        EXPECT_EQ(t.euler() % 2, 0);  // closed orientable surfaces only
        EXPECT_GT(signed_volume(mesh), 0);
    }
}

// A checkerboard: every face of every interior cell is ambiguous.
TEST(Meshing, CheckerboardFieldGivesAClosedMarchingCubesMesh) {
    ScalarField field = sample_field(10, 10, 10, [](const Vec3& p) {
        const int parity = int(p[0]) + int(p[1]) + int(p[2]);
        const bool border = p[0] < 1 || p[1] < 1 || p[2] < 1 || p[0] > 9 || p[1] > 9 || p[2] > 9;
        // Slightly uneven magnitudes so the decider goes both ways.
        return border ? 1.0 : (parity % 2 ? 1.0 + 0.1 * std::sin(p[0] * 7 + p[1] * 3) : -1.0);
    });
    const test::Topology t = test::topology(marching_cubes(field));
    EXPECT_TRUE(t.closed_and_oriented);
    EXPECT_TRUE(t.vertex_manifold);
    EXPECT_GT(t.faces, 0);
}

// ---- tiling and device -----------------------------------------------------------------------

TEST(Meshing, OutputIsIdenticalForEveryBrickSize) {
    for (const ScalarField& field : {torus_field(), noise_field(13, 7)})
        for (auto method :
             {detail::MeshingMethod::SurfaceNets, detail::MeshingMethod::MarchingCubes}) {
            const Mesh whole = detail::mesh_field_reference(field, 0.0f, method, 1 << 20);
            EXPECT_GT(whole.triangles.size(), 0u);
            for (int brick : {1, 2, 3, 5, 8, 17})
                expect_identical(detail::mesh_field_reference(field, 0.0f, method, brick), whole);
        }
}

// Counts and offsets exist only for the active bricks, so the mesher's memory and work follow the
// surface: a small sphere in a large grid gets slots for a thin shell of bricks around it. A
// brick of b^3 samples is active only if its samples with their one-sample halo change sign, so
// every active brick lies within b + 1 samples (per axis) of the sphere's surface.
TEST(Meshing, SlotsCoverOnlyBricksNearTheSurface) {
    const Vec3 centre{60.3, 61.7, 59.2};
    const double radius = 9.4;
    const ScalarField field = sample_field(
        128, 128, 128, [&](const Vec3& p) { return sphere_distance(p, centre, radius); });
    for (int brick : {4, 8}) {
        const detail::BrickLayout layout = detail::active_bricks(field, 0.0f, brick);
        ASSERT_FALSE(layout.origins.empty());
        uint64_t samples = 0;
        for (const auto& o : layout.origins) {
            // The brick's box, grown by its reach, meets the sphere's surface.
            double near2 = 0, far2 = 0;
            for (int k = 0; k < 3; ++k) {
                const double lo = o[k] + 0.5 - 1e-9, hi = o[k] + brick + 0.5 + 1e-9;
                const double c = std::clamp(centre[k], lo, hi);
                near2 += (c - centre[k]) * (c - centre[k]);
                far2 += std::max((lo - centre[k]) * (lo - centre[k]),
                                 (hi - centre[k]) * (hi - centre[k]));
            }
            EXPECT_LE(std::sqrt(near2), radius + 1e-6) << o[0] << " " << o[1] << " " << o[2];
            EXPECT_GE(std::sqrt(far2), radius - 1e-6) << o[0] << " " << o[1] << " " << o[2];
            samples += uint64_t(brick) * brick * brick;
        }
        EXPECT_EQ(layout.slots, samples);  // no brick is clipped by this grid
        // A shell of thickness 2 (brick + 1) around the sphere bounds the active volume.
        const double shell = 4.0 / 3.0 * M_PI *
                             (std::pow(radius + 2 * (brick + 1), 3) -
                              std::pow(std::max(0.0, radius - 2 * (brick + 1)), 3));
        EXPECT_LE(double(samples), shell) << "brick " << brick;
        EXPECT_LT(samples, field.values.size() / 8) << "brick " << brick;
    }
}

TEST(Meshing, DeviceEqualsHostReferenceBitForBit) {
    for (const ScalarField& field : {sphere_field(), torus_field(), noise_field(13, 3)})
        for (const float iso : {0.0f, 0.25f}) {
            for (auto method :
                 {detail::MeshingMethod::SurfaceNets, detail::MeshingMethod::MarchingCubes}) {
                const Mesh reference = detail::mesh_field_reference(field, iso, method, 32);
                const bool nets = method == detail::MeshingMethod::SurfaceNets;
                expect_identical(nets ? surface_nets(device(), field, iso)
                                      : marching_cubes(device(), field, iso),
                                 reference);
                // The host meshers (through the field's meshing view) give it too.
                expect_identical(nets ? surface_nets(field, iso) : marching_cubes(field, iso),
                                 reference);
            }
        }
}

// The device meshers as a GPU runs them (device_used_as_a_gpu: the field uploaded, the counts
// and triangles downloaded from the device's memory) give the host reference's meshes.
TEST(Meshing, DeviceRunAsOnAGpuEqualsHostReference) {
    for (const ScalarField& field : {sphere_field(), noise_field(13, 3)})
        for (auto method :
             {detail::MeshingMethod::SurfaceNets, detail::MeshingMethod::MarchingCubes}) {
            const Mesh reference = detail::mesh_field_reference(field, 0.0f, method, 32);
            const bool nets = method == detail::MeshingMethod::SurfaceNets;
            expect_identical(nets ? surface_nets(device_used_as_a_gpu(), field, 0.0f)
                                  : marching_cubes(device_used_as_a_gpu(), field, 0.0f),
                             reference);
        }
}

// Progress over the scan, count and emit passes keeps the fields' contract (one fixed total, never
// back, ending at it), changes no vertex, and a false answer cancels on the device as on the host.
TEST(Meshing, ProgressReportsEveryPassAndCancels) {
    const ScalarField field = torus_field();
    const Mesh expected = marching_cubes(field);
    for (bool on_device : {true, false})
        for (bool nets : {false, true}) {
            auto mesh = [&](const ProgressCallback& progress) {
                if (nets)
                    return on_device ? surface_nets(device(), field, 0.0f, progress)
                                     : surface_nets(field, 0.0f, progress);
                return on_device ? marching_cubes(device(), field, 0.0f, progress)
                                 : marching_cubes(field, 0.0f, progress);
            };
            const std::string what =
                std::string(on_device ? "device " : "host ") + (nets ? "surface nets" : "cubes");
            test::ProgressLog log;
            log.slow = on_device;  // every kernel slice's report reaches the callback
            const Mesh got = mesh(log.callback());
            log.expect_contract(what);
            if (on_device) EXPECT_GE(log.steps_inside(), 3u) << what;  // scan, count, emit
            if (!nets) expect_identical(got, expected);
            for (double at : {0.0, 0.5, 1.0}) {
                test::ProgressLog cancel;
                cancel.cancel_from = at;
                EXPECT_THROW(mesh(cancel.callback()), Cancelled) << what << " at " << at;
                EXPECT_TRUE(cancel.cancelled) << what << " at " << at;
            }
        }
}

// ---- sparse fields ---------------------------------------------------------------------------
// The independent reference of the sparse meshers is the dense mesher run on the field's dense
// copy: the meshes must be equal bit for bit, order included.

void expect_sparse_meshes_dense(const SparseField& field, float iso, const std::string& what) {
    SCOPED_TRACE(what + " iso " + std::to_string(iso));
    const ScalarField dense = field.to_dense();
    const Mesh nets = surface_nets(field, iso), cubes = marching_cubes(field, iso);
    expect_identical(nets, surface_nets(dense, iso));
    expect_identical(cubes, marching_cubes(dense, iso));
    EXPECT_EQ(border_samples_inside(field, iso), border_samples_inside(dense, iso));
}

// Distance fields of a sphere off the origin (parity sign), the scan (parity) and open random
// triangles (winding-number sign: the inside voxels change across holes, away from any leaf), on
// grids that are not multiples of the leaves, at several bands and iso values.
TEST(SparseMeshing, EqualsMeshingTheDenseCopyBitForBit) {
    const Vec3 centre{-310.25, 7.5, 1200.75};
    Grid sphere_grid;
    sphere_grid.dims = {37, 35, 41};
    sphere_grid.voxel_size = 0.2;
    sphere_grid.origin = {centre[0] - 3.7, centre[1] - 3.5, centre[2] - 4.1};
    const Mesh bunny = load_mesh(test::mesh_path("bunny00.off"));
    GridFit fit;
    fit.resolution = 45;
    fit.pad = 4;
    Grid random_grid;
    random_grid.dims = {29, 34, 27};
    const struct {
        const char* name;
        Mesh mesh;
        Grid grid;
    } cases[] = {{"sphere", test::icosphere(centre, 2.6, 3), sphere_grid},
                 {"bunny00", bunny, fit_grid(bunny, fit)},
                 {"random", test::random_triangles(120, -3.0, 33.0, 5.0, 11), random_grid}};
    for (const auto& c : cases)
        for (double band : {3.0, 1.25}) {
            SdfOptions o;
            o.band_voxels = band;
            const SparseField field = signed_distance_sparse_reference(c.mesh, c.grid, o);
            const float background = field.background();
            EXPECT_GT(surface_nets(field).triangles.size(), 100u) << c.name;
            for (float iso : {0.0f, 0.4f * background, -0.7f * background, background})
                expect_sparse_meshes_dense(field, iso,
                                           std::string(c.name) + " band " + std::to_string(band));
        }
}

// Sign changes far from every leaf come from the inside voxels alone: a box of them that crosses
// the voxels' bricks (8^3, so full words border other bricks), a one-voxel speck, a hollow shell,
// and random leaves of random values (many sign changes, leaves on the grid's faces).
TEST(SparseMeshing, InsideVoxelsAwayFromTheLeavesAndRandomLeavesMeshAsTheDenseCopy) {
    Grid g;
    g.dims = {43, 29, 38};
    g.voxel_size = 0.5;
    g.origin = {-3.0, 2.0, 11.0};
    SparseVoxels inside(g, 8);
    // Faces on the bricks' faces (multiples of 8) and between them.
    for (int64_t k = 3; k < 32; ++k)
        for (int64_t j = 4; j < 16; ++j)
            for (int64_t i = 2; i < 24; ++i) {
                const bool hollow = i >= 8 && i < 16 && j >= 8 && j < 12 && k >= 16 && k < 23;
                if (!hollow) inside.set(i, j, k);
            }
    inside.set(35, 25, 33);
    for (int64_t k = 0; k < 38; ++k) inside.set(40, 1, k);  // a column along z to the faces

    SparseField no_leaves(g, 1.5, inside);
    expect_sparse_meshes_dense(no_leaves, 0.0f, "no leaves");
    EXPECT_GT(marching_cubes(no_leaves).triangles.size(), 1000u);
    // Both backgrounds on one side of iso: no surface at all.
    for (float iso : {-2.0f * no_leaves.background(), 1.1f * no_leaves.background()}) {
        EXPECT_TRUE(surface_nets(no_leaves, iso).triangles.empty());
        EXPECT_TRUE(marching_cubes(no_leaves, iso).positions.empty());
    }

    std::mt19937 rng(5);
    SparseField leaves(g, 1.5, inside);
    const auto n = leaves.leaf_dims();
    std::vector<float> samples(SparseField::kLeafSamples);
    std::uniform_real_distribution<float> value(-leaves.background(), leaves.background());
    for (uint64_t leaf = 0; leaf < uint64_t(n[0] * n[1] * n[2]); ++leaf) {
        if (rng() % 4) continue;
        for (float& v : samples) v = value(rng);
        leaves.append_leaf(leaf, samples.data());
    }
    ASSERT_GT(leaves.leaf_count(), 10u);
    for (float iso : {0.0f, 0.3f, -0.9f}) expect_sparse_meshes_dense(leaves, iso, "random leaves");
}

// A dense field's meshing view keeps only the values the meshers read as values (the corners of
// cells on both sides of iso) and the sides of all others, so it meshes as the dense field does:
// smooth fields, noise full of ambiguous faces, grids not multiples of 8 and thin ones.
TEST(SparseMeshing, DenseFieldsMeshThroughTheirMeshingViewsAsTheyDo) {
    const ScalarField thin =
        sample_field(19, 2, 11, [](const Vec3& p) { return p[0] - 7.3 + p[2] * 0.1; });
    // Planes crossing just above a leaf's low face (z = 8, y = 16, x = 8): the leaf above holds
    // the crossing's upper corners while all of its own samples lie on one side.
    const ScalarField z_plane = sample_field(
        20, 19, 21, [](const Vec3& p) { return p[2] - 8.25 + 0.01 * p[0] - 0.02 * p[1]; });
    const ScalarField y_plane =
        sample_field(18, 25, 17, [](const Vec3& p) { return 16.25 - p[1] + 0.015 * p[2]; });
    const ScalarField x_plane =
        sample_field(23, 12, 10, [](const Vec3& p) { return p[0] - 8.2 + 0.01 * p[1]; });
    for (const ScalarField& field : {sphere_field(), torus_field(), noise_field(13, 3),
                                     noise_field(21, 8), thin, z_plane, y_plane, x_plane})
        for (const float iso : {0.0f, 0.25f, -0.3f}) {
            SCOPED_TRACE(std::to_string(field.grid.dims[0]) + " iso " + std::to_string(iso));
            const SparseField view = detail::meshing_view(field, iso, "test");
            for (auto method :
                 {detail::MeshingMethod::SurfaceNets, detail::MeshingMethod::MarchingCubes}) {
                const bool nets = method == detail::MeshingMethod::SurfaceNets;
                expect_identical(nets ? surface_nets(view, iso) : marching_cubes(view, iso),
                                 detail::mesh_field_reference(field, iso, method, 32));
            }
        }
    EXPECT_THROW(detail::meshing_view(sphere_field(), NAN, "test"), InputError);
}

// The builder holds two leaf layers and decides a leaf layer only once the one above is in: tall
// fields whose sign changes lie on both sides of leaf-layer boundaries (z = 16, 24, 32), with
// the last leaf layer partial, given a layer at a time, mesh as the dense reference does, and the
// view's samples below iso are the field's (what a preview draws).
TEST(SparseMeshing, FieldsGivenALayerAtATimeMeshAsTheDenseFieldDoes) {
    const ScalarField slabs = sample_field(13, 11, 45, [](const Vec3& p) {
        return std::abs(p[2] - 24.0 + 0.03 * p[0]) - 7.9 + 0.02 * p[1];  // z near 16.1 and 31.9
    });
    const ScalarField ball = sample_field(21, 18, 37, [](const Vec3& p) {
        return sphere_distance(p, {9.7, 8.2, 23.6}, 8.4);
    });
    const ScalarField noise = noise_field(27, 4);
    for (const ScalarField* field_pointer : {&slabs, &ball, &noise})
        for (const float iso : {0.0f, 0.2f}) {
            const ScalarField& field = *field_pointer;
            SCOPED_TRACE(std::to_string(field.grid.dims[2]) + " layers, iso " +
                         std::to_string(iso));
            MeshingViewBuilder builder(field.grid, iso);
            const size_t per_layer = size_t(field.grid.dims[0] * field.grid.dims[1]);
            for (int64_t k = 0; k < field.grid.dims[2]; ++k) {
                // A copy, so the builder cannot lean on the layers staying where they were.
                std::vector<float> layer(&field.values[size_t(k) * per_layer],
                                         &field.values[size_t(k + 1) * per_layer]);
                builder.add_layer(layer.data());
            }
            const SparseField view = builder.finish();
            if (&field == &slabs)  // none in the leaf layers z < 8 and z >= 40
                for (const uint64_t leaf : view.leaf_indices())
                    EXPECT_TRUE(leaf >= 2 * 2 && leaf < 5 * 2 * 2) << leaf;
            expect_identical(
                surface_nets(view, iso),
                detail::mesh_field_reference(field, iso, detail::MeshingMethod::SurfaceNets, 32));
            expect_identical(
                marching_cubes(view, iso),
                detail::mesh_field_reference(field, iso, detail::MeshingMethod::MarchingCubes, 32));
            const ScalarField dense = view.to_dense();
            for (size_t s = 0; s < field.values.size(); ++s)
                ASSERT_EQ(dense.values[s] < iso, field.values[s] < iso) << "sample " << s;
        }
    // Layers out of turn and bad samples are named.
    MeshingViewBuilder early(ball.grid, 0.0f);
    early.add_layer(ball.values.data());
    EXPECT_THROW(early.finish(), GridError);
    MeshingViewBuilder late(slabs.grid, 0.0f);
    for (int64_t k = 0; k < slabs.grid.dims[2]; ++k)
        late.add_layer(&slabs.values[size_t(k * 13 * 11)]);
    EXPECT_THROW(late.add_layer(slabs.values.data()), GridError);
    std::vector<float> bad(ball.values.begin(), ball.values.end());
    bad[size_t(4 + 21 * (5 + 18 * 19))] = NAN;
    MeshingViewBuilder nan(ball.grid, 0.0f);
    try {
        for (int64_t k = 0; k < ball.grid.dims[2]; ++k) nan.add_layer(&bad[size_t(k * 21 * 18)]);
        ADD_FAILURE() << "a NaN sample was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("(4, 5, 19)"), std::string::npos) << e.what();
    }
    EXPECT_THROW(MeshingViewBuilder(ball.grid, INFINITY), InputError);
}

TEST(SparseMeshing, ProgressReachesItsTotalAndCancels) {
    SdfOptions o;
    o.band_voxels = 2.0;
    const SparseField field = signed_distance_sparse_reference(
        test::icosphere({1.0, 2.0, 3.0}, 2.0, 3), test::unit_grid(48, 48, 48), o);
    for (bool nets : {false, true}) {
        auto mesh = [&](const ProgressCallback& progress) {
            return nets ? surface_nets(field, 0.0f, progress)
                        : marching_cubes(field, 0.0f, progress);
        };
        test::ProgressLog log;
        const Mesh got = mesh(log.callback());
        log.expect_contract(nets ? "sparse surface nets" : "sparse cubes");
        expect_identical(got, mesh({}));
        for (double at : {0.0, 0.5}) {
            test::ProgressLog cancel;
            cancel.cancel_from = at;
            EXPECT_THROW(mesh(cancel.callback()), Cancelled) << at;
        }
    }
}

TEST(SparseMeshing, NonFiniteSamplesAndIsoAreRejected) {
    const Grid g = test::unit_grid(12, 10, 9);
    SparseField field(g, 2.0, SparseVoxels(g, 8));
    std::vector<float> samples(SparseField::kLeafSamples, 1.0f);
    samples[2 + 8 * (1 + 8 * 1)] = NAN;  // voxel (10, 1, 1)
    field.append_leaf(1, samples.data());
    EXPECT_THROW(surface_nets(field), InputError);
    EXPECT_THROW(marching_cubes(SparseField(g, 2.0, SparseVoxels(g, 8)), INFINITY), InputError);
    // A grid without cells meshes to nothing.
    const Grid flat = test::unit_grid(9, 9, 1);
    EXPECT_TRUE(surface_nets(SparseField(flat, 2.0, SparseVoxels(flat, 8))).positions.empty());
}

// ---- the same bits on any conformant device ---------------------------------------------------
// OpenCL 1.2 allows x / y to be off by 2.5 ulp. Vertex positions therefore divide through
// om_divide, which walks from any estimate to the correctly rounded quotient; these tests hold it
// to the host's IEEE division, from estimates off by a few ulps (what a device may return) and
// from far away.

uint32_t bits(float x) {
    uint32_t u;
    std::memcpy(&u, &x, sizeof u);
    return u;
}

float step_ulps(float x, int ulps) {
    for (; ulps > 0; --ulps) x = std::nextafter(x, INFINITY);
    for (; ulps < 0; ++ulps) x = std::nextafter(x, 0.0f);
    return x;
}

// A float with a random sign-free mantissa and an exponent in [lo, hi] (2^lo .. 2^hi).
float random_float(std::mt19937& rng, int lo, int hi) {
    std::uniform_int_distribution<int> exponent(lo, hi);
    std::uniform_int_distribution<uint32_t> mantissa(0, (1u << 23) - 1);
    return std::ldexp(1.0f + float(mantissa(rng)) / float(1u << 23), exponent(rng));
}

// om_divide_from(n, d, start) must be IEEE's n / d for every start within `ulps` of it.
void expect_correct_quotient(float n, float d, int ulps) {
    const float exact = n / d;  // the host divides with IEEE round-to-nearest-even
    ASSERT_EQ(bits(detail::om_divide(n, d)), bits(exact)) << n << " / " << d;
    for (int off = -ulps; off <= ulps; ++off) {
        const float start = step_ulps(exact, off);
        ASSERT_EQ(bits(detail::om_divide_from(n, d, start)), bits(exact))
            << n << " / " << d << " from an estimate off by " << off << " ulps";
    }
}

TEST(Meshing, PortableDivisionIsCorrectlyRoundedFromAnEstimateOffByUlps) {
    std::mt19937 rng(7);
    // Quotients in the range vertex positions use ([0, 1]) and far outside it, including
    // subnormal ones; operands anywhere in the float range.
    for (int i = 0; i < 200000; ++i) {
        const float d = random_float(rng, -126, 100);
        const float n = random_float(rng, -149 + 30, 100);
        if (!std::isfinite(n / d)) continue;
        expect_correct_quotient(n, d, i % 50 == 0 ? 4 : 1);
    }
    // Quotients next to a rounding midpoint: n = the float nearest to (q + ulp/2) * d, and its
    // neighbours, for random q in [0, 1] and d.
    for (int i = 0; i < 50000; ++i) {
        const float q = random_float(rng, -30, -1), d = random_float(rng, -20, 20);
        const double midpoint = 0.5 * (double(q) + double(std::nextafter(q, 1.0f)));
        const float n = float(midpoint * double(d));
        for (const float m : {std::nextafter(n, 0.0f), n, std::nextafter(n, INFINITY)})
            expect_correct_quotient(m, d, 3);
    }
    // Hand-picked: exact quotients, zero, a quotient that is exactly a tie (subnormal results
    // only: 2^-149 / 2 rounds to 0, 3 * 2^-149 / 2 and 5 * 2^-149 / 2 to 2 * 2^-149), the
    // largest and smallest operands, and the 1/3, 1/10 family that is never exact.
    const float tiny = std::numeric_limits<float>::denorm_min();
    EXPECT_EQ(bits(detail::om_divide(tiny, 2.0f)), bits(0.0f));
    EXPECT_EQ(bits(detail::om_divide(3 * tiny, 2.0f)), bits(2 * tiny));
    EXPECT_EQ(bits(detail::om_divide(5 * tiny, 2.0f)), bits(2 * tiny));
    const float cases[][2] = {{0.0f, 1.0f},        {0.0f, tiny},     {1.0f, 1.0f},
                              {1.0f, 3.0f},        {2.0f, 3.0f},     {1.0f, 10.0f},
                              {7.0f, 12.0f},       {11.0f, 12.0f},   {tiny, 1.0f},
                              {tiny, tiny},        {tiny, 3.0f},     {FLT_MAX, FLT_MAX},
                              {1.0f, FLT_MAX},     {FLT_MAX, 3e38f}, {1e-30f, 1e10f},
                              {0.1f, 0.30000001f}, {FLT_MIN, 3.0f},  {3 * tiny, 7 * tiny}};
    for (const auto& c : cases) expect_correct_quotient(c[0], c[1], 4);
    // The estimate only decides where the walk starts (each step is one ulp, so a far estimate
    // costs time, not correctness): from 1000 ulps below or above it still ends on the correctly
    // rounded quotient.
    for (int i = 0; i < 200; ++i) {
        const float n = random_float(rng, -12, 0), d = random_float(rng, -1, 3);
        EXPECT_EQ(bits(detail::om_divide_from(n, d, step_ulps(n / d, -1000))), bits(n / d));
        EXPECT_EQ(bits(detail::om_divide_from(n, d, step_ulps(n / d, 1000))), bits(n / d));
    }
}

// The edge crossing equals IEEE's (iso - a) / (b - a) wherever that is finite (up to the sign of
// a zero), and stays in [0, 1] when b - a overflows.
TEST(Meshing, EdgeCrossingIsTheIeeeQuotientOfTheDifferences) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> value(-4.0f, 4.0f);
    for (int i = 0; i < 100000; ++i) {
        const float iso = i % 3 == 0 ? 0.0f : value(rng);
        float a = value(rng), b = value(rng);
        if ((a < iso) == (b < iso)) continue;
        const float expected = (iso - a) / (b - a);
        EXPECT_EQ(bits(detail::om_crossing(a, b, iso)), bits(expected + 0.0f))
            << a << " " << b << " " << iso;
    }
    const float t = detail::om_crossing(-FLT_MAX, FLT_MAX, 0.0f);
    EXPECT_EQ(t, 0.5f);
    EXPECT_EQ(detail::om_crossing(FLT_MAX, -FLT_MAX, 0.0f), 0.5f);
}

// Programs are built with -cl-fp32-correctly-rounded-divide-sqrt exactly when the device says it
// supports it, never with options that relax IEEE arithmetic, and with OV_WIDE_BLOCKS on CPUs.
TEST(Meshing, BuildOptionsFollowTheDevicesReportedFloatCapability) {
    const std::string plain =
        detail::build_options(CL_FP_ROUND_TO_NEAREST | CL_FP_INF_NAN, CL_DEVICE_TYPE_GPU);
    EXPECT_EQ(plain, "-cl-std=CL1.2");
    const std::string with = detail::build_options(
        CL_FP_ROUND_TO_NEAREST | CL_FP_INF_NAN | CL_FP_DENORM | CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT,
        CL_DEVICE_TYPE_GPU);
    EXPECT_EQ(with, "-cl-std=CL1.2 -cl-fp32-correctly-rounded-divide-sqrt");
    // CPU devices take the surface kernels' 16-lane blocks (the same bits).
    EXPECT_EQ(detail::build_options(CL_FP_ROUND_TO_NEAREST | CL_FP_INF_NAN, CL_DEVICE_TYPE_CPU),
              "-cl-std=CL1.2 -DOV_WIDE_BLOCKS");

    // The device in use: its program was built with the options its capability calls for.
    Device::Impl& cl = detail::device_impl(device());
    const cl_device_fp_config config = cl.device.getInfo<CL_DEVICE_SINGLE_FP_CONFIG>();
    const bool supports = (config & CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT) != 0;
    (void)surface_nets(device(), sphere_field());  // builds (or loads) the meshing program
    std::string used;
    for (const auto& [hash, program] : cl.programs)
        used = program.getBuildInfo<CL_PROGRAM_BUILD_OPTIONS>(cl.device);
    std::printf("[ measured ] %s: single fp config 0x%llx, build options \"%s\"\n",
                device().info().name.c_str(), (unsigned long long)config, used.c_str());
    EXPECT_EQ(used.find("-cl-fp32-correctly-rounded-divide-sqrt") != std::string::npos, supports);
    EXPECT_EQ(used.find("fast"), std::string::npos);
    EXPECT_EQ(used.find("mad"), std::string::npos);
}

// ---- occupancy fields ---------------------------------------------------------------------------

TEST(Meshing, SmoothedOccupancyOfABoxIsClosedAndRoundsItsCorners) {
    Grid grid;
    grid.dims = {12, 12, 12};
    SparseVoxels voxels(grid, 8);
    for (int k = 0; k < 12; ++k)  // touches the grid border: the grown field must still close it
        for (int j = 2; j < 9; ++j)
            for (int i = 3; i < 10; ++i) voxels.set(i, j, k);
    const ScalarField field = occupancy_to_field(voxels, 2);
    EXPECT_EQ(field.grid.dims[0], 12 + 2 * 3);
    EXPECT_EQ(field.grid.origin[0], -3.0);
    for (const Mesh& mesh : {marching_cubes(field), surface_nets(field)}) {
        expect_closed_surface(mesh, 2, 1);
        // Smoothing only moves the surface of a convex box inwards (7 x 7 x 12 voxels).
        const double volume = signed_volume(mesh);
        EXPECT_LT(volume, 7.0 * 7.0 * 12.0);
        EXPECT_GT(volume, 0.7 * 7.0 * 7.0 * 12.0);
    }
    EXPECT_THROW(occupancy_to_field(voxels, -1), GridError);
}

// One pass of the 3x3x3 box filter over a 3x3x3 block of set voxels, worked by hand: a sample
// keeps -0.5 per set and +0.5 per unset voxel among its 27 neighbours, divided by 27.
TEST(Meshing, OneSmoothingPassAveragesTheTwentySevenNeighbours) {
    Grid grid;
    grid.dims = {5, 5, 5};
    SparseVoxels voxels(grid, 4);
    for (int k = 1; k < 4; ++k)
        for (int j = 1; j < 4; ++j)
            for (int i = 1; i < 4; ++i) voxels.set(i, j, k);
    const ScalarField field = occupancy_to_field(voxels, 1);  // grown by 2: voxel v is sample v+2
    EXPECT_NEAR(field.at(4, 4, 4), -0.5, 1e-6);               // 27 set
    EXPECT_NEAR(field.at(3, 4, 4), (18 * -0.5 + 9 * 0.5) / 27, 1e-6);  // block face centre
    EXPECT_NEAR(field.at(3, 3, 3), (8 * -0.5 + 19 * 0.5) / 27, 1e-6);  // block corner
    EXPECT_NEAR(field.at(2, 4, 4), (9 * -0.5 + 18 * 0.5) / 27, 1e-6);  // just outside a face
    EXPECT_EQ(field.at(0, 0, 0), 0.5f);
}

// The smoothing as the whole-grid passes it is defined by (x, then y, then z, each a 3-tap average
// with +0.5 beyond the grid), written here over the whole grid: the independent reference of the
// layer-at-a-time filter.
std::vector<float> smoothed_whole_grid(const SparseVoxels& voxels, int passes) {
    const int64_t pad = passes + 1;
    const auto& d = voxels.grid().dims;
    const int64_t n[3] = {d[0] + 2 * pad, d[1] + 2 * pad, d[2] + 2 * pad};
    std::vector<float> values(size_t(n[0] * n[1] * n[2]), 0.5f), next(values.size());
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
        values[size_t((i + pad) + n[0] * ((j + pad) + n[1] * (k + pad)))] = -0.5f;
    });
    const int64_t stride[3] = {1, n[0], n[0] * n[1]};
    for (int pass = 0; pass < passes; ++pass)
        for (int axis = 0; axis < 3; ++axis) {
            for (int64_t z = 0; z < n[2]; ++z)
                for (int64_t y = 0; y < n[1]; ++y)
                    for (int64_t x = 0; x < n[0]; ++x) {
                        const int64_t s = x + n[0] * (y + n[1] * z);
                        const int64_t c = axis == 0 ? x : axis == 1 ? y : z;
                        const float below = c > 0 ? values[size_t(s - stride[axis])] : 0.5f;
                        const float above =
                            c + 1 < n[axis] ? values[size_t(s + stride[axis])] : 0.5f;
                        next[size_t(s)] = (below + values[size_t(s)] + above) / 3.0f;
                    }
            values.swap(next);
        }
    return values;
}

// Random voxels over several bricks (some empty), 0 to 3 passes: the field made a layer at a time
// is the whole-grid filter's bit for bit, and its meshing view meshes as that field does.
TEST(Meshing, OccupancyFieldLayersAreTheWholeGridSmoothingBitForBit) {
    Grid grid;
    grid.dims = {21, 13, 30};
    grid.origin = {-1.0, 2.5, 0.25};
    grid.voxel_size = 0.5;
    SparseVoxels voxels(grid, 8);
    std::mt19937 rng(17);
    for (int v = 0; v < 900; ++v) {
        const int64_t k = int64_t(rng() % 30);
        if (k >= 8 && k < 16) continue;  // a layer of empty bricks
        voxels.set(int64_t(rng() % 21), int64_t(rng() % 13), k);
    }
    for (int passes = 0; passes <= 3; ++passes) {
        SCOPED_TRACE(std::to_string(passes) + " passes");
        const std::vector<float> want = smoothed_whole_grid(voxels, passes);
        const ScalarField field = occupancy_to_field(voxels, passes);
        ASSERT_EQ(field.values.size(), want.size());
        EXPECT_EQ(field.grid.origin[0], grid.origin[0] - (passes + 1) * grid.voxel_size);
        for (size_t s = 0; s < want.size(); ++s)
            ASSERT_EQ(bits(field.values[s]), bits(want[s])) << "sample " << s;
        const SparseField view = occupancy_meshing_view(voxels, passes, 0.1f);
        expect_identical(
            marching_cubes(view, 0.1f),
            detail::mesh_field_reference(field, 0.1f, detail::MeshingMethod::MarchingCubes, 32));
    }
    OccupancyFieldLayers layers(voxels, 1);
    std::vector<float> layer(size_t(layers.grid().dims[0] * layers.grid().dims[1]));
    for (int64_t k = 0; k < layers.grid().dims[2]; ++k) layers.next_layer(layer.data());
    EXPECT_THROW(layers.next_layer(layer.data()), GridError);
}

TEST(Meshing, FieldsWithoutASignChangeOrWithoutCellsGiveEmptyMeshes) {
    const ScalarField outside = sample_field(6, 5, 4, [](const Vec3&) { return 1.0; });
    const ScalarField flat = sample_field(6, 5, 1, [](const Vec3& p) { return p[0] - 3; });
    for (const ScalarField* field : {&outside, &flat}) {
        for (const Mesh& mesh :
             {surface_nets(*field), marching_cubes(*field), surface_nets(device(), *field),
              marching_cubes(device(), *field)}) {
            EXPECT_TRUE(mesh.positions.empty());
            EXPECT_TRUE(mesh.triangles.empty());
        }
    }
}

TEST(Meshing, BadFieldsAreRejectedWithNamedErrors) {
    ScalarField field = sphere_field();
    field.values.pop_back();
    EXPECT_THROW(marching_cubes(field), GridError);
    field = sphere_field();
    field.values[17] = NAN;
    EXPECT_THROW(surface_nets(field), InputError);
    EXPECT_THROW(surface_nets(sphere_field(), INFINITY), InputError);
    EXPECT_THROW(sphere_field().at(40, 0, 0), std::out_of_range);
}

// ---- writers ---------------------------------------------------------------------------------

std::string temp_path(const std::string& name) {
    return ::testing::TempDir() + "oclvox_meshing_" + name;
}

std::string read_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

template <typename T>
T little_endian(const std::string& bytes, size_t at) {
    uint64_t bits = 0;
    for (size_t i = 0; i < sizeof(T); ++i) bits |= uint64_t(uint8_t(bytes.at(at + i))) << (8 * i);
    T value;
    std::memcpy(&value, &bits, sizeof value);  // the test machine is little-endian (x86/ARM)
    return value;
}

Mesh read_obj(const std::string& path) {
    std::ifstream in(path);
    Mesh mesh;
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream s(line);
        std::string tag;
        s >> tag;
        if (tag == "v") {
            Vec3 p;
            s >> p[0] >> p[1] >> p[2];
            mesh.positions.push_back(p);
        } else if (tag == "f") {
            std::array<uint32_t, 3> t;
            s >> t[0] >> t[1] >> t[2];
            for (auto& i : t) --i;
            mesh.triangles.push_back(t);
        }
    }
    return mesh;
}

Mesh read_ply(const std::string& path) {
    const std::string bytes = read_bytes(path);
    const size_t body = bytes.find("end_header\n") + 11;
    size_t vertices = 0, faces = 0;
    std::istringstream header(bytes.substr(0, body));
    std::string word;
    while (header >> word)
        if (word == "element") {
            header >> word;
            (word == "vertex" ? vertices : faces) = [&] {
                size_t n;
                header >> n;
                return n;
            }();
        }
    EXPECT_NE(bytes.find("format binary_little_endian 1.0"), std::string::npos);
    Mesh mesh;
    size_t at = body;
    for (size_t v = 0; v < vertices; ++v, at += 24)
        mesh.positions.push_back({little_endian<double>(bytes, at),
                                  little_endian<double>(bytes, at + 8),
                                  little_endian<double>(bytes, at + 16)});
    for (size_t f = 0; f < faces; ++f, at += 13) {
        EXPECT_EQ(bytes.at(at), 3);
        mesh.triangles.push_back({little_endian<uint32_t>(bytes, at + 1),
                                  little_endian<uint32_t>(bytes, at + 5),
                                  little_endian<uint32_t>(bytes, at + 9)});
    }
    EXPECT_EQ(at, bytes.size());
    return mesh;
}

TEST(Meshing, WrittenMeshesReadBackExactly) {
    const Mesh mesh = marching_cubes(torus_field());
    const std::string obj = temp_path("torus.OBJ"), ply = temp_path("torus.ply"),
                      stl = temp_path("torus.stl");
    write_mesh(obj, mesh);
    write_mesh(ply, mesh);
    write_mesh(stl, mesh);
    expect_identical(read_obj(obj), mesh);
    expect_identical(read_ply(ply), mesh);

    // STL: float corners of each facet, a unit normal agreeing with the winding.
    const std::string bytes = read_bytes(stl);
    ASSERT_EQ(bytes.size(), 84 + 50 * mesh.triangles.size());
    EXPECT_EQ(little_endian<uint32_t>(bytes, 80), mesh.triangles.size());
    for (size_t t = 0; t < mesh.triangles.size(); t += 97) {
        const size_t at = 84 + 50 * t;
        for (int c = 0; c < 3; ++c)
            for (int k = 0; k < 3; ++k)
                EXPECT_EQ(little_endian<float>(bytes, at + 12 + 12 * c + 4 * k),
                          float(mesh.positions[mesh.triangles[t][c]][k]));
        const Vec3& a = mesh.positions[mesh.triangles[t][0]];
        const Vec3& b = mesh.positions[mesh.triangles[t][1]];
        const Vec3& c = mesh.positions[mesh.triangles[t][2]];
        const Vec3 n{(b[1] - a[1]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[1] - a[1]),
                     (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2]),
                     (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])};
        double dot = 0, length = 0;
        for (int k = 0; k < 3; ++k) {
            dot += n[k] * little_endian<float>(bytes, at + 4 * k);
            length += n[k] * n[k];
        }
        EXPECT_NEAR(dot, std::sqrt(length), 1e-4 * std::sqrt(length));
    }
    for (const auto& path : {obj, ply, stl}) std::remove(path.c_str());
}

TEST(Meshing, WriteMeshRejectsUnknownExtensionsAndBadIndicesWithoutWriting) {
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    mesh.triangles = {{0, 1, 2}};
    const std::string off = temp_path("mesh.off");
    EXPECT_THROW(write_mesh(off, mesh), OutputError);
    mesh.triangles = {{0, 1, 3}};
    const std::string obj = temp_path("bad.obj");
    EXPECT_THROW(write_mesh(obj, mesh), OutputError);
    EXPECT_FALSE(std::ifstream(off).good());
    EXPECT_FALSE(std::ifstream(obj).good());
}

// Writing a mesh reports as writing voxels does (one total, never back, the end before the file
// takes its name); a cancel leaves the file that was there. The mesh is large enough for many
// parts of the file to be formatted at once, and the file read back is the mesh.
TEST(Meshing, WritingReportsProgressAndACancelKeepsThePreviousFile) {
    const ScalarField field = sample_field(160, 160, 160, [](const Vec3& p) {
        return sphere_distance(p, {80.2, 79.6, 80.1}, 70.3);
    });
    const Mesh mesh = marching_cubes(field);
    ASSERT_GT(mesh.positions.size() + mesh.triangles.size(), 2 * 65536u);  // several reports
    for (const char* extension : {".obj", ".ply", ".stl"}) {
        const std::string path = temp_path(std::string("progress") + extension);
        test::ProgressLog log;
        log.slow = true;
        bool existed_at_the_end = true;
        auto callback = log.callback();
        write_mesh(path, mesh, [&](uint64_t done, uint64_t total) {
            if (done == total) existed_at_the_end = std::ifstream(path).good();
            return callback(done, total);
        });
        log.expect_contract(extension);
        EXPECT_FALSE(existed_at_the_end) << extension;
        if (std::string(extension) != ".stl") EXPECT_GE(log.steps_inside(), 2u) << extension;
        const std::string written = read_bytes(path);
        // Formatted in many parts on the cores and written in order: the same mesh read back.
        if (std::string(extension) == ".obj") expect_identical(read_obj(path), mesh);
        if (std::string(extension) == ".ply") expect_identical(read_ply(path), mesh);
        if (std::string(extension) == ".stl")
            EXPECT_EQ(written.size(), 84 + 50 * mesh.triangles.size());
        test::ProgressLog cancel;
        cancel.cancel_from = 0.5;
        EXPECT_THROW(write_mesh(path, Mesh{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}},
                                cancel.callback()),
                     Cancelled);
        EXPECT_EQ(read_bytes(path), written) << extension;
        std::remove(path.c_str());
    }
}

}  // namespace
}  // namespace oclvox
