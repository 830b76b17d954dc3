// Binary formats (npy, ply, stl, vox) are little-endian on disk whatever the host's byte order.
// Values go through their bit patterns, so floats keep every bit.
#pragma once

#include <cstdint>
#include <cstring>
#include <ostream>
#include <type_traits>

namespace oclvox::detail {

// Stores `value` (an integer or floating-point type) as sizeof(T) little-endian bytes at `out`.
template <typename T>
inline void store_le(char* out, T value) {
    static_assert(std::is_arithmetic_v<T> &&
                  (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8));
    using Bits = std::conditional_t<
        sizeof(T) == 1, uint8_t,
        std::conditional_t<sizeof(T) == 2, uint16_t,
                           std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>>>;
    Bits bits;
    std::memcpy(&bits, &value, sizeof bits);
    for (size_t b = 0; b < sizeof bits; ++b) out[b] = char((bits >> (8 * b)) & 0xffu);
}

template <typename T>
inline void write_le(std::ostream& out, T value) {
    char bytes[sizeof(T)];
    store_le(bytes, value);
    out.write(bytes, sizeof bytes);
}

}  // namespace oclvox::detail
