// Fitting a voxel grid to a mesh, and checking grids for sizes that cannot work.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "mesh_bounds.hpp"
#include "number_text.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox {

namespace {
std::string dims_text(const std::array<int64_t, 3>& d) {
    return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

}  // namespace

void detail::used_bounds(const Mesh& mesh, std::array<double, 3>& lo, std::array<double, 3>& hi) {
    // Chunks of triangles on all cores, then the chunks' boxes: minima and maxima are the same in
    // any order.
    constexpr size_t kChunk = 65536;
    const size_t chunks = (mesh.triangles.size() + kChunk - 1) / kChunk;
    constexpr double kInf = std::numeric_limits<double>::infinity();
    std::vector<std::array<double, 6>> boxes(chunks, {kInf, kInf, kInf, -kInf, -kInf, -kInf});
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        std::array<double, 6>& box = boxes[c];
        const size_t end = std::min(mesh.triangles.size(), (c + 1) * kChunk);
        for (size_t t = c * kChunk; t < end; ++t)
            for (const uint32_t v : mesh.triangles[t])
                for (int k = 0; k < 3; ++k) {
                    box[k] = std::min(box[k], mesh.positions[v][k]);
                    box[3 + k] = std::max(box[3 + k], mesh.positions[v][k]);
                }
    });
    lo.fill(kInf);
    hi.fill(-kInf);
    for (const auto& box : boxes)
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::min(lo[k], box[k]);
            hi[k] = std::max(hi[k], box[3 + k]);
        }
}

bool same_grid(const Grid& a, const Grid& b) {
    return a.origin == b.origin && a.voxel_size == b.voxel_size && a.dims == b.dims;
}

std::string to_string(const Grid& g) {
    return std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" +
           std::to_string(g.dims[2]) + " voxels of " + detail::number_text(g.voxel_size) + " at (" +
           detail::number_text(g.origin[0]) + ", " + detail::number_text(g.origin[1]) + ", " +
           detail::number_text(g.origin[2]) + ")";
}

void validate_grid(const Grid& grid) {
    if (!(grid.voxel_size > 0) || !std::isfinite(grid.voxel_size))
        throw GridError("voxel size must be a positive finite number, got " +
                        detail::number_text(grid.voxel_size));
    for (int k = 0; k < 3; ++k) {
        if (!std::isfinite(grid.origin[k])) throw GridError("grid origin is not finite");
        if (grid.dims[k] < 1)
            throw GridError("grid dimensions must be at least 1, got " + dims_text(grid.dims));
        if (grid.dims[k] > kMaxGridAxis)
            throw GridError("grid dimensions " + dims_text(grid.dims) + " exceed the maximum of " +
                            std::to_string(kMaxGridAxis) + " voxels per axis");
    }
}

Grid fit_grid(const Mesh& mesh, const GridFit& fit) {
    validate_mesh(mesh);
    if (fit.pad < 0 || fit.pad > kMaxGridAxis) throw GridError("padding must be in [0, 2^20]");
    std::array<double, 3> lo, hi;
    detail::used_bounds(mesh, lo, hi);
    const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});

    // Phase 1: the voxel size, from an explicit size or the resolution along the longest axis.
    Grid grid;
    if (fit.voxel_size > 0) {
        grid.voxel_size = fit.voxel_size;
    } else {
        if (fit.resolution < 1 || fit.resolution > kMaxGridAxis)
            throw GridError("resolution " + std::to_string(fit.resolution) +
                            " is out of range: it must be in [1, " + std::to_string(kMaxGridAxis) +
                            "]");
        if (!(extent > 0))
            throw GridError(
                "the mesh has zero extent (all vertices coincide): give --voxel-size to voxelize "
                "it");
        grid.voxel_size = extent / double(fit.resolution);
    }
    if (!std::isfinite(grid.voxel_size) || !(grid.voxel_size > 0))
        throw GridError("voxel size must be a positive finite number");

    // Phase 2: dimensions. Fitted axes get as many voxels as the mesh needs (at least one); the
    // longest axis of a resolution fit gets exactly `resolution`; a cubic grid is resolution^3.
    const bool by_resolution = fit.voxel_size <= 0;
    for (int k = 0; k < 3; ++k) {
        double cells = std::ceil((hi[k] - lo[k]) / grid.voxel_size);
        if (!(cells < double(kMaxGridAxis)))
            throw GridError("the mesh spans " + detail::number_text(hi[k] - lo[k]) +
                            " units, more than the maximum " + std::to_string(kMaxGridAxis) +
                            " voxels of size " + detail::number_text(grid.voxel_size));
        // extent / (extent / N) can round to just above N (or a shorter axis's quotient to just
        // above a whole number), and ceil would then add a voxel the mesh does not reach.
        // So the count is the smallest that covers the mesh as the voxelizer computes positions.
        if (by_resolution && hi[k] - lo[k] == extent) {
            cells = double(fit.resolution);
        } else {
            while (cells > 1 && lo[k] + (cells - 1) * grid.voxel_size >= hi[k]) cells -= 1;
            while (lo[k] + cells * grid.voxel_size < hi[k]) cells += 1;
        }
        grid.dims[k] = std::max<int64_t>(1, int64_t(cells));
        if (fit.cubic && by_resolution) grid.dims[k] = fit.resolution;
        if (fit.has_dims) grid.dims[k] = fit.dims[k];
    }

    // Phase 3: origin: the box minimum, or the box centred in a grid larger than the mesh
    // (given dims, or a cube anchored at its centre).
    const bool centred =
        fit.has_dims || (fit.cubic && fit.cubic_anchor == GridFit::CubicAnchor::Centre);
    for (int k = 0; k < 3; ++k) {
        const double centre = 0.5 * (lo[k] + hi[k]);
        grid.origin[k] = centred ? centre - 0.5 * double(grid.dims[k]) * grid.voxel_size : lo[k];
        if (fit.has_origin) grid.origin[k] = fit.origin[k];
    }

    // Phase 4: padding on every side.
    for (int k = 0; k < 3; ++k) {
        grid.origin[k] -= double(fit.pad) * grid.voxel_size;
        grid.dims[k] += 2 * fit.pad;
    }
    validate_grid(grid);
    return grid;
}

}  // namespace oclvox
