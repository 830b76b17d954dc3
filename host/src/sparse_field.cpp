// Sparse narrow-band fields: leaves of 8x8x8 samples kept sorted by leaf index, and the inside
// voxels that sign every sample outside them. Reading a box finds each leaf it touches once per
// row of leaves, so any slab, the border or the whole grid costs one step per sample.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "host_memory.hpp"
#include "number_text.hpp"
#include "oclvox/field.hpp"

namespace oclvox {

namespace {

constexpr int64_t kLeaf = SparseField::kLeaf;

// Samples of a box from which copy_box reads its rows of leaves in parallel.
constexpr int64_t kParallelBox = 1 << 16;

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
                        detail::number_text(band_voxels) + " voxels");
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

    // Row of leaves by row of leaves (fixed ly, lz: consecutive in index order, so one search
    // finds the first stored one): a stored leaf's rows are copied; elsewhere the background,
    // signed by the inside voxels, marked once for each run of leaves not stored (a mark for each
    // such leaf cost more than copying the samples: the per-call work of finding bricks). Rows
    // write disjoint parts of the box: in parallel when the box is large (a small one, as the
    // meshers read, is not worth the tasks).
    const auto n = leaf_dims();
    const int64_t ly_first = lo[1] / kLeaf, ly_count = (hi[1] - 1) / kLeaf + 1 - ly_first;
    const int64_t lz_first = lo[2] / kLeaf, lz_count = (hi[2] - 1) / kLeaf + 1 - lz_first;
    const int64_t lx_first = lo[0] / kLeaf, lx_end = (hi[0] - 1) / kLeaf + 1;
    auto copy_row = [&](int64_t row_number) {
        const int64_t ly = ly_first + row_number % ly_count, lz = lz_first + row_number / ly_count;
        const int64_t oy = ly * kLeaf, oz = lz * kLeaf;
        const int64_t ay = std::max(lo[1], oy), az = std::max(lo[2], oz);
        const int64_t sy = std::min(hi[1], oy + kLeaf) - ay, sz = std::min(hi[2], oz + kLeaf) - az;
        float* first = out + wx * ((ay - lo[1]) + wy * (az - lo[2]));
        const uint64_t row = uint64_t(n[0]) * (uint64_t(ly) + uint64_t(n[1]) * uint64_t(lz));
        auto it = std::lower_bound(leaf_keys_.begin(), leaf_keys_.end(), row + uint64_t(lx_first));
        std::vector<uint8_t> inside;
        for (int64_t lx = lx_first; lx < lx_end;) {
            // The leaves [lx, next) are not stored; leaf `next` is, if inside the box.
            const int64_t next = it != leaf_keys_.end() && *it < row + uint64_t(lx_end)
                                     ? int64_t(*it - row)
                                     : lx_end;
            const int64_t ax = std::max(lo[0], lx * kLeaf);
            if (next > lx) {
                const int64_t sx = std::min(hi[0], next * kLeaf) - ax;
                inside.assign(size_t(sx * sy * sz), 0);
                inside_.mark_box({ax, ay, az}, {ax + sx, ay + sy, az + sz}, {1, sx, sx * sy},
                                 inside.data());
                for (int64_t z = 0; z < sz; ++z)
                    for (int64_t y = 0; y < sy; ++y)
                        for (int64_t x = 0; x < sx; ++x)
                            first[(ax - lo[0]) + x + wx * (y + wy * z)] =
                                inside[size_t(x + sx * (y + sy * z))] ? -background_ : background_;
                lx = next;
                continue;
            }
            const int64_t ox = lx * kLeaf, sx = std::min(hi[0], ox + kLeaf) - ax;
            const float* leaf = leaf_samples(size_t(it - leaf_keys_.begin()));
            for (int64_t z = 0; z < sz; ++z)
                for (int64_t y = 0; y < sy; ++y)
                    std::memcpy(first + (ax - lo[0]) + wx * (y + wy * z),
                                leaf + (ax - ox) + kLeaf * ((ay - oy + y) + kLeaf * (az - oz + z)),
                                size_t(sx) * sizeof(float));
            ++it;
            ++lx;
        }
    };
    if (wx * wy * (hi[2] - lo[2]) < kParallelBox)
        for (int64_t r = 0; r < ly_count * lz_count; ++r) copy_row(r);
    else
        tbb::parallel_for(int64_t(0), ly_count * lz_count, copy_row);
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
