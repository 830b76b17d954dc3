// The host reference for both meshing methods, tiled in bricks: it runs the same per-sample
// functions as the kernels (kernels/meshing_math.h), so the device must match it exactly.
//
// Phases: find the bricks whose samples (with the one-sample halo their cells and edges reach
// into) do not all lie on one side; count each of their samples' vertices and triangles into
// slots that exist only for those bricks; prefix-sum the counts in global sample order; emit
// brick by brick into the places the sums assign. Work and memory after the first pass follow
// the surface, not the grid. Because every vertex and triangle has one owner sample and slots
// follow the global sample order, the mesh does not depend on the brick size or the brick order,
// and brick borders need no stitching: a triangle reaching into the next brick finds its vertex
// through that sample's global offset.
#include <algorithm>
#include <limits>

#include "host_memory.hpp"
#include "meshing.hpp"

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

MeshingPhases add_meshing_phases(ProgressPhases& progress) {
    // As measured at 256^3 (spot, the Stanford bunny), on PoCL and on the host: the scan, which
    // reads the whole grid once, takes 1/3 to 1/10 of a pass over the active bricks' samples,
    // which calls the mesher's per-sample function; count and emit cost about the same.
    MeshingPhases phases;
    phases.scan = progress.add(1);
    phases.count = progress.add(4);
    phases.emit = progress.add(4);
    return phases;
}

BrickLayout active_bricks(const ScalarField& field, float iso, int brick_size,
                          const std::function<void(uint64_t done, uint64_t total)>& report) {
    const OmField f{{int(field.grid.dims[0]), int(field.grid.dims[1]), int(field.grid.dims[2])},
                    iso};
    BrickLayout layout;
    layout.tiling.size = brick_size;
    for (int k = 0; k < 3; ++k) layout.tiling.count[k] = (f.n[k] - 1) / brick_size + 1;
    layout.base.assign(size_t(layout.tiling.count[0]) * size_t(layout.tiling.count[1]) *
                           size_t(layout.tiling.count[2]),
                       OM_NO_BRICK);
    uint64_t slots = 0;
    size_t brick = 0;
    for (int bz = 0; bz < f.n[2]; bz += brick_size) {
        for (int by = 0; by < f.n[1]; by += brick_size)
            for (int bx = 0; bx < f.n[0]; bx += brick_size, ++brick) {
                const bool first = om_inside(field.values[om_index(f, bx, by, bz)], iso);
                const int end[3] = {std::min(bx + brick_size + 1, f.n[0]),
                                    std::min(by + brick_size + 1, f.n[1]),
                                    std::min(bz + brick_size + 1, f.n[2])};
                bool uniform = true;
                for (int z = bz; z < end[2] && uniform; ++z)
                    for (int y = by; y < end[1] && uniform; ++y) {
                        const float* row = field.values.data() + om_index(f, 0, y, z);
                        for (int x = bx; x < end[0] && uniform; ++x)
                            uniform = bool(om_inside(row[x], iso)) == first;
                    }
                if (uniform) continue;
                layout.origins.push_back({bx, by, bz});
                layout.base[brick] = uint32_t(slots);
                slots += uint64_t(std::min(brick_size, f.n[0] - bx)) *
                         uint64_t(std::min(brick_size, f.n[1] - by)) *
                         uint64_t(std::min(brick_size, f.n[2] - bz));
            }
        if (report) report(uint64_t(bz + brick_size), uint64_t(f.n[2]));
    }
    layout.slots = uint32_t(slots);  // at most the grid's samples, which validate_field bounds
    return layout;
}

uint32_t exclusive_scan(const ScalarField& field, const BrickLayout& layout,
                        std::vector<uint32_t>& counts, const char* what) {
    const int n[3] = {int(field.grid.dims[0]), int(field.grid.dims[1]), int(field.grid.dims[2])};
    const int size = layout.tiling.size;
    const std::vector<std::array<int, 3>>& origins = layout.origins;
    auto extent = [&](const std::array<int, 3>& o, int k) { return std::min(size, n[k] - o[k]); };
    auto base = [&](const std::array<int, 3>& o) {
        return layout
            .base[size_t(o[0] / size) +
                  size_t(layout.tiling.count[0]) *
                      (size_t(o[1] / size) + size_t(layout.tiling.count[1]) * (o[2] / size))];
    };
    // Global sample order is z, then y, then x: walk each slab of bricks (same z origin) plane by
    // plane, each plane row of bricks (same y origin) row by row, and each row across its bricks.
    uint64_t total = 0;
    for (size_t slab = 0; slab < origins.size();) {
        size_t slab_end = slab;
        while (slab_end < origins.size() && origins[slab_end][2] == origins[slab][2]) ++slab_end;
        for (int lz = 0; lz < extent(origins[slab], 2); ++lz)
            for (size_t row = slab; row < slab_end;) {
                size_t row_end = row;
                while (row_end < slab_end && origins[row_end][1] == origins[row][1]) ++row_end;
                const int ey = extent(origins[row], 1);
                for (int ly = 0; ly < ey; ++ly)
                    for (size_t b = row; b < row_end; ++b) {
                        const int ex = extent(origins[b], 0);
                        uint32_t* c = counts.data() + base(origins[b]) +
                                      size_t(ex) * (size_t(ly) + size_t(ey) * size_t(lz));
                        for (int lx = 0; lx < ex; ++lx) {
                            const uint32_t count = c[lx];
                            c[lx] = uint32_t(total);
                            total += count;
                        }
                    }
                row = row_end;
            }
        slab = slab_end;
    }
    check_mesh_indices(total, what);
    return uint32_t(total);
}

