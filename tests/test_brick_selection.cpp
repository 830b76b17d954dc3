// Brick selections (VoxelizeOptions::bricks) and candidate_bricks: the runs over the shards of a
// split are pieces of the unrestricted run, exactly, and together are all of it. That is what
// lets a grid be computed on several processes or machines and merged.
#include "test_support.hpp"

namespace oclvox::test {
namespace {

VoxelizeOptions options_for(VoxelizeMode mode, InsideTest inside = InsideTest::Auto) {
    VoxelizeOptions o;
    o.mode = mode;
    o.inside = inside;
    o.brick_size = 8;  // many bricks on a small grid
    return o;
}

Grid fitted(const Mesh& m, int64_t resolution) {
    GridFit fit;
    fit.resolution = resolution;
    return fit_grid(m, fit);
}

// `bricks` dealt round-robin into `count` shards, so every shard is scattered over the grid.
std::vector<std::vector<uint64_t>> deal(const std::vector<uint64_t>& bricks, size_t count) {
    std::vector<std::vector<uint64_t>> shards(count);
    for (size_t i = 0; i < bricks.size(); ++i) shards[i % count].push_back(bricks[i]);
    return shards;
}

using Run = std::function<SparseVoxels(const Mesh&, const Grid&, const VoxelizeOptions&)>;

const Run kDevice = [](const Mesh& m, const Grid& g, const VoxelizeOptions& o) {
    return device().voxelize(m, g, o);
};
const Run kReference = [](const Mesh& m, const Grid& g, const VoxelizeOptions& o) {
    return voxelize_reference(m, g, o);
};

// The property: candidate bricks cover the whole result; each shard's result holds exactly the
// whole result's voxels in the shard's bricks; the shards' results merge into the whole result.
void expect_shards_rebuild_the_whole(const Mesh& m, const Grid& g, const VoxelizeOptions& o,
                                     const Run& run) {
    const SparseVoxels whole = run(m, g, o);
    ASSERT_GT(whole.count(), 0u);
    const std::vector<uint64_t> candidates = candidate_bricks(m, g, o);
    ASSERT_TRUE(std::is_sorted(candidates.begin(), candidates.end()));
    for (const uint64_t brick : whole.brick_indices())
        ASSERT_TRUE(std::binary_search(candidates.begin(), candidates.end(), brick))
            << "brick " << brick << " of the result is not a candidate";

    SparseVoxels merged(g, o.brick_size);
    for (const std::vector<uint64_t>& shard : deal(candidates, 3)) {
        VoxelizeOptions restricted = o;
        restricted.bricks = shard;
        const SparseVoxels part = run(m, g, restricted);
        for (const uint64_t brick : part.brick_indices()) {
            ASSERT_TRUE(std::binary_search(shard.begin(), shard.end(), brick));
            const uint64_t* expected = whole.brick_blocks(brick);
            ASSERT_NE(expected, nullptr) << "brick " << brick << " is not in the whole result";
            ASSERT_TRUE(
                std::equal(expected, expected + whole.blocks_per_brick(), part.brick_blocks(brick)))
                << "brick " << brick << " differs from the whole result's";
            merged.merge_brick(brick, part.brick_blocks(brick));
        }
    }
    EXPECT_TRUE(merged.same_voxels(whole));
}

TEST(BrickSelection, ShardsRebuildTheSurface) {
    const Mesh m = load_mesh(mesh_path("spot.obj"));
    const Grid g = fitted(m, 48);
    for (VoxelizeMode mode : {VoxelizeMode::Surface, VoxelizeMode::Thin}) {
        SCOPED_TRACE(to_string(mode));
        expect_shards_rebuild_the_whole(m, g, options_for(mode), kDevice);
        expect_shards_rebuild_the_whole(m, g, options_for(mode), kReference);
    }
}

TEST(BrickSelection, ShardsRebuildParitySolidAndFilled) {
    const Mesh m = load_mesh(mesh_path("spot.obj"));
    const Grid g = fitted(m, 48);
    expect_shards_rebuild_the_whole(m, g, options_for(VoxelizeMode::Solid, InsideTest::Parity),
                                    kDevice);
    expect_shards_rebuild_the_whole(m, g, options_for(VoxelizeMode::Filled, InsideTest::Parity),
                                    kDevice);
    expect_shards_rebuild_the_whole(m, g, options_for(VoxelizeMode::Solid, InsideTest::Parity),
                                    kReference);
}

TEST(BrickSelection, ShardsRebuildWindingSolidOfAnOpenMesh) {
    const Mesh m = load_mesh(mesh_path("stanford-bunny.obj"));
    const Grid g = fitted(m, 40);
    expect_shards_rebuild_the_whole(m, g, options_for(VoxelizeMode::Solid, InsideTest::Winding),
                                    kDevice);
}

// Surface and parity work only on the selected bricks: the binning of one brick's run holds
// the (triangle, brick) pairs of that brick alone.
TEST(BrickSelection, SurfaceWorkIsOnlyTheSelectedBricks) {
    const Mesh m = load_mesh(mesh_path("spot.obj"));
    const Grid g = fitted(m, 48);
    VoxelizeOptions o = options_for(VoxelizeMode::Surface);
    VoxelizeStats whole;
    device().voxelize(m, g, o, &whole);
    const std::vector<uint64_t> candidates = candidate_bricks(m, g, o);
    o.bricks = {candidates[candidates.size() / 2]};
    VoxelizeStats one;
    device().voxelize(m, g, o, &one);
    EXPECT_EQ(whole.bricks_active, candidates.size());
    EXPECT_EQ(one.bricks_active, 1u);
    EXPECT_LT(one.brick_pairs * 10, whole.brick_pairs);

    VoxelizeOptions solid = options_for(VoxelizeMode::Solid, InsideTest::Parity);
    device().voxelize(m, g, solid, &whole);
    solid.bricks = o.bricks;
    device().voxelize(m, g, solid, &one);
    EXPECT_LT(one.brick_pairs * 10, whole.brick_pairs);
}

TEST(BrickSelection, BricksAwayFromTheMeshGiveNothing) {
    const Mesh m = box_mesh({1.5, 1.5, 1.5}, {6.5, 6.5, 6.5});
    const Grid g = unit_grid(32, 32, 32);
    for (VoxelizeMode mode : {VoxelizeMode::Surface, VoxelizeMode::Solid}) {
        VoxelizeOptions o = options_for(mode);
        const std::vector<uint64_t> candidates = candidate_bricks(m, g, o);
        EXPECT_EQ(candidates, std::vector<uint64_t>{0});  // the box lies in brick (0, 0, 0)
        o.bricks = {63};                                  // brick (3, 3, 3)
        EXPECT_EQ(device().voxelize(m, g, o).count(), 0u);
        EXPECT_EQ(voxelize_reference(m, g, o).count(), 0u);
    }
}

TEST(BrickSelection, BrickOutsideTheGridIsAnError) {
    const Mesh m = box_mesh({1.5, 1.5, 1.5}, {6.5, 6.5, 6.5});
    VoxelizeOptions o = options_for(VoxelizeMode::Surface);
    o.bricks = {0, 64};  // 4^3 bricks of 8 voxels: 0..63
    EXPECT_THROW(device().voxelize(m, unit_grid(32, 32, 32), o), GridError);
    EXPECT_THROW(voxelize_reference(m, unit_grid(32, 32, 32), o), GridError);
}

}  // namespace
}  // namespace oclvox::test
