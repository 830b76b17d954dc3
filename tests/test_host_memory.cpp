// The host memory budget (README "Guarantees"): every allocation whose size comes from the input
// (dense distance fields and their working copies, solid results and the winding number's dense
// state, dense copies, CSG fields, a sparse field's band, a band-less .vdb's leaves, the meshers'
// buffers, .npy samples) is checked against it
// before anything is allocated, and refused with an error naming both sizes. The budget is an
// option where the call has one (VoxelizeOptions::host_budget_bytes, SdfOptions::
// host_budget_bytes), else $OCLVOX_HOST_MEMORY_MIB, so these tests need no real memory: each
// refusal must also leave the process's peak resident memory where it was. Expected sizes are
// worked out here from the grid dimensions.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "oclvox/field.hpp"
#include "oclvox/sdf.hpp"
#include "test_support.hpp"

namespace oclvox::test {
namespace {

constexpr uint64_t kMiB = uint64_t(1) << 20;

// The process's peak resident memory (VmHWM), in MiB, after resetting it to the current
// resident memory, so that what follows is measured alone.
long reset_peak_mib() {
    std::ofstream("/proc/self/clear_refs") << "5";
    std::ifstream status("/proc/self/status");
    for (std::string line; std::getline(status, line);)
        if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6)) / 1024;
    return 0;
}
long peak_mib() {
    std::ifstream status("/proc/self/status");
    for (std::string line; std::getline(status, line);)
        if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6)) / 1024;
    return 0;
}

// "N MiB" for `bytes`, rounded up, as the messages give sizes.
std::string mib(uint64_t bytes) {
    return std::to_string((bytes + kMiB - 1) / kMiB) + " MiB";
}

// `run` must throw GridError naming every string of `names`, and (when `measure`) allocate less
// than 8 MiB before it does.
template <typename F>
void expect_refused(F run, const std::vector<std::string>& names, bool measure = true) {
    const long before = reset_peak_mib();
    try {
        run();
        ADD_FAILURE() << "no GridError";
    } catch (const GridError& e) {
        const std::string message = e.what();
        for (const std::string& name : names)
            EXPECT_NE(message.find(name), std::string::npos) << "'" << name << "' in: " << message;
    }
    if (measure) EXPECT_LT(peak_mib() - before, 8) << "MiB allocated before the refusal";
}

std::string budget_of(const char* mib_text) {
    return std::string("host memory budget of ") + mib_text;
}

TEST(HostMemory, BudgetVariableMustBeAWholeNumberOfMiB) {
    const Mesh mesh = box_mesh({2, 2, 2}, {6, 6, 6});
    for (const char* bad : {"12abc", "0", "-5", "1.5", "99999999999999999999"}) {
        ScopedBudget budget(bad);
        expect_refused([&] { signed_distance_reference(mesh, unit_grid(8, 8, 8), SdfOptions{}); },
                       {"OCLVOX_HOST_MEMORY_MIB", std::string("'") + bad + "'"});
    }
}

// 256^3 voxels at 8 bytes each (the squared distances and the field) need 128 MiB.
TEST(HostMemory, DistanceFieldOverBudgetIsRefusedBeforeAllocating) {
    Device& gpu = device();  // opened before anything is measured
    const Mesh mesh = box_mesh({100, 100, 100}, {150, 150, 150});
    const Grid grid = unit_grid(256, 256, 256);
    const std::vector<std::string> names = {"256x256x256", mib(uint64_t(256 * 256 * 256) * 8),
                                            budget_of("16 MiB")};
    {
        ScopedBudget budget("16");
        expect_refused([&] { signed_distance_reference(mesh, grid, SdfOptions{}); }, names);
        expect_refused([&] { signed_distance(gpu, mesh, grid, SdfOptions{}); }, names);
        expect_refused([&] { unsigned_distance(gpu, mesh, grid, SdfOptions{}); }, names);
    }
    // The option instead of the variable.
    ScopedBudget budget(nullptr);
    SdfOptions options;
    options.host_budget_bytes = 16 * kMiB;
    expect_refused([&] { signed_distance_reference(mesh, grid, options); }, names);
    expect_refused([&] { signed_distance(gpu, mesh, grid, options); }, names);
}

