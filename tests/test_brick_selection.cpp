// Brick selections (VoxelizeOptions::bricks), candidate_bricks and selection_triangles: the runs
// over the shards of a split are pieces of the unrestricted run, exactly, and together are all of
// it, also when each shard holds only the triangles selection_triangles gives it. That is what
// lets a grid be computed on several processes or machines and merged.
#include <cmath>
#include <cstring>
#include <random>
#include <set>

#include "binning.hpp"
#include "bit_count.hpp"
#include "block_download.hpp"
#include "device_batches.hpp"
#include "overlap_double.hpp"
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

// The run over one shard, on only the triangles selection_triangles gives it.
SparseVoxels run_on_its_triangles(const Mesh& m, const Grid& g, const VoxelizeOptions& o,
                                  const SelectionTriangles& plan, size_t shard, const Run& run) {
    VoxelizeOptions part = o;
    part.inside = plan.inside;
    if (plan.whole_mesh) return run(m, g, part);
    if (plan.triangles[shard].empty()) return SparseVoxels(g, o.brick_size);
    return run(submesh(m, plan.triangles[shard]), g, part);
}

// The property: candidate bricks cover the whole result; each shard's result, on the whole mesh
// and on its own triangles, holds exactly the whole result's voxels in the shard's bricks; the
// shards' results merge into the whole result.
void expect_shards_rebuild_the_whole(const Mesh& m, const Grid& g, const VoxelizeOptions& o,
                                     const Run& run) {
    const SparseVoxels whole = run(m, g, o);
    ASSERT_GT(whole.count(), 0u);
    const std::vector<uint64_t> candidates = candidate_bricks(m, g, o);
    ASSERT_TRUE(std::is_sorted(candidates.begin(), candidates.end()));
    for (const uint64_t brick : whole.brick_indices())
        ASSERT_TRUE(std::binary_search(candidates.begin(), candidates.end(), brick))
            << "brick " << brick << " of the result is not a candidate";

    const std::vector<std::vector<uint64_t>> shards = deal(candidates, 3);
    std::vector<std::vector<uint64_t>> selections = shards;
    const SelectionTriangles plan = selection_triangles(m, g, o, selections);
    SparseVoxels merged(g, o.brick_size);
    for (size_t s = 0; s < shards.size(); ++s) {
        const std::vector<uint64_t>& shard = shards[s];
        VoxelizeOptions restricted = o;
        restricted.bricks = shard;
        const SparseVoxels part = run(m, g, restricted);
        EXPECT_TRUE(run_on_its_triangles(m, g, restricted, plan, s, run).same_voxels(part))
            << "shard " << s << " on its " << (plan.whole_mesh ? 0 : plan.triangles[s].size())
            << " triangles differs from the shard on the whole mesh";
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

// The stats' voxel count is the result's, in every mode, with and without a selection (the solid
// counts once and recounts only when the surface or a selection changes it).
TEST(BrickSelection, TheReportedVoxelCountIsTheResults) {
    const Mesh m = load_mesh(mesh_path("spot.obj"));
    const Grid g = fitted(m, 40);
    for (VoxelizeMode mode :
         {VoxelizeMode::Surface, VoxelizeMode::Thin, VoxelizeMode::Solid, VoxelizeMode::Filled}) {
        SCOPED_TRACE(to_string(mode));
        VoxelizeOptions o = options_for(mode, InsideTest::Parity);
        const std::vector<uint64_t> candidates = candidate_bricks(m, g, o);
        for (bool selected : {false, true}) {
            o.bricks = selected ? deal(candidates, 2)[0] : std::vector<uint64_t>{};
            VoxelizeStats on_device, on_host;
            const SparseVoxels a = device().voxelize(m, g, o, &on_device);
            const SparseVoxels b = voxelize_reference(m, g, o, &on_host);
            ASSERT_GT(a.count(), 0u);
            EXPECT_EQ(on_device.voxels_set, a.count());
            EXPECT_EQ(on_host.voxels_set, b.count());
        }
    }
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

// Binning divides voxel indices by the brick size with a multiply and a shift: exact for every
// index a grid axis can have and every allowed brick size, checked against division.
TEST(BrickDivider, EqualsDivisionForEveryIndexAndBrickSize) {
    for (int size = 4; size <= 1024; size += 4) {
        const detail::BrickDivider divide(size);
        for (uint32_t index = 0; index < uint32_t(kMaxGridAxis); ++index)
            if (divide(index) != index / uint32_t(size))
                FAIL() << index << " / " << size << " gave " << divide(index);
    }
}

// ---- prepare_triangles ----

// A grid holding every vertex lets preparation skip counting the pieces; the triangles it
// prepares are those of the counting path, which an unused vertex outside the grid forces.
TEST(BitCount, CountBitsEqualsCountingOneBitAtATime) {
    std::mt19937_64 random(7);
    std::vector<uint64_t> words = {0, ~uint64_t(0), 1, uint64_t(1) << 63, 0x8000000000000001ull};
    for (int i = 0; i < 2000; ++i) {
        const uint64_t w = random();
        words.push_back(i % 3 == 0 ? w & random() & random() : w);  // sparse words too
    }
    for (size_t begin : {size_t(0), size_t(3), size_t(5)})
        for (size_t count : {size_t(0), size_t(1), size_t(2), size_t(7), words.size() - 5}) {
            uint64_t expected = 0;
            for (size_t i = begin; i < begin + count; ++i)
                for (int b = 0; b < 64; ++b) expected += words[i] >> b & 1;
            EXPECT_EQ(detail::count_bits(words.data() + begin, count), expected)
                << "words " << begin << " .. " << begin + count;
            EXPECT_EQ(detail::count_bits_portable(words.data() + begin, count), expected)
                << "words " << begin << " .. " << begin + count;
        }
    for (const uint64_t w : words) {
        uint32_t expected = 0;
        for (int b = 0; b < 64; ++b) expected += uint32_t(w >> b & 1);
        ASSERT_EQ(detail::popcount64(w), expected) << w;
    }
}

TEST(Preparation, SkippingTheCountGivesTheCountedTriangles) {
    const Mesh inside = random_triangles(20000, 4, 28, 3, 5);  // every vertex in [1, 31]
    Mesh with_far_vertex = inside;
    with_far_vertex.positions.push_back({500, -500, 7});
    const Grid g = unit_grid(32, 32, 32);
    for (const Boundary boundary : {Boundary::Closed, Boundary::HalfOpen}) {
        const detail::PreparedTriangles fast = detail::prepare_triangles(inside, g, boundary);
        const detail::PreparedTriangles counted =
            detail::prepare_triangles(with_far_vertex, g, boundary);
        ASSERT_EQ(fast.triangles.size(), inside.triangles.size());
        ASSERT_EQ(counted.triangles.size(), inside.triangles.size());
        for (size_t t = 0; t < fast.triangles.size(); ++t) {
            ASSERT_EQ(fast.source_of(t), t);
            ASSERT_EQ(counted.source_of(t), t);
            ASSERT_EQ(
                std::memcmp(&fast.triangles[t], &counted.triangles[t], sizeof(detail::OvTriangle)),
                0);
            ASSERT_EQ(std::memcmp(&fast.ranges[t], &counted.ranges[t], sizeof(detail::OvRange)), 0);
        }
    }
}

// The voxel range (ov_axis_range, shared by preparation and the kernels) takes a comparison where
// the definition takes a floor or a ceiling, relying on each coordinate lying at or above the
// anchor. Every prepared range is the definition's, computed here with std::floor and std::ceil
// of the rounded coordinates: on vertices at, just off and between whole voxel coordinates (the
// cases where ceil and floor differ), of triangles inside the grid, crossing its low faces
// (negative anchors) and clipped far outside it, at two voxel sizes.
TEST(Preparation, RangesAreThoseOfTheRoundedTriangles) {
    const double offsets[] = {0, 1e-12, -1e-12, 1e-7, -1e-7, 3e-8, 0.5, 0.999999999};
    std::mt19937 rng(11);
    std::uniform_int_distribution<int> whole(-3, 34), pick(0, 7), far(0, 9);
    Mesh m;
    for (int t = 0; t < 30000; ++t) {
        Vec3d v[3];
        for (auto& p : v)
            for (double& x : p)
                x = far(rng) == 0 ? 900.0 * (pick(rng) - 3) : whole(rng) + offsets[pick(rng)];
        add_triangle(m, v[0], v[1], v[2]);
    }
    Grid coarse = unit_grid(32, 32, 32);
    coarse.voxel_size = 0.7;
    coarse.origin = {-0.3, 0.1, 1.0 / 3};
    size_t clipped = 0;
    for (const Grid& g : {unit_grid(32, 32, 32), coarse})
        for (const Boundary boundary : {Boundary::Closed, Boundary::HalfOpen}) {
            const detail::PreparedTriangles prepared = detail::prepare_triangles(m, g, boundary);
            ASSERT_GT(prepared.triangles.size(), 1000u);
            clipped += prepared.source.size();
            const int half_open = boundary == Boundary::HalfOpen;
            for (size_t t = 0; t < prepared.triangles.size(); ++t) {
                const detail::OvTriangle& tri = prepared.triangles[t];
                for (int k = 0; k < 3; ++k) {
                    const double low = std::min({tri.u[k], tri.u[3 + k], tri.u[6 + k]});
                    const double high = std::max({tri.u[k], tri.u[3 + k], tri.u[6 + k]});
                    const double lo = half_open ? std::floor(low) : std::ceil(low) - 1;
                    ASSERT_EQ(prepared.ranges[t].lo[k], tri.anchor[k] + int64_t(lo))
                        << "piece " << t << ", axis " << k << ", half-open " << half_open;
                    ASSERT_EQ(prepared.ranges[t].hi[k], tri.anchor[k] + int64_t(std::floor(high)))
                        << "piece " << t << ", axis " << k << ", half-open " << half_open;
                }
            }
        }
    EXPECT_GT(clipped, 0u);  // the clipping path ran
}

// ---- bin_triangles ----

// Binning's (brick, triangle) pairs, in its order.
std::vector<std::pair<uint64_t, uint32_t>> binned_pairs(const detail::Binning& binning) {
    std::vector<std::pair<uint64_t, uint32_t>> pairs;
    for (size_t b = 0; b < binning.bricks.size(); ++b)
        for (uint64_t p = binning.brick_first_pair[b]; p < binning.brick_first_pair[b + 1]; ++p)
            pairs.emplace_back(binning.bricks[b], binning.pair_triangle[p]);
    return pairs;
}

// Binning works on chunks of triangles in parallel; its result is exactly the pairs the serial
// for_each_triangle_brick visits, sorted by brick and then triangle, whatever the threads: here
// over several chunks (8192 triangles each), triangles spanning many bricks, and a selection.
TEST(Binning, IsEveryPairSortedByBrickThenTriangle) {
    const Mesh m = random_triangles(20000, -2, 66, 9, 7);
    const Grid g = unit_grid(64, 64, 64);
    const SparseVoxels layout(g, 8);
    const detail::PreparedTriangles prepared = detail::prepare_triangles(m, g);
    std::vector<std::pair<uint64_t, uint32_t>> expected;
    detail::for_each_triangle_brick(
        prepared, g, 8, [&](uint32_t t, uint64_t brick) { expected.emplace_back(brick, t); });
    std::sort(expected.begin(), expected.end());
    ASSERT_GT(expected.size(), prepared.triangles.size());  // some triangles span bricks
    EXPECT_EQ(
        binned_pairs(detail::bin_triangles(prepared, g, 8, detail::BrickSelection({}, layout))),
        expected);

    std::vector<uint64_t> every_third;
    for (uint64_t brick = 0; brick < 8 * 8 * 8; brick += 3) every_third.push_back(brick);
    std::vector<std::pair<uint64_t, uint32_t>> expected_selected;
    for (const auto& pair : expected)
        if (pair.first % 3 == 0) expected_selected.push_back(pair);
    EXPECT_EQ(binned_pairs(detail::bin_triangles(prepared, g, 8,
                                                 detail::BrickSelection(every_third, layout))),
              expected_selected);
}

// Conservative: every point of a triangle inside the grid lies in a brick the triangle (or a
// piece of it) is binned to. Points sampled on a barycentric lattice, in double.
TEST(Binning, EveryPointOfATriangleIsInOneOfItsBricks) {
    const Mesh m = random_triangles(3000, -2, 34, 12, 11);
    const Grid g = unit_grid(32, 32, 32);
    const detail::PreparedTriangles prepared = detail::prepare_triangles(m, g);
    const detail::Binning binning =
        detail::bin_triangles(prepared, g, 8, detail::BrickSelection({}, SparseVoxels(g, 8)));
    std::set<std::pair<uint64_t, uint32_t>> binned;  // (brick, mesh triangle)
    for (const auto& [brick, piece] : binned_pairs(binning))
        binned.emplace(brick, prepared.source_of(piece));
    constexpr int kSteps = 12;
    uint64_t checked = 0;
    for (uint32_t t = 0; t < m.triangles.size(); ++t)
        for (int i = 0; i <= kSteps; ++i)
            for (int j = 0; i + j <= kSteps; ++j) {
                const double u = double(i) / kSteps, v = double(j) / kSteps;
                int64_t brick[3];
                bool inside = true;
                for (int k = 0; k < 3; ++k) {
                    const double p = (1 - u - v) * m.positions[m.triangles[t][0]][k] +
                                     u * m.positions[m.triangles[t][1]][k] +
                                     v * m.positions[m.triangles[t][2]][k];
                    inside = inside && p >= 0 && p < 32;
                    brick[k] = int64_t(std::floor(p)) / 8;
                }
                if (!inside) continue;
                ++checked;
                const uint64_t index = uint64_t(brick[0] + 4 * (brick[1] + 4 * brick[2]));
                if (!binned.count({index, t}))
                    FAIL() << "triangle " << t << " has a point in brick " << index
                           << ", which it is not binned to";
            }
    EXPECT_GT(checked, 3000u);
}

// Exact: every brick a triangle is binned to meets it. A triangle whose bricks form a row along
// one axis, inside the grid across the other two, is binned to the whole row without the cull's
// test, which must lose nothing: each brick of such a row meets the triangle (the double-precision
// test on the closed brick box grown by 1e-9), as does the one brick of a triangle within it.
// Other multi-brick triangles keep the bricks their cull keeps, which may be up to its margin
// (1e-3 and more) away; a triangle reaching out of the grid beside its one brick is not tested.
// Small triangles cross brick faces; others lie in a brick face, or touch one with a vertex, or
// reach out of the grid.
TEST(Binning, EveryBrickOfATriangleMeetsIt) {
    Mesh m = random_triangles(20000, -2, 66, 3, 13);
    std::mt19937 rng(17);
    std::uniform_int_distribution<int> face(0, 8), axis(0, 2);
    for (int t = 0; t < 4000; ++t) {  // in a brick face, or touching one with a vertex
        const auto tri = m.triangles[size_t(t)];
        const int k = axis(rng);
        const double plane = 8.0 * face(rng);
        for (int c = t % 2 ? 0 : 2; c < 3; ++c) m.positions[tri[size_t(c)]][size_t(k)] = plane;
    }
    const Grid g = unit_grid(64, 64, 64);
    const detail::PreparedTriangles prepared = detail::prepare_triangles(m, g);
    const detail::Binning binning =
        detail::bin_triangles(prepared, g, 8, detail::BrickSelection({}, SparseVoxels(g, 8)));
    uint64_t row_pairs = 0;
    for (const auto& [brick, piece] : binned_pairs(binning)) {
        const detail::OvTriangle& tri = prepared.triangles[piece];
        const detail::OvRange& r = prepared.ranges[piece];
        Vec3d v[3];
        int spanning = 0;
        bool within = true;
        for (int k = 0; k < 3; ++k) {
            for (int i = 0; i < 3; ++i) v[i][k] = double(tri.anchor[k]) + double(tri.u[3 * i + k]);
            const int64_t lo = std::max<int64_t>(r.lo[k], 0) / 8, hi = std::min(r.hi[k], 63) / 8;
            if (lo != hi)
                ++spanning;
            else
                within = within && r.lo[k] >= 0 && r.hi[k] <= 63;
        }
        if (spanning == 0 && !within) continue;
        const bool row = spanning == 1 && within;
        row_pairs += row;
        const double margin = row || spanning == 0 ? 1e-9 : 2e-3 + 1e-5 * 70;
        const int64_t b[3] = {int64_t(brick % 8), int64_t(brick / 8 % 8), int64_t(brick / 64)};
        const Vec3d lo{8.0 * b[0] - margin, 8.0 * b[1] - margin, 8.0 * b[2] - margin};
        const Vec3d hi{8.0 * b[0] + 8 + margin, 8.0 * b[1] + 8 + margin, 8.0 * b[2] + 8 + margin};
        if (!detail::triangle_box_overlap_double(v[0], v[1], v[2], lo, hi))
            FAIL() << "piece " << piece << (row ? " (a row)" : "") << " is binned to brick "
                   << brick << ", which it does not meet";
    }
    EXPECT_GT(row_pairs, 5000u);
}

// The limit on (triangle, brick) candidates refuses exactly the binnings over it: 9 small
// triangles (a brick each) and one across the whole 8^3-brick grid make 521 candidates. Under
// limits of 520 and 500 binning is refused; at 521 it goes ahead, having counted them, and at
// 5120 (triangles x bricks) and above, where the limit cannot be passed, without counting; the
// pairs are the same.
TEST(Binning, ThePairLimitRefusesExactlyTheBinningsOverIt) {
    Mesh m;
    for (int t = 0; t < 9; ++t) {
        const double x = 8.0 * (t % 8) + 1, y = 8.0 * (t / 8) + 2;
        const uint32_t v = uint32_t(m.positions.size());
        m.positions.push_back({x, y, 3});
        m.positions.push_back({x + 2, y + 1, 4});
        m.positions.push_back({x + 1, y + 3, 2});
        m.triangles.push_back({v, v + 1, v + 2});
    }
    const uint32_t v = uint32_t(m.positions.size());
    m.positions.push_back({0.5, 0.5, 0.5});
    m.positions.push_back({63.5, 0.5, 63.5});
    m.positions.push_back({0.5, 63.5, 63.5});
    m.triangles.push_back({v, v + 1, v + 2});
    const Grid g = unit_grid(64, 64, 64);
    const detail::PreparedTriangles prepared = detail::prepare_triangles(m, g);
    const detail::BrickSelection all({}, SparseVoxels(g, 8));
    EXPECT_THROW(detail::bin_triangles(prepared, g, 8, all, 520), GridError);
    EXPECT_THROW(detail::touched_bricks(prepared, g, 8, 500), GridError);
    const auto counted = binned_pairs(detail::bin_triangles(prepared, g, 8, all, 521));
    EXPECT_EQ(binned_pairs(detail::bin_triangles(prepared, g, 8, all, 5120)), counted);
    EXPECT_EQ(binned_pairs(detail::bin_triangles(prepared, g, 8, all)), counted);
    EXPECT_GT(counted.size(), 9u + 8 * 8);  // the large triangle is culled to its bricks only
    EXPECT_LT(counted.size(), 9u + 8 * 8 * 8);
}

// ---- selection_triangles ----

// Contiguous runs of the candidates, as oclvox.distributed cuts them.
std::vector<std::vector<uint64_t>> runs_of(const std::vector<uint64_t>& bricks, size_t count) {
    std::vector<std::vector<uint64_t>> runs(count);
    for (size_t i = 0; i < bricks.size(); ++i) runs[i * count / bricks.size()].push_back(bricks[i]);
    return runs;
}

// Bricks ordered by brick column, then height: runs of them are groups of whole columns, as the
// parity test reads them (oclvox.distributed orders solid shards so).
std::vector<uint64_t> column_major(std::vector<uint64_t> bricks, const Grid& g,
                                   const VoxelizeOptions& o) {
    const auto nb = SparseVoxels(g, o.brick_size).brick_dims();
    const uint64_t columns = uint64_t(nb[0]) * uint64_t(nb[1]);
    std::sort(bricks.begin(), bricks.end(), [&](uint64_t a, uint64_t b) {
        return std::make_pair(a % columns, a / columns) < std::make_pair(b % columns, b / columns);
    });
    return bricks;
}

// A shard reads about its share of the mesh, not all of it: the point of giving shards their
// own triangles. Every triangle a shard gets has a voxel range meeting one of its bricks.
TEST(SelectionTriangles, ShardsGetOnlyTheTrianglesReachingThem) {
    const Mesh m = load_mesh(mesh_path("spot.obj"));
    const Grid g = fitted(m, 64);
    for (VoxelizeMode mode : {VoxelizeMode::Surface, VoxelizeMode::Solid}) {
        SCOPED_TRACE(to_string(mode));
        const VoxelizeOptions o = options_for(mode);
        const auto shards = runs_of(column_major(candidate_bricks(m, g, o), g, o), 8);
        const SelectionTriangles plan = selection_triangles(m, g, o, shards);
        ASSERT_FALSE(plan.whole_mesh);
        if (mode == VoxelizeMode::Solid) EXPECT_EQ(plan.inside, InsideTest::Parity);  // closed
        size_t total = 0;
        for (size_t s = 0; s < shards.size(); ++s) {
            const auto& list = plan.triangles[s];
            EXPECT_TRUE(std::is_sorted(list.begin(), list.end()));
            EXPECT_EQ(std::adjacent_find(list.begin(), list.end()), list.end());
            EXPECT_LT(list.size(), m.triangles.size() / 2) << "shard " << s;
            total += list.size();
        }
        EXPECT_LT(total, 2 * m.triangles.size());
        // Every triangle of shard 0 reaches (by its voxel range grown by a voxel) a brick of it.
        const auto nb = SparseVoxels(g, o.brick_size).brick_dims();
        for (const uint32_t t : plan.triangles[0]) {
            std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
            for (const uint32_t v : m.triangles[t])
                for (int k = 0; k < 3; ++k) {
                    const double x = (m.positions[v][k] - g.origin[k]) / g.voxel_size;
                    lo[k] = std::min(lo[k], x);
                    hi[k] = std::max(hi[k], x);
                }
            bool reaches = false;
            for (const uint64_t brick : shards[0]) {
                const int64_t b[3] = {int64_t(brick % uint64_t(nb[0])),
                                      int64_t(brick / uint64_t(nb[0]) % uint64_t(nb[1])),
                                      int64_t(brick / uint64_t(nb[0] * nb[1]))};
                bool overlaps = true;
                for (int k = 0; k < 3; ++k) {
                    // Parity reads whole brick columns: any height below the brick's top.
                    const bool column_axis = mode == VoxelizeMode::Solid && k == 2;
                    overlaps = overlaps && hi[k] >= double(b[k] * o.brick_size) - 1 &&
                               (column_axis || lo[k] <= double((b[k] + 1) * o.brick_size) + 1);
                }
                reaches = reaches || overlaps;
            }
            EXPECT_TRUE(reaches) << "triangle " << t << " reaches no brick of shard 0";
        }
    }
}

// Parity counts crossings below each voxel centre, so a shard of a grid that cuts the mesh needs
// the triangles below the grid too, which the surface's binning drops.
TEST(SelectionTriangles, ParityShardKeepsTrianglesBelowTheGrid) {
    const Mesh m = box_mesh({1.25, 1.25, -10.25}, {6.25, 6.25, 6.25});
    const Grid g = unit_grid(16, 16, 16);  // z from 0: the box's bottom lies below it
    for (VoxelizeMode mode : {VoxelizeMode::Solid, VoxelizeMode::Filled}) {
        SCOPED_TRACE(to_string(mode));
        VoxelizeOptions o = options_for(mode);
        o.bricks = {0};
        const SparseVoxels expected = voxelize_reference(m, g, o);
        // Columns (1..5) x (1..5) inside from z = 0 to 5: 150 voxels.
        if (mode == VoxelizeMode::Solid) ASSERT_EQ(expected.count(), 150u);
        const SelectionTriangles plan = selection_triangles(m, g, o, {o.bricks});
        ASSERT_EQ(plan.inside, InsideTest::Parity);
        // The two triangles of the bottom face, below the grid, are there; in Solid, where only
        // crossings count, with the top face's two alone (the sides cross no voxel column).
        size_t bottom = 0;
        for (const uint32_t t : plan.triangles[0])
            bottom += m.positions[m.triangles[t][0]][2] == -10.25 &&
                      m.positions[m.triangles[t][1]][2] == -10.25 &&
                      m.positions[m.triangles[t][2]][2] == -10.25;
        EXPECT_EQ(bottom, 2u);
        EXPECT_EQ(plan.triangles[0].size(), mode == VoxelizeMode::Solid ? 4u : 12u);
        EXPECT_TRUE(run_on_its_triangles(m, g, o, plan, 0, kReference).same_voxels(expected));
        EXPECT_TRUE(run_on_its_triangles(m, g, o, plan, 0, kDevice).same_voxels(expected));
    }
}

// Auto picks parity for the whole closed mesh; a part of it is open and would pick the winding
// number, so the plan carries the whole mesh's choice. For an open mesh every shard needs it all.
TEST(SelectionTriangles, InsideTestIsTheWholeMeshs) {
    const VoxelizeOptions o = options_for(VoxelizeMode::Solid);
    const Mesh closed = load_mesh(mesh_path("spot.obj"));
    const Grid gc = fitted(closed, 32);
    const SelectionTriangles parity = selection_triangles(closed, gc, o, {{0}, {}});
    EXPECT_EQ(parity.inside, InsideTest::Parity);
    EXPECT_FALSE(parity.whole_mesh);
    EXPECT_EQ(parity.triangles[1].size(), closed.triangles.size());  // empty: every brick

    const Mesh open = load_mesh(mesh_path("stanford-bunny.obj"));
    const SelectionTriangles winding = selection_triangles(open, fitted(open, 32), o, {{0}});
    EXPECT_EQ(winding.inside, InsideTest::Winding);
    EXPECT_TRUE(winding.whole_mesh);
    EXPECT_TRUE(winding.triangles.empty());
    EXPECT_THROW(selection_triangles(closed, gc, o, {{1u << 20}}), GridError);
}

// ---- make_pair_batch ----

// Units 10, 20, 30 with triangles {7, 8}, {9}, {10, 11}; a triangle has (triangle % 3) work items
// in any unit, so triangle 9 has none. Worked by hand: the pairs with work, their slots and first
// items, and each item's pair, in unit order.
struct HandBinning {
    std::vector<uint64_t> units{10, 20, 30}, first_pair{0, 2, 3, 5};
    std::vector<uint32_t> pair_triangle{7, 8, 9, 10, 11};
    detail::PairBatch batch(size_t first, size_t max_slots, uint64_t max_items) const {
        return detail::make_pair_batch(
            units, first_pair, pair_triangle, first, max_slots, "brick", 0,
            [](size_t) { return [](uint32_t triangle) { return cl_uint(triangle % 3); }; },
            max_items);
    }
};

template <class V>
std::vector<cl_uint> values(const V& v) {
    return std::vector<cl_uint>(v.begin(), v.end());
}

TEST(PairBatches, HoldThePairsWithWorkAndEachItemsPair) {
    const detail::PairBatch b = HandBinning().batch(0, 3, 100);
    EXPECT_EQ(b.first_unit, 0u);
    EXPECT_EQ(b.unit_count, 3u);
    EXPECT_EQ(b.items, 6u);
    EXPECT_EQ(values(b.pair_triangle), (std::vector<cl_uint>{7, 8, 10, 11}));
    EXPECT_EQ(values(b.pair_slot), (std::vector<cl_uint>{0, 0, 2, 2}));
    EXPECT_EQ(values(b.pair_first_item), (std::vector<cl_uint>{0, 1, 3, 4}));
    EXPECT_EQ(values(b.item_pair), (std::vector<cl_uint>{0, 1, 1, 2, 3, 3}));
}

// Direct pairs (an entry whose low bits are a bit of their unit's 1000, here triangle t's bit
// 10 * t, and whose high bits are the kernel's, here t << 50) become entries of the batch whose
// bit is the batch's (slot * 1000 + bit) and whose high bits are kept, in unit order, and neither
// pairs nor work items; worked by hand for units {7 (2 items), 8 (direct)}, {9 (direct)},
// {10 (none), 11 (direct)}.
TEST(PairBatches, DirectPairsAreTheirUnitsBitsInTheBatch) {
    const HandBinning h;
    auto batch = [&](size_t first) {
        return detail::make_pair_batch(
            h.units, h.first_pair, h.pair_triangle, first, 3, "brick", 1000, [](size_t) {
                return [](uint32_t t) {
                    return t == 7    ? uint64_t(2)
                           : t == 10 ? uint64_t(0)
                                     : detail::kDirectPair | uint64_t(t) << 50 | (10 * t);
                };
            });
    };
    const detail::PairBatch all = batch(0);
    EXPECT_EQ(all.items, 2u);
    EXPECT_EQ(values(all.pair_triangle), (std::vector<cl_uint>{7}));
    EXPECT_EQ(values(all.item_pair), (std::vector<cl_uint>{0, 0}));
    const auto high = [](uint64_t t) { return t << 50; };
    EXPECT_EQ(std::vector<cl_ulong>(all.direct_entries.begin(), all.direct_entries.end()),
              (std::vector<cl_ulong>{high(8) | 80, high(9) | 1090, high(11) | 2110}));
    const detail::PairBatch later = batch(1);  // slots count from the first unit
    EXPECT_EQ(later.items, 0u);
    EXPECT_TRUE(later.pair_triangle.empty());
    EXPECT_EQ(std::vector<cl_ulong>(later.direct_entries.begin(), later.direct_entries.end()),
              (std::vector<cl_ulong>{high(9) | 90, high(11) | 1110}));
}

TEST(PairBatches, StopAtTheSlotsOrTheWorkItemsAndStartWhereAsked) {
    const HandBinning h;
    const detail::PairBatch by_slots = h.batch(0, 1, 100);
    EXPECT_EQ(by_slots.unit_count, 1u);
    EXPECT_EQ(values(by_slots.item_pair), (std::vector<cl_uint>{0, 1, 1}));
    const detail::PairBatch by_items = h.batch(0, 3, 5);  // the third unit would make 6
    EXPECT_EQ(by_items.unit_count, 2u);
    EXPECT_EQ(by_items.items, 3u);
    const detail::PairBatch later = h.batch(1, 3, 100);  // slots count from the first unit
    EXPECT_EQ(later.first_unit, 1u);
    EXPECT_EQ(later.unit_count, 2u);
    EXPECT_EQ(values(later.pair_triangle), (std::vector<cl_uint>{10, 11}));
    EXPECT_EQ(values(later.pair_slot), (std::vector<cl_uint>{1, 1}));
    EXPECT_EQ(values(later.pair_first_item), (std::vector<cl_uint>{0, 1}));
    EXPECT_EQ(values(later.item_pair), (std::vector<cl_uint>{0, 1, 1}));
}

TEST(PairBatches, AUnitOverTheWorkItemsAloneIsAnErrorNamingIt) {
    try {
        HandBinning().batch(2, 3, 2);
        ADD_FAILURE() << "no GridError";
    } catch (const GridError& e) {
        EXPECT_NE(std::string(e.what()).find("brick 30 needs 3 work items"), std::string::npos)
            << e.what();
    }
}

// A compact download's blocks land at their indices, worked by hand for 3 units of 4 blocks;
// indices a driver broke (descending, repeated, beyond the batch) are refused, and nothing is
// written outside the batch's blocks either way.
TEST(CompactDownloads, BlocksLandAtTheirIndicesAndBrokenIndicesAreRefused) {
    auto place = [](const std::vector<cl_uint>& indices, std::vector<uint64_t>& blocks) {
        std::vector<cl_uint> words;
        for (const cl_uint index : indices) words.insert(words.end(), {index + 100, index + 200});
        blocks.assign(13, 0);  // 3 x 4 blocks and a sentinel
        blocks[12] = 7;
        const bool placed = detail::place_compact_blocks(indices, words, 3, 4, blocks.data());
        EXPECT_EQ(blocks[12], 7u);
        return placed;
    };
    auto block = [](uint64_t index) { return (index + 100) | (index + 200) << 32; };
    std::vector<uint64_t> blocks;
    ASSERT_TRUE(place({1, 5, 6, 11}, blocks));
    EXPECT_EQ(blocks, (std::vector<uint64_t>{0, block(1), 0, 0, 0, block(5), block(6), 0, 0, 0, 0,
                                             block(11), 7}));
    EXPECT_TRUE(place({}, blocks));
    EXPECT_FALSE(place({5, 1}, blocks));
    EXPECT_FALSE(place({6, 5, 9}, blocks));
    EXPECT_FALSE(place({3, 3}, blocks));
    EXPECT_FALSE(place({1, 12}, blocks));
    EXPECT_FALSE(place({4000000000u}, blocks));
}

}  // namespace
}  // namespace oclvox::test
