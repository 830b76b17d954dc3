// Solid voxelization by the generalized winding number: a bounding-ball tree over the triangles
// (Barill et al. 2018, second order); then, from coarse tiles of the mesh's bounding box down to
// voxels, w at the centres of the tiles the surface does not touch, each deciding its whole tile
// when the bound on how much w can change inside it allows (see winding_device). The host
// reference sums every triangle exactly, in double, at every voxel.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <memory>
#include <type_traits>

#include "bit_count.hpp"
#include "device_batches.hpp"
#include "position_numbering.hpp"
#include "solid_internal.hpp"
#include "winding_fans.hpp"
#include "winding_tree.hpp"

namespace oclvox::detail {

namespace {

// The host reference winding number refuses more triangle evaluations than this.
constexpr uint64_t kMaxReferenceWindingTerms = uint64_t(1) << 34;

// Voxels whose centres lie in the mesh's bounding box, per axis (empty if lo > hi). Outside it
// the winding number of a closed mesh is 0; for open meshes oclvox defines the solid to stay
// within the bounding box.
struct VoxelBox {
    int64_t lo[3], hi[3];
    bool empty() const { return lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]; }
};

VoxelBox centre_box(const Mesh& mesh, const Grid& grid) {
    VoxelBox box;
    for (int k = 0; k < 3; ++k) {
        double mn = INFINITY, mx = -INFINITY;
        for (const auto& tri : mesh.triangles)
            for (uint32_t v : tri) {
                const double g = (mesh.positions[v][k] - grid.origin[k]) / grid.voxel_size;
                mn = std::min(mn, g);
                mx = std::max(mx, g);
            }
        box.lo[k] = std::max<int64_t>(0, int64_t(std::ceil(std::max(mn - 0.5, -1.0))));
        box.hi[k] = std::min<int64_t>(
            grid.dims[k] - 1, int64_t(std::floor(std::min(mx - 0.5, double(grid.dims[k])))));
    }
    return box;
}

// `lists` appended to `out` in their order, each copied by one thread to the place the sizes
// before it give. Joined one after another they were a serial pass over tens of megabytes of
// fresh pages, a fifth of a phase on 16 cores.
template <typename Vector, typename List>
void append_in_parallel(Vector& out, const std::vector<const List*>& lists) {
    std::vector<size_t> at(lists.size() + 1, out.size());
    for (size_t i = 0; i < lists.size(); ++i) at[i + 1] = at[i] + lists[i]->size();
    out.resize(at.back());
    tbb::parallel_for(size_t(0), lists.size(), [&](size_t i) {
        std::copy(lists[i]->begin(), lists[i]->end(), out.begin() + ptrdiff_t(at[i]));
    });
}

// The lists of every thread, for append_in_parallel.
template <typename List>
std::vector<const List*> thread_lists(const tbb::enumerable_thread_specific<List>& lists) {
    std::vector<const List*> out;
    for (const List& list : lists) out.push_back(&list);
    return out;
}

// One bit per cell of a dense box of cells, x fastest.
class BoxBits {
  public:
    BoxBits(int64_t nx, int64_t ny, int64_t nz)
        : n_{nx, ny, nz}, words_((uint64_t(nx) * uint64_t(ny) * uint64_t(nz) + 63) / 64) {}
    int64_t dim(int k) const { return n_[k]; }
    bool get(uint64_t i) const { return words_[i >> 6] >> (i & 63) & 1; }
    void set(uint64_t i) { words_[i >> 6] |= uint64_t(1) << (i & 63); }
    // set(i) where other threads may set cells of the same word at the same time.
    void set_concurrently(uint64_t i) {
        __atomic_fetch_or(&words_[i >> 6], uint64_t(1) << (i & 63), __ATOMIC_RELAXED);
    }
    bool get(int64_t x, int64_t y, int64_t z) const { return get(index(x, y, z)); }
    void set(int64_t x, int64_t y, int64_t z) { set(index(x, y, z)); }
    // Cells [64 w, 64 w + 64) as one word, the first cell in the lowest bit.
    size_t word_count() const { return words_.size(); }
    void set_word(size_t w, uint64_t bits) { words_[w] = bits; }
    // The cells of this box grouped into 2x2x2 parents: a parent is set if any child is. Visits
    // the set cells only (these boxes hold surfaces, a few percent of their cells), in parallel.
    BoxBits coarser() const {
        BoxBits up((n_[0] + 1) / 2, (n_[1] + 1) / 2, (n_[2] + 1) / 2);
        const uint64_t nx = uint64_t(n_[0]), ny = uint64_t(n_[1]);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, words_.size(), 4096), [&](const auto& r) {
            for (size_t w = r.begin(); w != r.end(); ++w)
                for (uint64_t bits = words_[w]; bits; bits &= bits - 1) {
                    const uint64_t i = uint64_t(w) * 64 + uint64_t(__builtin_ctzll(bits));
                    up.set_concurrently(up.index(int64_t(i % nx / 2), int64_t(i / nx % ny / 2),
                                                 int64_t(i / nx / ny / 2)));
                }
        });
        return up;
    }
    // Cells [first, first + count) in index order as the low bits of a word; count in [1, 64].
    uint64_t bits_at(uint64_t first, int count) const {
        const uint64_t word = first >> 6;
        const int shift = int(first & 63);
        uint64_t bits = words_[word] >> shift;
        if (shift + count > 64) bits |= words_[word + 1] << (64 - shift);
        return count == 64 ? bits : bits & ((uint64_t(1) << count) - 1);
    }

    uint64_t index(int64_t x, int64_t y, int64_t z) const {
        return uint64_t(x) + uint64_t(n_[0]) * (uint64_t(y) + uint64_t(n_[1]) * uint64_t(z));
    }

    // Prepares rank(); call it after the last set().
    void index_ranks() {
        ranks_.assign(words_.size() + 1, 0);
        for (size_t w = 0; w < words_.size(); ++w)
            ranks_[w + 1] = ranks_[w] + uint64_t(popcount64(words_[w]));
    }
    // The number of set cells before cell i.
    uint64_t rank(uint64_t i) const {
        const uint64_t below = words_[i >> 6] & ((uint64_t(1) << (i & 63)) - 1);
        return ranks_[i >> 6] + uint64_t(popcount64(below));
    }

  private:
    int64_t n_[3];
    std::vector<uint64_t> words_;
    std::vector<uint64_t> ranks_;  // set cells before each word
};

// The voxels of the box (box-relative) whose closed boxes the surface touches, and the triangles
// touching each, by the double-precision overlap test.
struct SurfaceVoxels {
    BoxBits bits;
    FilledLaterVector<std::pair<uint64_t, uint32_t>> voxel_triangle;  // sorted by voxel index
    // The pairs of the k-th set voxel (in index order) are [first_pair[k], first_pair[k + 1]).
    FilledLaterVector<size_t> first_pair;

    // The pairs of voxel i, as a range of voxel_triangle: a lookup, not a search.
    std::pair<size_t, size_t> pairs_of(uint64_t i) const {
        if (!bits.get(i)) return {0, 0};
        const uint64_t k = bits.rank(i);
        return {first_pair[k], first_pair[k + 1]};
    }
};

