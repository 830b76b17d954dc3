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

ScalarField occupancy_to_field(const SparseVoxels& voxels, int smoothing_passes) {
    if (smoothing_passes < 0)
        throw GridError("smoothing passes must be >= 0, got " + std::to_string(smoothing_passes));

    // Phase 1: the grown grid. Each pass spreads the solid by one sample, so passes + 1 outside
    // samples keep the border outside and the surface closed.
    const int64_t pad = int64_t(smoothing_passes) + 1;
    ScalarField field;
    field.grid = voxels.grid();
    for (int k = 0; k < 3; ++k) {
        field.grid.origin[k] -= double(pad) * field.grid.voxel_size;
        field.grid.dims[k] += 2 * pad;
    }
    validate_grid(field.grid);
    if (field.grid.voxel_count() > std::numeric_limits<uint32_t>::max())
        throw GridError("a field of " + std::to_string(field.grid.voxel_count()) +
                        " samples is too large to mesh (at most 2^32 - 1)");
    // The field, and a second copy for the smoothing passes.
    const uint64_t copies = smoothing_passes > 0 ? 2 : 1;
    detail::check_host_memory(
        field.grid.voxel_count() * sizeof(float) * copies, detail::default_host_budget(),
        "a field of " + std::to_string(field.grid.dims[0]) + "x" +
            std::to_string(field.grid.dims[1]) + "x" + std::to_string(field.grid.dims[2]) +
            " samples" + (copies > 1 ? " and its smoothing copy" : ""));

    // Phase 2: -0.5 for set voxels, +0.5 elsewhere.
    const int64_t nx = field.grid.dims[0], ny = field.grid.dims[1], nz = field.grid.dims[2];
    field.values.assign(size_t(field.grid.voxel_count()), 0.5f);
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
        field.values[size_t((i + pad) + nx * ((j + pad) + ny * (k + pad)))] = -0.5f;
    });

    // Phase 3: the 3x3x3 box filter, as three 3-tap averages along x, y and z.
    std::vector<float> scratch(smoothing_passes > 0 ? field.values.size() : 0);
    const int64_t stride[3] = {1, nx, nx * ny};
    for (int pass = 0; pass < smoothing_passes; ++pass)
        for (int axis = 0; axis < 3; ++axis) {
            const int64_t n = field.grid.dims[axis], step = stride[axis];
            for (int64_t z = 0; z < nz; ++z)
                for (int64_t y = 0; y < ny; ++y)
                    for (int64_t x = 0; x < nx; ++x) {
                        const int64_t s = x + nx * (y + ny * z);
                        const int64_t c = axis == 0 ? x : axis == 1 ? y : z;
                        const float below = c > 0 ? field.values[size_t(s - step)] : 0.5f;
                        const float above = c + 1 < n ? field.values[size_t(s + step)] : 0.5f;
                        scratch[size_t(s)] = (below + field.values[size_t(s)] + above) / 3.0f;
                    }
            field.values.swap(scratch);
        }
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
