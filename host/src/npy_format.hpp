// NumPy .npy files (format version 1.0, numpy.org/neps/nep-0001-npy-format.html) with the JSON
// sidecar `<path>.json` that places the array in space. Shared by the voxel and field writers.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// Magic, version, header length and the header dict for a Fortran-order (x fastest) 3-D array of
// `descr` (a numpy type string such as "|u1" or "<f4"), padded so the data starts at a multiple
// of 64 bytes as numpy itself writes it.
void write_npy_header(std::ostream& out, const std::string& descr,
                      const std::array<int64_t, 3>& dims);

// The sidecar keys every .npy we write has: file name, dims, origin, voxel size, axis order.
nlohmann::json npy_sidecar(const std::string& npy_path, const Grid& grid);

// Writes the array (header, then `write_data` streams the samples) and then its sidecar, each
// atomically. The sidecar is made (`make_sidecar`) after the samples are written, so it can say
// what only they tell (a streamed field's band). An array without its placement is misleading, so
// if the sidecar cannot be written the array is removed too and nothing is left under either
// name. Throws OutputError.
void write_npy_with_sidecar(const std::string& path, const std::string& descr, const Grid& grid,
                            const std::function<void(std::ostream&)>& write_data,
                            const std::function<nlohmann::json()>& make_sidecar);

}  // namespace oclvox::detail
