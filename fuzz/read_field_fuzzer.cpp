// read_field on an arbitrary .npy file and JSON sidecar. The input is split in two: its first
// byte (times 4, capped at what follows) is the sidecar's length, the sidecar comes next and the
// .npy file is the rest. Only an oclvox::Error may come out.
#include <algorithm>

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
    try {
        const oclvox::ScalarField field = oclvox::read_field(npy.path());
        if (field.values.size() != field.grid.voxel_count()) __builtin_trap();
    } catch (const oclvox::Error&) {
    }
    return 0;
}
