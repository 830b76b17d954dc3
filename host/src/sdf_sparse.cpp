// Sparse narrow-band distance fields: the band computed only in the 8x8x8 leaves a triangle's band
// reaches, signed by the solid voxelization, kept as a SparseField. The leaves, and the triangles
// reaching each, are binned first on the host from the same block culls the band pass makes (so
// the leaf set is exact, not a guess, and the same on every device); then each leaf's samples are
// the minimum over its triangles (on a device, sdf_sparse_device.cpp), or, in the reference here,
// every triangle scatters its band samples into the leaves. The samples equal the dense field's
// bit for bit: the same prepared triangles, the same squared distances, the same minimum, the same
// conversion and the same solid. Dense fields are in sdf.cpp.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

#include "bit_count.hpp"
#include "host_memory.hpp"
#include "sdf_internal.hpp"

namespace oclvox {

namespace detail {

namespace {

constexpr int64_t kLeaf = SparseField::kLeaf;
constexpr size_t kLeafSamples = SparseField::kLeafSamples;

// The reference of band_leaf_samples, all leaves in one batch: every triangle scatters its band
// samples into the leaves, through the same culls as the dense band pass.
std::vector<float> leaf_distance2_reference(const SdfTriangles& prepared, const LeafSet& leaves,
                                            ProgressPhases& progress, size_t phase) {
    std::vector<float> distance2(size_t(leaves.count) * kLeafSamples, prepared.band2);
    for (size_t index = 0; index < prepared.triangles.size(); ++index) {
        const OvSdfTriangle& t = prepared.triangles[index];
        for_each_near_block(t, prepared.band, [&](int bx, int by, int bz) {
            float* samples =
                &distance2[leaves.slot(leaves.leaf_of_block(bx, by, bz)) * kLeafSamples];
            for_each_band_sample(
                t, bx, by, bz, prepared.band, prepared.band2, [&](int i, int j, int k, float d2) {
                    float& sample = samples[(i & 7) + kLeaf * ((j & 7) + kLeaf * (k & 7))];
                    sample = std::min(sample, d2);
                });
        });
        progress.report(phase, prepared.first_item[index + 1], prepared.first_item.back());
    }
    return distance2;
}

// Appends the leaves of the next `slots` slots to the field, batch after batch in slot order:
// world distances as distance_field makes them, negated where the inside voxels are set, as
// apply_sign negates them. leaf_ walks the set leaf bits alongside the slots.
class LeafWriter {
  public:
    LeafWriter(const LeafSet& leaves, const SdfTriangles& prepared)
        : leaves_(leaves), band2_(prepared.band2) {}

    void append(SparseField& field, uint64_t slots, const float* distance2) {
        float signs[kLeafSamples], samples[kLeafSamples];
        for (uint64_t s = 0; s < slots; ++s, ++leaf_) {
            leaf_ = leaves_.set_from(leaf_);
            // The leaf is not stored yet: copy_leaf gives -background at its inside voxels.
            field.copy_leaf(leaf_, signs);
            const float* d2 = distance2 + s * kLeafSamples;
            for (size_t v = 0; v < kLeafSamples; ++v) {
                const float value = d2[v] < band2_
                                        ? float(std::sqrt(double(d2[v])) * field.grid().voxel_size)
                                        : field.background();
                samples[v] = signs[v] < 0 ? -value : value;
            }
            field.append_leaf(leaf_, samples);
        }
    }

