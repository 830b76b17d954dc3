// Surface Nets and Marching Cubes on the host: of a sparse narrow-band field without a dense
// copy, and of a dense field through its meshing view (the leaves around its sign changes, the
// sides of its other samples), which MeshingViewBuilder gathers a layer at a time, so fields that
// are never whole (computed in slabs, read from a file) are meshed too. The per-sample functions of
// the dense reference and the kernels (kernels/meshing_math.h) run on small dense boxes read from
// the leaves, and the prefix sums follow the same global sample order, so the mesh equals meshing
// field.to_dense() bit for bit: the same vertices in the same order and the same triangles. Work
// and memory follow the surface: the blocks near it, three slabs of them at a time, plus the mesh.
//
// Phases:
//  1. Candidate blocks: the 8^3 blocks of the leaves' tiling whose samples, with the one-sample
//     halo their cells and edges reach, do not all lie on one side of iso. A sample outside the
//     leaves is -background where the inside voxels are set and +background elsewhere, so such a
//     block either reaches a stored leaf or a place where the inside voxels change; of those,
//     the ones kept are told exactly from per-leaf summaries of the sides of their samples (and
//     the inside voxels where no leaf is stored), without reading a sample twice.
//  2. Slab by slab (the blocks of one z), count each sample's vertices and triangles from a box
//     of its block with a halo; blocks that own nothing are dropped.
//  3. Exclusive prefix sums over the slab in global sample order, continued from the slab before:
//     the dense mesh's numbering.
//  4. Emit a slab once the next one is counted, since Marching Cubes' triangles use vertices owned
//     one sample above (Surface Nets' quads use cells one sample below, counted already). The
//     vertex records become world positions at once.
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <atomic>
#include <cfloat>
#include <cmath>
#include <limits>
#include <optional>

#include "host_memory.hpp"
#include "meshing.hpp"

namespace oclvox {

namespace {

using Index3 = std::array<int64_t, 3>;

constexpr int kBlock = SparseField::kLeaf;
constexpr size_t kBlockSamples = SparseField::kLeafSamples;
// The box read for a block reaches one sample below it (Surface Nets' quads join the cells one
// below) and two above (Marching Cubes ranks the edges of the samples one above, which read one
// further). Within it, the per-sample functions' checks against the box's faces say what they
// say against the grid's for every sample of the block.
constexpr int64_t kBelow = 1, kAbove = 2;

struct Block {
    Index3 origin{};               // lowest sample
    Index3 box_lo{}, box_hi{};     // the box read, clipped to the grid
    std::vector<float> box;        // its samples, x fastest
    std::vector<uint16_t> owners;  // the slots of its samples that own vertices or triangles
};

// The blocks of one z that own vertices or triangles, by (y, x), with kBlockSamples slots each
// (x fastest over the whole block; slots beyond the grid stay unused).
struct Slab {
    int64_t bz = 0;
    std::vector<Block> blocks;
    std::vector<uint64_t> keys;  // the blocks' indices, for lookups
    std::vector<uint32_t> vertex_count, vertex_offset, triangle_offset;
    uint32_t first_vertex = 0, first_triangle = 0, end_vertex = 0, end_triangle = 0;
};

// Index x + nx * (y + ny * z) of c in a box of n, and back.
uint64_t ravel(const Index3& c, const Index3& n) {
    return uint64_t(c[0]) + uint64_t(n[0]) * (uint64_t(c[1]) + uint64_t(n[1]) * uint64_t(c[2]));
}
Index3 unravel(uint64_t index, const Index3& n) {
    return {int64_t(index % uint64_t(n[0])), int64_t(index / uint64_t(n[0]) % uint64_t(n[1])),
            int64_t(index / (uint64_t(n[0]) * uint64_t(n[1])))};
}

size_t slot_in_block(const Index3& origin, int64_t x, int64_t y, int64_t z) {
    return size_t((x - origin[0]) + kBlock * ((y - origin[1]) + kBlock * (z - origin[2])));
}

// Calls f(origin) for every 4^3 word of the voxels that may hold or border a change: a word with
// both set and unset voxels, or a full one beside one that is not (stored or not). Neighbours
// beyond the grid's faces hold no samples, so they border nothing. Bricks are visited in
// parallel, so f must be safe to call from several threads.
template <typename F>
void for_each_inside_boundary(const SparseVoxels& voxels, F f) {
    const int64_t words_per_axis = voxels.blocks_per_brick_axis(), word = SparseVoxels::kBlock;
    const Index3 bricks = voxels.brick_dims();
    const auto& n = voxels.grid().dims;
    auto word_at = [&](const Index3& w) {  // w in words of the whole grid, inside it
        const uint64_t* words = voxels.brick_blocks(
            ravel({w[0] / words_per_axis, w[1] / words_per_axis, w[2] / words_per_axis}, bricks));
        if (!words) return uint64_t(0);
        return words[(w[0] % words_per_axis) +
                     words_per_axis *
                         ((w[1] % words_per_axis) + words_per_axis * (w[2] % words_per_axis))];
    };
    const std::vector<uint64_t> stored = voxels.brick_indices();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, stored.size(), 16), [&](const auto& r) {
        for (size_t s = r.begin(); s != r.end(); ++s) {
            const uint64_t brick = stored[s];
            const Index3 b = unravel(brick, bricks);
            const uint64_t* words = voxels.brick_blocks(brick);
            const size_t stride[3] = {1, size_t(words_per_axis),
                                      size_t(words_per_axis * words_per_axis)};
            size_t i = 0;
            for (int64_t wz = 0; wz < words_per_axis; ++wz)
                for (int64_t wy = 0; wy < words_per_axis; ++wy)
                    for (int64_t wx = 0; wx < words_per_axis; ++wx, ++i) {
                        if (words[i] == 0) continue;
                        const Index3 w = {b[0] * words_per_axis + wx, b[1] * words_per_axis + wy,
                                          b[2] * words_per_axis + wz};
                        bool border = words[i] != ~uint64_t(0);
                        for (int a = 0; a < 3 && !border; ++a)
                            for (int64_t step : {-1, 1}) {
                                Index3 beside = w;
                                beside[a] += step;
                                if (beside[a] < 0 || beside[a] * word >= n[a]) continue;
                                const int64_t local = (a == 0 ? wx : a == 1 ? wy : wz) + step;
                                const uint64_t value =
                                    local >= 0 && local < words_per_axis  // in this brick
                                        ? words[i + size_t(step) * stride[a]]
                                        : word_at(beside);
                                if (value != ~uint64_t(0)) border = true;
                            }
                        if (border) f(Index3{w[0] * word, w[1] * word, w[2] * word});
                    }
        }
    });
}

