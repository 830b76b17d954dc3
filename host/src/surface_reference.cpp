// The CPU reference voxelizer: the same prepared triangles and the same per-triangle setup and
// per-voxel test (voxel_math.h) as the kernels, but none of their machinery (no binning, no
// bricks, no blocks, no atomics): every triangle tests every grid voxel of its range. Device
// results must equal it bit for bit.
#include <algorithm>

#include "brick_selection.hpp"
#include "oclvox/oclvox.hpp"
#include "prepare.hpp"
#include "solid.hpp"
#include "surface_tests.hpp"
#include "timing.hpp"

namespace oclvox {

namespace {

using detail::Clock;
using detail::seconds_since;

// The reference tests every voxel of every triangle's range; refuse work no machine can finish.
constexpr uint64_t kMaxReferenceVoxelTests = uint64_t(1) << 36;

void refuse_absurd_work(const detail::PreparedTriangles& prepared, const Grid& grid) {
    uint64_t tests = 0;
    for (size_t t = 0; t < prepared.triangles.size(); ++t) {
        const detail::OvRange& r = prepared.ranges[t];
        uint64_t n = 1;
        for (int k = 0; k < 3; ++k) {
            const int64_t lo = std::max<int64_t>(r.lo[k], 0);
            const int64_t hi = std::min<int64_t>(r.hi[k], grid.dims[k] - 1);
            n *= hi >= lo ? uint64_t(hi - lo + 1) : 0;
        }
        tests += n;
        if (tests > kMaxReferenceVoxelTests)
            throw GridError("the CPU reference would test more than " +
                            std::to_string(kMaxReferenceVoxelTests) +
                            " voxels: lower the resolution");
    }
}

// `conservative`: the test is SAT or PEF, which set the voxels of a triangle whose range is a row
// of voxels without testing them, as the kernels do (ov_range_is_row).
template <typename Setup, typename Overlaps>
void voxelize_triangles(const detail::PreparedTriangles& prepared, SparseVoxels& out, Setup setup,
                        Overlaps overlaps, bool conservative) {
    const Grid& grid = out.grid();
    for (size_t t = 0; t < prepared.triangles.size(); ++t) {
        const detail::OvRange& r = prepared.ranges[t];
        int lo[3], hi[3];
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::max<int>(r.lo[k], 0);
            hi[k] = int(std::min<int64_t>(r.hi[k], grid.dims[k] - 1));
        }
        if (conservative && detail::ov_range_is_row(r)) {
            for (int z = lo[2]; z <= hi[2]; ++z)
                for (int y = lo[1]; y <= hi[1]; ++y)
                    for (int x = lo[0]; x <= hi[0]; ++x) out.set(x, y, z);
            continue;
        }
        const auto s = setup(prepared.triangles[t]);
        for (int z = lo[2]; z <= hi[2]; ++z)
            for (int y = lo[1]; y <= hi[1]; ++y)
                for (int x = lo[0]; x <= hi[0]; ++x)
                    if (overlaps(&s, float(x - s.anchor[0]), float(y - s.anchor[1]),
                                 float(z - s.anchor[2])))
                        out.set(x, y, z);
    }
}

}  // namespace

SparseVoxels voxelize_reference(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                                VoxelizeStats* stats) {
    SparseVoxels out(grid, options.brick_size);
    // The reference computes every brick and keeps the selected ones.
    const detail::BrickSelection selection(options.bricks, out);
    if (options.mode == VoxelizeMode::Solid || options.mode == VoxelizeMode::Filled) {
        VoxelizeStats solid_stats;
        out = detail::solid_reference(mesh, grid, options, solid_stats);
        if (options.mode == VoxelizeMode::Filled) {
            VoxelizeOptions surface_options = options;
            surface_options.mode = VoxelizeMode::Surface;
            const SparseVoxels surface = voxelize_reference(mesh, grid, surface_options);
            detail::finish_solid(out, &surface, selection, solid_stats);
        } else {
            detail::finish_solid(out, nullptr, selection, solid_stats);
        }
        if (stats) *stats = solid_stats;
        return out;
    }
    const auto start = Clock::now();
    const detail::SurfaceTest test = detail::surface_test_for(options);
    const detail::PreparedTriangles prepared =
        detail::prepare_triangles(mesh, grid, options.boundary);
    refuse_absurd_work(prepared, grid);
    detail::with_host_surface_test(test, options.boundary, [&](auto setup, auto overlaps) {
        voxelize_triangles(prepared, out, setup, overlaps, test != detail::SurfaceTest::Thin);
    });
    selection.restrict(out);
    if (stats) {
        *stats = VoxelizeStats{};
        stats->triangles_in = mesh.triangles.size();
        stats->triangles_used = prepared.triangles.size();
        stats->seconds_kernels = seconds_since(start);
        stats->voxels_set = out.count();
    }
    return out;
}

}  // namespace oclvox
