// Sparse brick storage of a bit grid. See SparseVoxels in oclvox.hpp for the layout.
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cstring>
#include <functional>

#include "bit_count.hpp"
#include "host_memory.hpp"
#include "oclvox/oclvox.hpp"
#include "sparse_voxels_access.hpp"

namespace oclvox {

namespace {
int64_t ceil_div(int64_t a, int64_t b) {
    return (a + b - 1) / b;
}
}  // namespace

SparseVoxels::SparseVoxels(const Grid& grid, int brick_size)
    : grid_(grid), brick_size_(brick_size) {
    if (brick_size < 4 || brick_size > 1024 || brick_size % kBlock != 0)
        throw GridError("brick size " + std::to_string(brick_size) +
                        " is invalid: it must be a multiple of 4 in [4, 1024]");
}

namespace {
// Zeroed words for one brick of its own.
std::shared_ptr<uint64_t> new_brick(size_t words) {
    return std::shared_ptr<uint64_t>(new uint64_t[words](), std::default_delete<uint64_t[]>());
}
}  // namespace

SparseVoxels::SparseVoxels(const SparseVoxels& other)
    : grid_(other.grid_), brick_size_(other.brick_size_) {
    if (other.bricks_.empty()) return;
    // One run for all the bricks.
    const size_t n = blocks_per_brick();
    const std::shared_ptr<uint64_t> run = new_brick(n * other.bricks_.size());
    uint64_t* next = run.get();
    bricks_.reserve(other.bricks_.size());
    for (const auto& [index, words] : other.bricks_) {
        std::copy_n(words.get(), n, next);
        bricks_.emplace(index, std::shared_ptr<uint64_t>(run, next));
        next += n;
    }
}

SparseVoxels& SparseVoxels::operator=(const SparseVoxels& other) {
    if (this != &other) *this = SparseVoxels(other);
    return *this;
}

uint64_t* SparseVoxels::writable_brick(uint64_t brick_index) {
    const auto it = bricks_.find(brick_index);
    if (it != bricks_.end()) return it->second.get();
    return bricks_.emplace(brick_index, new_brick(blocks_per_brick())).first->second.get();
}

size_t SparseVoxels::blocks_per_brick() const {
    size_t nb = size_t(blocks_per_brick_axis());
    return nb * nb * nb;
}

std::array<int64_t, 3> SparseVoxels::brick_dims() const {
    return {ceil_div(grid_.dims[0], brick_size_), ceil_div(grid_.dims[1], brick_size_),
            ceil_div(grid_.dims[2], brick_size_)};
}

namespace {
struct Address {
    uint64_t brick;
    size_t word;
    int bit;
};

Address address_of(const SparseVoxels& v, int64_t i, int64_t j, int64_t k) {
    const int b = v.brick_size();
    const auto nbricks = v.brick_dims();
    const uint64_t brick =
        uint64_t(i / b) +
        uint64_t(nbricks[0]) * (uint64_t(j / b) + uint64_t(nbricks[1]) * uint64_t(k / b));
    const int64_t li = i % b, lj = j % b, lk = k % b;
    const int64_t nb = v.blocks_per_brick_axis();
    const size_t word = size_t(li / 4 + nb * (lj / 4 + nb * (lk / 4)));
    const int bit = int(li % 4 + 4 * (lj % 4 + 4 * (lk % 4)));
    return {brick, word, bit};
}

// The bits of a 4x4x4 block whose coordinate along `axis` lies in [from, to] (clipped to 0..3).
uint64_t block_mask_within(int axis, int64_t from, int64_t to) {
    uint64_t mask = 0;
    for (int bit = 0; bit < 64; ++bit) {
        const int64_t c = axis == 0 ? (bit & 3) : axis == 1 ? (bit >> 2 & 3) : (bit >> 4);
        if (c >= from && c <= to) mask |= uint64_t(1) << bit;
    }
    return mask;
}

bool inside(const Grid& g, int64_t i, int64_t j, int64_t k) {
    return i >= 0 && j >= 0 && k >= 0 && i < g.dims[0] && j < g.dims[1] && k < g.dims[2];
}
}  // namespace

bool SparseVoxels::get(int64_t i, int64_t j, int64_t k) const {
    if (!inside(grid_, i, j, k)) return false;
    const Address a = address_of(*this, i, j, k);
    auto it = bricks_.find(a.brick);
    return it != bricks_.end() && ((it->second.get()[a.word] >> a.bit) & 1u);
}

void SparseVoxels::set(int64_t i, int64_t j, int64_t k) {
    if (!inside(grid_, i, j, k)) throw std::out_of_range("SparseVoxels::set outside the grid");
    const Address a = address_of(*this, i, j, k);
    writable_brick(a.brick)[a.word] |= uint64_t(1) << a.bit;
}

uint64_t SparseVoxels::count() const {
    // The bricks in parallel: a large surface's bricks hold hundreds of MiB of words (a serial
    // count of stanford-bunny's at 1024^3 took 7 ms of a 75 ms voxelize phase).
    std::vector<const uint64_t*> all;
    all.reserve(bricks_.size());
    for (const auto& [index, words] : bricks_) all.push_back(words.get());
    const size_t words_per_brick = blocks_per_brick();
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, all.size()), uint64_t(0),
        [&](const tbb::blocked_range<size_t>& range, uint64_t n) {
            for (size_t i = range.begin(); i < range.end(); ++i)
                n += detail::count_bits(all[i], words_per_brick);
            return n;
        },
        std::plus<uint64_t>());
}

