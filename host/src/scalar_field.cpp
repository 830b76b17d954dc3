// Scalar fields: sample access, input checks for meshing, and the signed field of a voxel
// occupancy.
#include <algorithm>
#include <cmath>
#include <limits>

#include "host_memory.hpp"
#include "meshing.hpp"

namespace oclvox {

float ScalarField::at(int64_t i, int64_t j, int64_t k) const {
    const auto& n = grid.dims;
    if (i < 0 || j < 0 || k < 0 || i >= n[0] || j >= n[1] || k >= n[2])
        throw std::out_of_range("ScalarField::at(" + std::to_string(i) + ", " + std::to_string(j) +
                                ", " + std::to_string(k) + ") is outside the grid");
    return values.at(size_t(i + n[0] * (j + n[1] * k)));
}

uint64_t border_samples_inside(const ScalarField& field, float iso) {
    const auto& n = field.grid.dims;
    if (field.values.size() != field.grid.voxel_count())
        throw GridError("the field has " + std::to_string(field.values.size()) +
                        " values but its grid has " + std::to_string(field.grid.voxel_count()) +
                        " samples");
    uint64_t inside = 0;
    const size_t per_layer = size_t(n[0]) * size_t(n[1]);
    for (int64_t k = 0; k < n[2]; ++k)
        inside += border_samples_inside(field.grid, k, &field.values[size_t(k) * per_layer], iso);
    return inside;
}

uint64_t border_samples_inside(const Grid& grid, int64_t k, const float* samples, float iso) {
    const auto& n = grid.dims;
    uint64_t inside = 0;
    for (int64_t j = 0; j < n[1]; ++j) {
        const bool face = k == 0 || k == n[2] - 1 || j == 0 || j == n[1] - 1;
        // Inside a face row every sample is on the border; elsewhere only the two ends.
        const int64_t step = face ? 1 : std::max<int64_t>(1, n[0] - 1);
        for (int64_t i = 0; i < n[0]; i += step) inside += samples[size_t(i + n[0] * j)] < iso;
    }
    return inside;
}

// The field is made a layer at a time: pass p's layer k is the z average of pass p - 1's layers
// k - 1, k and k + 1, each first averaged along x and then y within itself, which is the whole-grid
// filter's order (x, then y, then z, every pass) sample for sample. So each pass holds its three
// x-y averaged layers in a ring, and a layer of the last pass pulls what it needs through them.
struct OccupancyFieldLayers::Impl {
    const SparseVoxels& voxels;
    Grid grid;
    int64_t pad = 0;
    size_t per_layer = 0;
    struct Pass {
        std::array<std::vector<float>, 3> ring;  // x-y averaged input layer j in ring[j % 3]
        int64_t averaged = 0;                    // input layers averaged so far
    };
    std::vector<Pass> passes;
    std::vector<float> row;  // the x average of a layer, before its y average
    int64_t next_layer = 0;

    Impl(const SparseVoxels& v, int smoothing_passes) : voxels(v) {
        if (smoothing_passes < 0)
            throw GridError("smoothing passes must be >= 0, got " +
                            std::to_string(smoothing_passes));
        // Each pass spreads the solid by one sample, so passes + 1 outside samples keep the
        // border outside and the surface closed.
        pad = int64_t(smoothing_passes) + 1;
        grid = voxels.grid();
        for (int k = 0; k < 3; ++k) {
            grid.origin[k] -= double(pad) * grid.voxel_size;
            grid.dims[k] += 2 * pad;
        }
        validate_grid(grid);
        per_layer = size_t(grid.dims[0]) * size_t(grid.dims[1]);
        detail::check_host_memory(uint64_t(3 * smoothing_passes + 1) * per_layer * sizeof(float),
                                  detail::default_host_budget(),
                                  "the smoothing passes' layers of " +
                                      std::to_string(grid.dims[0]) + "x" +
                                      std::to_string(grid.dims[1]) + " samples");
        passes.resize(size_t(smoothing_passes));
        for (Pass& pass : passes)
            for (std::vector<float>& layer : pass.ring) layer.resize(per_layer);
        row.resize(per_layer);
    }

    // Layer k of the unsmoothed field: -0.5 at set voxels, +0.5 elsewhere.
    void occupancy_layer(int64_t k, float* out) const {
        std::fill_n(out, per_layer, 0.5f);
        const int64_t v = k - pad;  // the voxels' layer
        const Grid& g = voxels.grid();
        if (v < 0 || v >= g.dims[2]) return;
        const int64_t brick = voxels.brick_size(), words = voxels.blocks_per_brick_axis();
        const auto bricks = voxels.brick_dims();
        const int64_t bz = v / brick, wz = v % brick / SparseVoxels::kBlock,
                      z = v % SparseVoxels::kBlock;
        for (int64_t by = 0; by < bricks[1]; ++by)
            for (int64_t bx = 0; bx < bricks[0]; ++bx) {
                const uint64_t* blocks =
                    voxels.brick_blocks(uint64_t(bx + bricks[0] * (by + bricks[1] * bz)));
                if (!blocks) continue;
                for (int64_t wy = 0; wy < words; ++wy)
                    for (int64_t wx = 0; wx < words; ++wx) {
                        const uint64_t word = blocks[size_t(wx + words * (wy + words * wz))];
                        if (!word) continue;
                        for (int64_t y = 0; y < SparseVoxels::kBlock; ++y)
                            for (int64_t x = 0; x < SparseVoxels::kBlock; ++x) {
                                if (!(word >> (x + 4 * (y + 4 * z)) & 1)) continue;
                                const int64_t i = bx * brick + wx * 4 + x + pad,
                                              j = by * brick + wy * 4 + y + pad;
                                out[size_t(i + grid.dims[0] * j)] = -0.5f;
                            }
                    }
            }
    }