// Which sides of iso samples lie on, as bits.
constexpr uint8_t kInsideSide = 1, kOutsideSide = 2, kBothSides = 3;

uint8_t side_of(float value, float iso) {
    return detail::om_inside(value, iso) ? kInsideSide : kOutsideSide;
}

// A block's samples with their halo, [o, o + 8] on each axis, lie in the 2x2x2 leaves from its
// own up: all of its own leaf, and of the leaf one above along the axes in a mask d only the
// samples at that leaf's low face along those axes. Part d of a leaf is that set of samples.
using PartSides = std::array<uint8_t, 8>;

// The sides of every part of each stored leaf's samples within the grid. The dense field holds
// no non-finite sample, so neither may a meshed sparse one.
std::vector<PartSides> leaf_sides(const SparseField& field, float iso, const char* who) {
    std::vector<PartSides> sides(field.leaf_count());
    const auto& n = field.grid().dims;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, sides.size(), 64), [&](const auto& r) {
        for (size_t l = r.begin(); l != r.end(); ++l) {
            const Index3 o = field.leaf_origin(field.leaf_indices()[l]);
            const float* samples = field.leaf_samples(l);
            // Each sample's side (0 beyond the grid), then each part's.
            uint8_t side[kBlockSamples] = {};
            for (int64_t z = 0; z < std::min<int64_t>(kBlock, n[2] - o[2]); ++z)
                for (int64_t y = 0; y < std::min<int64_t>(kBlock, n[1] - o[1]); ++y)
                    for (int64_t x = 0; x < std::min<int64_t>(kBlock, n[0] - o[0]); ++x) {
                        const size_t at = size_t(x + kBlock * (y + kBlock * z));
                        if (!std::isfinite(samples[at]))
                            throw InputError(
                                std::string(who) + ": sample (" + std::to_string(o[0] + x) + ", " +
                                std::to_string(o[1] + y) + ", " + std::to_string(o[2] + z) +
                                ") of the field is not finite");
                        side[at] = side_of(samples[at], iso);
                    }
            PartSides parts{};
            for (int d = 0; d < 8; ++d) {
                const int ex = d & 1 ? 1 : kBlock, ey = d & 2 ? 1 : kBlock, ez = d & 4 ? 1 : kBlock;
                for (int z = 0; z < ez; ++z)
                    for (int y = 0; y < ey; ++y)
                        for (int x = 0; x < ex; ++x)
                            parts[size_t(d)] |= side[size_t(x + kBlock * (y + kBlock * z))];
            }
            sides[l] = parts;
        }
    });
    return sides;
}

// The sides of part d of leaf cell c: a stored leaf's from `sides`; otherwise those of the
// backgrounds its inside voxels give it.
uint8_t part_sides(const SparseField& field, float iso, const std::vector<PartSides>& sides,
                   const Index3& c, int d) {
    const Index3 nb = field.leaf_dims();
    const uint64_t key = ravel(c, nb);
    const auto& keys = field.leaf_indices();
    const auto it = std::lower_bound(keys.begin(), keys.end(), key);
    if (it != keys.end() && *it == key) return sides[size_t(it - keys.begin())][size_t(d)];
    const auto& n = field.grid().dims;
    Index3 lo, hi;
    for (int a = 0; a < 3; ++a) {
        lo[a] = c[a] * kBlock;
        hi[a] = std::min(lo[a] + ((d >> a) & 1 ? 1 : kBlock), n[a]);
    }
    const uint64_t inside = field.inside().count_box(lo, hi);
    const uint64_t volume = uint64_t((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]));
    return uint8_t((inside ? side_of(-field.background(), iso) : 0) |
                   (inside < volume ? side_of(field.background(), iso) : 0));
}

