// The host memory budget, and the check every allocation whose size comes from the input (a grid's
// dense field, a sparse result's bricks, a mesher's buffers) makes before it allocates.
#pragma once

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// Bytes of physical memory; 8 GiB if the system does not say.
inline uint64_t physical_memory() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    return pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : uint64_t(8) << 30;
}

// The budget when the caller gives none: $OCLVOX_HOST_MEMORY_MIB MiB if set (for containers whose
// memory limit is below the machine's, and for tests), else half of the physical memory. Read at
// every call, so a program may change it between runs. Throws GridError if the variable is not a
// whole number of MiB in [1, 2^40].
inline uint64_t default_host_budget() {
    const char* text = std::getenv("OCLVOX_HOST_MEMORY_MIB");
    if (!text || !*text) return physical_memory() / 2;
    char* end = nullptr;
    errno = 0;
    const unsigned long long mib = std::strtoull(text, &end, 10);
    if (*end || errno || text[0] == '-' || mib < 1 || mib > (1ull << 40))
        throw GridError("OCLVOX_HOST_MEMORY_MIB must be a whole number of MiB in [1, 2^40], got '" +
                        std::string(text) + "'");
    return uint64_t(mib) << 20;
}

// `requested` bytes if non-zero (an option such as VoxelizeOptions::host_budget_bytes), else the
// default budget.
inline uint64_t host_budget(uint64_t requested) {
    return requested ? requested : default_host_budget();
}

// "12 MiB", rounded up.
inline std::string mib_text(uint64_t bytes) {
    return std::to_string(bytes / (1u << 20) + (bytes % (1u << 20) != 0)) + " MiB";
}

// Throws GridError if `bytes` are over `budget`, naming `what` (e.g. "a dense distance field of
// 256x256x256 voxels"), both sizes and the remedy; called before anything is allocated for it.
inline void check_host_memory(uint64_t bytes, uint64_t budget, const std::string& what) {
    if (bytes > budget)
        throw GridError(what + " needs " + mib_text(bytes) +
                        " of host memory, over the host memory budget of " + mib_text(budget) +
                        ": lower the resolution or raise the budget");
}

// Bytes of a page of host memory.
inline size_t host_page_size() {
    static const size_t page = [] {
        const long size = sysconf(_SC_PAGE_SIZE);
        return size > 0 ? size_t(size) : size_t(4096);
    }();
    return page;
}

// `bytes` (> 0) of zero, page-aligned host memory, owned by the pointer: fresh pages from the
// system, which cost nothing until first touched (unlike memory that is zeroed on allocation).
// nullptr if the system gives none.
inline std::shared_ptr<uint64_t> zeroed_host_pages(size_t bytes) {
    void* const p =
        mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return nullptr;
    return std::shared_ptr<uint64_t>(static_cast<uint64_t*>(p),
                                     [bytes](uint64_t* q) { munmap(q, bytes); });
}

// Gives the whole pages of zeroed_host_pages memory within [p, p + bytes) back to the system
// (they read as zero after, and take no memory until touched again).
inline void release_host_pages(void* p, size_t bytes) {
    const size_t page = host_page_size();
    const uintptr_t begin = (reinterpret_cast<uintptr_t>(p) + page - 1) / page * page;
    const uintptr_t end = (reinterpret_cast<uintptr_t>(p) + bytes) / page * page;
    if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_DONTNEED);
}

// The /proc/self/pagemap entries of `pages` pages from `p` (page-aligned), one 64-bit word a page
// (bit 63: in memory, bit 62: swapped out); false if the system does not give them.
inline bool read_page_map(const void* p, size_t pages, uint64_t* entries) {
    const int fd = open("/proc/self/pagemap", O_RDONLY | O_CLOEXEC);
    if (fd < 0) return false;
    const size_t want = pages * sizeof(uint64_t);
    const off_t at = off_t(reinterpret_cast<uintptr_t>(p) / host_page_size() * sizeof(uint64_t));
    size_t got = 0;
    while (got < want) {
        const ssize_t n =
            pread(fd, reinterpret_cast<char*>(entries) + got, want - got, at + off_t(got));
        if (n <= 0) break;
        got += size_t(n);
    }
    close(fd);
    return got == want;
}

// Which pages of the `bytes` of zeroed_host_pages memory from `p` (page-aligned) may hold anything
// but zeros: entry i for the i-th page, 0 only for a page never touched (neither in memory nor
// swapped out, as /proc/self/pagemap says: a fresh private page still reads as zero), which a
// caller can then know to be zero without reading it (a read would map it). Every page counts as
// touched where the system cannot say, or where, asked once about two fresh pages of which one
// was written, it did not answer exactly that (an emulated /proc must not make data vanish).
// (mincore would not do: a page swapped out is not resident either.)
inline std::vector<uint8_t> touched_host_pages(const void* p, size_t bytes) {
    static const bool page_map_tells = [] {
        const std::shared_ptr<uint64_t> probe = zeroed_host_pages(2 * host_page_size());
        if (!probe) return false;
        *static_cast<volatile uint64_t*>(probe.get()) = 1;
        uint64_t entries[2];
        return read_page_map(probe.get(), 2, entries) && (entries[0] >> 62) != 0 &&
               (entries[1] >> 62) == 0;
    }();
    const size_t pages = (bytes + host_page_size() - 1) / host_page_size();
    std::vector<uint8_t> touched(pages, 1);
    std::vector<uint64_t> entries(pages);
    if (page_map_tells && read_page_map(p, pages, entries.data()))
        for (size_t i = 0; i < pages; ++i) touched[i] = (entries[i] >> 62) != 0;
    return touched;
}

// An allocator whose resize leaves new elements of trivial types uninitialised instead of zeroing
// them. For buffers of many megabytes that are written in full right after (in parallel), the
// serial zeroing and its page faults cost more than the writes.
template <class T>
struct NoZeroAllocator : std::allocator<T> {
    template <class U>
    struct rebind {
        using other = NoZeroAllocator<U>;
    };
    NoZeroAllocator() = default;
    template <class U>
    NoZeroAllocator(const NoZeroAllocator<U>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

// A vector of trivial elements that `resize` does not zero.
template <class T>
using FilledLaterVector = std::vector<T, NoZeroAllocator<T>>;

}  // namespace oclvox::detail