void SparseVoxels::merge_brick(uint64_t brick_index, const uint64_t* blocks) {
    const auto nb = brick_dims();
    if (brick_index >= uint64_t(nb[0]) * uint64_t(nb[1]) * uint64_t(nb[2]))
        throw GridError("brick index " + std::to_string(brick_index) + " is outside the grid");
    const size_t n = blocks_per_brick();
    bool any = false;
    for (size_t w = 0; w < n && !any; ++w) any = blocks[w] != 0;
    if (!any) return;
    uint64_t* const brick = writable_brick(brick_index);
    for (size_t w = 0; w < n; ++w) brick[w] |= blocks[w];
}

namespace {
// brick_index(i) for i in [0, count); throws GridError for one outside the grid of `voxels`.
std::vector<uint64_t> checked_brick_indices(const SparseVoxels& voxels, size_t count,
                                            const std::function<uint64_t(size_t)>& brick_index) {
    const auto nb = voxels.brick_dims();
    const uint64_t bricks = uint64_t(nb[0]) * uint64_t(nb[1]) * uint64_t(nb[2]);
    std::vector<uint64_t> indices(count);
    for (size_t i = 0; i < count; ++i) {
        indices[i] = brick_index(i);
        if (indices[i] >= bricks)
            throw GridError("brick index " + std::to_string(indices[i]) + " is outside the grid");
    }
    return indices;
}
}  // namespace

void SparseVoxels::merge_bricks(size_t count, const std::function<uint64_t(size_t)>& brick_index,
                                const std::function<void(size_t, uint64_t*)>& fill) {
    const std::vector<uint64_t> indices = checked_brick_indices(*this, count, brick_index);
    const size_t n = blocks_per_brick();
    std::vector<std::shared_ptr<uint64_t>> filled(count);
    tbb::parallel_for(size_t(0), count, [&](size_t i) {
        std::shared_ptr<uint64_t> blocks = new_brick(n);
        fill(i, blocks.get());
        if (std::any_of(blocks.get(), blocks.get() + n, [](uint64_t w) { return w != 0; }))
            filled[i] = std::move(blocks);
    });
    for (size_t i = 0; i < count; ++i) {
        if (!filled[i]) continue;
        const auto [it, fresh] = bricks_.try_emplace(indices[i], filled[i]);
        if (!fresh)
            for (size_t w = 0; w < n; ++w) it->second.get()[w] |= filled[i].get()[w];
    }
}

void detail::SparseVoxelsAccess::adopt_bricks(SparseVoxels& voxels,
                                              const std::shared_ptr<uint64_t>& run, size_t count,
                                              const std::function<uint64_t(size_t)>& brick_index) {
    const std::vector<uint64_t> indices = checked_brick_indices(voxels, count, brick_index);
    const size_t n = voxels.blocks_per_brick();
    // Phase 1: which bricks hold a voxel, in parallel. A brick none of whose pages was ever
    // touched is empty unread: devices write only the blocks that hold voxels, so most empty
    // bricks of a solid's columns are such (reading them, and giving back the pages the reads
    // mapped, one system call and one TLB flush of the other cores a brick, took 8% of a parity
    // solid's run at 1024^3). The others are read, up to their first set word, and the pages of
    // the empty ones given back.
    const size_t brick_bytes = n * sizeof(uint64_t), page = host_page_size();
    const auto first_page = reinterpret_cast<uintptr_t>(run.get()) / page * page;
    const std::vector<uint8_t> touched = touched_host_pages(
        reinterpret_cast<const void*>(first_page),
        reinterpret_cast<uintptr_t>(run.get()) + count * brick_bytes - first_page);
    std::vector<uint8_t> holds_voxels(count);
    tbb::parallel_for(size_t(0), count, [&](size_t i) {
        uint64_t* const words = run.get() + i * n;
        const uintptr_t begin = reinterpret_cast<uintptr_t>(words) - first_page;
        if (std::none_of(touched.begin() + ptrdiff_t(begin / page),
                         touched.begin() + ptrdiff_t((begin + brick_bytes - 1) / page + 1),
                         [](uint8_t t) { return t != 0; }))
            return;
        holds_voxels[i] = std::any_of(words, words + n, [](uint64_t w) { return w != 0; });
        if (!holds_voxels[i]) release_host_pages(words, brick_bytes);
    });
    // Phase 2: the others are stored where they lie, or ORed into the brick already stored.
    for (size_t i = 0; i < count; ++i) {
        if (!holds_voxels[i]) continue;
        uint64_t* const words = run.get() + i * n;
        const auto [it, fresh] =
            voxels.bricks_.try_emplace(indices[i], std::shared_ptr<uint64_t>(run, words));
        if (fresh) continue;
        for (size_t w = 0; w < n; ++w) it->second.get()[w] |= words[w];
        release_host_pages(words, brick_bytes);
    }
}