// Phase 1: the indices (bx + nbx * (by + nby * bz), increasing) of the blocks whose samples, with
// the one-sample halo above them, lie on both sides of iso: those that may own part of the
// surface.
std::vector<uint64_t> candidate_blocks(const SparseField& field, float iso, const char* who) {
    const Index3 nb = field.leaf_dims();  // blocks tile the grid as the leaves do
    const auto& n = field.grid().dims;
    std::vector<uint64_t> blocks;
    auto add_range = [&](const Index3& lo, const Index3& hi) {  // inclusive block coordinates
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
            for (int64_t y = lo[1]; y <= hi[1]; ++y)
                for (int64_t x = lo[0]; x <= hi[0]; ++x) blocks.push_back(ravel({x, y, z}, nb));
    };
    // Where a change may be: a stored leaf reaches its own block and, through their halo, the
    // seven below it.
    const std::vector<PartSides> sides = leaf_sides(field, iso, who);
    blocks.reserve(8 * field.leaf_count());
    for (uint64_t leaf : field.leaf_indices()) {
        const Index3 l = unravel(leaf, nb);
        add_range({std::max<int64_t>(l[0] - 1, 0), std::max<int64_t>(l[1] - 1, 0),
                   std::max<int64_t>(l[2] - 1, 0)},
                  l);
    }
    // Changes of the inside voxels matter only when the two backgrounds lie on either side of
    // iso. An edge with an end in the word at p is owned by a sample in [p - 1, p + 3].
    const float background = field.background();
    if (detail::om_inside(-background, iso) != detail::om_inside(background, iso)) {
        tbb::enumerable_thread_specific<std::vector<uint64_t>> found;
        for_each_inside_boundary(field.inside(), [&](const Index3& p) {
            std::vector<uint64_t>& local = found.local();
            Index3 lo, hi;
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::max<int64_t>(p[k] - 1, 0) / kBlock;
                hi[k] = std::min<int64_t>(p[k] + SparseVoxels::kBlock - 1, n[k] - 1) / kBlock;
            }
            for (int64_t z = lo[2]; z <= hi[2]; ++z)
                for (int64_t y = lo[1]; y <= hi[1]; ++y)
                    for (int64_t x = lo[0]; x <= hi[0]; ++x) local.push_back(ravel({x, y, z}, nb));
        });
        for (const std::vector<uint64_t>& local : found)
            blocks.insert(blocks.end(), local.begin(), local.end());
    }
    tbb::parallel_sort(blocks.begin(), blocks.end());
    blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());

    // Kept: the blocks whose samples and halo (parts of the 2x2x2 leaves from their own up) lie on
    // both sides of iso, told from the leaves' parts and, where no leaf is stored, from the
    // inside voxels.
    std::vector<uint8_t> keep(blocks.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, blocks.size(), 256), [&](const auto& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
            const Index3 c = unravel(blocks[i], nb);
            uint8_t both = 0;
            for (int d = 0; d < 8 && both != kBothSides; ++d) {
                const Index3 cell = {c[0] + (d & 1), c[1] + (d >> 1 & 1), c[2] + (d >> 2 & 1)};
                if (cell[0] < nb[0] && cell[1] < nb[1] && cell[2] < nb[2])
                    both |= part_sides(field, iso, sides, cell, d);
            }
            keep[i] = both == kBothSides;
        }
    });
    size_t kept = 0;
    for (size_t i = 0; i < blocks.size(); ++i)
        if (keep[i]) blocks[kept++] = blocks[i];
    blocks.resize(kept);
    return blocks;
}

class SparseMesher {
  public:
    SparseMesher(const SparseField& field, float iso, detail::MeshingMethod method, const char* who)
        : field_(field),
          n_(field.grid().dims),
          nb_(field.leaf_dims()),
          iso_(iso),
          nets_(method == detail::MeshingMethod::SurfaceNets),
          table_(nets_ ? nullptr : detail::marching_cubes_table().data()),
          who_(who) {}

