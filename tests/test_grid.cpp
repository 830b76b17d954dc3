// Grid fitting, the limits that refuse impossible grids, and the sparse bit grid's storage.
#include <cstring>

#include "host_memory.hpp"
#include "sparse_voxels_access.hpp"
#include "test_support.hpp"

namespace oclvox::test {
namespace {

Mesh long_box() {
    return box_mesh({-1, 0, 2}, {3, 1, 2.5});
}  // extents 4 x 1 x 0.5

TEST(FitGrid, DefaultFitsBoundingBoxWithResolutionOnLongestAxis) {
    GridFit fit;
    fit.resolution = 8;
    const Grid g = fit_grid(long_box(), fit);
    EXPECT_DOUBLE_EQ(g.voxel_size, 0.5);
    EXPECT_EQ(g.dims, (std::array<int64_t, 3>{8, 2, 1}));
    EXPECT_EQ(g.origin, (std::array<double, 3>{-1, 0, 2}));
}

TEST(FitGrid, LongestAxisGetsExactlyTheResolutionAndOtherAxesTheFewestThatCover) {
    // extent / (extent / N) rounds to just above N for many N (spot at 50 gave 51 voxels).
    const Mesh spot = load_mesh(std::string(OCLVOX_SAMPLE_DIR) + "/spot.obj");
    std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (const auto& p : spot.positions)
        for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
    int longest = 0;
    for (int k = 1; k < 3; ++k)
        if (hi[k] - lo[k] > hi[longest] - lo[longest]) longest = k;
    const Mesh box = long_box();
    for (const Mesh* mesh : {&spot, &box})
        for (int64_t resolution = 1; resolution <= 700; ++resolution) {
            GridFit fit;
            fit.resolution = resolution;
            const Grid g = fit_grid(*mesh, fit);
            if (mesh == &spot) {
                ASSERT_EQ(g.dims[longest], resolution);
                for (int k = 0; k < 3; ++k) {
                    if (k == longest) continue;
                    // Covers the mesh, and one voxel fewer would not.
                    EXPECT_GE(g.origin[k] + double(g.dims[k]) * g.voxel_size, hi[k]) << resolution;
                    if (g.dims[k] > 1)
                        EXPECT_LT(g.origin[k] + double(g.dims[k] - 1) * g.voxel_size, hi[k])
                            << resolution;
                }
            } else {
                ASSERT_EQ(g.dims[0], resolution);
            }
        }
    GridFit fit;
    fit.resolution = 50;
    EXPECT_EQ(fit_grid(spot, fit).dims[longest], 50);
}

TEST(FitGrid, CubicIsResolutionCubedWithMeshCentred) {
    GridFit fit;
    fit.resolution = 8;
    fit.cubic = true;
    const Grid g = fit_grid(long_box(), fit);
    EXPECT_EQ(g.dims, (std::array<int64_t, 3>{8, 8, 8}));
    EXPECT_DOUBLE_EQ(g.origin[0], -1);
    EXPECT_DOUBLE_EQ(g.origin[1], 0.5 - 2);
    EXPECT_DOUBLE_EQ(g.origin[2], 2.25 - 2);
}

// binvox's convention (translate = box minimum, scale = longest side): the box minimum is the
// cube's corner on every axis, so the mesh touches the cube's three low faces.
TEST(FitGrid, CubicAtMinimumPutsTheBoxMinimumAtTheCorner) {
    GridFit fit;
    fit.resolution = 8;
    fit.cubic = true;
    fit.cubic_anchor = GridFit::CubicAnchor::Minimum;
    const Grid g = fit_grid(long_box(), fit);
    EXPECT_EQ(g.dims, (std::array<int64_t, 3>{8, 8, 8}));
    EXPECT_DOUBLE_EQ(g.voxel_size, 0.5);  // binvox scale 4 = longest side, over 8 voxels
    EXPECT_EQ(g.origin, (std::array<double, 3>{-1, 0, 2}));

    // Where the box lands: x in [-1, 3] fills voxels 0..7, y in [0, 1] touches 0..2 (closed boxes:
    // y = 1 is the face between voxels 1 and 2), z in [2, 2.5] touches 0..1.
    VoxelizeOptions options;
    const SparseVoxels voxels = voxelize_reference(long_box(), g, options);
    int64_t hi[3] = {-1, -1, -1}, lo[3] = {99, 99, 99};
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
        const int64_t v[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], v[a]), hi[a] = std::max(hi[a], v[a]);
    });
    EXPECT_EQ((std::array<int64_t, 3>{lo[0], lo[1], lo[2]}), (std::array<int64_t, 3>{0, 0, 0}));
    EXPECT_EQ((std::array<int64_t, 3>{hi[0], hi[1], hi[2]}), (std::array<int64_t, 3>{7, 2, 1}));
}

