// The box of a mesh that grids are fitted to and that solids stay within.
#pragma once

#include <array>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// Bounding box of the vertices that triangles use (unused vertices do not widen it).
void used_bounds(const Mesh& mesh, std::array<double, 3>& lo, std::array<double, 3>& hi);

}  // namespace oclvox::detail
