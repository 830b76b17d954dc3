// Grid fitting and the limits that refuse impossible grids.
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
    EXPECT_THROW(fit_grid(long_box(), fit), GridError);
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

}  // namespace
}  // namespace oclvox::test