TEST(FitGrid, VoxelSizeOriginDimsAndPadAreHonoured) {
    GridFit fit;
    fit.voxel_size = 0.25;
    fit.pad = 2;
    Grid g = fit_grid(long_box(), fit);
    EXPECT_EQ(g.dims, (std::array<int64_t, 3>{20, 8, 6}));
    EXPECT_DOUBLE_EQ(g.origin[0], -1.5);
    fit = GridFit{};
    fit.voxel_size = 1;
    fit.has_origin = true;
    fit.origin = {10, 20, 30};
    fit.has_dims = true;
    fit.dims = {3, 4, 5};
    g = fit_grid(long_box(), fit);
    EXPECT_EQ(g.dims, (std::array<int64_t, 3>{3, 4, 5}));
    EXPECT_EQ(g.origin, (std::array<double, 3>{10, 20, 30}));
}

TEST(FitGrid, ImpossibleGridsAreRefusedWithAReason) {
    GridFit fit;
    fit.resolution = 0;
    EXPECT_THROW(fit_grid(long_box(), fit), GridError);
    fit.resolution = 100000000;
    EXPECT_THROW(fit_grid(long_box(), fit), GridError);
    fit = GridFit{};
    fit.voxel_size = 1e-12;
    try {
        fit_grid(long_box(), fit);
        ADD_FAILURE() << "a grid of 1e-12 voxels was fitted";
    } catch (const GridError& e) {  // the size as given, not "0.000000"
        EXPECT_NE(std::string(e.what()).find("voxels of size 1e-12"), std::string::npos)
            << e.what();
    }
    Mesh point;
    add_triangle(point, {1, 1, 1}, {1, 1, 1}, {1, 1, 1});
    EXPECT_THROW(fit_grid(point, GridFit{}), GridError);
    fit = GridFit{};
    fit.voxel_size = 0.5;
    EXPECT_EQ(fit_grid(point, fit).dims, (std::array<int64_t, 3>{1, 1, 1}));
}

TEST(Voxelize, AbsurdGridIsRefusedBeforeAllocating) {
    // 2^20 voxels per axis with a mesh filling it: far more bricks than memory allows.
    Grid g = unit_grid(kMaxGridAxis, kMaxGridAxis, kMaxGridAxis);
    const Mesh m = box_mesh({0, 0, 0}, {double(kMaxGridAxis), double(kMaxGridAxis), 1});
    VoxelizeOptions o;
    o.brick_size = 8;
    EXPECT_THROW(voxelize_reference(m, g, o), GridError);
    g.dims = {16, 16, 16};
    o.brick_size = 6;  // not a multiple of 4
    EXPECT_THROW(voxelize_reference(m, g, o), GridError);
}

// A copy owns its bricks: changing either leaves the other as it was, whether its bricks were
// made one by one or taken whole from a device batch.
TEST(SparseVoxels, CopiesAreDeep) {
    SparseVoxels made(unit_grid(40, 40, 40), 8);
    made.set(1, 2, 3);
    made.set(30, 31, 32);
    const Mesh m = box_mesh({4, 4, 4}, {20, 12, 30});
    VoxelizeOptions o;
    o.brick_size = 8;
    o.download = Download::Whole;  // on a CPU device: the bricks the device wrote, taken whole
    const SparseVoxels voxelized = device().voxelize(m, unit_grid(40, 40, 40), o);
    for (const SparseVoxels* original : {static_cast<const SparseVoxels*>(&made), &voxelized}) {
        const uint64_t count = original->count();
        SparseVoxels copy = *original;
        ASSERT_TRUE(copy.same_voxels(*original));
        EXPECT_FALSE(original->get(0, 39, 0));
        copy.set(0, 39, 0);
        copy.set_box({0, 0, 0}, {8, 8, 8});
        EXPECT_FALSE(original->get(0, 39, 0));
        EXPECT_EQ(original->count(), count);
        SparseVoxels assigned(unit_grid(2, 2, 2), 4);
        assigned = copy;
        assigned.set(39, 0, 39);
        EXPECT_FALSE(copy.get(39, 0, 39));
        EXPECT_EQ(copy.count(), assigned.count() - 1);
    }
}