    // Phase 2 and 3 for the candidates [first, last), all of one z. Blocks are independent, so
    // they are counted in parallel, each into its own slots.
    Slab count(const uint64_t* first, const uint64_t* last) {
        Slab slab;
        slab.bz = unravel(*first, nb_)[2];
        const size_t candidates = size_t(last - first);
        slab.keys.assign(first, last);
        slab.blocks.resize(candidates);
        slab.vertex_count.assign(candidates * kBlockSamples, 0);
        slab.triangle_offset.assign(candidates * kBlockSamples, 0);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, candidates, 4), [&](const auto& range) {
            for (size_t b = range.begin(); b != range.end(); ++b) {
                Block& block = slab.blocks[b];
                const Index3 c = unravel(slab.keys[b], nb_);
                block.origin = {c[0] * kBlock, c[1] * kBlock, c[2] * kBlock};
                for (int k = 0; k < 3; ++k) {
                    block.box_lo[k] = std::max<int64_t>(block.origin[k] - kBelow, 0);
                    block.box_hi[k] = std::min<int64_t>(block.origin[k] + kBlock + kAbove, n_[k]);
                }
                read_box(block);
                const detail::OmField local = local_field(block);
                uint32_t* vertices = &slab.vertex_count[b * kBlockSamples];
                uint32_t* triangles = &slab.triangle_offset[b * kBlockSamples];
                for_each_changing_sample(block, [&](int64_t x, int64_t y, int64_t z) {
                    const size_t s = slot_in_block(block.origin, x, y, z);
                    const int lx = int(x - block.box_lo[0]), ly = int(y - block.box_lo[1]),
                              lz = int(z - block.box_lo[2]);
                    if (nets_)
                        detail::om_sn_count(block.box.data(), local, lx, ly, lz, &vertices[s],
                                            &triangles[s]);
                    else
                        detail::om_mc_count(block.box.data(), table_, local, lx, ly, lz,
                                            &vertices[s], &triangles[s]);
                    if (vertices[s] || triangles[s]) block.owners.push_back(uint16_t(s));
                });
            }
        });
        // Only the blocks that own something stay.
        size_t kept = 0;
        for (size_t b = 0; b < candidates; ++b) {
            if (slab.blocks[b].owners.empty()) continue;
            if (kept != b) {
                slab.blocks[kept] = std::move(slab.blocks[b]);
                slab.keys[kept] = slab.keys[b];
                std::copy_n(&slab.vertex_count[b * kBlockSamples], kBlockSamples,
                            &slab.vertex_count[kept * kBlockSamples]);
                std::copy_n(&slab.triangle_offset[b * kBlockSamples], kBlockSamples,
                            &slab.triangle_offset[kept * kBlockSamples]);
            }
            ++kept;
        }
        slab.blocks.resize(kept);
        slab.keys.resize(kept);
        slab.vertex_count.resize(kept * kBlockSamples);
        slab.triangle_offset.resize(kept * kBlockSamples);
        scan(slab);
        return slab;
    }

    // Phase 4: the slab's vertices and triangles into the mesh; `below` and `above` are the
    // slabs one block below and above it, or null. Blocks write disjoint parts of the mesh, so
    // they are emitted in parallel.
    void emit(const Slab& slab, const Slab* below, const Slab* above, Mesh& mesh) const {
        std::vector<uint32_t> vertex_sample(slab.end_vertex - slab.first_vertex);
        std::vector<float> vertex_local(3 * vertex_sample.size());
        mesh.positions.resize(slab.end_vertex);
        // The slab's triangles are written where they stay: a triangle is three uint32_t.
        static_assert(sizeof(std::array<uint32_t, 3>) == 3 * sizeof(uint32_t));
        mesh.triangles.resize(slab.end_triangle);
        uint32_t* const triangles =
            reinterpret_cast<uint32_t*>(mesh.triangles.data() + slab.first_triangle);
        struct BoxOffsets {
            std::vector<uint32_t> vertex, triangle;
        };
        tbb::enumerable_thread_specific<BoxOffsets> scratch;
        tbb::parallel_for(
            tbb::blocked_range<size_t>(0, slab.blocks.size(), 4), [&](const auto& range) {
                BoxOffsets& box = scratch.local();
                for (size_t b = range.begin(); b != range.end(); ++b) {
                    const Block& block = slab.blocks[b];
                    // The global offsets of the box's samples that own something (the only ones
                    // read); one brick covers the box, so a slot in it is the sample's index in
                    // the box.
                    box.vertex.resize(std::max(box.vertex.size(), block.box.size()));
                    box.triangle.resize(box.vertex.size());
                    for (const Slab* from : {nets_ ? below : above, &slab})
                        if (from) copy_offsets(*from, block, box.vertex, box.triangle);
                    const detail::OmField local = local_field(block);
                    detail::OmTiling tiling{};
                    tiling.size = std::max({local.n[0], local.n[1], local.n[2]});
                    tiling.count[0] = tiling.count[1] = tiling.count[2] = 1;
                    const uint32_t box_base[1] = {0};
                    for (const uint16_t owner : block.owners) {
                        const int64_t x = block.origin[0] + owner % kBlock,
                                      y = block.origin[1] + owner / kBlock % kBlock,
                                      z = block.origin[2] + owner / (kBlock * kBlock);
                        const int lx = int(x - block.box_lo[0]), ly = int(y - block.box_lo[1]),
                                  lz = int(z - block.box_lo[2]);
                        if (nets_)
                            detail::om_sn_emit(block.box.data(), local, lx, ly, lz, tiling,
                                               box_base, box.vertex.data(), box.triangle.data(),
                                               slab.first_vertex, slab.first_triangle,
                                               vertex_sample.data(), vertex_local.data(),
                                               triangles);
                        else
                            detail::om_mc_emit(block.box.data(), table_, local, lx, ly, lz, tiling,
                                               box_base, box.vertex.data(), box.triangle.data(),
                                               slab.first_vertex, slab.first_triangle,
                                               vertex_sample.data(), vertex_local.data(),
                                               triangles);
                        // The sample's vertex records as world positions.
                        const size_t s = b * kBlockSamples + owner;
                        const uint32_t first = slab.vertex_offset[s];
                        for (uint32_t v = first; v < first + slab.vertex_count[s]; ++v)
                            mesh.positions[v] = detail::vertex_position(
                                field_.grid(), {uint64_t(x), uint64_t(y), uint64_t(z)},
                                &vertex_local[3 * size_t(v - slab.first_vertex)]);
                    }
                }
            });
    }

  private:
    // Calls f(x, y, z) for the block's samples whose cell corners are not all on one side of iso:
    // the others own nothing (their edges are edges of that cell, or do not exist), and they are
    // most of a block. The corners' sides are packed a bit per x in a row per (y, z), so a row of
    // cells is tested at once. Corners beyond the grid repeat the last sample: they change
    // nothing, as edges and cells beyond the grid do not exist.
    template <typename F>
    void for_each_changing_sample(const Block& block, F f) const {
        const Index3 &o = block.origin, &lo = block.box_lo, &hi = block.box_hi;
        const int64_t wx = hi[0] - lo[0], wy = hi[1] - lo[1];
        auto row = [&](int64_t y, int64_t z) {  // box-local, clamped to the box
            y = std::min(y, wy - 1);
            z = std::min(z, hi[2] - lo[2] - 1);
            const float* values = &block.box[size_t(wx * (y + wy * z))];
            uint32_t bits = 0;
            for (int64_t x = 0; x < wx; ++x) bits |= uint32_t(values[x] < iso_) << x;
            return bits | ((bits >> (wx - 1)) & 1u) << wx;
        };
        const int64_t x0 = o[0] - lo[0], y0 = o[1] - lo[1], z0 = o[2] - lo[2];
        const int64_t ex = std::min<int64_t>(kBlock, n_[0] - o[0]),
                      ey = std::min<int64_t>(kBlock, n_[1] - o[1]),
                      ez = std::min<int64_t>(kBlock, n_[2] - o[2]);
        const uint32_t block_bits = ((1u << ex) - 1u) << x0;
        // Each row once: a row of cells takes four rows, and each row serves four rows of cells.
        uint32_t rows[kBlock + 1][kBlock + 1];
        for (int64_t z = 0; z <= ez; ++z)
            for (int64_t y = 0; y <= ey; ++y) rows[z][y] = row(y0 + y, z0 + z);
        for (int64_t z = z0; z < z0 + ez; ++z)
            for (int64_t y = y0; y < y0 + ey; ++y) {
                const uint32_t* below = rows[z - z0];
                const uint32_t* above = rows[z - z0 + 1];
                const uint32_t r00 = below[y - y0], r10 = below[y - y0 + 1], r01 = above[y - y0],
                               r11 = above[y - y0 + 1];
                const uint32_t all = r00 & r10 & r01 & r11, any = r00 | r10 | r01 | r11;
                uint32_t changing = ~((all & (all >> 1)) | ~(any | (any >> 1))) & block_bits;
                while (changing) {
                    const int x = __builtin_ctz(changing);
                    changing &= changing - 1;
                    f(lo[0] + x, lo[1] + y, lo[2] + z);
                }
            }
    }

    detail::OmField local_field(const Block& block) const {
        detail::OmField local{};
        for (int k = 0; k < 3; ++k) local.n[k] = int(block.box_hi[k] - block.box_lo[k]);
        local.iso = iso_;
        return local;
    }

    void read_box(Block& block) const {
        block.box.resize(
            size_t((block.box_hi[0] - block.box_lo[0]) * (block.box_hi[1] - block.box_lo[1]) *
                   (block.box_hi[2] - block.box_lo[2])));
        field_.copy_box(block.box_lo, block.box_hi, block.box.data());
    }

    // Phase 3: the slab's counts become offsets in global sample order (z, then y, then x over
    // the whole grid): layer by layer, each row of blocks row by row, and each row of samples
    // across the blocks. The walk in that order is over segments (a block's row of up to 8
    // samples at one y and z), whose sums are taken and whose samples are numbered in parallel.
    void scan(Slab& slab) {
        slab.first_vertex = uint32_t(vertices_);
        slab.first_triangle = uint32_t(triangles_);
        slab.vertex_offset.resize(slab.vertex_count.size());
        const int64_t z0 = slab.bz * kBlock;
        const int64_t ez = std::min<int64_t>(kBlock, n_[2] - z0);
        constexpr size_t kSegments = size_t(kBlock) * kBlock;  // per block, (ly, lz)
        auto extent = [&](const Block& block, int a) {
            return std::min<int64_t>(kBlock, n_[a] - block.origin[a]);
        };
        // Segment (ly, lz) of block b is [b * kBlockSamples + kBlock * (ly + kBlock * lz), + ex).
        std::vector<uint64_t> segment_vertices(slab.blocks.size() * kSegments),
            segment_triangles(segment_vertices.size());
        auto for_each_segment = [&](auto&& f) {
            tbb::parallel_for(
                tbb::blocked_range<size_t>(0, slab.blocks.size(), 16), [&](const auto& range) {
                    for (size_t b = range.begin(); b != range.end(); ++b) {
                        const Block& block = slab.blocks[b];
                        const int64_t ex = extent(block, 0), ey = extent(block, 1);
                        for (int64_t lz = 0; lz < ez; ++lz)
                            for (int64_t ly = 0; ly < ey; ++ly)
                                f(b * kSegments + size_t(ly + kBlock * lz),
                                  b * kBlockSamples + size_t(kBlock * (ly + kBlock * lz)), ex);
                    }
                });
        };
        for_each_segment([&](size_t segment, size_t s, int64_t ex) {
            uint64_t vertices = 0, triangles = 0;
            for (int64_t lx = 0; lx < ex; ++lx) {
                vertices += slab.vertex_count[s + lx];
                triangles += slab.triangle_offset[s + lx];
            }
            segment_vertices[segment] = vertices;
            segment_triangles[segment] = triangles;
        });
        // The segments in global order; their sums become their first offsets.
        for (int64_t lz = 0; lz < ez; ++lz)
            for (size_t row = 0; row < slab.blocks.size();) {
                size_t row_end = row;
                const int64_t y0 = slab.blocks[row].origin[1];
                while (row_end < slab.blocks.size() && slab.blocks[row_end].origin[1] == y0)
                    ++row_end;
                for (int64_t ly = 0; ly < std::min<int64_t>(kBlock, n_[1] - y0); ++ly)
                    for (size_t b = row; b < row_end; ++b) {
                        const size_t segment = b * kSegments + size_t(ly + kBlock * lz);
                        const uint64_t vertices = segment_vertices[segment];
                        const uint64_t triangles = segment_triangles[segment];
                        segment_vertices[segment] = vertices_;
                        segment_triangles[segment] = triangles_;
                        vertices_ += vertices;
                        triangles_ += triangles;
                    }
                row = row_end;
            }
        for_each_segment([&](size_t segment, size_t s, int64_t ex) {
            uint64_t vertex = segment_vertices[segment], triangle = segment_triangles[segment];
            for (int64_t lx = 0; lx < ex; ++lx) {
                slab.vertex_offset[s + lx] = uint32_t(vertex);
                vertex += slab.vertex_count[s + lx];
                const uint32_t triangles = slab.triangle_offset[s + lx];
                slab.triangle_offset[s + lx] = uint32_t(triangle);
                triangle += triangles;
            }
        });
        detail::check_mesh_indices(vertices_, "vertices");
        detail::check_mesh_indices(triangles_, "triangles");
        detail::check_meshing_memory(slab.vertex_count.size(), vertices_, triangles_, who_);
        slab.end_vertex = uint32_t(vertices_);
        slab.end_triangle = uint32_t(triangles_);
    }

    // The offsets of the owners of `from`'s blocks whose vertices `block`'s samples may use:
    // Surface Nets' quads join cells down to one sample below, Marching Cubes' triangles use
    // edges owned up to one sample above.
    void copy_offsets(const Slab& from, const Block& block, std::vector<uint32_t>& box_vertex,
                      std::vector<uint32_t>& box_triangle) const {
        const Index3& box = block.box_lo;
        const int64_t wx = block.box_hi[0] - box[0], wy = block.box_hi[1] - box[1];
        Index3 lo, hi;  // the samples whose offsets are used
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::max<int64_t>(block.origin[a] - (nets_ ? 1 : 0), 0);
            hi[a] = std::min<int64_t>(block.origin[a] + kBlock + (nets_ ? 0 : 1), n_[a]);
        }
        for (int64_t by = lo[1] / kBlock; by <= (hi[1] - 1) / kBlock; ++by)
            for (int64_t bx = lo[0] / kBlock; bx <= (hi[0] - 1) / kBlock; ++bx) {
                const uint64_t key = ravel({bx, by, from.bz}, nb_);
                const auto it = std::lower_bound(from.keys.begin(), from.keys.end(), key);
                if (it == from.keys.end() || *it != key) continue;
                const size_t b = size_t(it - from.keys.begin());
                const Index3& o = from.blocks[b].origin;
                for (const uint16_t owner : from.blocks[b].owners) {  // in z, y, x order
                    const int64_t x = o[0] + owner % kBlock, y = o[1] + owner / kBlock % kBlock,
                                  z = o[2] + owner / (kBlock * kBlock);
                    if (z >= hi[2]) break;
                    if (x < lo[0] || y < lo[1] || z < lo[2] || x >= hi[0] || y >= hi[1]) continue;
                    const size_t at =
                        size_t((x - box[0]) + wx * ((y - box[1]) + wy * (z - box[2])));
                    box_vertex[at] = from.vertex_offset[b * kBlockSamples + owner];
                    box_triangle[at] = from.triangle_offset[b * kBlockSamples + owner];
                }
            }
    }

    const SparseField& field_;
    const std::array<int64_t, 3> n_, nb_;
    const float iso_;
    const bool nets_;
    const uint8_t* table_;
    const char* who_;
    uint64_t vertices_ = 0, triangles_ = 0;
};