// 64^3 voxels at 8 bytes each: 2 MiB, for a narrow band and a full grid alike, on the device and
// in the reference (the full grid's search keeps no per-voxel state beyond the distances).
TEST(HostMemory, FullGridFieldNeedsWhatTheNarrowBandNeeds) {
    ScopedBudget unset(nullptr);
    Device& gpu = device();  // opened before anything is measured
    const Mesh mesh = box_mesh({20, 20, 20}, {40, 40, 40});
    const Grid grid = unit_grid(64, 64, 64);
    for (bool full : {false, true}) {
        SdfOptions options;
        options.full_grid = full;
        options.host_budget_bytes = kMiB;
        const std::vector<std::string> names = {"64x64x64", "2 MiB", budget_of("1 MiB")};
        expect_refused([&] { signed_distance_reference(mesh, grid, options); }, names);
        expect_refused([&] { signed_distance(gpu, mesh, grid, options); }, names);
        options.host_budget_bytes = 3 * kMiB;
        EXPECT_EQ(signed_distance_reference(mesh, grid, options).values.size(), grid.voxel_count());
        EXPECT_EQ(signed_distance(gpu, mesh, grid, options).values.size(), grid.voxel_count());
    }
}

// Grid 256^3 in 64^3 bricks (32 KiB each) around a box [1, 255]^3: parity may need every brick
// of the 4x4 brick columns the box covers, 64 bricks = 2 MiB. The winding number holds the box
// of voxel centres inside [1, 255] (254^3 voxels) densely, 1.5 bytes each, plus the same 64
// bricks.
TEST(HostMemory, SolidOverBudgetIsRefusedBeforeAllocating) {
    ScopedBudget unset(nullptr);
    Device& gpu = device();
    const Mesh mesh = box_mesh({1, 1, 1}, {255, 255, 255});
    const Grid grid = unit_grid(256, 256, 256);
    VoxelizeOptions options;
    options.mode = VoxelizeMode::Solid;
    options.host_budget_bytes = kMiB;
    const uint64_t bricks = 64 * 32 * kMiB / 1024;
    const std::vector<std::string> parity = {"64 bricks", mib(bricks), budget_of("1 MiB")};
    options.inside = InsideTest::Parity;
    expect_refused([&] { gpu.voxelize(mesh, grid, options); }, parity);
    expect_refused([&] { voxelize_reference(mesh, grid, options); }, parity);

    options.inside = InsideTest::Winding;
    // A state byte per voxel, four bit planes (inside, surface, fans, their pyramids: half a byte)
    // and the flood's queued marks (an eighth).
    const uint64_t voxels = uint64_t(254) * 254 * 254;
    expect_refused([&] { gpu.voxelize(mesh, grid, options); },
                   {std::to_string(voxels) + " voxels",
                    mib(bricks + voxels + voxels / 2 + voxels / 8), budget_of("1 MiB")});
    expect_refused([&] { voxelize_reference(mesh, grid, options); }, parity);

    // Filled and the default budget from the variable.
    ScopedBudget budget("1");
    options.host_budget_bytes = 0;
    options.mode = VoxelizeMode::Filled;
    options.inside = InsideTest::Parity;
    expect_refused([&] { gpu.voxelize(mesh, grid, options); }, parity);
}

// The surface voxelizer's result check takes the variable when the options give no budget.
TEST(HostMemory, SurfaceResultTakesTheDefaultBudget) {
    ScopedBudget budget("1");
    Device& gpu = device();
    const Mesh mesh = box_mesh({1, 1, 1}, {255, 255, 255});
    expect_refused([&] { gpu.voxelize(mesh, unit_grid(256, 256, 256), VoxelizeOptions{}); },
                   {"active bricks", budget_of("1 MiB")});
}

TEST(HostMemory, DenseCopiesOverBudgetAreRefusedBeforeAllocating) {
    ScopedBudget budget("16");
    SparseVoxels voxels(unit_grid(320, 320, 320), 64);
    voxels.set(5, 6, 7);
    // One byte per voxel: 31.25 MiB.
    expect_refused([&] { voxels.to_dense(); }, {"320x320x320", "32 MiB", budget_of("16 MiB")});

    // The field grows by passes + 1 samples on every side: (200 + 2 (passes + 1))^3 floats (the
    // smoothing works a layer at a time, with no second copy).
    SparseVoxels small(unit_grid(200, 200, 200), 64);
    small.set(5, 6, 7);
    const uint64_t samples = uint64_t(204) * 204 * 204;
    expect_refused([&] { occupancy_to_field(small, 1); },
                   {"204x204x204", mib(samples * 4), budget_of("16 MiB")});
    expect_refused([&] { occupancy_to_field(small, 0); },
                   {"202x202x202", mib(uint64_t(202) * 202 * 202 * 4), budget_of("16 MiB")});
}

