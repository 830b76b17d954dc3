// Size checks for the dense streaming writers; see slabs.hpp.
#include "slabs.hpp"

#include <filesystem>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

void check_dense_size(const std::string& path, uint64_t bytes, const std::string& what) {
    const auto gib = [](uint64_t bytes) { return std::to_string((bytes + (1u << 29)) >> 30); };
    if (bytes > kMaxDenseBytes)
        throw OutputError("cannot write " + path + ": " + what + " file of this grid would need " +
                          gib(bytes) + " GiB; write .vdb (sparse) or lower the resolution");
    std::error_code error;
    const std::filesystem::path folder = std::filesystem::absolute(path).parent_path();
    const auto space = std::filesystem::space(folder, error);
    if (!error && space.available < bytes)
        throw OutputError("cannot write " + path + ": " + what + " file of this grid needs " +
                          gib(bytes) + " GiB but its folder has only " + gib(space.available) +
                          " GiB free; write .vdb (sparse) or lower the resolution");
}

}  // namespace oclvox::detail
