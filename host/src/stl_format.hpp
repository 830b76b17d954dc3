// Binary STL, shared by the mesh writer and the voxel-cube writer: an 80-byte header, the
// triangle count (32-bit), then per triangle its unit normal and three corners as floats and a
// 16-bit attribute word.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <ios>
#include <string>

#include "block_writer.hpp"

namespace oclvox::detail {

// Where the triangle count lies in the file: after the 80-byte header text.
constexpr std::streamoff kStlCountOffset = 80;

// The header: `text`, cut to 80 bytes and padded with zero bytes, then the triangle count.
inline void write_stl_header(BlockWriter& w, const std::string& text, uint32_t triangles) {
    char header[kStlCountOffset] = {};
    std::memcpy(header, text.data(), std::min(text.size(), sizeof header));
    w.bytes(header, sizeof header);
    w.little_endian(triangles);
}

// Triangle (a, b, c) with its unit normal n, everything rounded to float.
inline void write_stl_facet(BlockWriter& w, const std::array<double, 3>& n,
                            const std::array<double, 3>& a, const std::array<double, 3>& b,
                            const std::array<double, 3>& c) {
    for (double x : n) w.little_endian(float(x));
    for (const auto* p : {&a, &b, &c})
        for (double x : *p) w.little_endian(float(x));
    w.little_endian(uint16_t(0));
}

// Triangle (a, b, c) with the normal from its corners in double (zero for a degenerate one).
inline void write_stl_facet(BlockWriter& w, const std::array<double, 3>& a,
                            const std::array<double, 3>& b, const std::array<double, 3>& c) {
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    std::array<double, 3> n = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                               u[0] * v[1] - u[1] * v[0]};
    const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (double& x : n) x = length > 0 ? x / length : 0.0;
    write_stl_facet(w, n, a, b, c);
}

}  // namespace oclvox::detail
