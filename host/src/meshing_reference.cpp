// The host reference for both meshing methods, tiled in bricks: it runs the same per-sample
// functions as the kernels (kernels/meshing_math.h), so the device must match it exactly.
//
// Phases: count each sample's vertices and triangles brick by brick, skipping bricks whose
// samples (with the one-sample halo their cells and edges reach into) all lie on one side;
// prefix-sum the counts over the whole grid in sample order; emit brick by brick into the slots
// the sums assign. Because every vertex and triangle has one owner sample and slots follow the
// global sample order, the mesh does not depend on the brick size or the brick order, and brick
// borders need no stitching: a triangle reaching into the next brick finds its vertex through
// that sample's global offset.
#include <algorithm>
#include <limits>

#include "meshing.hpp"
#include "meshing_math.h"

namespace oclvox::detail {

namespace {

struct Brick {
    int lo[3], hi[3];  // samples [lo, hi) owned by the brick
};

Brick brick_at(const OmField& f, const std::array<int, 3>& origin, int brick_size) {
    Brick b;
    for (int k = 0; k < 3; ++k) {
        b.lo[k] = origin[k];
        b.hi[k] = std::min(origin[k] + brick_size, f.n[k]);
    }
    return b;
}

template <typename F>
void for_each_sample(const Brick& b, F f) {
    for (int z = b.lo[2]; z < b.hi[2]; ++z)
        for (int y = b.lo[1]; y < b.hi[1]; ++y)
            for (int x = b.lo[0]; x < b.hi[0]; ++x) f(x, y, z);
}

}  // namespace

std::vector<std::array<int, 3>> active_bricks(const ScalarField& field, float iso, int brick_size) {
    const OmField f{{int(field.grid.dims[0]), int(field.grid.dims[1]), int(field.grid.dims[2])},
                    iso};
    std::vector<std::array<int, 3>> active;
    for (int bz = 0; bz < f.n[2]; bz += brick_size)
        for (int by = 0; by < f.n[1]; by += brick_size)
            for (int bx = 0; bx < f.n[0]; bx += brick_size) {
                const bool first = om_inside(field.values[om_index(f, bx, by, bz)], iso);
                const int end[3] = {std::min(bx + brick_size + 1, f.n[0]),
                                    std::min(by + brick_size + 1, f.n[1]),
                                    std::min(bz + brick_size + 1, f.n[2])};
                bool uniform = true;
                for (int z = bz; z < end[2] && uniform; ++z)
                    for (int y = by; y < end[1] && uniform; ++y)
                        for (int x = bx; x < end[0] && uniform; ++x)
                            uniform =
                                bool(om_inside(field.values[om_index(f, x, y, z)], iso)) == first;
                if (!uniform) active.push_back({bx, by, bz});
            }
    return active;
}

uint32_t exclusive_scan(std::vector<uint32_t>& counts, const char* what) {
    uint64_t total = 0;
    for (uint32_t& c : counts) {
        const uint32_t n = c;
        c = uint32_t(total);
        total += n;
    }
    if (3 * total > std::numeric_limits<uint32_t>::max())
        throw GridError("the surface has " + std::to_string(total) + " " + what +
                        ", more than the 32-bit indices of the mesher can address");
    return uint32_t(total);
}

Mesh records_to_mesh(const ScalarField& field, const std::vector<uint32_t>& vertex_sample,
                     const std::vector<float>& vertex_local,
                     const std::vector<uint32_t>& triangles) {
    const Grid& g = field.grid;
    const uint64_t nx = uint64_t(g.dims[0]), ny = uint64_t(g.dims[1]);
    Mesh mesh;
    mesh.positions.resize(vertex_sample.size());
    for (size_t v = 0; v < vertex_sample.size(); ++v) {
        const uint64_t s = vertex_sample[v];
        const uint64_t index[3] = {s % nx, s / nx % ny, s / (nx * ny)};
        // Samples sit at voxel centres, hence the half voxel.
        for (int k = 0; k < 3; ++k)
            mesh.positions[v][k] =
                g.origin[k] +
                (double(index[k]) + 0.5 + double(vertex_local[3 * v + k])) * g.voxel_size;
    }
    mesh.triangles.resize(triangles.size() / 3);
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
        mesh.triangles[t] = {triangles[3 * t], triangles[3 * t + 1], triangles[3 * t + 2]};
    return mesh;
}

Mesh mesh_field_reference(const ScalarField& field, float iso, MeshingMethod method,
                          int brick_size) {
    const bool nets = method == MeshingMethod::SurfaceNets;
    const char* who = nets ? "surface_nets" : "marching_cubes";
    validate_field(field, iso, who);
    if (brick_size < 1)
        throw GridError(std::string(who) + ": brick size must be >= 1, got " +
                        std::to_string(brick_size));
    const OmField f{{int(field.grid.dims[0]), int(field.grid.dims[1]), int(field.grid.dims[2])},
                    iso};
    // A grid one sample thin has no cells, hence no surface.
    if (f.n[0] < 2 || f.n[1] < 2 || f.n[2] < 2) return Mesh{};
    const float* values = field.values.data();
    const uint8_t* table = nets ? nullptr : marching_cubes_table().data();

    // Phase 1: per-sample counts in the bricks that can hold surface.
    std::vector<uint32_t> vertex_offset(field.values.size(), 0);
    std::vector<uint32_t> triangle_offset(field.values.size(), 0);
    std::vector<Brick> active;
    for (const auto& origin : active_bricks(field, iso, brick_size)) {
        active.push_back(brick_at(f, origin, brick_size));
        for_each_sample(active.back(), [&](int x, int y, int z) {
            const uint32_t s = om_index(f, x, y, z);
            if (nets)
                om_sn_count(values, f, x, y, z, &vertex_offset[s], &triangle_offset[s]);
            else
                om_mc_count(values, table, f, x, y, z, &vertex_offset[s], &triangle_offset[s]);
        });
    }

    // Phase 2: global slots.
    const uint32_t vertex_count = exclusive_scan(vertex_offset, "vertices");
    const uint32_t triangle_count = exclusive_scan(triangle_offset, "triangles");

    // Phase 3: emit.
    std::vector<uint32_t> vertex_sample(vertex_count), triangles(3 * size_t(triangle_count));
    std::vector<float> vertex_local(3 * size_t(vertex_count));
    for (const Brick& b : active)
        for_each_sample(b, [&](int x, int y, int z) {
            if (nets)
                om_sn_emit(values, f, x, y, z, vertex_offset.data(), triangle_offset.data(),
                           vertex_sample.data(), vertex_local.data(), triangles.data());
            else
                om_mc_emit(values, table, f, x, y, z, vertex_offset.data(), triangle_offset.data(),
                           vertex_sample.data(), vertex_local.data(), triangles.data());
        });
    return records_to_mesh(field, vertex_sample, vertex_local, triangles);
}

}  // namespace oclvox::detail
