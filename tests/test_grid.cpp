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