    // Layer k of the field after `done` passes (k increasing for each `done`).
    void layer(size_t done, int64_t k, float* out) {
        if (done == 0) return occupancy_layer(k, out);
        Pass& pass = passes[done - 1];
        const int64_t nz = grid.dims[2];
        while (pass.averaged < std::min(k + 2, nz)) {
            std::vector<float>& averaged = pass.ring[size_t(pass.averaged % 3)];
            layer(done - 1, pass.averaged++, averaged.data());
            average_along_x_then_y(averaged);
        }
        const float* here = pass.ring[size_t(k % 3)].data();
        const float* below = k > 0 ? pass.ring[size_t((k - 1) % 3)].data() : nullptr;
        const float* above = k + 1 < nz ? pass.ring[size_t((k + 1) % 3)].data() : nullptr;
        for (size_t s = 0; s < per_layer; ++s)
            out[s] = ((below ? below[s] : 0.5f) + here[s] + (above ? above[s] : 0.5f)) / 3.0f;
    }

    // The 3-tap averages along x and then y within one layer (+0.5 beyond its edges).
    void average_along_x_then_y(std::vector<float>& layer) {
        const int64_t nx = grid.dims[0], ny = grid.dims[1];
        for (int64_t y = 0; y < ny; ++y)
            for (int64_t x = 0; x < nx; ++x) {
                const size_t s = size_t(x + nx * y);
                const float below = x > 0 ? layer[s - 1] : 0.5f;
                const float above = x + 1 < nx ? layer[s + 1] : 0.5f;
                row[s] = (below + layer[s] + above) / 3.0f;
            }
        for (int64_t y = 0; y < ny; ++y)
            for (int64_t x = 0; x < nx; ++x) {
                const size_t s = size_t(x + nx * y);
                const float below = y > 0 ? row[s - size_t(nx)] : 0.5f;
                const float above = y + 1 < ny ? row[s + size_t(nx)] : 0.5f;
                layer[s] = (below + row[s] + above) / 3.0f;
            }
    }
};

OccupancyFieldLayers::OccupancyFieldLayers(const SparseVoxels& voxels, int smoothing_passes)
    : impl_(std::make_unique<Impl>(voxels, smoothing_passes)) {}
OccupancyFieldLayers::~OccupancyFieldLayers() = default;

const Grid& OccupancyFieldLayers::grid() const {
    return impl_->grid;
}

void OccupancyFieldLayers::next_layer(float* samples) {
    if (impl_->next_layer == impl_->grid.dims[2])
        throw GridError("occupancy field: every one of its " + std::to_string(impl_->grid.dims[2]) +
                        " layers was given already");
    impl_->layer(impl_->passes.size(), impl_->next_layer++, samples);
}

SparseField occupancy_meshing_view(const SparseVoxels& voxels, int smoothing_passes, float iso) {
    OccupancyFieldLayers layers(voxels, smoothing_passes);
    MeshingViewBuilder view(layers.grid(), iso);
    std::vector<float> layer(size_t(layers.grid().dims[0]) * size_t(layers.grid().dims[1]));
    for (int64_t k = 0; k < layers.grid().dims[2]; ++k) {
        layers.next_layer(layer.data());
        view.add_layer(layer.data());
    }
    return view.finish();
}

ScalarField occupancy_to_field(const SparseVoxels& voxels, int smoothing_passes) {
    OccupancyFieldLayers layers(voxels, smoothing_passes);
    ScalarField field;
    field.grid = layers.grid();
    if (field.grid.voxel_count() > std::numeric_limits<uint32_t>::max())
        throw GridError("a field of " + std::to_string(field.grid.voxel_count()) +
                        " samples is too large to mesh (at most 2^32 - 1)");
    detail::check_host_memory(field.grid.voxel_count() * sizeof(float),
                              detail::default_host_budget(),
                              "a field of " + std::to_string(field.grid.dims[0]) + "x" +
                                  std::to_string(field.grid.dims[1]) + "x" +
                                  std::to_string(field.grid.dims[2]) + " samples");
    field.values.resize(size_t(field.grid.voxel_count()));
    const size_t per_layer = size_t(field.grid.dims[0]) * size_t(field.grid.dims[1]);
    for (int64_t k = 0; k < field.grid.dims[2]; ++k)
        layers.next_layer(&field.values[size_t(k) * per_layer]);
    return field;
}

namespace detail {

void validate_field(const ScalarField& field, float iso, const char* who) {
    validate_grid(field.grid);
    if (field.grid.voxel_count() > std::numeric_limits<uint32_t>::max())
        throw GridError(std::string(who) + ": a field of " +
                        std::to_string(field.grid.voxel_count()) +
                        " samples is too large (at most 2^32 - 1)");
    if (field.values.size() != field.grid.voxel_count())
        throw GridError(std::string(who) + ": the field has " +
                        std::to_string(field.values.size()) + " values but its grid has " +
                        std::to_string(field.grid.voxel_count()) + " samples");
    if (!std::isfinite(iso)) throw InputError(std::string(who) + ": the iso value is not finite");
    for (size_t s = 0; s < field.values.size(); ++s)
        if (!std::isfinite(field.values[s]))
            throw InputError(std::string(who) + ": sample " + std::to_string(s) +
                             " of the field is not finite");
}

}  // namespace detail

}  // namespace oclvox
