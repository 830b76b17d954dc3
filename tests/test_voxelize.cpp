// The OpenCL path: device results equal the CPU reference bit for bit, for every brick size,
// budget and triangle order, on random and real meshes.
#include <algorithm>

#include "opencl_runtime.hpp"
#include "test_support.hpp"

namespace oclvox::test {
namespace {

const OverlapTest kTests[] = {OverlapTest::SAT, OverlapTest::PEF};

VoxelizeOptions options(OverlapTest test, int brick = 16) {
    VoxelizeOptions o;
    o.test = test;
    o.brick_size = brick;
    return o;
}

void expect_same(const SparseVoxels& device_result, const SparseVoxels& reference) {
    EXPECT_EQ(device_result.count(), reference.count());
    EXPECT_TRUE(device_result.same_voxels(reference));
}

class DeviceMatchesReference : public ::testing::TestWithParam<OverlapTest> {};

TEST_P(DeviceMatchesReference, OnRandomTrianglesOfAllSizes) {
    const Grid g = unit_grid(40, 33, 47);
    for (uint32_t seed = 1; seed <= 3; ++seed) {
        const Mesh m = random_triangles(400, -3, 45, seed * seed * 2.0, seed);
        expect_same(device().voxelize(m, g, options(GetParam())),
                    voxelize_reference(m, g, options(GetParam())));
    }
}

TEST_P(DeviceMatchesReference, OnHandWorkedCube) {
    const Mesh m = box_mesh({1, 1, 1}, {5, 5, 5});
    const SparseVoxels v = device().voxelize(m, unit_grid(8, 8, 8), options(GetParam(), 4));
    EXPECT_EQ(v.count(), 208u);
}

TEST_P(DeviceMatchesReference, OnSpotAndTheCadPart) {
    for (const char* name : {"spot.obj", "TR12J_OCC.stl"}) {
        const Mesh m = load_mesh(mesh_path(name));
        GridFit fit;
        fit.resolution = 64;
        const Grid g = fit_grid(m, fit);
        expect_same(device().voxelize(m, g, options(GetParam(), 32)),
                    voxelize_reference(m, g, options(GetParam(), 32)));
    }
}

// The result does not depend on brick size or on the device budget (which decides how many
// bricks share a batch): a 96^3 grid in bricks of 4..96 and with a budget of a single brick.
TEST_P(DeviceMatchesReference, ForEveryBrickSizeAndBudget) {
    const Grid g = unit_grid(96, 80, 90);
    const Mesh m = random_triangles(300, 0, 90, 20, 17);
    const SparseVoxels ref = voxelize_reference(m, g, options(GetParam()));
    for (int brick : {4, 8, 12, 32, 96}) {
        VoxelizeStats stats;
        expect_same(device().voxelize(m, g, options(GetParam(), brick), &stats), ref);
        EXPECT_EQ(stats.voxels_set, ref.count());
    }
    VoxelizeOptions tight = options(GetParam(), 16);
    tight.device_budget_bytes = 16 * 16 * 16 / 8;  // exactly one brick per batch
    VoxelizeStats stats;
    expect_same(device().voxelize(m, g, tight, &stats), ref);
    EXPECT_EQ(stats.batches, stats.bricks_active);
}

// Whole batches and only their non-empty blocks bring back the same voxels, in one batch or in a
// batch per brick, and the compact download is the size of the result's non-empty blocks.
TEST_P(DeviceMatchesReference, ForBothDownloadsAndEveryBudget) {
    const Grid g = unit_grid(96, 80, 90);
    const Mesh m = random_triangles(300, 0, 90, 20, 17);
    const SparseVoxels ref = voxelize_reference(m, g, options(GetParam()));
    for (uint64_t budget : {uint64_t(256) << 20, uint64_t(16 * 16 * 16 / 8), uint64_t(4096)}) {
        VoxelizeOptions o = options(GetParam(), 16);
        o.device_budget_bytes = budget;
        VoxelizeStats whole, compact;
        o.download = Download::Whole;
        expect_same(device().voxelize(m, g, o, &whole), ref);
        o.download = Download::NonEmptyBlocks;
        expect_same(device().voxelize(m, g, o, &compact), ref);
        EXPECT_EQ(compact.batches, whole.batches);
        expect_compact_download(ref, whole, compact);
        EXPECT_LT(compact.bytes_downloaded, whole.bytes_downloaded) << budget;
    }
}

// Shuffling the triangle order changes the binning and the order of atomic ORs, never the bits.
TEST_P(DeviceMatchesReference, ForShuffledTriangles) {
    const Grid g = unit_grid(32, 32, 32);
    Mesh m = random_triangles(300, 0, 32, 6, 23);
    const SparseVoxels before = device().voxelize(m, g, options(GetParam()));
    std::mt19937 rng(3);
    std::shuffle(m.triangles.begin(), m.triangles.end(), rng);
    expect_same(device().voxelize(m, g, options(GetParam())), before);
}

INSTANTIATE_TEST_SUITE_P(BothTests, DeviceMatchesReference, ::testing::ValuesIn(kTests),
                         [](const auto& info) { return std::string(to_string(info.param)); });

// Thin voxelization and the half-open boundary rule run the same tiled path with other setup and
// test functions: device == reference for every brick size.
TEST(DeviceMatchesReferenceForModes, ThinAndHalfOpen) {
    const Grid g = unit_grid(48, 40, 44);
    Mesh m = random_triangles(300, 0, 44, 6, 29);
    // A box puts faces exactly on voxel planes, where the boundary rule matters.
    const Mesh box = box_mesh({4, 4, 4}, {20, 12, 30});
    for (const auto& t : box.triangles)
        add_triangle(m, box.positions[t[0]], box.positions[t[1]], box.positions[t[2]]);
    for (int brick : {8, 16, 48}) {
        VoxelizeOptions thin = options(OverlapTest::PEF, brick);
        thin.mode = VoxelizeMode::Thin;
        expect_same(device().voxelize(m, g, thin), voxelize_reference(m, g, thin));
        thin.boundary = Boundary::HalfOpen;
        expect_same(device().voxelize(m, g, thin), voxelize_reference(m, g, thin));
        for (OverlapTest test : kTests) {
            VoxelizeOptions open = options(test, brick);
            open.boundary = Boundary::HalfOpen;
            expect_same(device().voxelize(m, g, open), voxelize_reference(m, g, open));
        }
    }
}

// The surface kernels and their batches as a GPU runs them (device_used_as_a_gpu: 4-lane
// blocks, uploads, bit buffers the device fills, compact or whole downloads) equal the
// reference: SAT, PEF and thin, closed and half-open, on random triangles with a box on voxel
// planes and on spot, in one batch and in a batch per brick.
TEST(DeviceMatchesReferenceForModes, WhenRunAsOnAGpu) {
    Device& gpu = device_used_as_a_gpu();
    ASSERT_EQ(detail::device_impl(gpu).build_options.find("OV_WIDE_BLOCKS"), std::string::npos);
    Mesh m = random_triangles(300, 0, 44, 6, 31);
    const Mesh box = box_mesh({4, 4, 4}, {20, 12, 30});
    for (const auto& t : box.triangles)
        add_triangle(m, box.positions[t[0]], box.positions[t[1]], box.positions[t[2]]);
    const Mesh spot = load_mesh(mesh_path("spot.obj"));
    GridFit fit;
    fit.resolution = 64;
    for (const auto& [mesh, grid] : {std::pair<const Mesh&, Grid>{m, unit_grid(48, 40, 44)},
                                     std::pair<const Mesh&, Grid>{spot, fit_grid(spot, fit)}})
        for (const VoxelizeMode mode : {VoxelizeMode::Surface, VoxelizeMode::Thin})
            for (const OverlapTest test : kTests)
                for (const Boundary boundary : {Boundary::Closed, Boundary::HalfOpen}) {
                    if (mode == VoxelizeMode::Thin && test == OverlapTest::SAT) continue;
                    VoxelizeOptions o = options(test, 16);
                    o.mode = mode;
                    o.boundary = boundary;
                    SCOPED_TRACE(std::string(to_string(mode)) + " " + to_string(test) + " " +
                                 to_string(boundary));
                    const SparseVoxels reference = voxelize_reference(mesh, grid, o);
                    VoxelizeStats stats;
                    expect_same(gpu.voxelize(mesh, grid, o, &stats), reference);
                    EXPECT_EQ(stats.batches, 1u);
                    o.device_budget_bytes = 16 * 16 * 16 / 8;  // a brick a batch
                    expect_same(gpu.voxelize(mesh, grid, o, &stats), reference);
                    EXPECT_EQ(stats.batches, stats.bricks_active);
                    o.download = Download::Whole;  // mapped from the device's memory
                    expect_same(gpu.voxelize(mesh, grid, o), reference);
                }
}

// The kernels find each voxel row's run from a bound and walk to its exact ends; the bound is
// widest where a test's x coefficient is tiny. Large triangles nearly parallel to the rows (normals
// almost perpendicular to x, tilted by 1e-7 to 1e-2), on and just off voxel planes, with every
// predicate and boundary rule, give long rows on which any bound that is too tight drops voxels.
TEST(DeviceMatchesReferenceForModes, LongRowsNearlyParallelToX) {
    const Grid g = unit_grid(90, 37, 41);
    Mesh m;
    uint32_t state = 7;
    const auto next = [&state] {
        state = state * 1664525u + 1013904223u;
        return double(state >> 8) / double(1u << 24);
    };
    for (double tilt : {0.0, 1e-7, 3e-5, 1e-2}) {
        for (double offset : {10.0, 10.5, 10.0 + 1e-6}) {
            // Plane y = offset + tilt * x (+ a little z), and the same with y and z swapped.
            const double a = -2 + 4 * next(), b = 92 * next(), z0 = 40 * next();
            add_triangle(m, {a, offset + tilt * a, z0}, {b, offset + tilt * b, 40 - z0},
                         {0.5 * (a + b), offset + tilt * (0.5 * (a + b)) + 1e-3, 20 * next()});
            add_triangle(m, {a, z0 * 0.9, offset - tilt * a}, {b, 36 - z0 * 0.9, offset - tilt * b},
                         {0.5 * (a + b), 18 * next(), offset + 2 * tilt});
        }
    }
    for (int brick : {16, 64}) {
        for (const Boundary boundary : {Boundary::Closed, Boundary::HalfOpen}) {
            VoxelizeOptions thin = options(OverlapTest::PEF, brick);
            thin.mode = VoxelizeMode::Thin;
            thin.boundary = boundary;
            expect_same(device().voxelize(m, g, thin), voxelize_reference(m, g, thin));
            for (OverlapTest test : kTests) {
                VoxelizeOptions o = options(test, brick);
                o.boundary = boundary;
                expect_same(device().voxelize(m, g, o), voxelize_reference(m, g, o));
            }
        }
    }
}

// SAT and PEF with `boundary`, on the suite's device (also as a GPU runs it) and as the reference,
// with bricks of 8, 16 and 48, set exactly the voxels of `expected` on mesh m.
void expect_conservative_tests_set(const Mesh& m, const Grid& g, Boundary boundary,
                                   const SparseVoxels& expected) {
    for (OverlapTest test : kTests)
        for (int brick : {8, 16, 48}) {
            SCOPED_TRACE(std::string(to_string(test)) + " " + to_string(boundary) + ", bricks of " +
                         std::to_string(brick));
            VoxelizeOptions o = options(test, brick);
            o.boundary = boundary;
            expect_same(device().voxelize(m, g, o), expected);
            expect_same(device_used_as_a_gpu().voxelize(m, g, o), expected);
            expect_same(voxelize_reference(m, g, o), expected);
        }
}

// A triangle within one voxel's box meets that voxel and no other: its range is one voxel, and the
// conservative tests set it without testing (ov_range_is_row). Hand-worked on 3000 such
// triangles at dyadic coordinates (exact in float): strictly inside their voxel for closed boxes,
// and for half-open ones also with vertices on the voxel's lower faces, which belong to it alone.
// Device (also as a GPU runs it) and reference must set exactly those voxels, for every brick
// size; among larger triangles, device == reference.
TEST(DeviceMatchesReferenceForModes, TrianglesWithinOneVoxelSetThatVoxelAlone) {
    const Grid g = unit_grid(40, 33, 47);
    for (const Boundary boundary : {Boundary::Closed, Boundary::HalfOpen}) {
        std::mt19937 rng(boundary == Boundary::Closed ? 3 : 4);
        std::uniform_int_distribution<int> fraction(boundary == Boundary::Closed ? 1 : 0, 63);
        Mesh m;
        SparseVoxels expected(g, 16);
        for (int t = 0; t < 3000; ++t) {
            const int64_t v[3] = {int64_t(rng() % 40), int64_t(rng() % 33), int64_t(rng() % 47)};
            Vec3d corner[3];
            for (Vec3d& p : corner)
                for (int k = 0; k < 3; ++k) p[k] = double(v[k]) + fraction(rng) / 64.0;
            add_triangle(m, corner[0], corner[1], corner[2]);
            expected.set(v[0], v[1], v[2]);
        }
        expect_conservative_tests_set(m, g, boundary, expected);
        // Mixed with triangles of every size, the one-voxel ones still take their own path.
        Mesh mixed = random_triangles(300, -3, 45, 8, 5);
        for (const auto& t : m.triangles)
            add_triangle(mixed, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]);
        for (OverlapTest test : kTests) {
            VoxelizeOptions o = options(test, 16);
            o.boundary = boundary;
            expect_same(device().voxelize(mixed, g, o), voxelize_reference(mixed, g, o));
        }
    }
}

// A triangle within one voxel's box across two axes meets every voxel of its range along the
// third (it is connected, and its coordinates there fill the interval of its vertices'), and the
// conservative tests set that row without testing (ov_range_is_row). Hand-worked on rows along
// each axis at dyadic coordinates (exact in float), some reaching out of the grid: across the
// row, strictly inside the voxel for closed boxes (also on its lower face for half-open ones);
// along it, ends anywhere, on voxel faces too, so the row is the voxels k with
// ceil(lo) - 1 <= k <= floor(hi) for closed boxes (a face touched belongs to both voxels) and
// floor(lo) <= k <= floor(hi) for half-open ones. Device (also as a GPU runs it) and reference
// must set exactly those voxels, for brick sizes that cut the rows in many places.
TEST(DeviceMatchesReferenceForModes, TrianglesWithinOneVoxelRowSetTheWholeRow) {
    const Grid g = unit_grid(40, 33, 47);
    for (const Boundary boundary : {Boundary::Closed, Boundary::HalfOpen}) {
        std::mt19937 rng(boundary == Boundary::Closed ? 5 : 6);
        std::uniform_int_distribution<int> fraction(boundary == Boundary::Closed ? 1 : 0, 63);
        std::uniform_int_distribution<int> along(0, 12 * 64);  // up to 12 voxels long
        Mesh m;
        SparseVoxels expected(g, 16);
        for (int t = 0; t < 3000; ++t) {
            const int axis = t % 3;
            int64_t v[3] = {int64_t(rng() % 40), int64_t(rng() % 33), int64_t(rng() % 47)};
            const int start = int(rng() % uint32_t(g.dims[axis] + 6)) - 4;  // some leave the grid
            Vec3d corner[3];
            double lo = 1e9, hi = -1e9;
            for (Vec3d& p : corner) {
                for (int k = 0; k < 3; ++k) p[k] = double(v[k]) + fraction(rng) / 64.0;
                p[axis] = start + along(rng) / 64.0;
                lo = std::min(lo, p[axis]);
                hi = std::max(hi, p[axis]);
            }
            add_triangle(m, corner[0], corner[1], corner[2]);
            const int64_t first =
                boundary == Boundary::Closed ? int64_t(std::ceil(lo)) - 1 : int64_t(std::floor(lo));
            for (int64_t k = std::max<int64_t>(first, 0);
                 k <= std::min<int64_t>(int64_t(std::floor(hi)), g.dims[axis] - 1); ++k) {
                v[axis] = k;
                expected.set(v[0], v[1], v[2]);
            }
        }
        expect_conservative_tests_set(m, g, boundary, expected);
    }
}

// A grid whose dense bit array is 64x the device budget still works, in many batches, and the
// bunny's surface is exact up to rounding against the double-precision test.
TEST(Tiling, GridLargerThanDeviceBudget) {
    const Mesh m = load_mesh(mesh_path("bunny00.off"));
    GridFit fit;
    fit.resolution = 256;
    const Grid g = fit_grid(m, fit);
    VoxelizeOptions o = options(OverlapTest::PEF, 32);
    o.device_budget_bytes = g.voxel_count() / 8 / 64;
    VoxelizeStats stats;
    const SparseVoxels v = device().voxelize(m, g, o, &stats);
    EXPECT_GT(stats.batches, 8u);
    EXPECT_LT(stats.bricks_active, stats.bricks_total);  // empty space costs nothing
    expect_exact_up_to(v, m, 1e-4);
}

// One huge triangle across a 512^3 grid is spread over many bricks and work items, and the
// binning culls the bricks it passes by.
TEST(Tiling, HugeTriangleIsSpreadAndCulled) {
    Mesh m;
    add_triangle(m, {0, 0, 0}, {512, 0, 512}, {0, 512, 512});
    VoxelizeStats stats;
    const Grid g = unit_grid(512, 512, 512);
    const SparseVoxels v = device().voxelize(m, g, options(OverlapTest::SAT, 64), &stats);
    EXPECT_LT(stats.brick_pairs, 8u * 8u * 8u);  // culled below the bounding box's 512 bricks
    EXPECT_GT(stats.work_items, 1000u);
    // Plane x + y - z = 0 (restricted to the triangle): sample the known answer on a few voxels.
    EXPECT_TRUE(v.get(0, 0, 0));
    EXPECT_TRUE(v.get(100, 100, 200));
    EXPECT_FALSE(v.get(100, 100, 100));
    expect_same(v, voxelize_reference(m, g, options(OverlapTest::SAT, 64)));
}

// Progress is reported per batch and a false return cancels.
TEST(Progress, ReportsBatchesAndCancels) {
    const Grid g = unit_grid(64, 64, 64);
    const Mesh m = random_triangles(200, 0, 64, 10, 2);
    VoxelizeOptions o = options(OverlapTest::PEF, 8);
    o.device_budget_bytes = 8 * 8 * 8 / 8 * 4;
    uint64_t calls = 0, last = 0;
    o.progress = [&](uint64_t done, uint64_t total) {
        ++calls;
        EXPECT_GT(done, last);
        EXPECT_LE(done, total);
        last = done;
        return true;
    };
    VoxelizeStats stats;
    device().voxelize(m, g, o, &stats);
    EXPECT_EQ(calls, stats.batches);
    EXPECT_EQ(last, stats.bricks_active);
    o.progress = [](uint64_t, uint64_t) { return false; };
    EXPECT_THROW(device().voxelize(m, g, o), Cancelled);
}

// 30000 small triangles along x, in [0, 0.1] x [0, 1e-3] x {0}: enough for several of the
// preparation's parallel chunks.
Mesh many_small_triangles() {
    Mesh m;
    for (int t = 0; t < 30000; ++t) {
        const double x = 1e-3 * (t % 100);
        add_triangle(m, {x, 0, 0}, {x + 1e-3, 0, 0}, {x, 1e-3, 0});
    }
    return m;
}

// The InputError message of voxelizing m on g on the device and with the reference (both must
// throw one).
std::vector<std::string> input_errors_of(const Mesh& m, const Grid& g) {
    std::vector<std::string> messages;
    for (bool on_device : {false, true}) {
        try {
            if (on_device)
                device().voxelize(m, g, VoxelizeOptions{});
            else
                voxelize_reference(m, g, VoxelizeOptions{});
            ADD_FAILURE() << "no InputError " << (on_device ? "on the device" : "in the reference");
        } catch (const InputError& e) {
            messages.push_back(e.what());
        }
    }
    return messages;
}

// Triangles are prepared in parallel chunks; the error still names the first triangle that does
// not fit grid coordinates, in a later chunk than the first thousands.
TEST(Tiling, TheFirstTriangleOutsideGridCoordinatesIsNamed) {
    Mesh m = many_small_triangles();
    // (1e10 - 0) / 1e-300 overflows to infinity; triangles 20000 and 10000 reach it.
    m.positions[m.triangles[20000][1]][2] = 1e10;
    m.positions[m.triangles[10000][2]][1] = 1e10;
    Grid g;
    g.voxel_size = 1e-300;
    g.dims = {8, 8, 8};
    for (const std::string& message : input_errors_of(m, g))
        EXPECT_NE(message.find("triangle 10000 "), std::string::npos) << message;
}

// Preparation checks vertex indices on its way instead of validating the mesh first; the error
// must still be validation's, naming the first bad triangle, even where a triangle before it does
// not fit grid coordinates.
TEST(Tiling, AMissingVertexIsNamedAsValidationWouldNameIt) {
    Mesh m = many_small_triangles();
    m.triangles[25000][2] = uint32_t(m.positions.size());
    m.triangles[20000][0] = uint32_t(m.positions.size() + 7);
    const std::string expected =
        "triangle 20000 refers to vertex " + std::to_string(m.positions.size() + 7);
    // Every vertex in the grid (prepared without a pass to count pieces), and a mesh whose
    // triangle 10000 does not fit grid coordinates.
    Grid fitted;
    fitted.voxel_size = 1e-3;
    fitted.dims = {128, 8, 8};
    Mesh overflowing = m;
    overflowing.positions[m.triangles[10000][1]][2] = 1e10;
    Grid tiny = fitted;
    tiny.voxel_size = 1e-300;
    for (const auto& [mesh, g] : {std::pair{m, fitted}, std::pair{overflowing, tiny}})
        for (const std::string& message : input_errors_of(mesh, g))
            EXPECT_NE(message.find(expected), std::string::npos) << message;
}

TEST(Tiling, AbsurdGridIsRefusedBeforeAllocating) {
    const Grid g = unit_grid(kMaxGridAxis, kMaxGridAxis, kMaxGridAxis);
    const Mesh m = box_mesh({0, 0, 0}, {double(kMaxGridAxis), double(kMaxGridAxis), 1});
    EXPECT_THROW(device().voxelize(m, g, options(OverlapTest::PEF, 8)), GridError);
}

// A kernel that does not compile raises KernelBuildError carrying the compiler's log.
TEST(Devices, KernelBuildFailureCarriesTheBuildLog) {
    std::vector<cl::Platform> platforms;
    cl::Platform::get(&platforms);
    std::vector<cl::Device> devices;
    platforms.at(0).getDevices(CL_DEVICE_TYPE_ALL, &devices);
    Device::Impl impl;
    impl.device = devices.at(0);
    impl.info.name = "test device";
    impl.context = cl::Context(impl.device);
    const detail::KernelSource broken{
        "broken", "__kernel void f() { this is not C; }",
        "0000000000000000000000000000000000000000000000000000000000000000"};
    setenv("OCLVOX_CACHE_DIR", "off", 1);
    try {
        impl.program(broken);
        FAIL() << "a broken kernel built";
    } catch (const KernelBuildError& e) {
        EXPECT_NE(std::string(e.what()).find("CL_BUILD_PROGRAM_FAILURE"), std::string::npos);
        EXPECT_NE(e.build_log().find("error"), std::string::npos) << e.build_log();
    }
    unsetenv("OCLVOX_CACHE_DIR");
}

// load_kernels loads every program the voxelize call with the same options uses: with the disk
// cache off every load is a build the callback hears of, and the call after it hears of none.
TEST(Devices, LoadKernelsLeavesNothingForVoxelizeToBuild) {
    const Mesh m = load_mesh(mesh_path("spot.obj"));
    GridFit fit;
    fit.resolution = 24;
    const Grid g = fit_grid(m, fit);
    setenv("OCLVOX_CACHE_DIR", "off", 1);
    for (const VoxelizeMode mode :
         {VoxelizeMode::Surface, VoxelizeMode::Thin, VoxelizeMode::Solid, VoxelizeMode::Filled})
        for (const Download download : {Download::Whole, Download::NonEmptyBlocks}) {
            Device d = Device::open(device_selector());
            std::vector<std::string> built;
            d.on_kernel_compile([&](const Device::KernelCompile& c) {
                if (c.finished) built.push_back(c.program);
            });
            VoxelizeOptions o;
            o.mode = mode;
            o.brick_size = 8;
            o.download = download;
            d.load_kernels(o);
            EXPECT_FALSE(built.empty());
            const size_t loaded = built.size();
            d.voxelize(m, g, o);
            EXPECT_EQ(built.size(), loaded)
                << to_string(mode) << " " << to_string(download) << " built " << built.back();
        }
    unsetenv("OCLVOX_CACHE_DIR");
}

TEST(Devices, MissingDeviceIsAnErrorNotAFallback) {
    EXPECT_THROW(Device::open("no-such-device-anywhere"), DeviceError);
    EXPECT_FALSE(list_devices().empty());
    EXPECT_NO_THROW(Device::open(list_devices().front().id));
}

}  // namespace
}  // namespace oclvox::test
