// load_mesh on arbitrary bytes, one fuzz target per file extension (OCLVOX_FUZZ_EXTENSION, set by
// fuzz/CMakeLists.txt), so that each format has its own corpus and dictionary. The only outcome
// allowed besides a mesh is an oclvox::Error; any other exception, crash, sanitizer report, leak
// or oversized allocation is a finding.
#include "fuzz_support.hpp"
#include "oclvox/oclvox.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static const oclvox_fuzz::ScratchFile file(OCLVOX_FUZZ_EXTENSION);
    try {
        const oclvox::Mesh mesh = oclvox::load_mesh(file.write(data, size));
        // What load_mesh returns must be a valid mesh: it promises to have checked it.
        oclvox::validate_mesh(mesh);
    } catch (const oclvox::Error&) {
    }
    return 0;
}