// Marks the voxels of [lo, hi] (box-relative, inclusive) that triangle t touches, recursing from
// the triangle's voxel range into halves.
void mark_surface(const std::array<double, 9>& t, uint32_t id, const VoxelBox& box,
                  const BoxBits& cells, const int64_t* lo, const int64_t* hi,
                  std::vector<std::pair<uint64_t, uint32_t>>& out) {
    // A small range is tested voxel by voxel: halving it would test about as many larger boxes
    // again on the way down.
    constexpr int64_t kDirectVoxels = 64;
    if ((hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1) <= kDirectVoxels) {
        const Vec3d a{t[0], t[1], t[2]}, b{t[3], t[4], t[5]}, c{t[6], t[7], t[8]};
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
            for (int64_t y = lo[1]; y <= hi[1]; ++y)
                for (int64_t x = lo[0]; x <= hi[0]; ++x) {
                    const Vec3d voxel_lo{double(box.lo[0] + x), double(box.lo[1] + y),
                                         double(box.lo[2] + z)};
                    const Vec3d voxel_hi{voxel_lo[0] + 1, voxel_lo[1] + 1, voxel_lo[2] + 1};
                    if (triangle_box_overlap_double(a, b, c, voxel_lo, voxel_hi))
                        out.push_back({cells.index(x, y, z), id});
                }
        return;
    }
    Vec3d box_lo, box_hi;
    for (int k = 0; k < 3; ++k) {
        box_lo[k] = double(box.lo[k] + lo[k]);
        box_hi[k] = double(box.lo[k] + hi[k] + 1);
    }
    if (!triangle_box_overlap_double({t[0], t[1], t[2]}, {t[3], t[4], t[5]}, {t[6], t[7], t[8]},
                                     box_lo, box_hi))
        return;
    int axis = 0;
    for (int k = 1; k < 3; ++k)
        if (hi[k] - lo[k] > hi[axis] - lo[axis]) axis = k;
    if (hi[axis] == lo[axis]) {
        out.push_back({cells.index(lo[0], lo[1], lo[2]), id});
        return;
    }
    const int64_t mid = lo[axis] + (hi[axis] - lo[axis]) / 2;
    int64_t split_hi[3] = {hi[0], hi[1], hi[2]}, split_lo[3] = {lo[0], lo[1], lo[2]};
    split_hi[axis] = mid;
    split_lo[axis] = mid + 1;
    mark_surface(t, id, box, cells, lo, split_hi, out);
    mark_surface(t, id, box, cells, split_lo, hi, out);
}

SurfaceVoxels surface_voxels(const std::vector<std::array<double, 9>>& tri, const VoxelBox& box) {
    SurfaceVoxels out{
        BoxBits(box.hi[0] - box.lo[0] + 1, box.hi[1] - box.lo[1] + 1, box.hi[2] - box.lo[2] + 1),
        {},
        {}};
    // Triangles are independent, so they are marked in parallel, each thread into a list of its
    // own; sorting the pairs afterwards makes the result the same for any number of threads.
    tbb::enumerable_thread_specific<std::vector<std::pair<uint64_t, uint32_t>>> lists;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tri.size(), 64), [&](const auto& range) {
        auto& list = lists.local();
        for (size_t i = range.begin(); i != range.end(); ++i) {
            const auto& t = tri[i];
            int64_t lo[3], hi[3];
            bool empty = false;
            for (int k = 0; k < 3; ++k) {
                const double mn = std::min({t[k], t[3 + k], t[6 + k]});
                const double mx = std::max({t[k], t[3 + k], t[6 + k]});
                // Voxel i's closed box [i, i + 1] holds x for i from ceil(x) - 1 to floor(x);
                // clamped first so huge coordinates stay exact.
                const double below = double(box.lo[k]) - 2, above = double(box.hi[k]) + 2;
                lo[k] = std::max<int64_t>(
                    0, int64_t(std::ceil(std::clamp(mn, below, above))) - 1 - box.lo[k]);
                hi[k] = std::min<int64_t>(
                    out.bits.dim(k) - 1,
                    int64_t(std::floor(std::clamp(mx, below, above))) - box.lo[k]);
                empty = empty || lo[k] > hi[k];
            }
            if (!empty) mark_surface(t, uint32_t(i), box, out.bits, lo, hi, list);
        }
    });
    append_in_parallel(out.voxel_triangle, thread_lists(lists));
    tbb::parallel_sort(out.voxel_triangle.begin(), out.voxel_triangle.end());
    // Each voxel's first pair, in parallel: chunks of pairs count the voxels starting in them,
    // then each writes its own from where the counts before it end.
    const auto& pairs = out.voxel_triangle;
    auto starts_voxel = [&](size_t p) { return p == 0 || pairs[p].first != pairs[p - 1].first; };
    constexpr size_t kPairsPerChunk = size_t(1) << 16;
    const size_t chunks = (pairs.size() + kPairsPerChunk - 1) / kPairsPerChunk;
    std::vector<size_t> first_voxel(chunks + 1, 0);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        for (size_t p = c * kPairsPerChunk; p < std::min(pairs.size(), (c + 1) * kPairsPerChunk);
             ++p)
            first_voxel[c + 1] += starts_voxel(p);
    });
    for (size_t c = 0; c < chunks; ++c) first_voxel[c + 1] += first_voxel[c];
    out.first_pair.resize(first_voxel.back() + 1);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        size_t voxel = first_voxel[c];
        for (size_t p = c * kPairsPerChunk; p < std::min(pairs.size(), (c + 1) * kPairsPerChunk);
             ++p)
            if (starts_voxel(p)) {
                out.bits.set_concurrently(pairs[p].first);
                out.first_pair[voxel++] = p;
            }
    });
    out.first_pair.back() = pairs.size();
    out.bits.index_ranks();
    return out;
}

// Whether triangle t may meet the segment from p to p + 1 along `axis`: false only when it
// certainly does not (double precision with a margin far above its rounding; a triangle
// parallel to the segment counts as meeting it).
bool may_cross(const std::array<double, 9>& t, const Vec3d& p, int axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    double x[3], y[3], z[3];
    for (int i = 0; i < 3; ++i) {
        x[i] = t[3 * i + u] - p[u];
        y[i] = t[3 * i + v] - p[v];
        z[i] = t[3 * i + axis] - p[axis];
    }
    double e[3], scale = 0;
    for (int i = 0; i < 3; ++i) {
        const int a = (i + 1) % 3, b = (i + 2) % 3;
        e[i] = x[a] * y[b] - y[a] * x[b];
        scale = std::max(scale, std::fabs(x[a] * y[b]) + std::fabs(y[a] * x[b]));
    }
    const double tol = 1e-12 * scale;
    const bool all_up = e[0] >= -tol && e[1] >= -tol && e[2] >= -tol;
    const bool all_down = e[0] <= tol && e[1] <= tol && e[2] <= tol;
    if (!all_up && !all_down) return false;
    const double area = e[0] + e[1] + e[2];
    if (std::fabs(area) <= 4 * tol) return true;
    const double h = (e[0] * z[0] + e[1] * z[1] + e[2] * z[2]) / area;
    return h >= -1e-9 && h <= 1 + 1e-9;
}