TEST(HostMemory, CsgFieldOverBudgetIsRefusedBeforeAllocating) {
    ScalarField a;
    a.grid = unit_grid(170, 170, 170);
    a.values.assign(a.grid.voxel_count(), 1.0f);
    const ScalarField b = a;
    ScopedBudget budget("16");
    expect_refused([&] { csg(a, b, CsgOp::Union); },
                   {std::to_string(a.values.size()) + " samples", mib(a.values.size() * 4),
                    budget_of("16 MiB")});
}

// One triangle across 16384^2 voxels reaches 2^21 leaves of a sparse field's band, 4 GiB of
// samples: over a 4 MiB budget (2048 leaves) it is refused while the band's leaves are listed,
// before the lists grow (its 2^24 blocks alone would list 128 MiB), and so is a band of few
// leaves but many pairs. A field whose samples (and a batch of them beside) just fit is not
// refused, and one byte less is refused by the check on the whole list.
TEST(HostMemory, SparseFieldOverBudgetIsRefusedWhileItsBandIsListed) {
    ScopedBudget unset(nullptr);
    Device& gpu = device();
    Mesh triangle;
    add_triangle(triangle, {0, 0, 4}, {16384, 0, 4}, {0, 16384, 4});
    const Grid grid = unit_grid(16384, 16384, 8);
    SdfOptions options;
    options.host_budget_bytes = 4 * kMiB;
    const std::vector<std::string> outgrown = {"band of this sparse distance field outgrows",
                                               budget_of("4 MiB")};
    expect_refused([&] { signed_distance_sparse(gpu, triangle, grid, options); }, outgrown);
    expect_refused([&] { signed_distance_sparse_reference(triangle, grid, options); }, outgrown);
    // 100,000 copies of one small triangle: a few leaves, but 100,000 (leaf, triangle) pairs at
    // 26 bytes, over 1 MiB.
    Mesh copies;
    for (int t = 0; t < 100000; ++t) add_triangle(copies, {3, 3, 3}, {5, 3, 3}, {3, 5, 3});
    options.host_budget_bytes = kMiB;
    expect_refused([&] { signed_distance_sparse(gpu, copies, unit_grid(16, 16, 16), options); },
                   {"band of this sparse distance field outgrows", budget_of("1 MiB")}, false);

    const Mesh box = box_mesh({10, 10, 10}, {50, 50, 50});
    const Grid small = unit_grid(64, 64, 64);
    VoxelizeStats stats;
    options.host_budget_bytes = 0;
    signed_distance_sparse(gpu, box, small, options, &stats);
    const uint64_t leaves = stats.bricks_active;
    ASSERT_GT(leaves, 100u);
    options.host_budget_bytes = 2 * leaves * SparseField::kLeafSamples * sizeof(float);
    EXPECT_EQ(signed_distance_sparse(gpu, box, small, options).leaf_count(), leaves);
    options.host_budget_bytes -= 1;
    expect_refused([&] { signed_distance_sparse(gpu, box, small, options); },
                   {"the samples of " + std::to_string(leaves) + " leaves"}, false);
}

// A sphere of radius 30 voxels in a 96^3 field: its surface needs a few MiB of mesher buffers and
// mesh (about 11,000 vertices at 40 bytes and 22,000 triangles at 24), over 1 MiB, under 64. So
// few MiB cannot be told from the allocator's own growth (under AddressSanitizer), so only the
// errors are checked here.
TEST(HostMemory, MeshingBuffersOverBudgetAreRefused) {
    Device& gpu = device();
    ScalarField field;
    field.grid = unit_grid(96, 96, 96);
    field.values.resize(field.grid.voxel_count());
    for (int k = 0; k < 96; ++k)
        for (int j = 0; j < 96; ++j)
            for (int i = 0; i < 96; ++i)
                field.values[size_t(i + 96 * (j + 96 * k))] =
                    float(std::sqrt((i - 48.0) * (i - 48.0) + (j - 47.5) * (j - 47.5) +
                                    (k - 47.3) * (k - 47.3)) -
                          30.0);
    {
        ScopedBudget budget("1");
        expect_refused([&] { surface_nets(field); }, {"surface_nets", budget_of("1 MiB")}, false);
        expect_refused([&] { marching_cubes(field); }, {"marching_cubes", budget_of("1 MiB")},
                       false);
        expect_refused([&] { surface_nets(gpu, field); }, {"surface_nets", budget_of("1 MiB")},
                       false);
        expect_refused([&] { marching_cubes(gpu, field); }, {"marching_cubes", budget_of("1 MiB")},
                       false);
    }
    ScopedBudget budget("64");
    EXPECT_GT(marching_cubes(field).triangles.size(), 10000u);
    EXPECT_GT(surface_nets(gpu, field).triangles.size(), 10000u);
}

