// Sparse narrow-band fields: leaves of 8x8x8 samples kept sorted by leaf index, and the inside
// voxels that sign every sample outside them. Reading a box finds each leaf it touches once per
// row of leaves, so any slab, the border or the whole grid costs one step per sample.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "host_memory.hpp"
#include "oclvox/field.hpp"

namespace oclvox {

namespace {

constexpr int64_t kLeaf = SparseField::kLeaf;

}  // namespace

SparseField::SparseField(const Grid& grid, double band_voxels, SparseVoxels inside)
    : grid_(grid),
      band_voxels_(band_voxels),
      background_(float(band_voxels * grid.voxel_size)),
      inside_(std::move(inside)) {
    validate_grid(grid);
    if (!same_grid(inside_.grid(), grid))
        throw GridError("a sparse field's inside voxels must have the field's grid");
    if (!(background_ > 0) || !std::isfinite(background_))
        throw GridError("a sparse field's band must be finite and positive, got " +
                        std::to_string(band_voxels) + " voxels");
}

std::array<int64_t, 3> SparseField::leaf_dims() const {
    return {(grid_.dims[0] + kLeaf - 1) / kLeaf, (grid_.dims[1] + kLeaf - 1) / kLeaf,
            (grid_.dims[2] + kLeaf - 1) / kLeaf};
}

std::array<int64_t, 3> SparseField::leaf_origin(uint64_t leaf_index) const {
    const auto n = leaf_dims();
    return {int64_t(leaf_index % uint64_t(n[0])) * kLeaf,
            int64_t(leaf_index / uint64_t(n[0]) % uint64_t(n[1])) * kLeaf,
            int64_t(leaf_index / (uint64_t(n[0]) * uint64_t(n[1]))) * kLeaf};
}

void SparseField::append_leaf(uint64_t leaf_index, const float* samples) {
    const auto n = leaf_dims();
    if (leaf_index >= uint64_t(n[0]) * uint64_t(n[1]) * uint64_t(n[2]))
        throw GridError("leaf " + std::to_string(leaf_index) + " is outside the field's grid");
    if (!leaf_keys_.empty() && leaf_index <= leaf_keys_.back())
        throw GridError("leaf " + std::to_string(leaf_index) +
                        " does not come after the last stored leaf");
    leaf_keys_.push_back(leaf_index);
    samples_.insert(samples_.end(), samples, samples + kLeafSamples);
}

void SparseField::merge(const SparseField& other) {
    if (!same_grid(grid_, other.grid_) || band_voxels_ != other.band_voxels_ ||
        inside_.brick_size() != other.inside_.brick_size())
        throw GridError("merging sparse fields needs the same grid, band and brick size");
    for (const uint64_t brick : other.inside_.brick_indices())
        inside_.merge_brick(brick, other.inside_.brick_blocks(brick));
    if (other.leaf_keys_.empty()) return;
    if (leaf_keys_.empty() || other.leaf_keys_.front() > leaf_keys_.back()) {
        leaf_keys_.insert(leaf_keys_.end(), other.leaf_keys_.begin(), other.leaf_keys_.end());
        samples_.insert(samples_.end(), other.samples_.begin(), other.samples_.end());
        return;
    }
    // Interleaved leaves: both sorted lists merged into new ones.
    std::vector<uint64_t> keys;
    std::vector<float> samples;
    keys.reserve(leaf_keys_.size() + other.leaf_keys_.size());
    samples.reserve(samples_.size() + other.samples_.size());
    size_t a = 0, b = 0;
    while (a < leaf_keys_.size() || b < other.leaf_keys_.size()) {
        const bool from_this = b == other.leaf_keys_.size() ||
                               (a < leaf_keys_.size() && leaf_keys_[a] < other.leaf_keys_[b]);
        if (!from_this && a < leaf_keys_.size() && leaf_keys_[a] == other.leaf_keys_[b])
            throw GridError("leaf " + std::to_string(leaf_keys_[a]) +
                            " is in both of the sparse fields being merged");
        const float* leaf = from_this ? leaf_samples(a) : other.leaf_samples(b);
        keys.push_back(from_this ? leaf_keys_[a++] : other.leaf_keys_[b++]);
        samples.insert(samples.end(), leaf, leaf + kLeafSamples);
    }
    leaf_keys_ = std::move(keys);
    samples_ = std::move(samples);
}

float SparseField::at(int64_t i, int64_t j, int64_t k) const {
    const auto& d = grid_.dims;
    if (i < 0 || j < 0 || k < 0 || i >= d[0] || j >= d[1] || k >= d[2])
        throw std::out_of_range("SparseField::at(" + std::to_string(i) + ", " + std::to_string(j) +
                                ", " + std::to_string(k) + ") is outside the grid");
    float value;
    copy_box({i, j, k}, {i + 1, j + 1, k + 1}, &value);
    return value;
}

void SparseField::copy_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi,
                           float* out) const {
    for (int a = 0; a < 3; ++a)
        if (lo[a] < 0 || lo[a] > hi[a] || hi[a] > grid_.dims[a])
            throw GridError("box [" + std::to_string(lo[a]) + ", " + std::to_string(hi[a]) +
                            ") on axis " + std::to_string(a) + " is not inside the field's grid");
    const int64_t wx = hi[0] - lo[0], wy = hi[1] - lo[1];
    if (wx == 0 || wy == 0 || hi[2] == lo[2]) return;

    // Leaf by leaf over the box: a stored leaf's rows are copied; elsewhere the background,
    // signed by the inside voxels (marked only there, since leaves are most of a box near the
    // surface). The leaves of a row (fixed ly, lz) are consecutive in index order, so one search
    // finds the first of them.
    const auto n = leaf_dims();
    uint8_t inside[kLeafSamples];
    for (int64_t lz = lo[2] / kLeaf; lz <= (hi[2] - 1) / kLeaf; ++lz)
        for (int64_t ly = lo[1] / kLeaf; ly <= (hi[1] - 1) / kLeaf; ++ly) {
            const uint64_t row = uint64_t(n[0]) * (uint64_t(ly) + uint64_t(n[1]) * uint64_t(lz));
            auto it = std::lower_bound(leaf_keys_.begin(), leaf_keys_.end(),
                                       row + uint64_t(lo[0] / kLeaf));
            for (int64_t lx = lo[0] / kLeaf; lx <= (hi[0] - 1) / kLeaf; ++lx) {
                const int64_t ox = lx * kLeaf, oy = ly * kLeaf, oz = lz * kLeaf;
                const std::array<int64_t, 3> a = {std::max(lo[0], ox), std::max(lo[1], oy),
                                                  std::max(lo[2], oz)};
                const std::array<int64_t, 3> b = {std::min(hi[0], ox + kLeaf),
                                                  std::min(hi[1], oy + kLeaf),
                                                  std::min(hi[2], oz + kLeaf)};
                float* first = out + (a[0] - lo[0]) + wx * ((a[1] - lo[1]) + wy * (a[2] - lo[2]));
                const int64_t sx = b[0] - a[0], sy = b[1] - a[1], sz = b[2] - a[2];
                if (it != leaf_keys_.end() && *it == row + uint64_t(lx)) {
                    const float* leaf = leaf_samples(size_t(it - leaf_keys_.begin()));
                    for (int64_t z = 0; z < sz; ++z)
                        for (int64_t y = 0; y < sy; ++y)
                            std::memcpy(first + wx * (y + wy * z),
                                        leaf + (a[0] - ox) +
                                            kLeaf * ((a[1] - oy + y) + kLeaf * (a[2] - oz + z)),
                                        size_t(sx) * sizeof(float));
                    ++it;
                    continue;
                }
                std::fill_n(inside, size_t(sx * sy * sz), uint8_t(0));
                inside_.mark_box(a, b, {1, sx, sx * sy}, inside);
                for (int64_t z = 0; z < sz; ++z)
                    for (int64_t y = 0; y < sy; ++y)
                        for (int64_t x = 0; x < sx; ++x)
                            first[x + wx * (y + wy * z)] =
                                inside[size_t(x + sx * (y + sy * z))] ? -background_ : background_;
            }
        }
}

