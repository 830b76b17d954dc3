// Population counts, inline. Baseline x86-64 has no popcnt instruction, so __builtin_popcount
// compiles to a call into libgcc; counting the bits of a large grid that way was a visible part
// of a run.
#pragma once

#include <cstdint>

namespace oclvox::detail {

// The set bits of x, by summing bit fields of doubling width.
inline uint32_t popcount64(uint64_t x) {
    x = x - ((x >> 1) & 0x5555555555555555ull);
    x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
    x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0full;
    return uint32_t((x * 0x0101010101010101ull) >> 56);
}

}  // namespace oclvox::detail
