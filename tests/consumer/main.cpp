// Voxelizes a unit cube through the installed library and checks the hand-worked count, then
// writes it as a .vdb, which the installed library does through its OpenVDB module (loaded from
// its own folder on the first .vdb). The public header compiles without any OpenCL header on the
// include path.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <oclvox/oclvox.hpp>
#include <string>

int main() {
    oclvox::Mesh cube;
    for (int i = 0; i < 8; ++i)
        cube.positions.push_back({i & 1 ? 5.0 : 1.0, i & 2 ? 5.0 : 1.0, i & 4 ? 5.0 : 1.0});
    const uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                  {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& q : quads) {
        cube.triangles.push_back({q[0], q[1], q[2]});
        cube.triangles.push_back({q[0], q[2], q[3]});
    }
    oclvox::Grid grid;
    grid.dims = {8, 8, 8};
    const auto voxels = oclvox::voxelize_reference(cube, grid, oclvox::VoxelizeOptions{});
    // Voxels 0..5 per axis meet the closed cube [1,5]^3; the 2^3 inside the open cube do not.
    if (voxels.count() != 208) {
        std::fprintf(stderr, "consumer: expected 208 voxels, got %llu\n",
                     static_cast<unsigned long long>(voxels.count()));
        return 1;
    }
    const std::filesystem::path vdb =
        std::filesystem::temp_directory_path() / ("consumer-" + std::to_string(getpid()) + ".vdb");
    oclvox::write_voxels(vdb.string(), voxels);
    const auto bytes = std::filesystem::file_size(vdb);
    std::filesystem::remove(vdb);
    if (bytes == 0) {
        std::fprintf(stderr, "consumer: the .vdb written is empty\n");
        return 1;
    }
    std::printf("consumer: find_package(oclvox) works, 208 voxels as expected, .vdb written\n");
    return 0;
}
