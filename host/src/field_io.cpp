// Field files: write_field picks the format by extension; .npy (float32, Fortran order, with a
// JSON sidecar placing it in space) is written and read here, .vdb in field_vdb.cpp.
//
// .npy format version 1.0 (numpy.org/neps/nep-0001-npy-format.html). Shape (nx, ny, nz) in
// Fortran order means x fastest, which is exactly ScalarField's layout, so numpy's arr[i, j, k]
// is voxel (i, j, k) and the data needs no reordering. The sidecar is `<path>.json`, as for the
// voxel writer's .npy.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>

#include "field_vdb.hpp"
#include "file_names.hpp"
#include "little_endian.hpp"
#include "npy_format.hpp"
#include "oclvox/sdf.hpp"

namespace oclvox {

namespace {

void check_field(const ScalarField& field, const std::string& path) {
    validate_grid(field.grid);
    if (field.values.size() != field.grid.voxel_count())
        throw OutputError("cannot write " + path + ": the field has " +
                          std::to_string(field.values.size()) + " values for a grid of " +
                          std::to_string(field.grid.voxel_count()) + " voxels");
}

// The largest |value| in voxels: the band of a narrow-band field.
double inferred_band(const ScalarField& field) {
    float largest = 0;
    for (float v : field.values) largest = std::max(largest, std::abs(v));
    return double(largest) / field.grid.voxel_size;
}

void write_npy_field(const std::string& path, const ScalarField& field, double band_voxels) {
    // The samples as little-endian float32, converted a chunk at a time so the copy stays small.
    auto write_samples = [&](std::ostream& out) {
        constexpr size_t kChunk = size_t(1) << 16;
        std::vector<char> bytes(kChunk * 4);
        for (size_t first = 0; first < field.values.size(); first += kChunk) {
            const size_t n = std::min(kChunk, field.values.size() - first);
            for (size_t v = 0; v < n; ++v) detail::store_le(&bytes[v * 4], field.values[first + v]);
            out.write(bytes.data(), std::streamsize(n * 4));
        }
    };
    nlohmann::json sidecar = detail::npy_sidecar(path, field.grid);
    sidecar["dtype"] = "float32, distance in world units";
    sidecar["sample_position"] = "voxel centres: origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size";
    sidecar["sign_convention"] = "negative inside, positive outside";
    sidecar["band_voxels"] = band_voxels;
    sidecar["background"] = band_voxels * field.grid.voxel_size;
    detail::write_npy_with_sidecar(path, "<f4", field.grid, write_samples, sidecar);
}

[[noreturn]] void bad_npy(const std::string& path, const std::string& why) {
    throw InputError("cannot read field " + path + ": " + why);
}

// Grid placement from the sidecar `<path>.json`.
Grid read_sidecar(const std::string& path) {
    std::ifstream in(path + ".json");
    if (!in) bad_npy(path, "its sidecar " + path + ".json (origin and voxel size) is missing");
    Grid grid;
    try {
        const nlohmann::json j = nlohmann::json::parse(in);
        grid.origin = j.at("origin").get<std::array<double, 3>>();
        grid.voxel_size = j.at("voxel_size").get<double>();
    } catch (const nlohmann::json::exception& e) {
        bad_npy(path, "its sidecar " + path + ".json is not valid: " + e.what());
    }
    return grid;
}

}  // namespace

void write_field(const std::string& path, const ScalarField& field, double band_voxels) {
    check_field(field, path);
    if (!(band_voxels > 0)) band_voxels = inferred_band(field);
    const std::string extension = detail::lowercase_extension(path);
    if (extension == ".npy") return write_npy_field(path, field, band_voxels);
    if (extension == ".vdb") return detail::write_field_vdb(path, field, band_voxels);
    throw OutputError("cannot write field " + path + ": unknown extension '" + extension +
                      "' (expected .npy or .vdb)");
}

ScalarField read_field(const std::string& path) {
    if (detail::lowercase_extension(path) != ".npy")
        throw InputError("cannot read field " + path + ": only .npy fields can be read");
    std::ifstream in(path, std::ios::binary);
    if (!in) bad_npy(path, "it cannot be opened");

    // Phase 1: magic, version and header dict.
    char preamble[8];
    if (!in.read(preamble, 8) || std::memcmp(preamble, "\x93NUMPY", 6) != 0)
        bad_npy(path, "it is not a .npy file");
    const int major = preamble[6];
    if (major < 1 || major > 3) bad_npy(path, "unsupported .npy version " + std::to_string(major));
    unsigned char length_bytes[4] = {0, 0, 0, 0};
    const int length_size = major == 1 ? 2 : 4;
    if (!in.read(reinterpret_cast<char*>(length_bytes), length_size))
        bad_npy(path, "truncated header");
    const size_t header_length = size_t(length_bytes[0]) | size_t(length_bytes[1]) << 8 |
                                 size_t(length_bytes[2]) << 16 | size_t(length_bytes[3]) << 24;
    if (header_length > (1u << 20)) bad_npy(path, "implausible header length");
    std::string header(header_length, '\0');
    if (!in.read(header.data(), std::streamsize(header_length))) bad_npy(path, "truncated header");

    std::smatch m;
    if (!std::regex_search(header, m, std::regex("'descr'\\s*:\\s*'([<>|=]?)(f4|f8)'")))
        bad_npy(path, "its dtype is not float32 or float64 (header " + header + ")");
    const bool doubles = m[2] == "f8";
    if (m[1] == ">") bad_npy(path, "big-endian arrays are not supported");
    if (!std::regex_search(header, m, std::regex("'fortran_order'\\s*:\\s*(True|False)")))
        bad_npy(path, "its header has no fortran_order");
    const bool fortran = m[1] == "True";
    if (!std::regex_search(
            header, m,
            std::regex("'shape'\\s*:\\s*\\(\\s*(\\d+)\\s*,\\s*(\\d+)\\s*,\\s*(\\d+)\\s*,?\\s*\\)")))
        bad_npy(path, "it is not a 3-D array (header " + header + ")");

    // Phase 2: placement from the sidecar, dims from the array.
    ScalarField field;
    field.grid = read_sidecar(path);
    for (int k = 0; k < 3; ++k) field.grid.dims[k] = std::stoll(m[k + 1].str());
    try {
        validate_grid(field.grid);
    } catch (const GridError& e) {
        bad_npy(path, e.what());
    }

    // Phase 3: the samples, little-endian; C order (z fastest) is transposed to x fastest.
    const size_t count = size_t(field.grid.voxel_count());
    const size_t item = doubles ? 8 : 4;
    std::vector<unsigned char> bytes(count * item);
    if (!in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size())))
        bad_npy(path, "the data is shorter than its shape says");
    field.values.resize(count);
    const int64_t nx = field.grid.dims[0], ny = field.grid.dims[1], nz = field.grid.dims[2];
    for (size_t s = 0; s < count; ++s) {
        uint64_t bits = 0;
        for (size_t b = 0; b < item; ++b) bits |= uint64_t(bytes[s * item + b]) << (8 * b);
        float value;
        if (doubles) {
            double d;
            std::memcpy(&d, &bits, 8);
            value = float(d);
        } else {
            const auto b32 = uint32_t(bits);
            std::memcpy(&value, &b32, 4);
        }
        size_t v = s;
        if (!fortran) {  // s = k + nz * (j + ny * i)
            const int64_t k = int64_t(s) % nz, j = int64_t(s) / nz % ny, i = int64_t(s) / (nz * ny);
            v = size_t(i + nx * (j + ny * k));
        }
        field.values[v] = value;
    }
    return field;
}

}  // namespace oclvox
