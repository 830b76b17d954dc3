// read_field on an arbitrary .npy file and JSON sidecar, and the same file read a layer at a time
// (FieldLayerReader), which must give read_field's samples layer for layer, or fail where it
// fails. The input is split in two: its first byte (times 4, capped at what follows) is the
// sidecar's length, the sidecar comes next and the .npy file is the rest. Only an oclvox::Error
// may come out.
#include <algorithm>
#include <cstring>
#include <optional>
#include <vector>

#include "fuzz_support.hpp"
#include "oclvox/field.hpp"
#include "oclvox/sdf.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static const oclvox_fuzz::ScratchFile npy(".npy");
    static const oclvox_fuzz::ScratchFile sidecar(".npy.json");
    if (size == 0) return 0;
    const size_t sidecar_size = std::min<size_t>(size_t(data[0]) * 4, size - 1);
    sidecar.write(data + 1, sidecar_size);
    npy.write(data + 1 + sidecar_size, size - 1 - sidecar_size);
    std::optional<oclvox::ScalarField> field;
    try {
        field = oclvox::read_field(npy.path());
        if (field->values.size() != field->grid.voxel_count()) __builtin_trap();
    } catch (const oclvox::Error&) {
    }
    try {
        oclvox::FieldLayerReader reader(npy.path());
        const oclvox::Grid& grid = reader.grid();
        const size_t per_layer = size_t(grid.dims[0]) * size_t(grid.dims[1]);
        std::vector<float> layer(per_layer);
        for (int64_t k = 0; k < grid.dims[2]; ++k) {
            reader.read_layer(layer.data());
            // Compared as bits: NaN samples are read as they are stored.
            if (!field || std::memcmp(layer.data(), &field->values[size_t(k) * per_layer],
                                      per_layer * sizeof(float)) != 0)
                __builtin_trap();
        }
    } catch (const oclvox::Error&) {
    }
    return 0;
}