void SparseVoxels::for_each(const std::function<void(int64_t, int64_t, int64_t)>& f) const {
    const auto nbricks = brick_dims();
    const int64_t b = brick_size_, nb = blocks_per_brick_axis();
    const size_t words_per_brick = blocks_per_brick();
    for (const auto& [index, words] : bricks_) {
        const int64_t bx = int64_t(index % uint64_t(nbricks[0]));
        const int64_t by = int64_t(index / uint64_t(nbricks[0]) % uint64_t(nbricks[1]));
        const int64_t bz = int64_t(index / (uint64_t(nbricks[0]) * uint64_t(nbricks[1])));
        for (size_t w = 0; w < words_per_brick; ++w) {
            uint64_t mask = words.get()[w];
            if (!mask) continue;
            const int64_t ox = bx * b + int64_t(w % nb) * 4;
            const int64_t oy = by * b + int64_t(w / nb % nb) * 4;
            const int64_t oz = bz * b + int64_t(w / (nb * nb)) * 4;
            while (mask) {
                const int bit = __builtin_ctzll(mask);
                mask &= mask - 1;
                f(ox + bit % 4, oy + bit / 4 % 4, oz + bit / 16);
            }
        }
    }
}

std::vector<uint64_t> SparseVoxels::brick_indices() const {
    std::vector<uint64_t> indices;
    indices.reserve(bricks_.size());
    for (const auto& entry : bricks_) indices.push_back(entry.first);
    std::sort(indices.begin(), indices.end());
    return indices;
}

const uint64_t* SparseVoxels::brick_blocks(uint64_t brick_index) const {
    const auto it = bricks_.find(brick_index);
    return it == bricks_.end() ? nullptr : it->second.get();
}

namespace {

// The inclusive voxel range [first, last] of the box [lo, hi) clipped to the grid; false if empty.
bool clip_box(const Grid& grid, const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi,
              std::array<int64_t, 3>& first, std::array<int64_t, 3>& last) {
    for (int a = 0; a < 3; ++a) {
        first[a] = std::max<int64_t>(lo[a], 0);
        last[a] = std::min(hi[a], grid.dims[a]) - 1;
        if (last[a] < first[a]) return false;
    }
    return true;
}

// Calls f(word, mask, block_origin) for every 4^3 block of the brick at `brick_origin` (of `size`
// voxels, `per_axis` blocks along an axis) that meets the inclusive voxel range [first, last],
// `mask` holding the block's bits inside the range.
template <typename F>
void for_each_block_in(const std::array<int64_t, 3>& brick_origin, int64_t size, int64_t per_axis,
                       const std::array<int64_t, 3>& first, const std::array<int64_t, 3>& last,
                       F f) {
    constexpr int64_t kBlock = SparseVoxels::kBlock;
    std::array<int64_t, 3> block_first{}, block_last{};
    for (int a = 0; a < 3; ++a) {
        block_first[a] = std::max<int64_t>(first[a] - brick_origin[a], 0) / kBlock;
        block_last[a] = std::min<int64_t>(last[a] - brick_origin[a], size - 1) / kBlock;
        if (block_last[a] < block_first[a]) return;
    }
    for (int64_t wz = block_first[2]; wz <= block_last[2]; ++wz)
        for (int64_t wy = block_first[1]; wy <= block_last[1]; ++wy)
            for (int64_t wx = block_first[0]; wx <= block_last[0]; ++wx) {
                const std::array<int64_t, 3> o{brick_origin[0] + wx * kBlock,
                                               brick_origin[1] + wy * kBlock,
                                               brick_origin[2] + wz * kBlock};
                uint64_t mask = ~uint64_t(0);
                for (int a = 0; a < 3; ++a)
                    if (o[a] < first[a] || o[a] + kBlock - 1 > last[a])
                        mask &= block_mask_within(a, first[a] - o[a], last[a] - o[a]);
                f(size_t(wx + per_axis * (wy + per_axis * wz)), mask, o);
            }
}

// Calls f(index, origin) for every brick (of `size` voxels, `nbricks` of them along the axes)
// that meets the inclusive voxel range [first, last], with its linear index and lowest voxel.
template <typename F>
void for_each_brick_in(const std::array<int64_t, 3>& nbricks, int64_t size,
                       const std::array<int64_t, 3>& first, const std::array<int64_t, 3>& last,
                       F f) {
    for (int64_t bz = first[2] / size; bz <= last[2] / size; ++bz)
        for (int64_t by = first[1] / size; by <= last[1] / size; ++by)
            for (int64_t bx = first[0] / size; bx <= last[0] / size; ++bx)
                f(uint64_t(bx) +
                      uint64_t(nbricks[0]) * (uint64_t(by) + uint64_t(nbricks[1]) * uint64_t(bz)),
                  std::array<int64_t, 3>{bx * size, by * size, bz * size});
}

}  // namespace

