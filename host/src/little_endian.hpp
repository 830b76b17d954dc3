// Binary formats (npy, ply, stl, vox) are little-endian on disk whatever the host's byte order
// (PLY may also be big-endian). Values go through their bit patterns, so floats keep every bit.
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

// A value of type T stored in `bytes` with the given byte order (IEEE 754 for floating point).
template <class T>
T load_scalar(const char* bytes, bool big_endian) {
    unsigned char ordered[sizeof(T)];
    for (size_t b = 0; b < sizeof(T); ++b)
        ordered[b] = static_cast<unsigned char>(bytes[big_endian ? sizeof(T) - 1 - b : b]);
    static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the byte order above is the host's");
    T value;
    std::memcpy(&value, ordered, sizeof(T));
    return value;
}

}  // namespace oclvox::detail
