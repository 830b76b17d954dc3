// Numbers in error messages, shared by everything that names a size, a band or a coordinate.
#pragma once

#include <charconv>
#include <string>

namespace oclvox::detail {

// The shortest text that reads back as x: std::to_string prints 6 decimals, so a voxel of 1e-7
// would read "0.000000", a band of 1e30 31 digits, and two bands that differ in the 7th digit
// alike.
inline std::string number_text(double x) {
    char text[32];
    return std::string(text, std::to_chars(text, text + sizeof text, x).ptr);
}

}  // namespace oclvox::detail
