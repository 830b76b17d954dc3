// Sparse brick storage of a bit grid. See SparseVoxels in oclvox.hpp for the layout.
#include <cstring>

#include "oclvox/oclvox.hpp"

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

bool inside(const Grid& g, int64_t i, int64_t j, int64_t k) {
    return i >= 0 && j >= 0 && k >= 0 && i < g.dims[0] && j < g.dims[1] && k < g.dims[2];
}
}  // namespace

bool SparseVoxels::get(int64_t i, int64_t j, int64_t k) const {
    if (!inside(grid_, i, j, k)) return false;
    const Address a = address_of(*this, i, j, k);
    auto it = bricks_.find(a.brick);
    return it != bricks_.end() && ((it->second[a.word] >> a.bit) & 1u);
}

void SparseVoxels::set(int64_t i, int64_t j, int64_t k) {
    if (!inside(grid_, i, j, k)) throw std::out_of_range("SparseVoxels::set outside the grid");
    const Address a = address_of(*this, i, j, k);
    auto& brick = bricks_[a.brick];
    if (brick.empty()) brick.assign(blocks_per_brick(), 0);
    brick[a.word] |= uint64_t(1) << a.bit;
}

uint64_t SparseVoxels::count() const {
    uint64_t n = 0;
    for (const auto& [index, blocks] : bricks_)
        for (uint64_t w : blocks) n += uint64_t(__builtin_popcountll(w));
    return n;
}

void SparseVoxels::merge_brick(uint64_t brick_index, const uint64_t* blocks) {
    const size_t n = blocks_per_brick();
    bool any = false;
    for (size_t w = 0; w < n && !any; ++w) any = blocks[w] != 0;
    if (!any) return;
    auto& brick = bricks_[brick_index];
    if (brick.empty()) {
        brick.assign(blocks, blocks + n);
        return;
    }
    for (size_t w = 0; w < n; ++w) brick[w] |= blocks[w];
}

void SparseVoxels::for_each(const std::function<void(int64_t, int64_t, int64_t)>& f) const {
    const auto nbricks = brick_dims();
    const int64_t b = brick_size_, nb = blocks_per_brick_axis();
    for (const auto& [index, blocks] : bricks_) {
        const int64_t bx = int64_t(index % uint64_t(nbricks[0]));
        const int64_t by = int64_t(index / uint64_t(nbricks[0]) % uint64_t(nbricks[1]));
        const int64_t bz = int64_t(index / (uint64_t(nbricks[0]) * uint64_t(nbricks[1])));
        for (size_t w = 0; w < blocks.size(); ++w) {
            uint64_t mask = blocks[w];
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

std::vector<uint8_t> SparseVoxels::to_dense() const {
    const uint64_t n = grid_.voxel_count();
    if (n > (uint64_t(1) << 36))
        throw GridError("a dense copy of this " + std::to_string(grid_.dims[0]) + "x" +
                        std::to_string(grid_.dims[1]) + "x" + std::to_string(grid_.dims[2]) +
                        " grid would need " + std::to_string(n >> 30) +
                        " GiB; choose a sparse output or a lower resolution");
    std::vector<uint8_t> dense(n, 0);
    const int64_t nx = grid_.dims[0], ny = grid_.dims[1];
    for_each([&](int64_t i, int64_t j, int64_t k) { dense[size_t(i + nx * (j + ny * k))] = 1; });
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