Mesh mesh_sparse(const SparseField& field, float iso, detail::MeshingMethod method,
                 const ProgressCallback& callback) {
    const char* who =
        method == detail::MeshingMethod::SurfaceNets ? "surface_nets" : "marching_cubes";
    if (!std::isfinite(iso)) throw InputError(std::string(who) + ": the iso value is not finite");
    detail::ProgressPhases progress(callback, who);
    const detail::MeshingPhases phases = detail::add_meshing_phases(progress);
    Mesh mesh;
    const auto& n = field.grid().dims;
    if (n[0] < 2 || n[1] < 2 || n[2] < 2) {  // no cells
        progress.finish();
        return mesh;
    }

    // Phase 1: candidates.
    const std::vector<uint64_t> candidates = candidate_blocks(field, iso, who);
    progress.report(phases.scan, 1, 1);

    // Room for the mesh, so that it does not grow by copies: a candidate block owns about 64
    // vertices and 128 triangles (bunny00 and buildings, either mesher); pages not written cost
    // nothing, and a mesh that needs more still grows.
    mesh.positions.reserve(candidates.size() * 80);
    mesh.triangles.reserve(candidates.size() * 160);

    // Phases 2 to 4, a slab at a time: slab i is emitted once slab i + 1 is counted.
    SparseMesher mesher(field, iso, method, who);
    const uint64_t per_slab = uint64_t(field.leaf_dims()[0]) * uint64_t(field.leaf_dims()[1]);
    const uint64_t* next = candidates.data();
    const uint64_t* end = next + candidates.size();
    auto count_next = [&]() -> std::optional<Slab> {
        if (next == end) return std::nullopt;
        const uint64_t* last = next;
        while (last != end && *last / per_slab == *next / per_slab) ++last;
        Slab slab = mesher.count(next, last);
        next = last;
        progress.report(phases.count, uint64_t(next - candidates.data()), candidates.size());
        return slab;
    };
    std::optional<Slab> below, current = count_next();
    while (current) {
        std::optional<Slab> following = count_next();
        mesher.emit(*current, below && below->bz + 1 == current->bz ? &*below : nullptr,
                    following && following->bz == current->bz + 1 ? &*following : nullptr, mesh);
        progress.report(phases.emit, uint64_t(next - candidates.data()), candidates.size());
        below = std::move(current);
        current = std::move(following);
    }
    progress.finish();
    return mesh;
}

}  // namespace

