// Distances on an OpenCL device: the band pass over (triangle, block) work items with atomic
// minima into a dense buffer of squared distances, and for full-grid fields the nearest-triangle
// seeds and the jump-flooding passes. Same prepared triangles and shared math as the reference in
// sdf.cpp, so the result matches it bit for bit.
#include <algorithm>
#include <chrono>
#include <cstring>

#include "opencl_runtime.hpp"
#include "sdf_internal.hpp"

namespace oclvox::detail {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}

uint32_t float_bits(float f) {
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    return bits;
}

}  // namespace

std::vector<float> distance2_device(Device& device, const SdfTriangles& prepared, const Grid& grid,
                                    const SdfOptions& options, ProgressPhases& progress,
                                    const SdfPhases& phases, VoxelizeStats& stats) {
    Device::Impl& cl = device.impl();

    // Phase 1: the dense buffer must fit one allocation. It is allocated once for the whole
    // field, not per batch, so a device allocation failure is a DeviceError: there is no smaller
    // batch to retry with.
    const uint64_t voxels = grid.voxel_count();
    if (voxels * sizeof(cl_uint) > cl.info.max_alloc)
        throw GridError("a dense distance field of " + std::to_string(voxels) + " voxels needs " +
                        std::to_string(voxels * sizeof(cl_uint) >> 20) +
                        " MiB in one buffer, over the device's allocation limit of " +
                        std::to_string(cl.info.max_alloc >> 20) + " MiB: lower the resolution");
    const uint64_t items = prepared.first_item.back();

    // Runs `kernel` over n items in slices, its argument `base_arg` taking each slice's first
    // item, reporting the slices as `phase` when anyone listens.
    auto run = [&](cl::Kernel& kernel, cl_uint base_arg, uint64_t n, size_t phase) {
        const size_t group = work_group_size(kernel, cl.device);
        run_sliced(
            cl.queue, n, group,
            [&](uint64_t first, uint64_t count) {
                kernel.setArg(base_arg, cl_ulong(first));
                launch(cl.queue, kernel, count, group);
            },
            progress.reporter(phase));
    };

    std::vector<float> distance2(size_t(voxels), prepared.band2);
    try {
        const cl::Program& program = cl.program(kKernel_sdf);

        // Phase 2: triangles and item offsets up; distances start at the band.
        auto t = Clock::now();
        const cl::Buffer triangles = upload(cl.context, cl.queue, prepared.triangles);
        const std::vector<cl_ulong> first_item(prepared.first_item.begin(),
                                               prepared.first_item.end());
        const cl::Buffer first = upload(cl.context, cl.queue, first_item);
        cl::Buffer distance(cl.context, CL_MEM_READ_WRITE, size_t(voxels) * sizeof(cl_uint));
        cl.queue.enqueueFillBuffer(distance, cl_uint(float_bits(prepared.band2)), 0,
                                   size_t(voxels) * sizeof(cl_uint));
        cl.queue.finish();
        stats.seconds_upload += seconds_since(t);

        // Phase 3: the band. Both band kernels take the same leading arguments.
        t = Clock::now();
        const cl_uint count = cl_uint(prepared.triangles.size());
        auto band_kernel = [&](const char* name) {
            cl::Kernel kernel(program, name);
            kernel.setArg(0, triangles);
            kernel.setArg(1, first);
            kernel.setArg(2, count);
            kernel.setArg(4, cl_ulong(items));
            kernel.setArg(5, prepared.band);
            kernel.setArg(6, prepared.band2);
            kernel.setArg(7, cl_int(grid.dims[0]));
            kernel.setArg(8, cl_int(grid.dims[1]));
            kernel.setArg(9, distance);
            return kernel;
        };
        cl::Kernel band = band_kernel("band_distance");
        run(band, 3, items, phases.band);

        // Phase 4: full grid only: seeds, then the jump flood ping-ponging the nearest triangles.
        if (options.full_grid && count > 0) {
            cl::Buffer nearest(cl.context, CL_MEM_READ_WRITE, size_t(voxels) * sizeof(cl_uint));
            cl::Buffer scratch(cl.context, CL_MEM_READ_WRITE, size_t(voxels) * sizeof(cl_uint));
            cl.queue.enqueueFillBuffer(nearest, cl_uint(kNoTriangle), 0,
                                       size_t(voxels) * sizeof(cl_uint));
            cl::Kernel seeds = band_kernel("band_nearest");
            seeds.setArg(10, nearest);
            run(seeds, 3, items, phases.seeds);

            cl::Kernel jump(program, "jump");
            jump.setArg(0, triangles);
            jump.setArg(3, cl_ulong(voxels));
            jump.setArg(5, cl_int(grid.dims[0]));
            jump.setArg(6, cl_int(grid.dims[1]));
            jump.setArg(7, cl_int(grid.dims[2]));
            jump.setArg(9, distance);
            size_t phase = phases.first_jump;
            for (int step : jump_steps(grid)) {
                jump.setArg(1, nearest);
                jump.setArg(4, cl_int(step));
                jump.setArg(8, scratch);
                run(jump, 2, voxels, phase++);
                std::swap(nearest, scratch);
            }
        }
        cl.queue.finish();
        stats.seconds_kernels += seconds_since(t);

        // Phase 5: the squared distances back (float bits, as the kernels stored them).
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
