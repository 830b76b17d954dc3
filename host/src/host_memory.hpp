// The host's physical memory, the base of the default host memory budgets.
#pragma once

#include <unistd.h>

#include <cstdint>

namespace oclvox::detail {

// Bytes of physical memory; 8 GiB if the system does not say.
inline uint64_t physical_memory() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    return pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : uint64_t(8) << 30;
}

}  // namespace oclvox::detail