void SparseField::copy_leaf(uint64_t leaf_index, float* samples) const {
    const auto n = leaf_dims();
    if (leaf_index >= uint64_t(n[0]) * uint64_t(n[1]) * uint64_t(n[2]))
        throw GridError("leaf " + std::to_string(leaf_index) + " is outside the field's grid");
    const auto it = std::lower_bound(leaf_keys_.begin(), leaf_keys_.end(), leaf_index);
    if (it != leaf_keys_.end() && *it == leaf_index) {
        std::memcpy(samples, leaf_samples(size_t(it - leaf_keys_.begin())),
                    kLeafSamples * sizeof(float));
        return;
    }
    // Not stored: the background, negated at the inside voxels of the leaf's part in the grid.
    const std::array<int64_t, 3> lo = leaf_origin(leaf_index);
    const std::array<int64_t, 3> hi = {std::min(lo[0] + kLeaf, grid_.dims[0]),
                                       std::min(lo[1] + kLeaf, grid_.dims[1]),
                                       std::min(lo[2] + kLeaf, grid_.dims[2])};
    uint8_t inside[kLeafSamples] = {};
    inside_.mark_box(lo, hi, {1, kLeaf, kLeaf * kLeaf}, inside);
    for (size_t v = 0; v < kLeafSamples; ++v) samples[v] = inside[v] ? -background_ : background_;
}