  private:
    const LeafSet& leaves_;
    float band2_;
    uint64_t leaf_ = 0;
};

// A sparse field is a narrow band of the whole grid; its layers, if given, are whole leaf layers
// (so that a leaf is computed in one range of layers only).
void validate_sparse(const Grid& grid, const SdfOptions& options) {
    validate_sdf_options(grid, options);
    if (options.full_grid)
        throw GridError(
            "a sparse field holds a narrow band; a full-grid field needs the dense "
            "signed_distance");
    const int64_t end = options.end_layer ? options.end_layer : grid.dims[2];
    if (options.first_layer % kLeaf != 0 || (end % kLeaf != 0 && end != grid.dims[2]))
        throw GridError("the layers of a sparse field must start at a multiple of " +
                        std::to_string(kLeaf) + " and end at one or at the top of the grid, got " +
                        std::to_string(options.first_layer) + " to " + std::to_string(end));
}

// Prepares a mesh's triangles for a sparse field and adds its phases.
FieldJob plan_sparse(const Mesh& mesh, const Grid& grid, const SdfOptions& options,
                     ProgressPhases& progress, VoxelizeStats& stats) {
    return plan_field(mesh, grid, options, true, true, progress, stats);
}

// The job's sparse field on a device, or (device null) the reference.
SparseField compute_sparse(Device* device, const FieldJob& job, const Grid& grid,
                           const SdfOptions& options, ProgressPhases& progress,
                           VoxelizeStats& stats) {
    // Phase 1: the leaves the band reaches, and the memory their samples need (the field's
    // samples, and beside them one batch, or the reference's squared distances).
    auto t = Clock::now();
    // Triangles are clipped to the layers (plan_field), so the leaves are those of the layers.
    const BandLeaves band =
        band_leaves(job.prepared, grid, options, progress.reporter(job.phases.leaves));
    const LeafSet& leaves = band.leaves;
    stats.seconds_binning += seconds_since(t);
    stats.bricks_total =
        uint64_t(leaves.dims[0]) * uint64_t(leaves.dims[1]) * uint64_t(leaves.dims[2]);
    stats.bricks_active = leaves.count;
    const uint64_t working = device ? std::min(leaves.count, kMaxBatchLeaves) : leaves.count;
    check_host_memory(
        (leaves.count + working) * kLeafSamples * sizeof(float),
        host_budget(options.host_budget_bytes),
        "the samples of " + std::to_string(leaves.count) + " leaves of a sparse distance field");

    // Phase 2: the sign. The solid comes first so each batch of distances becomes signed leaves
    // as it arrives, and is dropped.
    SparseVoxels inside =
        sign_voxels(device, job.mesh, grid, options, progress, job.phases.sign, stats);
    SparseField field(grid, options.band_voxels, std::move(inside));
    field.reserve_leaves(size_t(leaves.count));
    LeafWriter writer(leaves, job.prepared);

    // Phase 3: the band in the leaves, batch by batch into the field.
    t = Clock::now();
    auto append = [&](uint64_t, uint64_t slots, const float* distance2) {
        writer.append(field, slots, distance2);
    };
    if (device) {
        leaf_distance2_device(*device, job.prepared, band, options, progress, job.phases.band,
                              stats, append);
    } else {
        const std::vector<float> distance2 =
            leaf_distance2_reference(job.prepared, leaves, progress, job.phases.band);
        stats.seconds_kernels += seconds_since(t);
        append(0, leaves.count, distance2.data());
    }
    return field;
}

SparseField sparse_run(Device* device, const Mesh& mesh, const Grid& grid,
                       const SdfOptions& options, VoxelizeStats* stats_out) {
    validate_sparse(grid, options);
    ProgressPhases progress(options.progress, "signed distance field");
    VoxelizeStats stats;
    const FieldJob job = plan_sparse(mesh, grid, options, progress, stats);
    SparseField field = compute_sparse(device, job, grid, options, progress, stats);
    progress.finish();
    if (stats_out) *stats_out = stats;
    return field;
}

SparseField sparse_csg_run(Device* device, const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                           const SdfOptions& options, VoxelizeStats* stats_out) {
    // Phase 1: both fields' phases, so that progress runs once over both.
    validate_sparse(grid, options);
    if (options.first_layer != 0 || options.end_layer != 0)
        throw GridError(
            "a sparse CSG of meshes covers the whole grid (no layers); the dense csg takes layers");
    ProgressPhases progress(options.progress, "CSG");
    VoxelizeStats stats, stats_b;
    const FieldJob job_a = plan_sparse(a, grid, options, progress, stats);
    const FieldJob job_b = plan_sparse(b, grid, options, progress, stats_b);

    // Phase 2: both fields, then their leaves combined.
    const SparseField field_a = compute_sparse(device, job_a, grid, options, progress, stats);
    const SparseField field_b = compute_sparse(device, job_b, grid, options, progress, stats_b);
    SparseField field = csg(field_a, field_b, op);
    progress.finish();
    add_second_field_stats(stats, stats_b);
    if (stats_out) *stats_out = stats;
    return field;
}

}  // namespace

uint64_t LeafSet::leaf_at(uint64_t slot) const {
    // The last word whose rank is at most the slot holds it (words with no bit share the rank of
    // the next word that has one).
    const size_t word =
        size_t(std::upper_bound(rank.begin(), rank.end(), uint32_t(slot)) - rank.begin() - 1);
    uint32_t bits_left = bits[word];
    for (uint64_t skip = slot - rank[word]; skip > 0; --skip) bits_left &= bits_left - 1;
    return uint64_t(word) * 32 + uint64_t(__builtin_ctz(bits_left));
}

void LeafSet::rank_bits() {
    rank.resize(bits.size());
    count = 0;
    for (size_t w = 0; w < bits.size(); ++w) {
        rank[w] = uint32_t(count);
        count += uint64_t(popcount64(bits[w]));
    }
}

LeafSet empty_leaf_set(const Grid& grid, const SdfOptions& options) {
    LeafSet leaves;
    for (int a = 0; a < 3; ++a) leaves.dims[a] = (grid.dims[a] + kLeaf - 1) / kLeaf;
    const uint64_t total =
        uint64_t(leaves.dims[0]) * uint64_t(leaves.dims[1]) * uint64_t(leaves.dims[2]);
    const uint64_t words = (total + 31) / 32;
    // Slots are 32-bit on the device: more leaves than that could never be held anyway.
    if (words > (uint64_t(1) << 27))
        throw GridError("a sparse field of " + std::to_string(total) +
                        " leaves is over the limit of 2^32 leaves: lower the resolution");
    check_host_memory(words * 2 * sizeof(uint32_t), host_budget(options.host_budget_bytes),
                      "the leaf bits of a sparse distance field");
    leaves.bits.assign(size_t(words), 0);
    return leaves;
}

namespace {

// The rows along y (bits 0-7) and layers along z (bits 8-15) of the leaf with lowest voxel
// `origin` that the triangle's voxel range reaches. band_leaf_samples tests a row against these
// bits before it copies the triangle: on a mesh of many small triangles three quarters of a
// leaf's (row, triangle) pairs fail the test, and the bits are 2 bytes in list order where the
// range is in a 188-byte triangle.
uint16_t leaf_rows(const OvSdfTriangle& t, const std::array<int64_t, 3>& origin) {
    auto bits = [](int64_t lo, int64_t hi) {  // bits lo..hi of 0..7
        lo = std::max<int64_t>(lo, 0);
        hi = std::min<int64_t>(hi, kLeaf - 1);
        return lo > hi ? 0u : (2u << hi) - (1u << lo);
    };
    return uint16_t(bits(t.lo[1] - origin[1], t.hi[1] - origin[1]) |
                    bits(t.lo[2] - origin[2], t.hi[2] - origin[2]) << 8);
}

struct LeafPair {
    uint64_t leaf;
    uint32_t triangle;
    uint16_t rows;  // leaf_rows
};

}  // namespace

BandLeaves band_leaves(const SdfTriangles& prepared, const Grid& grid, const SdfOptions& options,
                       const std::function<void(uint64_t done, uint64_t total)>& report) {
    BandLeaves out;
    out.leaves = empty_leaf_set(grid, options);
    LeafSet& leaves = out.leaves;
    const size_t n = prepared.triangles.size();
    const uint64_t budget = host_budget(options.host_budget_bytes);

    // Phase 1: each triangle's leaves, those holding a block its cull keeps. Triangles are
    // independent, so fixed chunks of them run in parallel and are joined in chunk order: the
    // lists come out in ascending triangle order whatever the threads. Reports (and so a cancel)
    // come between rounds of chunks, on this thread.
    // The budget is checked as the lists grow, not once they are whole, so that a grid too large
    // for it (one triangle across a grid of 100000^2 voxels reaches 1.5e8 leaves, 300 GB of
    // samples) is refused in a moment instead of after minutes and gigabytes of lists. Leaves
    // and pairs only grow, so every refusal here is one the checks on the whole would make: one
    // triangle's leaves are among the field's, a leaf is at most 8 of its blocks, and the pairs
    // so far are among all pairs. Which check comes first depends on the threads, so all three
    // give one message.
    const uint64_t pair_bytes = sizeof(LeafPair) + 2 * sizeof(uint32_t) + sizeof(uint16_t);
    const uint64_t max_leaves = budget / (kLeafSamples * sizeof(float));
    const uint64_t max_pairs = budget / pair_bytes;
    auto refuse = [&] {
        throw GridError(
            "the band of this sparse distance field outgrows the host memory budget of " +
            mib_text(budget) +
            " (its leaves' samples or their triangle lists): lower the resolution "
            "or the band, or raise the budget");
    };
    constexpr size_t kChunk = 2048, kRound = 32, kCountStep = 65536;
    const size_t chunks = (n + kChunk - 1) / kChunk;
    std::vector<std::vector<LeafPair>> chunk_pairs(chunks);
    std::atomic<uint64_t> pairs_so_far{0};
    for (size_t round = 0; round < chunks; round += kRound) {
        const size_t round_end = std::min(chunks, round + kRound);
        tbb::parallel_for(round, round_end, [&](size_t c) {
            auto& chunk = chunk_pairs[c];
            std::vector<uint64_t> own;
            size_t counted = 0;  // of the chunk's pairs, those in pairs_so_far
            const size_t end = std::min(n, (c + 1) * kChunk);
            for (size_t index = c * kChunk; index < end; ++index) {
                own.clear();
                for_each_near_block(prepared.triangles[index], prepared.band,
                                    [&](int bx, int by, int bz) {
                                        if (own.size() > 8 * max_leaves) refuse();
                                        own.push_back(leaves.leaf_of_block(bx, by, bz));
                                    });
                std::sort(own.begin(), own.end());
                own.erase(std::unique(own.begin(), own.end()), own.end());
                if (own.size() > max_leaves) refuse();
                for (const uint64_t leaf : own)
                    chunk.push_back({leaf, uint32_t(index),
                                     leaf_rows(prepared.triangles[index], leaves.origin(leaf))});
                // Added to the shared count in steps, not a triangle at a time, so that the
                // threads do not contend for it.
                if (chunk.size() - counted >= kCountStep || index + 1 == end) {
                    if ((pairs_so_far += chunk.size() - counted) > max_pairs) refuse();
                    counted = chunk.size();
                }
            }
        });
        if (report) report(round_end, chunks);
    }
    const uint64_t pairs = pairs_so_far;
    if (pairs >= (uint64_t(1) << 32))
        throw GridError("a sparse distance field of " + std::to_string(pairs) +
                        " (leaf, triangle) pairs is over the limit of 2^32: lower the resolution");

    // Phase 2: the leaf bits and their ranks, then the lists by slot (a counting sort, stable, so
    // each list stays ascending).
    for (const auto& chunk : chunk_pairs)
        for (const LeafPair& pair : chunk)
            leaves.bits[size_t(pair.leaf >> 5)] |= 1u << (pair.leaf & 31);
    leaves.rank_bits();
    out.first.assign(size_t(leaves.count) + 1, 0);
    for (const auto& chunk : chunk_pairs)
        for (const LeafPair& pair : chunk) ++out.first[size_t(leaves.slot(pair.leaf)) + 1];
    for (size_t slot = 0; slot < leaves.count; ++slot) out.first[slot + 1] += out.first[slot];
    out.triangles.resize(size_t(pairs));
    out.rows.resize(size_t(pairs));
    std::vector<uint32_t> next(out.first.begin(), out.first.end() - 1);
    for (auto& chunk : chunk_pairs) {
        for (const LeafPair& pair : chunk) {
            const uint32_t place = next[leaves.slot(pair.leaf)]++;
            out.triangles[place] = pair.triangle;
            out.rows[place] = pair.rows;
        }
        std::vector<LeafPair>().swap(chunk);
    }
    return out;
}

}  // namespace detail

SparseField signed_distance_sparse(Device& device, const Mesh& mesh, const Grid& grid,
                                   const SdfOptions& options, VoxelizeStats* stats) {
    return detail::sparse_run(&device, mesh, grid, options, stats);
}

SparseField signed_distance_sparse_reference(const Mesh& mesh, const Grid& grid,
                                             const SdfOptions& options, VoxelizeStats* stats) {
    return detail::sparse_run(nullptr, mesh, grid, options, stats);
}

SparseField csg_sparse(Device& device, const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                       const SdfOptions& options, VoxelizeStats* stats) {
    return detail::sparse_csg_run(&device, a, b, op, grid, options, stats);
}

SparseField csg_sparse_reference(const Mesh& a, const Mesh& b, CsgOp op, const Grid& grid,
                                 const SdfOptions& options, VoxelizeStats* stats) {
    return detail::sparse_csg_run(nullptr, a, b, op, grid, options, stats);
}

}  // namespace oclvox
