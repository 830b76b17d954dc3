// voxelize_reference on a small mesh made of arbitrary doubles: NaN, infinities, huge and tiny
// coordinates, degenerate and repeated triangles. Input: 4 option bytes, then triangles of nine
// little-endian doubles each (at most 64). Only an oclvox::Error may come out, and every voxel
// set must lie inside the grid.
#include <algorithm>
#include <cstring>

#include "oclvox/oclvox.hpp"

namespace {

constexpr size_t kTriangleBytes = 9 * sizeof(double);
constexpr size_t kMaxTriangles = 64;

oclvox::VoxelizeOptions options_from(const uint8_t* bytes) {
    static const oclvox::VoxelizeMode modes[] = {
        oclvox::VoxelizeMode::Surface, oclvox::VoxelizeMode::Thin, oclvox::VoxelizeMode::Solid,
        oclvox::VoxelizeMode::Filled};
    static const oclvox::InsideTest insides[] = {
        oclvox::InsideTest::Auto, oclvox::InsideTest::Parity, oclvox::InsideTest::Winding};
    oclvox::VoxelizeOptions options;
    options.mode = modes[bytes[1] % 4];
    options.inside = insides[(bytes[1] >> 2) % 3];
    options.test = bytes[1] & 0x10 ? oclvox::OverlapTest::PEF : oclvox::OverlapTest::SAT;
    options.boundary = bytes[1] & 0x20 ? oclvox::Boundary::HalfOpen : oclvox::Boundary::Closed;
    options.brick_size = 4 << (bytes[2] % 4);  // 4, 8, 16, 32
    options.host_budget_bytes = uint64_t(256) << 20;
    return options;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    if (size < 4) return 0;
    // Phase 1: options and grid fit from the first bytes.
    const oclvox::VoxelizeOptions options = options_from(data);
    oclvox::GridFit fit;
    fit.resolution = 1 + data[0] % 32;
    fit.cubic = data[3] & 1;
    fit.pad = (data[3] >> 1) % 3;

    // Phase 2: the mesh, three fresh vertices per triangle (the loader would weld them; the
    // voxelizer must not care).
    oclvox::Mesh mesh;
    const size_t triangles = std::min((size - 4) / kTriangleBytes, kMaxTriangles);
    for (size_t t = 0; t < triangles; ++t) {
        const uint8_t* at = data + 4 + t * kTriangleBytes;
        for (uint32_t corner = 0; corner < 3; ++corner) {
            std::array<double, 3> p;
            std::memcpy(p.data(), at + corner * 3 * sizeof(double), sizeof p);
            mesh.positions.push_back(p);
        }
        const uint32_t first = uint32_t(3 * t);
        mesh.triangles.push_back({first, first + 1, first + 2});
    }

    // Phase 3: the API a program would call, in order.
    try {
        oclvox::validate_mesh(mesh);
        const oclvox::Grid grid = oclvox::fit_grid(mesh, fit);
        const oclvox::SparseVoxels voxels = oclvox::voxelize_reference(mesh, grid, options);
        voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
            if (i < 0 || j < 0 || k < 0 || i >= grid.dims[0] || j >= grid.dims[1] ||
                k >= grid.dims[2])
                __builtin_trap();
        });
    } catch (const oclvox::Error&) {
    }
    return 0;
}