void check_mesh_indices(uint64_t total, const char* what) {
    if (3 * total > std::numeric_limits<uint32_t>::max())
        throw GridError("the surface has " + std::to_string(total) + " " + what +
                        ", more than the 32-bit indices of the mesher can address");
}

void check_meshing_memory(uint64_t slots, uint64_t vertices, uint64_t triangles, const char* who) {
    // Counts: a vertex and a triangle count per slot. Records: the owner sample and 3 floats per
    // vertex, 3 indices per triangle. Mesh: 3 doubles per vertex, 3 indices per triangle.
    const uint64_t bytes = slots * 2 * sizeof(uint32_t) +
                           vertices * (sizeof(uint32_t) + 3 * sizeof(float) + 3 * sizeof(double)) +
                           triangles * 2 * 3 * sizeof(uint32_t);
    check_host_memory(bytes, default_host_budget(),
                      std::string(who) + ": a surface over " + std::to_string(slots) +
                          " samples with " + std::to_string(vertices) + " vertices and " +
                          std::to_string(triangles) + " triangles");
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
        mesh.positions[v] =
            vertex_position(g, {s % nx, s / nx % ny, s / (nx * ny)}, &vertex_local[3 * v]);
    }
    mesh.triangles.resize(triangles.size() / 3);
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
        mesh.triangles[t] = {triangles[3 * t], triangles[3 * t + 1], triangles[3 * t + 2]};
    return mesh;
}

Mesh mesh_field_reference(const ScalarField& field, float iso, MeshingMethod method, int brick_size,
                          const ProgressCallback& callback) {
    const bool nets = method == MeshingMethod::SurfaceNets;
    const char* who = nets ? "surface_nets" : "marching_cubes";
    validate_field(field, iso, who);
    if (brick_size < 1)
        throw GridError(std::string(who) + ": brick size must be >= 1, got " +
                        std::to_string(brick_size));
    const OmField f{{int(field.grid.dims[0]), int(field.grid.dims[1]), int(field.grid.dims[2])},
                    iso};
    ProgressPhases progress(callback, who);
    const MeshingPhases phases = add_meshing_phases(progress);
    // A grid one sample thin has no cells, hence no surface.
    if (f.n[0] < 2 || f.n[1] < 2 || f.n[2] < 2) {
        progress.finish();
        return Mesh{};
    }
    const float* values = field.values.data();
    const uint8_t* table = nets ? nullptr : marching_cubes_table().data();

    // Phase 1: per-sample counts in the bricks that can hold surface, into their slots.
    const BrickLayout layout =
        active_bricks(field, iso, brick_size, progress.reporter(phases.scan));
    check_meshing_memory(layout.slots, 0, 0, who);
    std::vector<uint32_t> vertex_offset(layout.slots, 0), triangle_offset(layout.slots, 0);
    const uint32_t* base = layout.base.data();
    std::vector<Brick> active;
    for (const auto& origin : layout.origins) {
        active.push_back(brick_at(f, origin, brick_size));
        for_each_sample(active.back(), [&](int x, int y, int z) {
            const uint32_t s = om_slot(f, layout.tiling, base, x, y, z);
            if (nets)
                om_sn_count(values, f, x, y, z, &vertex_offset[s], &triangle_offset[s]);
            else
                om_mc_count(values, table, f, x, y, z, &vertex_offset[s], &triangle_offset[s]);
        });
        progress.report(phases.count, active.size(), layout.origins.size());
    }

    // Phase 2: global slots.
    const uint32_t vertex_count = exclusive_scan(field, layout, vertex_offset, "vertices");
    const uint32_t triangle_count = exclusive_scan(field, layout, triangle_offset, "triangles");
    check_meshing_memory(layout.slots, vertex_count, triangle_count, who);

    // Phase 3: emit.
    std::vector<uint32_t> vertex_sample(vertex_count), triangles(3 * size_t(triangle_count));
    std::vector<float> vertex_local(3 * size_t(vertex_count));
    for (size_t brick = 0; brick < active.size(); ++brick) {
        for_each_sample(active[brick], [&](int x, int y, int z) {
            if (nets)
                om_sn_emit(values, f, x, y, z, layout.tiling, base, vertex_offset.data(),
                           triangle_offset.data(), 0, 0, vertex_sample.data(), vertex_local.data(),
                           triangles.data());
            else
                om_mc_emit(values, table, f, x, y, z, layout.tiling, base, vertex_offset.data(),
                           triangle_offset.data(), 0, 0, vertex_sample.data(), vertex_local.data(),
                           triangles.data());
        });
        progress.report(phases.emit, brick + 1, active.size());
    }
    Mesh mesh = records_to_mesh(field, vertex_sample, vertex_local, triangles);
    progress.finish();
    return mesh;
}

}  // namespace oclvox::detail