ScalarField SparseField::to_dense() const {
    detail::check_host_memory(
        grid_.voxel_count() * sizeof(float), detail::default_host_budget(),
        "a dense field of " + std::to_string(grid_.voxel_count()) + " samples");
    ScalarField field;
    field.grid = grid_;
    field.values.resize(size_t(grid_.voxel_count()));
    // A layer of leaves at a time, so the inside marks stay small.
    const size_t layer = size_t(grid_.dims[0]) * size_t(grid_.dims[1]);
    for (int64_t z = 0; z < grid_.dims[2]; z += kLeaf) {
        const int64_t end = std::min(grid_.dims[2], z + kLeaf);
        copy_box({0, 0, z}, {grid_.dims[0], grid_.dims[1], end}, &field.values[size_t(z) * layer]);
    }
    return field;
}

uint64_t border_samples_inside(const SparseField& field, float iso) {
    // The six faces as boxes that do not overlap: both z faces whole, both y faces between them,
    // both x faces between those (a face of a one-sample-thick grid is counted once).
    const auto& d = field.grid().dims;
    std::vector<std::pair<std::array<int64_t, 3>, std::array<int64_t, 3>>> faces;
    for (int64_t k : {int64_t(0), d[2] - 1}) {
        faces.push_back({{0, 0, k}, {d[0], d[1], k + 1}});
        if (d[2] == 1) break;
    }
    for (int64_t j : {int64_t(0), d[1] - 1}) {
        faces.push_back({{0, j, 1}, {d[0], j + 1, std::max<int64_t>(1, d[2] - 1)}});
        if (d[1] == 1) break;
    }
    for (int64_t i : {int64_t(0), d[0] - 1}) {
        faces.push_back(
            {{i, 1, 1}, {i + 1, std::max<int64_t>(1, d[1] - 1), std::max<int64_t>(1, d[2] - 1)}});
        if (d[0] == 1) break;
    }
    // A face of a sparse grid can hold far more samples than memory, so none is read whole: the
    // stored leaves that meet it are read sample by sample, and every other sample is
    // -background at an inside voxel and +background elsewhere, so those are counted from the
    // inside voxels.
    const float background = field.background();
    const bool negative_inside = -background < iso, positive_inside = background < iso;
    uint64_t inside = 0;
    for (const auto& [lo, hi] : faces) {
        uint64_t leaf_samples = 0, leaf_voxels_inside = 0;
        for (size_t n = 0; n < field.leaf_count(); ++n) {
            const auto o = field.leaf_origin(field.leaf_indices()[n]);
            std::array<int64_t, 3> a, b;
            bool meets = true;
            for (int k = 0; k < 3; ++k) {
                a[k] = std::max(lo[k], o[k]);
                b[k] = std::min(hi[k], o[k] + kLeaf);
                meets = meets && a[k] < b[k];
            }
            if (!meets) continue;
            const float* leaf = field.leaf_samples(n);
            for (int64_t z = a[2]; z < b[2]; ++z)
                for (int64_t y = a[1]; y < b[1]; ++y)
                    for (int64_t x = a[0]; x < b[0]; ++x)
                        inside +=
                            leaf[(x - o[0]) + kLeaf * ((y - o[1]) + kLeaf * (z - o[2]))] < iso;
            leaf_samples += uint64_t((b[0] - a[0]) * (b[1] - a[1]) * (b[2] - a[2]));
            leaf_voxels_inside += field.inside().count_box(a, b);
        }
        const uint64_t others =
            uint64_t((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2])) - leaf_samples;
        const uint64_t others_inside = field.inside().count_box(lo, hi) - leaf_voxels_inside;
        inside +=
            (negative_inside ? others_inside : 0) + (positive_inside ? others - others_inside : 0);
    }
    return inside;
}

}  // namespace oclvox