// Leaf layer by leaf layer (8 layers of samples): pass 1 takes each leaf's sides when its layers
// are in, pass 2 keeps a leaf once the leaf layer above it is in (its halo reaches that layer's
// low face), pass 3 copies the kept leaves' samples. So two leaf layers of samples are held: the
// one being filled and the one below it, still to be decided.
struct MeshingViewBuilder::Impl {
    // The sides of a leaf's samples and of its six faces (x = 0, x = 7, y = 0, ...; a face beyond
    // the grid has none).
    using LeafSides = std::array<uint8_t, 7>;

    Grid grid;
    float iso = 0, background = 0;
    Index3 nb{};  // leaves per axis
    size_t per_layer = 0, leaves_per_layer = 0;
    int64_t layers_in = 0;
    std::vector<float> below, filling;  // the leaf layers' samples, x fastest, 8 layers each
    std::vector<LeafSides> sides_before, sides_below;  // of the two leaf layers below `filling`
    SparseVoxels inside;
    std::vector<uint64_t> kept_keys;
    std::vector<float> kept_samples;

    Impl(const Grid& g, float iso_value) : grid(g), iso(iso_value), inside(g, kBlock) {
        validate_grid(g);
        if (!std::isfinite(iso)) throw InputError("meshing view: the iso value is not finite");
        // Every sample outside the leaves becomes a background beyond iso on its side, so only its
        // side (its inside voxel) is kept; a value must be kept wherever it is read as a value,
        // which is at the corners of cells with both sides (crossings, face deciders, centres).
        background = std::abs(iso) < FLT_MAX / 2 ? std::max(1.0f, 2.0f * std::abs(iso)) : FLT_MAX;
        const auto& n = g.dims;
        nb = {(n[0] + kBlock - 1) / kBlock, (n[1] + kBlock - 1) / kBlock,
              (n[2] + kBlock - 1) / kBlock};
        per_layer = size_t(n[0]) * size_t(n[1]);
        leaves_per_layer = size_t(nb[0]) * size_t(nb[1]);
        detail::check_host_memory(uint64_t(2 * kBlock) * per_layer * sizeof(float) +
                                      3 * leaves_per_layer * sizeof(LeafSides),
                                  detail::default_host_budget(),
                                  "the meshing view's 16 layers of " + std::to_string(n[0]) + "x" +
                                      std::to_string(n[1]) + " samples");
        below.resize(size_t(kBlock) * per_layer);
        filling.resize(size_t(kBlock) * per_layer);
    }

