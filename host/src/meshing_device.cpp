// Surface Nets and Marching Cubes on an OpenCL device, identical to the host reference.
//
// Phases: find the bricks that can hold surface on the host (as the reference does); upload the
// field, the brick list and slot bases (and the Marching Cubes table); run the count kernel over
// the samples of those bricks in launch slices (reporting progress between them), into their
// slots; read the counts back and turn them into exclusive prefix sums in global sample order on
// the host; upload the offsets; run the emit kernel over the same bricks; read the vertex records
// and triangles back and convert them to world coordinates exactly as the reference does. The
// kernels run the same per-sample functions as the reference (kernels/meshing_math.h), so the
// result equals it bit for bit.
#include <algorithm>
#include <limits>

#include "meshing.hpp"
#include "opencl_runtime.hpp"

namespace oclvox {

namespace {

// Bricks of 4^3 samples: the kernels visit every sample of the active bricks, so the finer the
// bricks the closer that work is to the surface (16^3 bricks visited ~16 samples per surface
// cell); the host's emptiness check per brick re-reads a one-sample halo, which stays cheap.
// Measured on bunny00 at 256^3 through PoCL: mesh phase 16^3 ~2.7 s, 8^3 1.8 s, 4^3 0.8-1.2 s.
constexpr int kBrickSize = 4;

cl::Buffer buffer(Device::Impl& cl, cl_mem_flags flags, size_t bytes) {
    // Zero-length buffers are invalid in OpenCL.
    return cl::Buffer(cl.context, flags, std::max<size_t>(bytes, 4));
}

Mesh mesh_on_device(Device& device, const ScalarField& field, float iso,
                    detail::MeshingMethod method, const ProgressCallback& callback) {
    const bool nets = method == detail::MeshingMethod::SurfaceNets;
    const char* who = nets ? "surface_nets" : "marching_cubes";
    detail::validate_field(field, iso, who);
    detail::ProgressPhases progress(callback, who);
    const detail::MeshingPhases phases = detail::add_meshing_phases(progress);
    const auto& dims = field.grid.dims;
    if (dims[0] < 2 || dims[1] < 2 || dims[2] < 2) {  // no cells
        progress.finish();
        return Mesh{};
    }
    Device::Impl& cl = detail::device_impl(device);
    const uint32_t n = uint32_t(field.values.size());
    if (uint64_t(n) * sizeof(float) > cl.info.max_alloc)
        throw GridError(std::string(who) + ": the field needs " +
                        std::to_string(uint64_t(n) * sizeof(float)) +
                        " bytes, more than one buffer on " + cl.info.name + " can hold");

    // Phase 1: the bricks to visit, one work item per sample of each.
    const detail::BrickLayout layout =
        detail::active_bricks(field, iso, kBrickSize, progress.reporter(phases.scan));
    std::vector<cl_int> bricks;
    for (const auto& origin : layout.origins)
        bricks.insert(bricks.end(), origin.begin(), origin.end());
    const uint64_t items = uint64_t(layout.origins.size()) * kBrickSize * kBrickSize * kBrickSize;
    if (items > std::numeric_limits<uint32_t>::max())
        throw GridError(std::string(who) + ": " + std::to_string(layout.origins.size()) +
                        " bricks hold surface, more than 32-bit work item numbers can cover");
    const uint32_t slots = layout.slots;
    detail::check_meshing_memory(slots, 0, 0, who);

    try {
        const cl::Program& program = cl.program(detail::kKernel_meshing);

        // Phase 2: inputs. Every kernel takes (values, [table,] nx, ny, nz, iso, bricks,
        // brick_size, first, count, brick_base, ...), so the arguments after the table sit at the
        // same place for both methods.
        const cl::Buffer brick_buffer =
            buffer(cl, CL_MEM_READ_ONLY, bricks.size() * sizeof(cl_int));
        if (!bricks.empty())
            cl.queue.enqueueWriteBuffer(brick_buffer, CL_FALSE, 0, bricks.size() * sizeof(cl_int),
                                        bricks.data());
        const cl::Buffer brick_base =
            buffer(cl, CL_MEM_READ_ONLY, layout.base.size() * sizeof(cl_uint));
        cl.queue.enqueueWriteBuffer(brick_base, CL_FALSE, 0, layout.base.size() * sizeof(cl_uint),
                                    layout.base.data());
        // A CPU device reads the field where it is: copying a dense field costs as much as
        // meshing it. (The kernels never write it.)
        const cl::Buffer values = detail::read_in_place(cl, field.values);
        cl::Buffer table;
        if (!nets) {
            const std::vector<uint8_t>& table_data = detail::marching_cubes_table();
            table = buffer(cl, CL_MEM_READ_ONLY, table_data.size());
            cl.queue.enqueueWriteBuffer(table, CL_FALSE, 0, table_data.size(), table_data.data());
        }
        // Runs `kernel` over the items in slices; `slice_arg` is the index of its (first,
        // count) argument pair.
        auto run = [&](cl::Kernel& kernel, int slice_arg, size_t phase) {
            const size_t group = detail::work_group_size(kernel, cl.device);
            detail::run_sliced(
                cl.queue, items, group,
                [&](uint64_t first, uint64_t count) {
                    kernel.setArg(slice_arg, cl_uint(first));
                    kernel.setArg(slice_arg + 1, cl_uint(count));
                    detail::launch(cl.queue, kernel, count, group);
                },
                progress.reporter(phase));
        };
        const int shift = nets ? 0 : 1;
        auto set_common = [&](cl::Kernel& kernel) {
            kernel.setArg(0, values);
            if (!nets) kernel.setArg(1, table);
            detail::set_args(kernel, 1 + shift, cl_int(dims[0]), cl_int(dims[1]), cl_int(dims[2]),
                             cl_float(iso), brick_buffer, cl_int(kBrickSize));
            kernel.setArg(9 + shift, brick_base);
        };

        // Phase 3: counts into the active bricks' slots; the parts of border bricks beyond the
        // grid have no slots.
        cl::Buffer vertex_offset = buffer(cl, CL_MEM_READ_WRITE, slots * sizeof(cl_uint));
        cl::Buffer triangle_offset = buffer(cl, CL_MEM_READ_WRITE, slots * sizeof(cl_uint));
        cl::Kernel count(program, nets ? "sn_count" : "mc_count");
        set_common(count);
        detail::set_args(count, 10 + shift, vertex_offset, triangle_offset);
        run(count, 7 + shift, phases.count);

        // Phase 4: prefix sums in global sample order on the host.
        std::vector<uint32_t> vertex_counts(slots), triangle_counts(slots);
        if (slots) {
            cl.queue.enqueueReadBuffer(vertex_offset, CL_FALSE, 0, slots * sizeof(cl_uint),
                                       vertex_counts.data());
            cl.queue.enqueueReadBuffer(triangle_offset, CL_TRUE, 0, slots * sizeof(cl_uint),
                                       triangle_counts.data());
        }
        const uint32_t vertex_count =
            detail::exclusive_scan(field, layout, vertex_counts, "vertices");
        const uint32_t triangle_count =
            detail::exclusive_scan(field, layout, triangle_counts, "triangles");
        detail::check_meshing_memory(slots, vertex_count, triangle_count, who);
        if (slots) {
            cl.queue.enqueueWriteBuffer(vertex_offset, CL_FALSE, 0, slots * sizeof(cl_uint),
                                        vertex_counts.data());
            cl.queue.enqueueWriteBuffer(triangle_offset, CL_FALSE, 0, slots * sizeof(cl_uint),
                                        triangle_counts.data());
        }

        // Phase 5: emit.
        const cl::Buffer vertex_sample =
            buffer(cl, CL_MEM_WRITE_ONLY, vertex_count * sizeof(cl_uint));
        const cl::Buffer vertex_local =
            buffer(cl, CL_MEM_WRITE_ONLY, 3 * size_t(vertex_count) * sizeof(cl_float));
        const cl::Buffer triangles =
            buffer(cl, CL_MEM_WRITE_ONLY, 3 * size_t(triangle_count) * sizeof(cl_uint));
        cl::Kernel emit(program, nets ? "sn_emit" : "mc_emit");
        set_common(emit);
        detail::set_args(emit, 10 + shift, vertex_offset, triangle_offset, vertex_sample,
                         vertex_local, triangles);
        run(emit, 7 + shift, phases.emit);

        // Phase 6: results back, converted like the reference's.
        std::vector<uint32_t> host_sample(vertex_count), host_triangles(3 * size_t(triangle_count));
        std::vector<float> host_local(3 * size_t(vertex_count));
        if (vertex_count) {
            cl.queue.enqueueReadBuffer(vertex_sample, CL_FALSE, 0, vertex_count * sizeof(cl_uint),
                                       host_sample.data());
            cl.queue.enqueueReadBuffer(vertex_local, CL_FALSE, 0,
                                       host_local.size() * sizeof(cl_float), host_local.data());
        }
        if (triangle_count)
            cl.queue.enqueueReadBuffer(triangles, CL_FALSE, 0,
                                       host_triangles.size() * sizeof(cl_uint),
                                       host_triangles.data());
        cl.queue.finish();
        Mesh mesh = detail::records_to_mesh(field, host_sample, host_local, host_triangles);
        progress.finish();
        return mesh;
    } catch (const cl::Error& e) {
        detail::throw_device_error(e, std::string(who) + " on " + cl.info.name);
    }
}

}  // namespace

Mesh surface_nets(Device& device, const ScalarField& field, float iso,
                  const ProgressCallback& progress) {
    return mesh_on_device(device, field, iso, detail::MeshingMethod::SurfaceNets, progress);
}

Mesh marching_cubes(Device& device, const ScalarField& field, float iso,
                    const ProgressCallback& progress) {
    return mesh_on_device(device, field, iso, detail::MeshingMethod::MarchingCubes, progress);
}

}  // namespace oclvox
