// Brick selections: a sorted set, so membership costs a binary search and no storage scales with
// the grid (a 2^20-voxel axis with 4-voxel bricks has 2^54 bricks).
#include "brick_selection.hpp"

#include <algorithm>
#include <numeric>
#include <utility>

#include "binning.hpp"
#include "solid.hpp"

namespace oclvox::detail {

BrickSelection::BrickSelection(const std::vector<uint64_t>& bricks, const SparseVoxels& layout)
    : everything_(bricks.empty()), bricks_(bricks) {
    const auto nb = layout.brick_dims();
    const uint64_t column_count = uint64_t(nb[0]) * uint64_t(nb[1]);
    const uint64_t bricks_total = column_count * uint64_t(nb[2]);
    std::sort(bricks_.begin(), bricks_.end());
    bricks_.erase(std::unique(bricks_.begin(), bricks_.end()), bricks_.end());
    if (!bricks_.empty() && bricks_.back() >= bricks_total)
        throw GridError("brick index " + std::to_string(bricks_.back()) +
                        " is outside the grid, which has " + std::to_string(bricks_total) +
                        " bricks of " + std::to_string(layout.brick_size()) + "^3 voxels");
    columns_.reserve(bricks_.size());
    for (const uint64_t brick : bricks_) columns_.push_back(brick % column_count);
    std::sort(columns_.begin(), columns_.end());
    columns_.erase(std::unique(columns_.begin(), columns_.end()), columns_.end());
}

bool BrickSelection::contains(uint64_t brick) const {
    return everything_ || std::binary_search(bricks_.begin(), bricks_.end(), brick);
}

bool BrickSelection::contains_column(uint64_t column) const {
    return everything_ || std::binary_search(columns_.begin(), columns_.end(), column);
}

void BrickSelection::restrict(SparseVoxels& voxels) const {
    if (everything_) return;
    SparseVoxels kept(voxels.grid(), voxels.brick_size());
    for (const uint64_t brick : bricks_)
        if (const uint64_t* blocks = voxels.brick_blocks(brick)) kept.merge_brick(brick, blocks);
    voxels = std::move(kept);
}

}  // namespace oclvox::detail

namespace oclvox {

SelectionTriangles selection_triangles(const Mesh& mesh, const Grid& grid,
                                       const VoxelizeOptions& options,
                                       const std::vector<std::vector<uint64_t>>& selections) {
    // Phase 1: the inside test of the whole run; the winding number needs every triangle.
    validate_mesh(mesh);
    validate_grid(grid);
    const SparseVoxels layout(grid, options.brick_size);  // validates the brick size
    const bool solid = options.mode == VoxelizeMode::Solid || options.mode == VoxelizeMode::Filled;
    SelectionTriangles out;
    out.inside =
        solid ? detail::whole_mesh_inside_test(mesh, grid, options.inside) : options.inside;
    if (solid && out.inside == InsideTest::Winding) {
        out.whole_mesh = true;
        return out;
    }

    // Phase 2: which selections own each selected brick and brick column (sorted, for lookups
    // by binary search). An empty selection is every brick: it gets every triangle.
    const auto nb = layout.brick_dims();
    const uint64_t column_count = uint64_t(nb[0]) * uint64_t(nb[1]);
    std::vector<std::pair<uint64_t, uint32_t>> brick_owners, column_owners;
    out.triangles.resize(selections.size());
    for (size_t s = 0; s < selections.size(); ++s) {
        detail::BrickSelection(selections[s], layout);  // throws for a brick outside the grid
        for (const uint64_t brick : selections[s]) {
            brick_owners.push_back({brick, uint32_t(s)});
            column_owners.push_back({brick % column_count, uint32_t(s)});
        }
        if (selections[s].empty()) {
            out.triangles[s].resize(mesh.triangles.size());
            std::iota(out.triangles[s].begin(), out.triangles[s].end(), uint32_t(0));
        }
    }
    for (auto* owners : {&brick_owners, &column_owners}) {
        std::sort(owners->begin(), owners->end());
        owners->erase(std::unique(owners->begin(), owners->end()), owners->end());
    }

    // Phase 3: the binning's own (triangle, brick) and (triangle, column) pairs, each triangle
    // given to the selections owning its bricks. Triangles come in ascending order within a pass,
    // so remembering the last triangle each selection got keeps its list sorted and unique.
    std::vector<int64_t> last(selections.size());
    const auto give = [&](const std::vector<std::pair<uint64_t, uint32_t>>& owners, uint64_t key,
                          uint32_t triangle) {
        auto it = std::lower_bound(owners.begin(), owners.end(), std::make_pair(key, uint32_t(0)));
        for (; it != owners.end() && it->first == key; ++it)
            if (last[it->second] != int64_t(triangle)) {
                last[it->second] = triangle;
                out.triangles[it->second].push_back(triangle);
            }
    };
    if (options.mode != VoxelizeMode::Solid) {
        // Surface and Thin, and Filled's surface: bricks of the prepared triangles, which clipping
        // can split (a split triangle's pieces are consecutive).
        const detail::PreparedTriangles prepared =
            detail::prepare_triangles(mesh, grid, options.boundary);
        std::fill(last.begin(), last.end(), -1);
        detail::for_each_triangle_brick(prepared, grid, options.brick_size,
                                        [&](uint32_t piece, uint64_t brick) {
                                            give(brick_owners, brick, prepared.source_of(piece));
                                        });
    }
    if (solid) {
        // Parity: every triangle that can flip a voxel of a selected brick's column, including
        // those below the grid or far outside it, which the surface's clipping drops.
        std::fill(last.begin(), last.end(), -1);
        detail::for_each_parity_column(
            mesh, grid, options.brick_size,
            [&](uint32_t triangle, uint64_t column) { give(column_owners, column, triangle); });
    }
    if (options.mode == VoxelizeMode::Filled)
        for (std::vector<uint32_t>& list : out.triangles) {
            std::sort(list.begin(), list.end());
            list.erase(std::unique(list.begin(), list.end()), list.end());
        }
    return out;
}

}  // namespace oclvox