// The sparse meshers hold three slabs of blocks and the mesh, checked as the mesh grows.
TEST(HostMemory, SparseMeshingOverBudgetIsRefused) {
    SdfOptions options;
    options.band_voxels = 2.0;
    const SparseField field = signed_distance_sparse_reference(
        icosphere({48.0, 47.5, 47.3}, 40.0, 5), unit_grid(96, 96, 96), options);
    {
        ScopedBudget budget("1");
        expect_refused([&] { surface_nets(field); }, {"surface_nets", budget_of("1 MiB")}, false);
        expect_refused([&] { marching_cubes(field); }, {"marching_cubes", budget_of("1 MiB")},
                       false);
    }
    ScopedBudget budget("64");
    EXPECT_GT(marching_cubes(field).triangles.size(), 30000u);
}

// A .vdb of a field written layer by layer with no band (a full grid's) holds all its leaves until
// the largest distance is known: 16^3 leaves of 128^3 voxels, 2048 bytes of samples and 24 of
// origin each, 8.1 MiB. Over a 4 MiB budget it is refused before the first layer is asked for
// (a full grid computes its slabs as they are asked for), and leaves no file.
TEST(HostMemory, VdbOfEveryLeafOverBudgetIsRefusedBeforeItsFirstLayer) {
    const std::string path =
        ::testing::TempDir() + "oclvox_host_memory_" + std::to_string(getpid()) + ".vdb";
    const Grid grid = unit_grid(128, 128, 128);
    int layers = 0;
    const FieldLayer layer = [&](int64_t k, float* out) {
        ++layers;
        std::fill_n(out, 128 * 128, float(k) - 60.5f);
    };
    {
        ScopedBudget budget("4");
        expect_refused(
            [&] { write_field(path, grid, 0.0, layer); },
            {"128x128x128 voxels", mib(uint64_t(4096) * (2048 + 24)), budget_of("4 MiB")});
        EXPECT_EQ(layers, 0);
        EXPECT_FALSE(std::filesystem::exists(path));
    }
    ScopedBudget budget("16");
    write_field(path, grid, 0.0, layer);
    EXPECT_EQ(layers, 128);
    EXPECT_TRUE(std::filesystem::exists(path));
    std::filesystem::remove(path);
}

TEST(HostMemory, NpyFieldOverTheDefaultBudgetIsAnInputErrorNamingTheFile) {
    const std::string path =
        ::testing::TempDir() + "oclvox_host_memory_" + std::to_string(getpid()) + ".npy";
    ScalarField field;
    field.grid = unit_grid(128, 128, 128);
    field.values.assign(field.grid.voxel_count(), 1.0f);
    write_field(path, field, 1.0);
    {
        ScopedBudget budget("4");
        try {
            read_field(path);
            ADD_FAILURE() << "read within a 4 MiB budget";
        } catch (const InputError& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(path), std::string::npos) << message;
            EXPECT_NE(message.find("8 MiB, over the memory budget of 4 MiB"), std::string::npos)
                << message;
        }
        ScopedBudget bad("lots");
        try {
            read_field(path);
            ADD_FAILURE() << "read with an invalid budget";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("OCLVOX_HOST_MEMORY_MIB"), std::string::npos);
        }
    }
    ScopedBudget budget("8");
    EXPECT_EQ(read_field(path).values.size(), field.values.size());
    std::filesystem::remove(path);
    std::filesystem::remove(path + ".json");
}

}  // namespace
}  // namespace oclvox::test