    void add_layer(const float* samples) {
        const auto& n = grid.dims;
        if (layers_in == n[2])
            throw GridError("meshing view: every one of the grid's " + std::to_string(n[2]) +
                            " layers was added already");
        std::copy_n(samples, per_layer, &filling[size_t(layers_in % kBlock) * per_layer]);
        ++layers_in;
        if (layers_in % kBlock != 0 && layers_in != n[2]) return;
        const int64_t lz = (layers_in - 1) / kBlock;
        std::vector<LeafSides> sides_filling = take_sides(lz);
        if (lz > 0) keep_leaves(lz - 1, below, sides_before, sides_below, &sides_filling);
        std::swap(below, filling);
        sides_before = std::move(sides_below);
        sides_below = std::move(sides_filling);
        if (layers_in == n[2]) keep_leaves(lz, below, sides_before, sides_below, nullptr);
    }

    // Pass 1 for the leaf layer lz, just filled: its samples' sides as inside voxels, and each
    // leaf's sides.
    std::vector<LeafSides> take_sides(int64_t lz) {
        const auto& n = grid.dims;
        const int64_t depth = std::min<int64_t>(kBlock, n[2] - lz * kBlock);
        std::vector<LeafSides> sides(leaves_per_layer);
        std::vector<std::array<uint64_t, 8>> words(leaves_per_layer);
        std::atomic<bool> finite{true};
        tbb::parallel_for(size_t(0), leaves_per_layer, [&](size_t l) {
            const int64_t ox = int64_t(l % size_t(nb[0])) * kBlock,
                          oy = int64_t(l / size_t(nb[0])) * kBlock;
            const int64_t ex = std::min<int64_t>(kBlock, n[0] - ox),
                          ey = std::min<int64_t>(kBlock, n[1] - oy);
            LeafSides part{};
            for (int64_t z = 0; z < depth; ++z)
                for (int64_t y = 0; y < ey; ++y) {
                    const float* row =
                        &filling[size_t(z) * per_layer + size_t(ox + n[0] * (oy + y))];
                    uint8_t row_sides = 0;
                    for (int64_t x = 0; x < ex; ++x) {
                        if (!std::isfinite(row[x])) finite = false;
                        const bool in = detail::om_inside(row[x], iso);
                        row_sides |= in ? kInsideSide : kOutsideSide;
                        if (in)
                            words[l][size_t(x / 4 + 2 * (y / 4 + 2 * (z / 4)))] |=
                                uint64_t(1) << (x % 4 + 4 * (y % 4 + 4 * (z % 4)));
                    }
                    part[0] |= row_sides;
                    part[1] |= side_of(row[0], iso);
                    if (ex == kBlock) part[2] |= side_of(row[kBlock - 1], iso);
                    if (y == 0) part[3] |= row_sides;
                    if (y == kBlock - 1) part[4] |= row_sides;
                    if (z == 0) part[5] |= row_sides;
                    if (z == kBlock - 1) part[6] |= row_sides;
                }
            sides[l] = part;
        });
        if (!finite)
            for (size_t s = 0; s < size_t(depth) * per_layer; ++s)
                if (!std::isfinite(filling[s]))
                    throw InputError("sample (" + std::to_string(s % size_t(n[0])) + ", " +
                                     std::to_string(s / size_t(n[0]) % size_t(n[1])) + ", " +
                                     std::to_string(lz * kBlock + int64_t(s / per_layer)) +
                                     ") of the field is not finite");
        for (size_t l = 0; l < leaves_per_layer; ++l)
            inside.merge_brick(uint64_t(lz) * leaves_per_layer + l, words[l].data());
        return sides;
    }

