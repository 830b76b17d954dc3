// Distances on an OpenCL device: the band leaf by leaf as a sparse field's (sdf_sparse_device.cpp)
// copied into a dense array of squared distances, and for full-grid fields every voxel beyond the
// band from the tree over the triangles (a work item a row of 8 voxels). Same prepared triangles
// and shared math as the reference in sdf.cpp, so the result matches it bit for bit.
#include <algorithm>
#include <chrono>

#include "opencl_runtime.hpp"
#include "sdf_internal.hpp"
#include "timing.hpp"

namespace oclvox::detail {

std::vector<float> distance2_device(Device& device, const SdfTriangles& prepared, const Grid& grid,
                                    const SdfOptions& options, ProgressPhases& progress,
                                    const SdfPhases& phases, VoxelizeStats& stats) {
    Device::Impl& cl = device_impl(device);

    // Phase 1: a full-grid field's far pass keeps the dense distances on the device, so they must
    // fit one allocation. It is made once for the whole field, not per batch, so a device
    // allocation failure is a DeviceError: there is no smaller batch to retry with.
    const uint64_t voxels = grid.voxel_count();
    if (options.full_grid && voxels * sizeof(cl_uint) > cl.info.max_alloc)
        throw GridError("a full-grid distance field of " + std::to_string(voxels) +
                        " voxels needs " + std::to_string(voxels * sizeof(cl_uint) >> 20) +
                        " MiB in one buffer, over the device's allocation limit of " +
                        std::to_string(cl.info.max_alloc >> 20) + " MiB: lower the resolution");

    // Phase 2: the band, leaf by leaf as a sparse field computes it, each batch of leaves copied
    // into the dense squared distances (the leaves at the grid's high faces cut to the grid).
    auto t = Clock::now();
    const BandLeaves band = band_leaves(prepared, grid, options, {});
    stats.seconds_binning += seconds_since(t);
    std::vector<float> distance2(size_t(voxels), prepared.band2);
    constexpr int64_t kLeaf = SparseField::kLeaf;
    uint64_t leaf = 0;
    leaf_distance2_device(
        device, prepared, band, options, progress, phases.band, stats,
        [&](uint64_t, uint64_t slots, const float* leaf_distance2) {
            for (uint64_t s = 0; s < slots; ++s, ++leaf) {
                leaf = band.leaves.set_from(leaf);
                const auto [x, y, z] = band.leaves.origin(leaf);
                const float* samples = leaf_distance2 + s * SparseField::kLeafSamples;
                const int64_t width = std::min(kLeaf, grid.dims[0] - x);
                for (int64_t k = z; k < std::min(z + kLeaf, grid.dims[2]); ++k)
                    for (int64_t j = y; j < std::min(y + kLeaf, grid.dims[1]); ++j)
                        std::copy_n(samples + kLeaf * ((j - y) + kLeaf * (k - z)), width,
                                    &distance2[size_t(x + grid.dims[0] * (j + grid.dims[1] * k))]);
            }
        });
    if (!options.full_grid || prepared.triangles.empty()) return distance2;

    try {
        const cl::Program& program = cl.program(kKernel_sdf);

        // Phase 3: the tree, its triangles and the band's distances up.
        t = Clock::now();
        const SdfTree tree = build_sdf_tree(prepared.triangles);
        stats.seconds_binning += seconds_since(t);
        t = Clock::now();
        const cl::Buffer nodes = upload(cl.context, cl.queue, tree.nodes);
        // The triangles in the tree's order, so that a leaf's lie side by side: the walk reads
        // them leaf by leaf, and through an index they were scattered (bunny00's full grid at
        // 128, whole process through PoCL: 2.12 -> 1.72 s). Written where the buffer is mapped,
        // so the reordered copy costs no host memory of its own.
        const size_t count = tree.order.size();
        const cl::Buffer triangles(cl.context, CL_MEM_READ_ONLY,
                                   std::max<size_t>(1, count) * sizeof(OvSdfTriangle));
        write_mapped<OvSdfTriangle>(cl.queue, triangles, count, [&](OvSdfTriangle* out) {
            for (size_t t = 0; t < count; ++t) out[t] = prepared.triangles[tree.order[t]];
        });
        cl::Buffer distance(cl.context, CL_MEM_READ_WRITE, size_t(voxels) * sizeof(cl_uint));
        cl.queue.enqueueWriteBuffer(distance, CL_TRUE, 0, size_t(voxels) * sizeof(cl_uint),
                                    distance2.data());
        stats.seconds_upload += seconds_since(t);

        // Phase 4: every voxel beyond the band from the tree, OV_SDF_FAR_ROWS rows of 8 along x
        // per work item, in slices.
        t = Clock::now();
        cl::Kernel far(program, "far_distances");
        const uint64_t items = uint64_t((grid.dims[0] + 7) / 8) *
                               uint64_t((grid.dims[1] + OV_SDF_FAR_ROWS - 1) / OV_SDF_FAR_ROWS) *
                               uint64_t(grid.dims[2]);
        set_args(far, 0, nodes, triangles, cl_ulong(0), cl_ulong(items), cl_int(grid.dims[0]),
                 cl_int(grid.dims[1]), prepared.band2, distance);
        const size_t group = work_group_size(far, cl.device);
        run_sliced(
            cl.queue, items, group,
            [&](uint64_t first, uint64_t count) {
                far.setArg(2, cl_ulong(first));
                launch(cl.queue, far, count, group);
            },
            progress.reporter(phases.far));
        cl.queue.finish();
        stats.seconds_kernels += seconds_since(t);

        // Phase 5: the squared distances back (float bits, as the kernel stored them).
        t = Clock::now();
        cl.queue.enqueueReadBuffer(distance, CL_TRUE, 0, size_t(voxels) * sizeof(cl_uint),
                                   distance2.data());
        stats.seconds_download += seconds_since(t);
    } catch (const cl::Error& e) {
        throw_device_error(e, "computing a distance field on " + cl.info.name);
    }
    return distance2;
}

}  // namespace oclvox::detail