// Bricks taken whole stay where they lie: all-zero ones are not stored, one already stored takes
// the taken one's bits, and a brick outside the grid is an error.
TEST(SparseVoxels, TakenBricksStayInTheirRun) {
    SparseVoxels v(unit_grid(128, 128, 128), 64);  // 8 bricks of 32 KiB, whole pages
    v.set(100, 1, 1);                              // brick 1
    const size_t n = v.blocks_per_brick();
    std::shared_ptr<uint64_t> run = detail::zeroed_host_pages(3 * n * sizeof(uint64_t));
    ASSERT_TRUE(run);
    run.get()[n + 5] = 0x8000000000000001u;  // run brick 1 -> grid brick 6
    run.get()[2 * n] = 2;                    // run brick 2 -> grid brick 1, voxel (65, 0, 0)
    const uint64_t grid_brick[3] = {0, 6, 1};
    detail::SparseVoxelsAccess::adopt_bricks(v, run, 3, [&](size_t i) { return grid_brick[i]; });
    EXPECT_EQ(v.brick_count(), 2u);
    EXPECT_EQ(v.brick_blocks(0), nullptr);
    EXPECT_EQ(v.brick_blocks(6), run.get() + n);  // not a copy
    EXPECT_EQ(v.count(), 4u);
    // Block 5 of brick 6 (origin (0, 64, 64)) starts at (20, 64, 64); bit 63 is its (3, 3, 3).
    EXPECT_TRUE(v.get(20, 64, 64));
    EXPECT_TRUE(v.get(23, 67, 67));
    EXPECT_TRUE(v.get(100, 1, 1));
    EXPECT_TRUE(v.get(65, 0, 0));
    run.reset();  // the voxels keep what they took
    EXPECT_TRUE(v.get(23, 67, 67));
    std::shared_ptr<uint64_t> outside = detail::zeroed_host_pages(n * sizeof(uint64_t));
    EXPECT_THROW(detail::SparseVoxelsAccess::adopt_bricks(v, outside, 1, [](size_t) { return 8; }),
                 GridError);
}

// Pages of fresh host memory count as untouched until written, and again once given back; so
// adopting bricks skips the never-touched ones unread, while bricks in touched pages are read: one
// written with zeros (memset) is empty and its pages are given back, and small bricks sharing a
// touched page are each kept or dropped by their own bits.
TEST(SparseVoxels, TakenBricksInPagesNeverTouchedAreEmptyUnread) {
    const size_t page = detail::host_page_size();
    std::shared_ptr<uint64_t> pages = detail::zeroed_host_pages(8 * page);
    ASSERT_TRUE(pages);
    char* const bytes = reinterpret_cast<char*>(pages.get());
    bytes[3 * page + 17] = 1;
    std::vector<uint8_t> touched = detail::touched_host_pages(bytes, 8 * page);
    ASSERT_EQ(touched.size(), 8u);
    EXPECT_TRUE(touched[3]);  // written: always touched
    // Linux says which pages were never touched (/proc/self/pagemap); that is what saves the reads.
    EXPECT_EQ(std::count(touched.begin(), touched.end(), 0), 7);
    detail::release_host_pages(bytes + 3 * page, page);
    EXPECT_EQ(detail::touched_host_pages(bytes, 8 * page), std::vector<uint8_t>(8, 0));

    SparseVoxels v(unit_grid(128, 128, 128), 64);  // 8 bricks of 32 KiB, whole pages
    const size_t n = v.blocks_per_brick();
    std::shared_ptr<uint64_t> run = detail::zeroed_host_pages(3 * n * sizeof(uint64_t));
    ASSERT_TRUE(run);
    std::memset(run.get() + n, 0, n * sizeof(uint64_t));  // run brick 1: touched, all zero
    run.get()[2 * n + 7] = 4;                             // run brick 2: voxel (30, 0, 0) of 3
    detail::SparseVoxelsAccess::adopt_bricks(v, run, 3, [](size_t i) { return uint64_t(i + 1); });
    EXPECT_EQ(v.brick_indices(), std::vector<uint64_t>{3});
    EXPECT_EQ(v.count(), 1u);
    EXPECT_TRUE(v.get(64 + 30, 64, 0));
    const std::vector<uint8_t> after =
        detail::touched_host_pages(run.get(), 3 * n * sizeof(uint64_t));
    EXPECT_EQ(
        std::count(after.begin(), after.begin() + ptrdiff_t(2 * n * sizeof(uint64_t) / page), 1),
        0);  // brick 0 never touched, brick 1's pages given back

    // 8^3 bricks of 64 bytes: 64 to a page.
    SparseVoxels small(unit_grid(64, 64, 64), 8);
    std::shared_ptr<uint64_t> shared = detail::zeroed_host_pages(128 * 8 * sizeof(uint64_t));
    ASSERT_TRUE(shared);
    shared.get()[8 * 5] = 1;        // brick 5: voxel (40, 0, 0)
    shared.get()[8 * 100 + 3] = 1;  // brick 100 (another page), block (1, 1, 0): voxel (36, 36, 8)
    detail::SparseVoxelsAccess::adopt_bricks(small, shared, 128,
                                             [](size_t i) { return uint64_t(i); });
    EXPECT_EQ(small.brick_indices(), (std::vector<uint64_t>{5, 100}));
    EXPECT_EQ(small.count(), 2u);
    EXPECT_TRUE(small.get(40, 0, 0));
    EXPECT_TRUE(small.get(36, 36, 8));
}

}  // namespace
}  // namespace oclvox::test
