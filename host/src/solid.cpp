// Solid voxelization: choosing the inside test (crossing parity for closed meshes, the
// generalized winding number otherwise) and running it, on a device or as the host reference.
// The tests themselves are in solid_parity.cpp and solid_winding.cpp.
#include "solid.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <string>

#include "position_numbering.hpp"
#include "solid_internal.hpp"

namespace oclvox::detail {

namespace {

struct Choice {
    InsideTest test;
    std::string reason;
};

Choice choose_inside_test(const Mesh& mesh, InsideTest requested, bool parity_fits) {
    const std::string too_far = "the mesh reaches more than " +
                                std::to_string(OVS_MAX_UNITS / OVS_UNITS) +
                                " voxels from the grid origin, beyond exact parity arithmetic";
    if (requested == InsideTest::Parity) {
        if (!parity_fits) throw GridError("parity inside test impossible: " + too_far);
        return {InsideTest::Parity, "forced by options"};
    }
    if (requested == InsideTest::Winding) return {InsideTest::Winding, "forced by options"};
    const MeshEdgeReport edges = mesh_edge_report(mesh);
    if (edges.boundary)
        return {InsideTest::Winding,
                "mesh has " + std::to_string(edges.boundary) + " boundary edges"};
    if (edges.non_manifold)
        return {InsideTest::Winding,
                "mesh has " + std::to_string(edges.non_manifold) + " non-manifold edges"};
    if (!parity_fits) return {InsideTest::Winding, too_far};
    // Crossing parity counts crossings whichever way a triangle winds, so a closed mesh with
    // flipped triangles is still filled exactly. The winding number is not: a flipped triangle
    // adds minus twice its own winding number, which nears 1 in size beside it (a cube of 10
    // voxels a side with its top face flipped loses 196 voxels of the three layers under it).
    if (edges.misoriented)
        return {InsideTest::Parity, "mesh is closed (" + std::to_string(edges.misoriented) +
                                        " edges between inconsistently oriented triangles: "
                                        "crossing parity does not depend on orientation)"};
    return {InsideTest::Parity, "mesh is closed"};
}
// Shared by both entry points: choose the test, and record the choice.
template <typename Parity, typename Winding>
SparseVoxels run_solid(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                       VoxelizeStats& stats, Parity parity, Winding winding) {
    validate_mesh(mesh);
    validate_grid(grid);
    SparseVoxels result(grid, options.brick_size);
    const auto nb = result.brick_dims();
    stats.triangles_in = mesh.triangles.size();
    stats.bricks_total = uint64_t(nb[0]) * uint64_t(nb[1]) * uint64_t(nb[2]);

    ParityTriangles triangles;
    const bool fits = parity_triangles(mesh, grid, triangles);
    const Choice choice = choose_inside_test(mesh, options.inside, fits);
    stats.inside_test = to_string(choice.test);
    stats.inside_test_reason = choice.reason;
    stats.triangles_used = mesh.triangles.size();
    if (choice.test == InsideTest::Parity)
        parity(triangles, result);
    else
        winding(result);
    stats.voxels_set = result.count();
    return result;
}

}  // namespace

MeshEdgeReport mesh_edge_report(const Mesh& mesh) {
    // The edge uses between welded vertices, counted per edge straight from their buckets: each
    // bucket's uses of one edge are adjacent, so no list of edges is made.
    const NumberedPositions numbered = number_positions(mesh.positions);
    const EdgeUses uses = edge_uses(mesh, numbered.numbers, numbered.positions.size());
    auto add = [](MeshEdgeReport a, const MeshEdgeReport& b) {
        a.edges += b.edges;
        a.boundary += b.boundary;
        a.non_manifold += b.non_manifold;
        a.misoriented += b.misoriented;
        return a;
    };
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, numbered.positions.size()), MeshEdgeReport{},
        [&](const tbb::blocked_range<size_t>& vertices, MeshEdgeReport report) {
            for (size_t v = vertices.begin(); v < vertices.end(); ++v)
                for (size_t e = uses.first[v]; e < uses.first[v + 1];) {
                    uint64_t runs[2] = {0, 0};  // low -> high, high -> low
                    const uint64_t upper = uses.upper[e] >> 1;
                    for (; e < uses.first[v + 1] && uses.upper[e] >> 1 == upper; ++e)
                        ++runs[uses.upper[e] & 1];
                    ++report.edges;
                    if (runs[0] + runs[1] == 1)
                        ++report.boundary;
                    else if (runs[0] + runs[1] > 2)
                        ++report.non_manifold;
                    else if (runs[0] != 1)
                        ++report.misoriented;
                }
            return report;
        },
        add);
}
InsideTest whole_mesh_inside_test(const Mesh& mesh, const Grid& grid, InsideTest requested) {
    ParityTriangles triangles;
    return choose_inside_test(mesh, requested, parity_triangles(mesh, grid, triangles)).test;
}
SparseVoxels solid_device(Device::Impl& cl, const Mesh& mesh, const Grid& grid,
                          const VoxelizeOptions& options, VoxelizeStats& stats) {
    try {
        return run_solid(
            mesh, grid, options, stats,
            [&](const ParityTriangles& triangles, SparseVoxels& result) {
                parity_device(cl, triangles, result, options, stats);
            },
            [&](SparseVoxels& result) { winding_device(cl, mesh, result, options, stats); });
    } catch (const cl::Error& e) {
        throw_device_error(e, "solid voxelization on " + cl.info.name);
    }
}

SparseVoxels solid_reference(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                             VoxelizeStats& stats) {
    const auto start = Clock::now();
    SparseVoxels result = run_solid(
        mesh, grid, options, stats,
        [&](const ParityTriangles& triangles, SparseVoxels& out) {
            parity_reference(triangles, out, options, stats);
        },
        [&](SparseVoxels& out) { winding_reference(mesh, out, options); });
    stats.seconds_kernels = seconds_since(start);
    return result;
}

}  // namespace oclvox::detail