void SparseVoxels::mark_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi,
                            const std::array<int64_t, 3>& strides, uint8_t* out) const {
    std::array<int64_t, 3> first{}, last{};
    if (!clip_box(grid_, lo, hi, first, last)) return;
    // Where the window is contiguous along an axis (a stride of 1), a block's 4 voxels along it
    // are 4 adjacent bytes, written as one 32-bit word where the block lies inside the box along
    // that axis; elsewhere, and for other windows, one byte per set voxel.
    const int line = strides[0] == 1 ? 0 : strides[1] == 1 ? 1 : strides[2] == 1 ? 2 : -1;
    const int across[2] = {(line + 1) % 3, (line + 2) % 3};
    constexpr int kBitStep[3] = {1, 4, 16};  // block bit x + 4y + 16z
    // Per nibble of a row: the word with byte t = 1 where bit t is set, and the mask of those bytes
    // (built through bytes, so whatever the machine's byte order).
    struct RowWords {
        std::array<uint32_t, 16> ones{}, bytes{};
    };
    static const RowWords rows = [] {
        RowWords words;
        for (uint32_t nibble = 0; nibble < 16; ++nibble) {
            uint8_t ones[4], bytes[4];
            for (int t = 0; t < 4; ++t) {
                ones[t] = uint8_t(nibble >> t & 1);
                bytes[t] = uint8_t(0xFF * (nibble >> t & 1));
            }
            std::memcpy(&words.ones[nibble], ones, 4);
            std::memcpy(&words.bytes[nibble], bytes, 4);
        }
        return words;
    }();
    // Phase 1: the stored bricks the box touches, found by lookup rather than by scanning all
    // bricks.
    std::vector<std::pair<const uint64_t*, std::array<int64_t, 3>>> touched;
    for_each_brick_in(brick_dims(), brick_size_, first, last,
                      [&](uint64_t index, const std::array<int64_t, 3>& origin) {
                          const auto it = bricks_.find(index);
                          if (it != bricks_.end()) touched.emplace_back(it->second.get(), origin);
                      });
    // Phase 2: each brick's blocks inside the box, then their set voxels. Bricks hold disjoint
    // voxels, so they write disjoint bytes of the window: in parallel.
    tbb::parallel_for(size_t(0), touched.size(), [&](size_t t) {
        const uint64_t* blocks = touched[t].first;
        for_each_block_in(
            touched[t].second, brick_size_, blocks_per_brick_axis(), first, last,
            [&](size_t word, uint64_t mask, const std::array<int64_t, 3>& o) {
                mask &= blocks[word];
                if (!mask) return;
                uint8_t* base = out + (o[0] - lo[0]) * strides[0] + (o[1] - lo[1]) * strides[1] +
                                (o[2] - lo[2]) * strides[2];
                if (line >= 0 && o[line] >= first[line] && o[line] + 3 <= last[line]) {
                    for (int a = 0; a < 4; ++a)
                        for (int b = 0; b < 4; ++b) {
                            const int bit = a * kBitStep[across[0]] + b * kBitStep[across[1]];
                            uint32_t nibble = 15;  // a full block (most of a solid) has all rows
                            if (mask != ~uint64_t(0)) {
                                nibble = 0;
                                for (int s = 0; s < 4; ++s)
                                    nibble |= uint32_t(mask >> (bit + s * kBitStep[line]) & 1) << s;
                                if (!nibble) continue;
                            }
                            uint8_t* p = base + a * strides[across[0]] + b * strides[across[1]];
                            uint32_t bytes;
                            std::memcpy(&bytes, p, 4);
                            bytes = (bytes & ~rows.bytes[nibble]) | rows.ones[nibble];
                            std::memcpy(p, &bytes, 4);
                        }
                    return;
                }
                while (mask) {
                    const int bit = __builtin_ctzll(mask);
                    mask &= mask - 1;
                    base[(bit & 3) * strides[0] + (bit >> 2 & 3) * strides[1] +
                         (bit >> 4) * strides[2]] = 1;
                }
            });
    });
}