    // Passes 2 and 3 for the leaf layer lz: a leaf holds a corner of a cell on both sides iff its
    // samples with the one-sample halo lie on both sides; the halo is the facing face of each face
    // neighbour and (counted whole, which only keeps a few leaves more than needed) the edge and
    // corner neighbours. `before` is empty for the lowest leaf layer, `above` null for the top one.
    void keep_leaves(int64_t lz, const std::vector<float>& samples,
                     const std::vector<LeafSides>& before, const std::vector<LeafSides>& own,
                     const std::vector<LeafSides>* above) {
        const auto& n = grid.dims;
        std::vector<uint8_t> keep(leaves_per_layer, 0);
        tbb::parallel_for(size_t(0), leaves_per_layer, [&](size_t l) {
            const int64_t lx = int64_t(l % size_t(nb[0])), ly = int64_t(l / size_t(nb[0]));
            uint8_t both = own[l][0];
            for (int dz = -1; dz <= 1 && both != kBothSides; ++dz) {
                const std::vector<LeafSides>* layer = dz < 0 ? &before : dz > 0 ? above : &own;
                if (!layer || layer->empty()) continue;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int64_t mx = lx + dx, my = ly + dy;
                        if ((dx | dy | dz) == 0 || mx < 0 || my < 0 || mx >= nb[0] || my >= nb[1])
                            continue;
                        const LeafSides& s = (*layer)[size_t(mx + nb[0] * my)];
                        const int axes = (dx != 0) + (dy != 0) + (dz != 0);
                        if (axes > 1)
                            both |= s[0];
                        else if (dx)
                            both |= s[dx > 0 ? 1 : 2];  // its x = 0 face, or its x = 7 face
                        else if (dy)
                            both |= s[dy > 0 ? 3 : 4];
                        else
                            both |= s[dz > 0 ? 5 : 6];
                    }
            }
            keep[l] = both == kBothSides;
        });
        std::vector<size_t> kept;
        for (size_t l = 0; l < leaves_per_layer; ++l)
            if (keep[l]) kept.push_back(l);
        const size_t first = kept_keys.size();
        // Twice: finish() copies them into the view.
        detail::check_host_memory(
            2 * (first + kept.size()) * kBlockSamples * sizeof(float),
            detail::default_host_budget(),
            "the meshing view's " + std::to_string(first + kept.size()) + " leaves");
        kept_samples.resize((first + kept.size()) * kBlockSamples, background);
        const int64_t depth = std::min<int64_t>(kBlock, n[2] - lz * kBlock);
        tbb::parallel_for(size_t(0), kept.size(), [&](size_t k) {
            const int64_t ox = int64_t(kept[k] % size_t(nb[0])) * kBlock,
                          oy = int64_t(kept[k] / size_t(nb[0])) * kBlock;
            float* out = &kept_samples[(first + k) * kBlockSamples];
            for (int64_t z = 0; z < depth; ++z)
                for (int64_t y = oy; y < std::min(oy + kBlock, n[1]); ++y)
                    std::copy(&samples[size_t(z) * per_layer + size_t(ox + n[0] * y)],
                              &samples[size_t(z) * per_layer +
                                       size_t(std::min(ox + kBlock, n[0]) + n[0] * y)],
                              &out[size_t(kBlock * ((y - oy) + kBlock * z))]);
        });
        for (const size_t l : kept) kept_keys.push_back(uint64_t(lz) * leaves_per_layer + l);
    }

    SparseField finish() {
        if (layers_in != grid.dims[2])
            throw GridError("meshing view: " + std::to_string(layers_in) + " of the grid's " +
                            std::to_string(grid.dims[2]) + " layers were added");
        SparseField view(grid, double(background) / grid.voxel_size, std::move(inside));
        view.reserve_leaves(kept_keys.size());
        for (size_t k = 0; k < kept_keys.size(); ++k)
            view.append_leaf(kept_keys[k], &kept_samples[k * kBlockSamples]);
        return view;
    }
};

MeshingViewBuilder::MeshingViewBuilder(const Grid& grid, float iso)
    : impl_(std::make_unique<Impl>(grid, iso)) {}
MeshingViewBuilder::~MeshingViewBuilder() = default;
MeshingViewBuilder::MeshingViewBuilder(MeshingViewBuilder&&) noexcept = default;
MeshingViewBuilder& MeshingViewBuilder::operator=(MeshingViewBuilder&&) noexcept = default;

void MeshingViewBuilder::add_layer(const float* samples) {
    if (!impl_) throw GridError("meshing view: the builder has finished");
    impl_->add_layer(samples);
}

SparseField MeshingViewBuilder::finish() {
    if (!impl_) throw GridError("meshing view: the builder has finished");
    SparseField view = impl_->finish();
    impl_.reset();
    return view;
}

namespace detail {

SparseField meshing_view(const ScalarField& field, float iso, const char* who) {
    if (!std::isfinite(iso) || field.values.size() != field.grid.voxel_count() ||
        field.grid.voxel_count() > std::numeric_limits<uint32_t>::max())
        validate_field(field, iso, who);
    try {
        MeshingViewBuilder builder(field.grid, iso);
        const size_t per_layer = size_t(field.grid.dims[0]) * size_t(field.grid.dims[1]);
        for (int64_t k = 0; k < field.grid.dims[2]; ++k)
            builder.add_layer(&field.values[size_t(k) * per_layer]);
        return builder.finish();
    } catch (const InputError& e) {  // the caller's name on the builder's errors
        throw InputError(std::string(who) + ": " + e.what());
    } catch (const GridError& e) {
        throw GridError(std::string(who) + ": " + e.what());
    }
}

}  // namespace detail

Mesh surface_nets(const SparseField& field, float iso, const ProgressCallback& progress) {
    return mesh_sparse(field, iso, detail::MeshingMethod::SurfaceNets, progress);
}

Mesh marching_cubes(const SparseField& field, float iso, const ProgressCallback& progress) {
    return mesh_sparse(field, iso, detail::MeshingMethod::MarchingCubes, progress);
}

Mesh surface_nets(const ScalarField& field, float iso, const ProgressCallback& progress) {
    return surface_nets(detail::meshing_view(field, iso, "surface_nets"), iso, progress);
}

Mesh marching_cubes(const ScalarField& field, float iso, const ProgressCallback& progress) {
    return marching_cubes(detail::meshing_view(field, iso, "marching_cubes"), iso, progress);
}

}  // namespace oclvox
