// Solid voxelization by crossing parity. Phases: snap every vertex to fixed point
// (solid_math.h); bin triangles into the brick columns (brick_size^2 footprints over the whole grid
// height) their xy boxes reach; then per batch of brick columns that fits the device budget: flip
// one bit per (triangle, covered voxel column), prefix-XOR every voxel column while packing its
// bits into bricks, and merge the non-empty ones. A voxel column never crosses a batch, so the
// result cannot depend on the brick size. The host reference does the same flips, prefix and
// packing.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>

#include "block_download.hpp"
#include "brick_selection.hpp"
#include "device_batches.hpp"
#include "solid_internal.hpp"

namespace oclvox::detail {

namespace {

struct Layout {
    int brick;              // brick edge in voxels
    int nx, ny, nz;         // grid
    int64_t nbx, nby, nbz;  // bricks per axis
    uint32_t words;         // 32-bit words per voxel column
    size_t blocks_per_brick;
    uint64_t slot_bytes() const {
        return uint64_t(brick) * brick * words * 4 + uint64_t(nbz) * blocks_per_brick * 8;
    }
};

Layout make_layout(const SparseVoxels& result) {
    const Grid& g = result.grid();
    const auto nb = result.brick_dims();
    return {result.brick_size(),
            int(g.dims[0]),
            int(g.dims[1]),
            int(g.dims[2]),
            nb[0],
            nb[1],
            nb[2],
            uint32_t((g.dims[2] + 31) / 32),
            result.blocks_per_brick()};
}

// Triangles by selected brick column (index bx + nbx * by), only those that can flip a grid voxel.
struct ColumnBins {
    std::vector<uint64_t> columns;     // brick columns with at least one triangle, ascending
    std::vector<uint64_t> first_pair;  // per column, into pair_triangle; one extra at the end
    std::vector<uint32_t> pair_triangle;
};

// Calls f(column) for every brick column (index bx + nbx * by) where `tri` can flip a grid voxel.
template <class F>
void for_each_column_of(const OvParityTriangle& tri, const Layout& l, F&& f) {
    // A crossing at or above the centre of the top voxel flips nothing in the grid.
    const int64_t top_centre = int64_t(l.nz - 1) * OVS_UNITS + OVS_UNITS / 2;
    if (std::min({tri.v[2], tri.v[5], tri.v[8]}) >= top_centre) return;
    OvColumnRange r;
    if (!ovs_column_range(&tri, 0, 0, std::max(l.nx, l.ny), l.nx, l.ny, &r)) return;
    for (int by = r.lo[1] / l.brick; by <= r.hi[1] / l.brick; ++by)
        for (int bx = r.lo[0] / l.brick; bx <= r.hi[0] / l.brick; ++bx)
            f(uint64_t(bx) + uint64_t(l.nbx) * uint64_t(by));
}

ColumnBins bin_columns(const ParityTriangles& triangles, const Layout& l,
                       const BrickSelection& selection) {
    // (column, triangle) pairs in triangle order, then sorted by column, then triangle: by a
    // stable counting sort when the grid has few brick columns for its pairs (the usual case),
    // else by a comparison sort.
    std::vector<std::pair<uint64_t, uint32_t>> pairs;
    for (size_t t = 0; t < triangles.size(); ++t)
        for_each_column_of(triangles[t], l, [&](uint64_t column) {
            if (selection.contains_column(column)) pairs.push_back({column, uint32_t(t)});
        });
    const uint64_t columns = uint64_t(l.nbx) * uint64_t(l.nby);
    ColumnBins bins;
    bins.pair_triangle.resize(pairs.size());
    if (columns <= 4 * pairs.size() + 4096) {
        std::vector<uint64_t> start(columns, 0);  // pairs per column, then its first pair
        for (const auto& pair : pairs) ++start[pair.first];
        uint64_t total = 0;
        for (uint64_t c = 0; c < columns; ++c) {
            const uint64_t count = start[c];
            start[c] = total;
            if (count == 0) continue;
            bins.columns.push_back(c);
            bins.first_pair.push_back(total);
            total += count;
        }
        for (const auto& [column, t] : pairs) bins.pair_triangle[start[column]++] = t;
    } else {
        std::sort(pairs.begin(), pairs.end());
        for (size_t p = 0; p < pairs.size(); ++p) {
            if (p == 0 || pairs[p].first != pairs[p - 1].first) {
                bins.columns.push_back(pairs[p].first);
                bins.first_pair.push_back(p);
            }
            bins.pair_triangle[p] = pairs[p].second;
        }
    }
    bins.first_pair.push_back(pairs.size());
    return bins;
}

// The brick coordinates (bx, by) of brick column `column` (bx + nbx * by).
std::array<int, 2> column_coordinates(const Layout& l, uint64_t column) {
    return {int(column % uint64_t(l.nbx)), int(column / uint64_t(l.nbx))};
}

// Brick columns [first, ...) as one batch: a work item per voxel row of a triangle's footprint in
// a brick column.
PairBatch make_batch(const ColumnBins& bins, const ParityTriangles& triangles, const Layout& l,
                     size_t first, size_t max_slots) {
    return make_pair_batch(bins.columns, bins.first_pair, bins.pair_triangle, first, max_slots,
                           "brick column", /* no direct pairs */ 0, [&](size_t c) {
                               const auto [bx, by] = column_coordinates(l, bins.columns[c]);
                               return [&, bx = bx, by = by](uint32_t triangle) {
                                   OvColumnRange r;
                                   const bool covers =
                                       ovs_column_range(&triangles[triangle], bx, by, l.brick, l.nx,
                                                        l.ny, &r) > 0;
                                   return covers ? cl_uint(r.hi[1] - r.lo[1] + 1) : 0u;
                               };
                           });
}

// The brick index of brick `row` (from the bottom) of brick column `column`.
uint64_t column_brick(const Layout& l, uint64_t column, uint64_t row) {
    return column + uint64_t(l.nbx) * uint64_t(l.nby) * row;
}

// Merges the bricks of one packed brick column (bricks bottom to top, blocks as 64-bit words).
void merge_column(SparseVoxels& result, const Layout& l, uint64_t column, const uint64_t* blocks) {
    for (int64_t row = 0; row < l.nbz; ++row)
        result.merge_brick(column_brick(l, column, uint64_t(row)),
                           blocks + size_t(row) * l.blocks_per_brick);
}
}  // namespace

// Vertices snapped to fixed-point grid units, or false if a vertex lies too far outside the grid
// for the exact integer arithmetic of solid_math.h. Each vertex is snapped once (a vertex serves
// about six triangles); only the vertices triangles use must fit.
bool parity_triangles(const Mesh& mesh, const Grid& grid, ParityTriangles& out) {
    const double limit = double(OVS_MAX_UNITS) / OVS_UNITS;
    const double inv = 1.0 / grid.voxel_size;
    constexpr ovs_long kBeyond = -OVS_MAX_UNITS - 1;  // marks a vertex beyond the limit
    FilledLaterVector<std::array<ovs_long, 3>> snapped(mesh.positions.size());
    tbb::parallel_for(size_t(0), mesh.positions.size(), [&](size_t v) {
        for (int k = 0; k < 3; ++k) {
            const double g = (mesh.positions[v][k] - grid.origin[k]) * inv;
            snapped[v][k] = std::fabs(g) < limit ? std::llround(g * OVS_UNITS) : kBeyond;
        }
    });
    out.resize(mesh.triangles.size());
    std::atomic<bool> fits{true};
    tbb::parallel_for(size_t(0), mesh.triangles.size(), [&](size_t t) {
        for (int c = 0; c < 3; ++c)
            for (int k = 0; k < 3; ++k) {
                const ovs_long units = snapped[mesh.triangles[t][c]][k];
                if (units == kBeyond) fits = false;
                out[t].v[3 * c + k] = units;
            }
    });
    return fits;
}

void parity_device(Device::Impl& cl, const ParityTriangles& triangles, SparseVoxels& result,
                   const VoxelizeOptions& options, VoxelizeStats& stats) {
    auto t = Clock::now();
    const Layout l = make_layout(result);
    const ColumnBins bins = bin_columns(triangles, l, BrickSelection(options.bricks, result));
    stats.brick_pairs = bins.pair_triangle.size();
    stats.bricks_active = bins.columns.size() * uint64_t(l.nbz);
    stats.seconds_binning += seconds_since(t);
    if (bins.columns.empty()) return;
    check_solid_memory(result, stats.bricks_active, 0, options, "");

    const uint64_t budget = batch_budget(cl, options.device_budget_bytes, l.slot_bytes());
    if (l.slot_bytes() > budget)
        throw GridError("one brick column of " + std::to_string(l.brick) + "^2 x " +
                        std::to_string(l.nz) + " voxels needs " + mib_text(l.slot_bytes()) +
                        " for parity, over the device budget of " + mib_text(budget) +
                        ": use smaller bricks");
    size_t slots = size_t(std::min<uint64_t>(budget / l.slot_bytes(), bins.columns.size()));
    const size_t column_words = size_t(l.brick) * l.brick * l.words;
    const size_t block_words = 2 * size_t(l.nbz) * l.blocks_per_brick;

    const cl::Program& program = cl.program(kKernel_solid);
    t = Clock::now();
    const cl::Buffer tri_buffer = read_in_place(cl, triangles);
    cl.queue.finish();
    stats.seconds_upload += seconds_since(t);
    BitSlotBuffer bits(column_words * sizeof(cl_uint), BitSlotBuffer::FreshPages::ZeroOnEveryCore);
    // The blocks that hold voxels are written once, and a result in the host's memory takes their
    // pages (those of bricks without a voxel stay untouched: adopt_bricks skips them unread).
    BitSlotBuffer blocks(block_words * sizeof(cl_uint),
                         BitSlotBuffer::FreshPages::FaultWhereWritten);

    cl::Kernel flip(program, "parity_flip"), to_blocks(program, "parity_blocks");
    const size_t flip_group = work_group_size(flip, cl.device);
    const size_t to_blocks_group = work_group_size(to_blocks, cl.device);

    // Batches of brick columns, smaller after a device allocation failure (nothing of a failed
    // batch has been merged).
    auto run_batch = [&](size_t done, size_t max_columns) {
        t = Clock::now();
        const PairBatch batch = make_batch(bins, triangles, l, done, max_columns);
        const cl::Buffer& bit_buffer = bits.get(cl, max_columns, batch.unit_count);
        const cl::Buffer& block_buffer = blocks.get(cl, max_columns, batch.unit_count);
        std::vector<cl_int> slot_coordinates;  // each slot's brick column (bx, by)
        for (size_t slot = 0; slot < batch.unit_count; ++slot)
            for (const int k : column_coordinates(l, bins.columns[done + slot]))
                slot_coordinates.push_back(k);
        const cl::Buffer pair_triangle = read_in_place(cl, batch.pair_triangle);
        const cl::Buffer pair_slot = read_in_place(cl, batch.pair_slot);
        const cl::Buffer pair_first = read_in_place(cl, batch.pair_first_item);
        const cl::Buffer item_pair = read_in_place(cl, batch.item_pair);
        const cl::Buffer slot_column = read_in_place(cl, slot_coordinates);
        cl.queue.finish();
        stats.seconds_upload += seconds_since(t);

        // Flips, then parity up each voxel column into the brick layout.
        t = Clock::now();
        set_args(flip, 0, tri_buffer, pair_triangle, pair_slot, pair_first, item_pair, slot_column,
                 cl_uint(0), cl_uint(batch.items), cl_int(l.brick), cl_int(l.nx), cl_int(l.ny),
                 cl_int(l.nz), cl_uint(l.words), bit_buffer);
        run_sliced(cl.queue, batch.items, flip_group,
                   [&](uint64_t first, uint64_t count) {
                       flip.setArg(6, cl_uint(first));
                       launch(cl.queue, flip, count, flip_group);
                   },
                   {});
        // parity_blocks: an item per 4x4 voxel columns.
        const uint64_t block_items =
            uint64_t(batch.unit_count) * uint64_t(l.brick / 4) * uint64_t(l.brick / 4);
        set_args(to_blocks, 0, bit_buffer, cl_uint(batch.unit_count), cl_int(l.brick),
                 cl_int(l.nbz), cl_int(l.nz), cl_uint(l.words), block_buffer);
        launch(cl.queue, to_blocks, block_items, to_blocks_group);
        cl.queue.finish();
        stats.seconds_kernels += seconds_since(t);
        stats.work_items += batch.items + block_items;

        // Each slot's bricks, bottom to top, are units of the download.
        download_bricks(
            cl, block_buffer, blocks, batch.unit_count * size_t(l.nbz), l.blocks_per_brick,
            options.download, stats,
            [&](size_t unit) {
                const uint64_t column = bins.columns[batch.first_unit + unit / size_t(l.nbz)];
                return column_brick(l, column, unit % size_t(l.nbz));
            },
            result);
        ++stats.batches;
        const size_t finished = done + batch.unit_count;
        report_progress(options, finished * uint64_t(l.nbz), bins.columns.size() * uint64_t(l.nbz));
        return batch.unit_count;
    };
    run_batches(cl.queue, bins.columns.size(), slots, stats,
                "computing the parity solid on " + cl.info.name, "brick column", run_batch);
}

// The same flips, prefix and packing on the host, one brick column at a time.
void parity_reference(const ParityTriangles& triangles, SparseVoxels& result,
                      const VoxelizeOptions& options, VoxelizeStats& stats) {
    const Layout l = make_layout(result);
    const ColumnBins bins = bin_columns(triangles, l, BrickSelection({}, result));
    stats.brick_pairs = bins.pair_triangle.size();
    stats.bricks_active = bins.columns.size() * uint64_t(l.nbz);
    check_solid_memory(result, stats.bricks_active, 0, options, "");
    std::vector<uint32_t> bits(size_t(l.brick) * l.brick * l.words);
    std::vector<uint64_t> blocks(size_t(l.nbz) * l.blocks_per_brick);
    const int nb = l.brick / 4;
    for (size_t c = 0; c < bins.columns.size(); ++c) {
        const auto [bx, by] = column_coordinates(l, bins.columns[c]);
        std::fill(bits.begin(), bits.end(), 0u);
        for (uint64_t p = bins.first_pair[c]; p < bins.first_pair[c + 1]; ++p) {
            const OvParityTriangle& tri = triangles[bins.pair_triangle[p]];
            OvColumnRange r;
            if (!ovs_column_range(&tri, bx, by, l.brick, l.nx, l.ny, &r)) continue;
            for (int j = r.lo[1]; j <= r.hi[1]; ++j)
                for (int i = r.lo[0]; i <= r.hi[0]; ++i) {
                    const int k = ovs_parity_flip(&tri, i, j, l.nz);
                    if (k < 0 || k >= l.nz) continue;
                    const size_t column =
                        size_t(j - by * l.brick) * l.brick + size_t(i - bx * l.brick);
                    bits[column * l.words + size_t(k >> 5)] ^= 1u << (k & 31);
                }
        }
        std::fill(blocks.begin(), blocks.end(), 0);
        for (size_t column = 0; column < size_t(l.brick) * l.brick; ++column) {
            uint32_t carry = 0;
            const int x = int(column % size_t(l.brick)), y = int(column / size_t(l.brick));
            for (uint32_t w = 0; w < l.words; ++w) {
                const uint32_t v = ovs_prefix_xor(bits[column * l.words + w], carry);
                carry = v >> 31;
                for (int b = 0; b < 32; ++b) {
                    const int k = int(w) * 32 + b;
                    if (k >= l.nz || !(v >> b & 1u)) continue;
                    const int lz = k % l.brick;
                    const size_t block = size_t(k / l.brick) * l.blocks_per_brick +
                                         size_t(x / 4 + nb * (y / 4 + nb * (lz / 4)));
                    blocks[block] |= uint64_t(1) << ((x & 3) + 4 * ((y & 3) + 4 * (lz & 3)));
                }
            }
        }
        merge_column(result, l, bins.columns[c], blocks.data());
    }
}
void for_each_parity_column(const Mesh& mesh, const Grid& grid, int brick_size,
                            const std::function<void(uint32_t, uint64_t)>& f) {
    ParityTriangles triangles;
    if (!parity_triangles(mesh, grid, triangles))
        throw GridError("parity columns asked for a mesh beyond exact parity arithmetic");
    const Layout l = make_layout(SparseVoxels(grid, brick_size));
    for (size_t t = 0; t < triangles.size(); ++t)
        for_each_column_of(triangles[t], l, [&](uint64_t column) { f(uint32_t(t), column); });
}
}  // namespace oclvox::detail