// Voxels of the box, and bricks of `result` meeting it (all of which the result may hold).
uint64_t box_voxels(const VoxelBox& box) {
    uint64_t voxels = 1;
    for (int k = 0; k < 3; ++k) voxels *= uint64_t(box.hi[k] - box.lo[k] + 1);
    return voxels;
}
uint64_t box_bricks(const SparseVoxels& result, const VoxelBox& box) {
    const int64_t b = result.brick_size();
    uint64_t bricks = 1;
    for (int k = 0; k < 3; ++k) bricks *= uint64_t(box.hi[k] / b - box.lo[k] / b + 1);
    return bricks;
}

// Tiles of the winding solid: cubes of 2^level voxels aligned to the box's low corner, clipped
// to the box. Tiles of the first level hold 2^kTopLevel voxels per axis; tiles are evaluated down
// to kFinestTileLevel (below it, a near-surface tile's centre costs about as much as its voxels).
constexpr int kTopLevel = 5;
constexpr int kFinestTileLevel = 3;
// Tile evaluations accept a subtree only when its expansion error bound is at most this (in
// units of w); the sum of the accepted bounds is the tile's certified error.
constexpr float kTileNodeTolerance = 1e-2f;
// Slack for float rounding in a tile's w (a few hundred terms of relative error 2^-24 or so).
constexpr double kTileRounding = 1e-3;
// Rounds of seeds for the pockets the flood cannot reach (phase 3); few pockets need a second.
constexpr int kSeedRounds = 4;

struct Tile {
    int64_t lo[3], hi[3];  // box-relative voxel range, inclusive
};

}  // namespace

EdgeUses edge_uses(const Mesh& mesh, const std::vector<uint32_t>& welded, size_t vertices) {
    // Every triangle's edges, bucketed by their lower end (a counting sort: linear, where sorting
    // all edges was most of the closed-mesh check), then each bucket (a few edges) sorted, in
    // parallel.
    auto for_each_edge = [&](auto&& f) {
        for (const auto& tri : mesh.triangles) {
            const uint32_t v[3] = {welded[tri[0]], welded[tri[1]], welded[tri[2]]};
            if (v[0] == v[1] || v[1] == v[2] || v[2] == v[0]) continue;
            for (int e = 0; e < 3; ++e) f(v[e], v[(e + 1) % 3]);
        }
    };
    EdgeUses out;
    out.first.assign(vertices + 1, 0);
    for_each_edge([&](uint32_t a, uint32_t b) { ++out.first[std::min(a, b) + size_t(1)]; });
    for (size_t v = 1; v <= vertices; ++v) out.first[v] += out.first[v - 1];
    out.upper.resize(out.first.back());
    std::vector<size_t> next(out.first.begin(), out.first.end() - 1);
    for_each_edge([&](uint32_t a, uint32_t b) {
        out.upper[next[std::min(a, b)]++] = uint64_t(std::max(a, b)) << 1 | uint64_t(a < b ? 0 : 1);
    });
    tbb::parallel_for(size_t(0), vertices, [&](size_t v) {
        std::sort(out.upper.begin() + ptrdiff_t(out.first[v]),
                  out.upper.begin() + ptrdiff_t(out.first[v + 1]));
    });
    return out;
}

WeldedEdges weld_edges(const Mesh& mesh) {
    // Phase 1: equal positions numbered alike, in the order their first vertex comes.
    NumberedPositions numbered = number_positions(mesh.positions);
    WeldedEdges out;
    out.positions = std::move(numbered.positions);

    // Phase 2: the edge uses by lower end, sorted; then per bucket its count of distinct edges,
    // and every edge's uses written to its place (buckets in parallel). Edges come out ordered by
    // (lower, upper) end.
    const size_t vertices = out.positions.size();
    const EdgeUses uses = edge_uses(mesh, numbered.numbers, vertices);
    std::vector<size_t> first_use(vertices + 1, 0);
    tbb::parallel_for(size_t(0), vertices, [&](size_t v) {
        for (size_t e = uses.first[v]; e < uses.first[v + 1]; ++e)
            if (e == uses.first[v] || uses.upper[e] >> 1 != uses.upper[e - 1] >> 1)
                ++first_use[v + 1];
    });
    for (size_t v = 0; v < vertices; ++v) first_use[v + 1] += first_use[v];
    out.uses.resize(first_use.back());
    tbb::parallel_for(size_t(0), vertices, [&](size_t v) {
        size_t use = first_use[v];
        for (size_t e = uses.first[v]; e < uses.first[v + 1]; ++e) {
            const uint32_t b = uint32_t(uses.upper[e] >> 1);
            if (e == uses.first[v] || b != uint32_t(uses.upper[e - 1] >> 1))
                out.uses[use++] = {{uint32_t(v), b}, {0, 0}};
            ++out.uses[use - 1].second[size_t(uses.upper[e] & 1)];
        }
    });
    return out;
}