uint64_t SparseVoxels::count_box(const std::array<int64_t, 3>& lo,
                                 const std::array<int64_t, 3>& hi) const {
    std::array<int64_t, 3> first{}, last{};
    if (!clip_box(grid_, lo, hi, first, last)) return 0;
    const auto nbricks = brick_dims();
    const int64_t b = brick_size_;
    uint64_t count = 0;
    auto count_brick = [&](const std::array<int64_t, 3>& origin, const uint64_t* blocks) {
        for_each_block_in(origin, b, blocks_per_brick_axis(), first, last,
                          [&](size_t word, uint64_t mask, const std::array<int64_t, 3>&) {
                              count += uint64_t(detail::popcount64(blocks[word] & mask));
                          });
    };
    // The box's bricks looked up, or every stored brick when they are fewer (a thin slab across
    // a huge sparse grid touches far more bricks than are stored).
    uint64_t touched = 1;
    for (int a = 0; a < 3; ++a) touched *= uint64_t(last[a] / b - first[a] / b + 1);
    if (touched > bricks_.size()) {
        for (const auto& [index, blocks] : bricks_)
            count_brick({int64_t(index % uint64_t(nbricks[0])) * b,
                         int64_t(index / uint64_t(nbricks[0]) % uint64_t(nbricks[1])) * b,
                         int64_t(index / (uint64_t(nbricks[0]) * uint64_t(nbricks[1]))) * b},
                        blocks.get());
        return count;
    }
    for_each_brick_in(nbricks, b, first, last,
                      [&](uint64_t index, const std::array<int64_t, 3>& origin) {
                          const auto it = bricks_.find(index);
                          if (it != bricks_.end()) count_brick(origin, it->second.get());
                      });
    return count;
}

void SparseVoxels::set_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi) {
    std::array<int64_t, 3> first{}, last{};
    if (!clip_box(grid_, lo, hi, first, last)) return;
    for_each_brick_in(brick_dims(), brick_size_, first, last,
                      [&](uint64_t index, const std::array<int64_t, 3>& origin) {
                          uint64_t* const blocks = writable_brick(index);
                          for_each_block_in(
                              origin, brick_size_, blocks_per_brick_axis(), first, last,
                              [&](size_t word, uint64_t mask, const std::array<int64_t, 3>&) {
                                  blocks[word] |= mask;
                              });
                      });
}

std::vector<uint8_t> SparseVoxels::to_dense() const {
    const uint64_t n = grid_.voxel_count();
    if (n > (uint64_t(1) << 36))
        throw GridError("a dense copy of this " + std::to_string(grid_.dims[0]) + "x" +
                        std::to_string(grid_.dims[1]) + "x" + std::to_string(grid_.dims[2]) +
                        " grid would need " + std::to_string(n >> 30) +
                        " GiB; choose a sparse output or a lower resolution");
    detail::check_host_memory(n, detail::default_host_budget(),
                              "a dense copy of this " + std::to_string(grid_.dims[0]) + "x" +
                                  std::to_string(grid_.dims[1]) + "x" +
                                  std::to_string(grid_.dims[2]) + " grid");
    std::vector<uint8_t> dense(n, 0);
    const int64_t nx = grid_.dims[0], ny = grid_.dims[1];
    mark_box({0, 0, 0}, grid_.dims, {1, nx, nx * ny}, dense.data());
    return dense;
}

bool SparseVoxels::same_voxels(const SparseVoxels& other) const {
    if (grid_.dims != other.grid_.dims || grid_.origin != other.grid_.origin ||
        grid_.voxel_size != other.grid_.voxel_size)
        return false;
    if (count() != other.count()) return false;
    bool same = true;
    for_each([&](int64_t i, int64_t j, int64_t k) { same = same && other.get(i, j, k); });
    return same;
}

}  // namespace oclvox