// The winding-number solid on the device, with tree evaluations only where they can matter.
// w = n + w_fans (BoundaryFans), where the integer n changes only across the mesh or a fan.
// Phases:
// 1. the tree over the triangles, the fans over the holes, and the voxels of the box that the
//    mesh or a fan touches (with a pyramid of coarser tiles over them);
// 2. per level, from the first level's tiles down to kFinestTileLevel: a tile that neither the
//    mesh nor a fan touches takes n from w (tree, certified error) minus w_fans (double) at its
//    centre; if the fans' w is certainly below 1/2 over the tile, n decides it (inside iff
//    n != 0); any other tile splits;
// 3. the voxels of undecided tiles take n from a neighbour across the segment between their
//    centres when no triangle of the mesh or a fan meets it (a flood from the decided tiles,
//    then from seeds in the pockets it cannot reach, each seed's n from one tree evaluation);
//    each decides |n + w_fans| > 1/2, with w_fans in double where its bound does not settle it;
// 4. the voxels still without n take |w| > 1/2 at their centres from the tree;
// 5. the inside bits into bricks.
void winding_device(Device::Impl& cl, const Mesh& mesh, SparseVoxels& result,
                    const VoxelizeOptions& options, VoxelizeStats& stats) {
    auto t = Clock::now();
    const Grid& grid = result.grid();
    const VoxelBox box = centre_box(mesh, grid);
    if (box.empty()) return;
    const int b = result.brick_size();
    const auto nb = result.brick_dims();
    // The box is held densely: a state byte per voxel, and bits for the inside, the surface, the
    // fans, their coarser pyramids and the flood's marks (under five eighths of a byte per voxel).
    const uint64_t voxels = box_voxels(box);
    check_solid_memory(
        result, box_bricks(result, box), voxels + voxels / 2 + voxels / 8, options,
        " and the winding number's dense state for " + std::to_string(voxels) + " voxels");
    std::vector<uint64_t> bricks;  // every brick meeting the box
    for (int64_t bz = box.lo[2] / b; bz <= box.hi[2] / b; ++bz)
        for (int64_t by = box.lo[1] / b; by <= box.hi[1] / b; ++by)
            for (int64_t bx = box.lo[0] / b; bx <= box.hi[0] / b; ++bx)
                bricks.push_back(uint64_t(bx) +
                                 uint64_t(nb[0]) * (uint64_t(by) + uint64_t(nb[1]) * uint64_t(bz)));
    stats.bricks_active = bricks.size();
    constexpr int kSteps = 4;  // progress: tiles, flood, voxels, bricks

    // Phase 1.
    auto tri = grid_triangles(mesh, grid);
    const WindingTree tree = build_winding_tree(tri);
    const BoundaryFans fans = boundary_fans(mesh, grid);
    const size_t first_fan = tri.size();
    tri.insert(tri.end(), fans.triangles.begin(), fans.triangles.end());
    const SurfaceVoxels surface = surface_voxels(tri, box);
    // The fans' voxels: those of the fan triangles' pairs (each triangle is marked on its own).
    BoxBits fan_pyramid(surface.bits.dim(0), surface.bits.dim(1), surface.bits.dim(2));
    tbb::parallel_for(tbb::blocked_range<size_t>(0, surface.voxel_triangle.size(), 4096),
                      [&](const auto& r) {
                          for (size_t p = r.begin(); p != r.end(); ++p)
                              if (surface.voxel_triangle[p].second >= first_fan)
                                  fan_pyramid.set_concurrently(surface.voxel_triangle[p].first);
                      });
    for (int level = 0; level < kFinestTileLevel; ++level) fan_pyramid = fan_pyramid.coarser();
    std::vector<BoxBits> pyramid{surface.bits.coarser()};
    while (int(pyramid.size()) < kTopLevel) pyramid.push_back(pyramid.back().coarser());
    stats.seconds_binning += seconds_since(t);
    WindingEvaluator evaluator(cl, tree, stats);
    const int64_t n[3] = {surface.bits.dim(0), surface.bits.dim(1), surface.bits.dim(2)};
    auto centre_of = [&](const Tile& tile) {
        Vec3d c;
        for (int k = 0; k < 3; ++k)
            c[k] = double(box.lo[k]) + (tile.lo[k] + tile.hi[k]) / 2.0 + 0.5;
        return c;
    };
    // The centre of the box-relative voxel v.
    auto centre_of_voxel = [&](const int64_t* v) {
        return Vec3d{double(box.lo[0] + v[0]) + 0.5, double(box.lo[1] + v[1]) + 0.5,
                     double(box.lo[2] + v[2]) + 0.5};
    };

    // The farthest a voxel centre of the tile lies from the tile's centre.
    auto tile_reach = [](const Tile& tile) {
        double reach2 = 0;
        for (int k = 0; k < 3; ++k)
            reach2 += double(tile.hi[k] - tile.lo[k]) * double(tile.hi[k] - tile.lo[k]) / 4;
        return std::sqrt(reach2);
    };

    // Phase 2. Per voxel: kUnknown, or n + kZero (n in [-kZero, kZero]). The inside bits are
    // taken from the states once phase 3 has classified them, a word at a time in parallel.
    constexpr uint8_t kUnknown = 0xFF, kZero = 0x7F;
    BoxBits inside(n[0], n[1], n[2]);
    const size_t state_size = size_t(n[0] * n[1] * n[2]);
    // Filled in parallel: its first touch of a hundred megabytes is no single thread's work.
    const std::unique_ptr<uint8_t[]> state_storage(new uint8_t[state_size]);
    uint8_t* const state = state_storage.get();
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, state_size, size_t(1) << 20),
        [&](const auto& r) { std::fill(state + r.begin(), state + r.end(), kUnknown); });
    std::vector<Tile> pending;
    const BoxBits& top = pyramid[kTopLevel - 1];
    for (int64_t z = 0; z < top.dim(2); ++z)
        for (int64_t y = 0; y < top.dim(1); ++y)
            for (int64_t x = 0; x < top.dim(0); ++x) {
                const int64_t at[3] = {x, y, z};
                Tile tile;
                for (int k = 0; k < 3; ++k) {
                    tile.lo[k] = at[k] << kTopLevel;
                    tile.hi[k] = std::min(tile.lo[k] + (int64_t(1) << kTopLevel), n[k]) - 1;
                }
                pending.push_back(tile);
            }
    // n + kZero at a point from the tree's w there and its error bound, where n is certain,
    // else kUnknown. The fans' w is estimated, unless the estimate's error leaves open what their
    // exact sum would decide: then it is that sum (so the decision is always the exact sum's).
    auto certain_state = [&](float w_tree, float w_error, const Vec3d& centre) {
        const double spread = double(w_error) + kTileRounding;
        BoundaryFans::Estimate fan{0, 0};
        if (!fans.triangles.empty()) fan = fans.winding_estimate(centre);
        double cycle = double(w_tree) - fan.value, whole = std::round(cycle);
        bool certain = std::fabs(cycle - whole) + spread + fan.error < 0.5;
        if (!certain && std::fabs(cycle - whole) + spread - fan.error < 0.5) {
            cycle = double(w_tree) - fans.winding(centre);
            whole = std::round(cycle);
            certain = std::fabs(cycle - whole) + spread < 0.5;
        }
        return certain && std::fabs(whole) < kZero ? uint8_t(int(whole) + kZero) : kUnknown;
    };
    FilledLaterVector<float> points;
    std::vector<float> w, error;
    for (int level = kTopLevel; level >= kFinestTileLevel; --level) {
        std::vector<Tile> evaluated, children;
        auto split = [&](const Tile& tile) {
            const int64_t half = int64_t(1) << (level - 1);
            for (int c = 0; c < 8; ++c) {
                Tile child;
                bool empty = false;
                for (int k = 0; k < 3; ++k) {
                    const int64_t mid = tile.lo[k] + half;
                    child.lo[k] = (c >> k & 1) ? mid : tile.lo[k];
                    child.hi[k] = (c >> k & 1) ? tile.hi[k] : std::min(mid - 1, tile.hi[k]);
                    empty = empty || child.lo[k] > child.hi[k];
                }
                if (!empty) children.push_back(child);
            }
        };
        points.clear();
        for (const Tile& tile : pending) {
            if (pyramid[level - 1].get(tile.lo[0] >> level, tile.lo[1] >> level,
                                       tile.lo[2] >> level)) {
                split(tile);
                continue;
            }
            evaluated.push_back(tile);
            for (double c : centre_of(tile)) points.push_back(float(c));
        }
        evaluator.evaluate(points, OVS_WINDING_FAR, kTileNodeTolerance, w, error);
        // Each evaluated tile's n, where it is certain over the whole tile, else kUnknown (the
        // tile is split). The fans' sums are the cost, and tiles are independent: in parallel.
        std::vector<uint8_t> tile_state(evaluated.size());
        tbb::parallel_for(size_t(0), evaluated.size(), [&](size_t i) {
            const Tile& tile = evaluated[i];
            const Vec3d centre = centre_of(tile);
            const uint8_t n_state = certain_state(w[i], error[i], centre);
            tile_state[i] = n_state == kUnknown || (!fans.triangles.empty() &&
                                                    !(fans.bound(centre, tile_reach(tile)) < 0.5))
                                ? kUnknown
                                : n_state;
        });
        // Decided tiles fill their own voxels' states (disjoint, so in parallel); the others split.
        tbb::parallel_for(size_t(0), evaluated.size(), [&](size_t i) {
            const Tile& tile = evaluated[i];
            if (tile_state[i] == kUnknown) return;
            for (int64_t z = tile.lo[2]; z <= tile.hi[2]; ++z)
                for (int64_t y = tile.lo[1]; y <= tile.hi[1]; ++y)
                    std::fill_n(state + inside.index(tile.lo[0], y, z), tile.hi[0] - tile.lo[0] + 1,
                                tile_state[i]);
        });
        for (size_t i = 0; i < evaluated.size(); ++i)
            if (tile_state[i] == kUnknown) split(evaluated[i]);
        pending = std::move(children);
    }
    report_progress(options, bricks.size() / kSteps, bricks.size());

    // Phase 3. Voxels travel with their coordinates, so none is divided back out of an index.
    const uint64_t step[3] = {1, uint64_t(n[0]), uint64_t(n[0]) * uint64_t(n[1])};
    // Whether no triangle (mesh or fan) meets the segment from the centre of voxel i (at v) one
    // step up `axis`: any that does touches one of the two voxels.
    auto clear = [&](uint64_t i, const int64_t* v, int axis) {
        const Vec3d p = centre_of_voxel(v);
        for (uint64_t end : {i, i + step[axis]}) {
            const auto [first, last] = surface.pairs_of(end);
            for (size_t pair = first; pair < last; ++pair)
                if (may_cross(tri[surface.voxel_triangle[pair].second], p, axis)) return false;
        }
        return true;
    };
    // The state voxel i at v (without n) takes from a neighbour across a clear segment, or
    // kUnknown if none gives one.
    auto settled_state = [&](uint64_t i, const int64_t* v) {
        for (int axis = 0; axis < 3; ++axis)
            for (int dir = -1; dir <= 1; dir += 2) {
                if (v[axis] + dir < 0 || v[axis] + dir >= n[axis]) continue;
                const uint64_t j = dir > 0 ? i + step[axis] : i - step[axis];
                if (state[j] == kUnknown) continue;
                if (surface.bits.get(i) || surface.bits.get(j)) {  // else the segment is free
                    int64_t lower[3] = {v[0], v[1], v[2]};
                    if (dir < 0) lower[axis] -= 1;
                    if (!clear(dir > 0 ? i : j, lower, axis)) continue;
                }
                return state[j];
            }
        return kUnknown;
    };
    // The flood goes in rounds. A round finds the voxels without n that may settle (first every
    // voxel of the pending tiles, then the neighbours of the voxels the round before settled),
    // works out each one's state reading only the states of earlier rounds, and then stores
    // them. So the states do not depend on the order of the voxels or on the threads; and as n
    // changes only across the mesh or a fan, which no clear segment crosses, they are the ones a
    // serial flood reaches. Rounds are few (about the depth of the pending tiles), and within one
    // the clear-segment tests, the cost, run in parallel. `queued` marks the voxels a round has
    // taken, so that each is worked out once.
    //
    // Pending tiles are the 2^kPendingLevel-voxel children of the finest split tiles. Within
    // one, the voxels the surface does not touch fall into regions joined by free segments (both
    // ends untouched): a region settles as a whole, from the first of its voxels (in index order)
    // that can, and is taken and stored as one (keyed by that first voxel). A tile without
    // surface voxels, about half of them, is one region; the regions of the others spare the
    // flood most of its items (at 512³, 2.7 M of the open scan's 3.7 M). Surface voxels flood one
    // by one, across the segments their triangles leave clear.
    constexpr int kPendingLevel = kFinestTileLevel - 1;
    static_assert(kPendingLevel == 2, "a pending tile's voxels are the bits of one word");
    const int64_t tile_size = int64_t(1) << kPendingLevel;
    const int64_t tiles_x = (n[0] + tile_size - 1) >> kPendingLevel;
    const int64_t tiles_y = (n[1] + tile_size - 1) >> kPendingLevel;
    const int64_t tiles_z = (n[2] + tile_size - 1) >> kPendingLevel;
    auto tile_number = [&](const int64_t* v) {
        return uint64_t((v[0] >> kPendingLevel) +
                        tiles_x * ((v[1] >> kPendingLevel) + tiles_y * (v[2] >> kPendingLevel)));
    };
    auto local_bit = [](const int64_t* v) { return (v[0] & 3) + 4 * (v[1] & 3) + 16 * (v[2] & 3); };
    // Each pending tile's regions as masks of its 4x4x4 voxels (bit x + 4 y + 16 z); the regions
    // of tile t are region_mask[region_first[t] .. region_first[t + 1]), in the order of their
    // first voxels.
    std::vector<uint32_t> region_first(size_t(tiles_x * tiles_y * tiles_z) + 1, 0);
    std::vector<uint64_t> region_mask;
    {
        std::vector<std::vector<uint64_t>> regions(pending.size());
        tbb::parallel_for(size_t(0), pending.size(), [&](size_t p) {
            const Tile& tile = pending[p];
            uint64_t in_box = 0, touched = 0;
            for (int64_t z = tile.lo[2]; z <= tile.hi[2]; ++z)
                for (int64_t y = tile.lo[1]; y <= tile.hi[1]; ++y) {
                    const int count = int(tile.hi[0] - tile.lo[0] + 1);
                    const int shift = 4 * int(y - tile.lo[1]) + 16 * int(z - tile.lo[2]);
                    in_box |= ((uint64_t(1) << count) - 1) << shift;
                    touched |= surface.bits.bits_at(surface.bits.index(tile.lo[0], y, z), count)
                               << shift;
                }
            // Grown a face step at a time within the untouched voxels until it stops growing.
            constexpr uint64_t kNotX0 = 0xEEEEEEEEEEEEEEEE, kNotX3 = 0x7777777777777777;
            constexpr uint64_t kNotY0 = 0xFFF0FFF0FFF0FFF0, kNotY3 = 0x0FFF0FFF0FFF0FFF;
            uint64_t left = in_box & ~touched;
            auto grow = [&](uint64_t r) {
                const uint64_t steps = ((r << 1) & kNotX0) | ((r >> 1) & kNotX3) |
                                       ((r << 4) & kNotY0) | ((r >> 4) & kNotY3) | (r << 16) |
                                       (r >> 16);
                return r | (steps & left);
            };
            while (left) {
                uint64_t region = left & (~left + 1);  // the first voxel left
                for (uint64_t grown = grow(region); grown != region; grown = grow(region))
                    region = grown;
                regions[p].push_back(region);
                left &= ~region;
            }
        });
        for (size_t p = 0; p < pending.size(); ++p)
            region_first[tile_number(pending[p].lo) + 1] = uint32_t(regions[p].size());
        for (size_t t = 0; t + 1 < region_first.size(); ++t) region_first[t + 1] += region_first[t];
        region_mask.resize(region_first.back());
        tbb::parallel_for(size_t(0), pending.size(), [&](size_t p) {
            std::copy(regions[p].begin(), regions[p].end(),
                      region_mask.begin() + region_first[tile_number(pending[p].lo)]);
        });
    }
    // The region holding untouched pending voxel v, as its mask (every voxel without n lies in
    // a pending tile, and each untouched one in exactly one of its regions); the tile's low
    // corner in `lo`.
    auto region_of = [&](const int64_t* v, int64_t* lo) {
        for (int k = 0; k < 3; ++k) lo[k] = v[k] >> kPendingLevel << kPendingLevel;
        const uint64_t t = tile_number(v), bit = uint64_t(1) << local_bit(v);
        uint32_t r = region_first[t];
        while (!(region_mask[r] & bit)) ++r;
        return region_mask[r];
    };
    // The voxel of a region's lowest bit (its first voxel in index order).
    auto first_voxel = [](const int64_t* lo, uint64_t region) {
        const int b = __builtin_ctzll(region);
        return std::array<int64_t, 3>{lo[0] + (b & 3), lo[1] + (b >> 2 & 3), lo[2] + (b >> 4)};
    };
    // Calls f(voxel) for each voxel of a region, in index order, while f returns true.
    auto for_each_region_voxel = [&](const int64_t* lo, uint64_t region, auto&& f) {
        for (; region; region &= region - 1)
            if (!f(first_voxel(lo, region).data())) return;
    };
    struct Settled {
        std::array<int32_t, 3> voxel;  // a region's first voxel when `region`
        uint8_t state;
        bool region;
    };
    using SettledLists = tbb::enumerable_thread_specific<std::vector<Settled>>;
    std::vector<std::atomic<uint64_t>> queued((state_size + 63) / 64);
    tbb::parallel_for(size_t(0), queued.size(),
                      [&](size_t w) { queued[w].store(0, std::memory_order_relaxed); });
    auto take = [&](uint64_t i) {
        const uint64_t bit = uint64_t(1) << (i & 63);
        return !(queued[i >> 6].fetch_or(bit, std::memory_order_relaxed) & bit);
    };
    // A surface voxel i at v, alone: false if it cannot settle yet.
    auto try_settle_voxel = [&](std::vector<Settled>& out, uint64_t i, const int64_t* v) {
        const uint8_t s = settled_state(i, v);
        if (s != kUnknown) out.push_back({{int32_t(v[0]), int32_t(v[1]), int32_t(v[2])}, s, false});
        return s != kUnknown;
    };
    // A region (its tile's low corner and mask): false if it cannot settle yet.
    auto try_settle_region = [&](std::vector<Settled>& out, const int64_t* lo, uint64_t region) {
        uint8_t s = kUnknown;
        for_each_region_voxel(lo, region, [&](const int64_t* u) {
            s = settled_state(inside.index(u[0], u[1], u[2]), u);
            return s == kUnknown;
        });
        if (s != kUnknown) {
            const auto first = first_voxel(lo, region);
            out.push_back({{int32_t(first[0]), int32_t(first[1]), int32_t(first[2])}, s, true});
        }
        return s != kUnknown;
    };
    // Stores a round's states; returns the voxels and regions they settled, the next round's
    // frontier.
    auto store = [&](SettledLists& lists) {
        FilledLaterVector<Settled> frontier;
        append_in_parallel(frontier, thread_lists(lists));
        for (auto& list : lists) list.clear();
        tbb::parallel_for(tbb::blocked_range<size_t>(0, frontier.size(), 1024), [&](const auto& r) {
            for (size_t f = r.begin(); f != r.end(); ++f) {
                const int64_t v[3] = {frontier[f].voxel[0], frontier[f].voxel[1],
                                      frontier[f].voxel[2]};
                if (!frontier[f].region) {
                    state[inside.index(v[0], v[1], v[2])] = frontier[f].state;
                    continue;
                }
                int64_t lo[3];
                for_each_region_voxel(lo, region_of(v, lo), [&](const int64_t* u) {
                    state[inside.index(u[0], u[1], u[2])] = frontier[f].state;
                    return true;
                });
            }
        });
        return frontier;
    };
    SettledLists lists;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pending.size(), 16), [&](const auto& r) {
        auto& out = lists.local();
        for (size_t p = r.begin(); p != r.end(); ++p) {
            const Tile& tile = pending[p];
            const uint64_t t = tile_number(tile.lo);
            for (uint32_t region = region_first[t]; region < region_first[t + 1]; ++region)
                try_settle_region(out, tile.lo, region_mask[region]);
            for (int64_t z = tile.lo[2]; z <= tile.hi[2]; ++z)
                for (int64_t y = tile.lo[1]; y <= tile.hi[1]; ++y)
                    for (int64_t x = tile.lo[0]; x <= tile.hi[0]; ++x) {
                        const uint64_t i = inside.index(x, y, z);
                        const int64_t v[3] = {x, y, z};
                        if (surface.bits.get(i) && state[i] == kUnknown)
                            try_settle_voxel(out, i, v);
                    }
        }
    });
    auto flood = [&](FilledLaterVector<Settled> frontier) {
        for (; !frontier.empty(); frontier = store(lists)) {
            // What a round takes but cannot settle may settle in a later one.
            tbb::enumerable_thread_specific<std::vector<uint64_t>> unsettled_lists;
            tbb::parallel_for(
                tbb::blocked_range<size_t>(0, frontier.size(), 64), [&](const auto& r) {
                    auto& out = lists.local();
                    auto& unsettled = unsettled_lists.local();
                    auto visit_neighbours = [&](const int64_t* k) {
                        const uint64_t ki = inside.index(k[0], k[1], k[2]);
                        for (int axis = 0; axis < 3; ++axis)
                            for (int dir = -1; dir <= 1; dir += 2) {
                                if (k[axis] + dir < 0 || k[axis] + dir >= n[axis]) continue;
                                const uint64_t j = dir > 0 ? ki + step[axis] : ki - step[axis];
                                if (state[j] != kUnknown) continue;
                                int64_t jv[3] = {k[0], k[1], k[2]};
                                jv[axis] += dir;
                                if (surface.bits.get(j)) {
                                    if (take(j) && !try_settle_voxel(out, j, jv))
                                        unsettled.push_back(j);
                                    continue;
                                }
                                // A region is taken at its first voxel.
                                int64_t lo[3];
                                const uint64_t region = region_of(jv, lo);
                                const auto first = first_voxel(lo, region);
                                const uint64_t key = inside.index(first[0], first[1], first[2]);
                                if (take(key) && !try_settle_region(out, lo, region))
                                    unsettled.push_back(key);
                            }
                        return true;
                    };
                    for (size_t f = r.begin(); f != r.end(); ++f) {
                        const int64_t k[3] = {frontier[f].voxel[0], frontier[f].voxel[1],
                                              frontier[f].voxel[2]};
                        if (frontier[f].region) {
                            int64_t lo[3];
                            for_each_region_voxel(lo, region_of(k, lo), visit_neighbours);
                        } else {
                            visit_neighbours(k);
                        }
                    }
                });
            for (const auto& list : unsettled_lists)
                for (const uint64_t key : list)
                    queued[key >> 6].fetch_and(~(uint64_t(1) << (key & 63)),
                                               std::memory_order_relaxed);
        }
    };
    flood(store(lists));
    // Pockets the flood cannot reach from the decided tiles (the inside of a building whose walls
    // leave no whole tile clear of the surface, at a coarse grid) would leave every voxel in them
    // to a tree evaluation of its own. So, in rounds while it settles any: each pending tile's
    // first region still without n is a seed, which takes n from one tree evaluation at its
    // first voxel where n is certain there (as a tile's), and the flood goes on from the seeds.
    // Seeds and rounds do not depend on the threads.
    for (int round = 0; round < kSeedRounds; ++round) {
        // A seed near the fans would flood n into voxels that each need the fans' sums: those
        // are left to their own evaluations, as before seeds.
        constexpr std::array<int64_t, 3> kNone{-1, -1, -1};
        std::vector<std::array<int64_t, 3>> seeds(pending.size(), kNone);
        tbb::parallel_for(size_t(0), pending.size(), [&](size_t p) {
            const uint64_t t = tile_number(pending[p].lo);
            for (uint32_t region = region_first[t]; region < region_first[t + 1]; ++region) {
                const auto first = first_voxel(pending[p].lo, region_mask[region]);
                if (state[inside.index(first[0], first[1], first[2])] != kUnknown) continue;
                if (fans.triangles.empty() || fans.below_half_at(centre_of_voxel(first.data())))
                    seeds[p] = first;
                return;
            }
        });
        seeds.erase(std::remove(seeds.begin(), seeds.end(), kNone), seeds.end());
        if (seeds.empty()) break;
        points.clear();
        for (const auto& seed : seeds)
            for (double c : centre_of_voxel(seed.data())) points.push_back(float(c));
        evaluator.evaluate(points, OVS_WINDING_FAR, kTileNodeTolerance, w, error);
        std::vector<uint8_t> seed_state(seeds.size());
        tbb::parallel_for(size_t(0), seeds.size(), [&](size_t i) {
            seed_state[i] = certain_state(w[i], error[i], centre_of_voxel(seeds[i].data()));
        });
        for (size_t i = 0; i < seeds.size(); ++i)
            if (seed_state[i] != kUnknown)
                lists.local().push_back(
                    {{int32_t(seeds[i][0]), int32_t(seeds[i][1]), int32_t(seeds[i][2])},
                     seed_state[i],
                     true});
        auto frontier = store(lists);
        if (frontier.empty()) break;
        flood(std::move(frontier));
    }
    // Each pending tile's voxels: settled ones inside or not (near a fan, from the fans' winding
    // at the tile's centre and its spread, or later on the device), unsettled ones to evaluate.
    // Tiles are independent (the fans' sums are the cost), so fixed chunks of them run in
    // parallel and their lists are joined in chunk order: the same lists for any threads.
    struct Classified {
        std::vector<uint64_t> unsettled, near_voxels;
        std::vector<int> near_whole;
        std::vector<float> points, near_points;
    };
    // Rounds of kChunksPerRound chunks bound the lists held at once.
    constexpr size_t kTilesPerChunk = 64, kChunksPerRound = 256;
    const size_t chunks = (pending.size() + kTilesPerChunk - 1) / kTilesPerChunk;
    FilledLaterVector<uint64_t> unsettled, near_voxels;
    FilledLaterVector<int> near_whole;
    FilledLaterVector<float> near_points;
    points.clear();
    std::vector<Classified> parts;
    for (size_t round = 0; round < chunks; round += kChunksPerRound) {
        parts.assign(std::min(kChunksPerRound, chunks - round), Classified());
        tbb::parallel_for(size_t(0), parts.size(), [&](size_t c) {
            Classified& out = parts[c];
            const size_t first = (round + c) * kTilesPerChunk;
            for (size_t p = first; p < std::min(pending.size(), first + kTilesPerChunk); ++p) {
                const Tile& tile = pending[p];
                // Per voxel, w_fans matters only where its bound over the tile does not settle it.
                // In a tile that no fan touches, w_fans at a voxel is within its distance from
                // the tile's centre times `gradient` (a bound over the tile's ball) of its value
                // at the centre.
                // The fans' w at the centre is estimated; where its error leaves a voxel's
                // decision open that the exact sum would settle, the exact sum is taken. All of
                // it is worked out at the tile's first settled voxel: a tile of unsettled voxels
                // needs none of it (in a model open everywhere, every tile's voxels may be).
                const Vec3d tile_centre = centre_of(tile);
                const double reach = tile_reach(tile);
                bool fans_known = false, near_fans = false, fan_centre_exact = true;
                BoundaryFans::Estimate fan_centre{0, 0};
                double gradient = INFINITY;
                auto know_fans = [&] {
                    fans_known = true;
                    near_fans = !fans.triangles.empty() && !(fans.bound(tile_centre, reach) < 0.5);
                    if (near_fans && !fan_pyramid.get(tile.lo[0] >> kFinestTileLevel,
                                                      tile.lo[1] >> kFinestTileLevel,
                                                      tile.lo[2] >> kFinestTileLevel)) {
                        fan_centre = fans.winding_estimate(tile_centre);
                        fan_centre_exact = false;
                        gradient = fans.gradient_bound(tile_centre, reach);
                    }
                };
                for (int64_t z = tile.lo[2]; z <= tile.hi[2]; ++z)
                    for (int64_t y = tile.lo[1]; y <= tile.hi[1]; ++y)
                        for (int64_t x = tile.lo[0]; x <= tile.hi[0]; ++x) {
                            const uint64_t i = inside.index(x, y, z);
                            const int64_t v[3] = {x, y, z};
                            const Vec3d centre = centre_of_voxel(v);
                            if (state[i] == kUnknown) {
                                out.unsettled.push_back(i);
                                for (double v : centre) out.points.push_back(float(v));
                                continue;
                            }
                            // Away from the fans a settled state, n + kZero, already says what
                            // the inside bits below read from it: inside iff n != 0.
                            if (!fans_known) know_fans();
                            if (!near_fans) continue;
                            // Near the fans the state is rewritten to say inside (kZero + 1) or
                            // not, or not yet (kZero: decided below, from w_fans summed on the
                            // device).
                            const int whole = int(state[i]) - kZero;
                            const double spread =
                                gradient == INFINITY
                                    ? INFINITY
                                    : gradient * BoundaryFans::distance(centre, tile_centre);
                            double low = std::fabs(whole + fan_centre.value) - spread;
                            double high = std::fabs(whole + fan_centre.value) + spread;
                            if (!fan_centre_exact && !(low - fan_centre.error > 0.5) &&
                                !(high + fan_centre.error < 0.5) &&
                                (low + fan_centre.error > 0.5 || high - fan_centre.error < 0.5)) {
                                fan_centre = {fans.winding(tile_centre), 0};
                                fan_centre_exact = true;
                                low = std::fabs(whole + fan_centre.value) - spread;
                                high = std::fabs(whole + fan_centre.value) + spread;
                            }
                            low -= fan_centre.error;
                            high += fan_centre.error;
                            state[i] = low > 0.5 ? kZero + 1 : kZero;
                            if (!(low > 0.5) && !(high < 0.5)) {
                                out.near_voxels.push_back(i);
                                out.near_whole.push_back(whole);
                                for (double v : centre) out.near_points.push_back(float(v));
                            }
                        }
            }
        });
        auto join = [&](auto& out, auto member) {
            std::vector<const std::remove_reference_t<decltype(parts[0].*member)>*> lists;
            for (const Classified& part : parts) lists.push_back(&(part.*member));
            append_in_parallel(out, lists);
        };
        join(unsettled, &Classified::unsettled);
        join(points, &Classified::points);
        join(near_voxels, &Classified::near_voxels);
        join(near_whole, &Classified::near_whole);
        join(near_points, &Classified::near_points);
    }
    // Every state now says inside (neither kZero nor kUnknown) or not yet known to be: the inside
    // bits, a word of 64 voxels at a time, each word in one thread. kZero and kUnknown are the two
    // states whose low seven bits are all set, so 8 states at a time: adding 1 to each byte's low
    // seven bits carries into its high bit just for those, and a multiply gathers the eight bits.
    static_assert((kZero & 0x7F) == 0x7F && (kUnknown & 0x7F) == 0x7F);
    constexpr uint64_t kLow7 = 0x7F7F7F7F7F7F7F7F, kOnes = 0x0101010101010101;
    constexpr uint64_t kGather = 0x0102040810204080;  // byte k's lowest bit to bit 56 + k
    tbb::parallel_for(tbb::blocked_range<size_t>(0, inside.word_count(), 1024), [&](const auto& r) {
        for (size_t word = r.begin(); word != r.end(); ++word) {
            const size_t first = word * 64, end = std::min(state_size, first + 64);
            uint64_t bits = 0;
            if (end - first == 64) {
                for (int part = 0; part < 8; ++part) {
                    uint64_t eight;
                    std::memcpy(&eight, state + first + 8 * size_t(part), 8);
                    const uint64_t in = ~((eight & kLow7) + kOnes) >> 7 & kOnes;
                    bits |= (in * kGather) >> 56 << (8 * part);
                }
            } else {
                for (size_t i = first; i < end; ++i)
                    bits |= uint64_t(state[i] != kZero && state[i] != kUnknown) << (i - first);
            }
            inside.set_word(word, bits);
        }
    });
    report_progress(options, 2 * bricks.size() / kSteps, bricks.size());

    if (!near_voxels.empty()) {
        // w_fans from a tree over the fans (each triangle as many times as its weight), like
        // the mesh's.
        std::vector<std::array<double, 9>> weighted;
        for (size_t f = 0; f < fans.triangles.size(); ++f)
            weighted.insert(weighted.end(), size_t(fans.weight[f]), fans.triangles[f]);
        WindingEvaluator fan_evaluator(cl, build_winding_tree(weighted), stats);
        fan_evaluator.evaluate(near_points, OVS_WINDING_FAR, INFINITY, w, error);
        for (size_t u = 0; u < near_voxels.size(); ++u)
            if (std::fabs(near_whole[u] + w[u]) > 0.5f) inside.set(near_voxels[u]);
    }

    // Phase 4.
    evaluator.evaluate(points, OVS_WINDING_FAR, INFINITY, w, error);
    for (size_t u = 0; u < unsettled.size(); ++u)
        if (std::fabs(w[u]) > 0.5f) inside.set(unsettled[u]);
    report_progress(options, 3 * bricks.size() / kSteps, bricks.size());

    // Phase 5, a row of up to 64 voxels at a time: each 4-voxel group of a row is a nibble of
    // one block word. Bricks are independent: merge_bricks fills them in parallel.
    t = Clock::now();
    const int64_t nbb = b / 4;
    result.merge_bricks(
        bricks.size(), [&](size_t i) { return bricks[i]; },
        [&](size_t i, uint64_t* blocks) {
            const uint64_t index = bricks[i];
            const int64_t at[3] = {int64_t(index % uint64_t(nb[0])) * b,
                                   int64_t(index / uint64_t(nb[0]) % uint64_t(nb[1])) * b,
                                   int64_t(index / uint64_t(nb[0]) / uint64_t(nb[1])) * b};
            int64_t lo[3], hi[3];  // the brick-local voxels inside the box
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::max<int64_t>(box.lo[k] - at[k], 0);
                hi[k] = std::min<int64_t>(box.hi[k] - at[k], b - 1);
            }
            for (int64_t z = lo[2]; z <= hi[2]; ++z)
                for (int64_t y = lo[1]; y <= hi[1]; ++y)
                    for (int64_t x0 = lo[0] & ~int64_t(63); x0 <= hi[0]; x0 += 64) {
                        const int64_t from = std::max(x0, lo[0]), to = std::min(x0 + 63, hi[0]);
                        uint64_t row = inside.bits_at(inside.index(at[0] + from - box.lo[0],
                                                                   at[1] + y - box.lo[1],
                                                                   at[2] + z - box.lo[2]),
                                                      int(to - from + 1))
                                       << (from - x0);
                        const size_t first_block = size_t(x0 / 4 + nbb * (y / 4 + nbb * (z / 4)));
                        const int shift = int(4 * ((y & 3) + 4 * (z & 3)));
                        while (row) {
                            const int group = __builtin_ctzll(row) / 4;
                            blocks[first_block + size_t(group)] |= (row >> (4 * group) & 15)
                                                                   << shift;
                            row &= ~(uint64_t(15) << (4 * group));
                        }
                    }
        });
    stats.seconds_download += seconds_since(t);
    report_progress(options, bricks.size(), bricks.size());
}

// Double-precision winding number at every voxel centre of the box, summing every triangle.
void winding_reference(const Mesh& mesh, SparseVoxels& result, const VoxelizeOptions& options) {
    const Grid& grid = result.grid();
    const VoxelBox box = centre_box(mesh, grid);
    if (box.empty()) return;
    check_solid_memory(result, box_bricks(result, box), 0, options, "");
    const uint64_t voxels = box_voxels(box);
    if (voxels > kMaxReferenceWindingTerms / std::max<uint64_t>(1, mesh.triangles.size()))
        throw GridError("the CPU reference winding number would sum more than " +
                        std::to_string(kMaxReferenceWindingTerms) +
                        " solid angles: lower the resolution");
    std::vector<std::array<double, 3>> g(mesh.positions.size());
    for (size_t v = 0; v < g.size(); ++v)
        for (int k = 0; k < 3; ++k)
            g[v][k] = (mesh.positions[v][k] - grid.origin[k]) / grid.voxel_size;
    for (int64_t z = box.lo[2]; z <= box.hi[2]; ++z)
        for (int64_t y = box.lo[1]; y <= box.hi[1]; ++y)
            for (int64_t x = box.lo[0]; x <= box.hi[0]; ++x) {
                const double p[3] = {double(x) + 0.5, double(y) + 0.5, double(z) + 0.5};
                double sum = 0;
                for (const auto& tri : mesh.triangles)
                    sum +=
                        solid_angle_double(g[tri[0]].data(), g[tri[1]].data(), g[tri[2]].data(), p);
                // |w| > 1/2: an inward-facing closed mesh has w = -1 inside.
                if (std::fabs(sum) > 2 * M_PI) result.set(x, y, z);
            }
}
}  // namespace oclvox::detail
