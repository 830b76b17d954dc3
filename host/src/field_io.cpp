// Field files: write_field picks the format by extension; .npy (float32, Fortran order, with a
// JSON sidecar placing it in space) is written and read here; .vdb is written by
// write_level_set_vdb.cpp and read by field_vdb.cpp (OpenVDB's module).
//
// .npy format version 1.0 (numpy.org/neps/nep-0001-npy-format.html). Shape (nx, ny, nz) in
// Fortran order means x fastest, which is exactly ScalarField's layout, so numpy's arr[i, j, k]
// is voxel (i, j, k) and the data needs no reordering. The sidecar is `<path>.json`, as for the
// voxel writer's .npy. Reading also takes the occupancy .npy that write_voxels writes (uint8 0/1,
// same layout, same sidecar placement).
#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <variant>

#include "file_names.hpp"
#include "host_memory.hpp"
#include "little_endian.hpp"
#include "npy_format.hpp"
#include "oclvox/sdf.hpp"
#include "slabs.hpp"
#include "vdb_module.hpp"
#include "vdb_stream.hpp"

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

// Layers [first, end) of a field, written to `samples` in x-fastest order.
using FieldSlab = std::function<void(int64_t first, int64_t end, float* samples)>;

// Writes the samples a slab of layers at a time, as slab_of gives them (at least `min_thickness`
// layers a slab where the grid has them: a sparse field's leaves are 8 layers deep). Only two slabs
// are held, whatever the field. band_voxels <= 0: the largest |value| written, in voxels (the
// sidecar is made after the samples).
void write_npy_field(const std::string& path, const Grid& grid, double band_voxels,
                     detail::ProgressPhases& progress, const FieldSlab& slab_of,
                     int64_t min_thickness = 1) {
    detail::check_dense_size(path, grid.voxel_count() * sizeof(float), "a float32 .npy");
    const size_t samples = progress.add(1);
    float largest = 0;
    auto write_samples = [&](std::ostream& out) {
        const size_t per_layer = size_t(grid.dims[0]) * size_t(grid.dims[1]);
        const uint64_t layer_bytes = per_layer * sizeof(float);
        const int64_t thickness = detail::slab_thickness(
            layer_bytes, grid.dims[2],
            std::max(detail::kCachedSlabBytes, uint64_t(min_thickness) * layer_bytes));
        // "<f4" is the host's float on the little-endian hosts oclvox builds for, so the samples
        // are written as they are.
        static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "npy's <f4 is the host's float");
        detail::stream_slabs<std::vector<float>>(
            grid.dims[2], thickness,
            [&](std::vector<float>& slab, int64_t first, int64_t end) {
                slab.resize(per_layer * size_t(thickness));
                slab_of(first, end, slab.data());
                if (!(band_voxels > 0))
                    for (size_t v = 0; v < per_layer * size_t(end - first); ++v)
                        largest = std::max(largest, std::abs(slab[v]));
            },
            [&](const std::vector<float>& slab, int64_t first, int64_t end) {
                out.write(reinterpret_cast<const char*>(slab.data()),
                          std::streamsize(layer_bytes * uint64_t(end - first)));
            },
            [&](int64_t first) {
                progress.report(samples, uint64_t(first), uint64_t(grid.dims[2]));
            });
        progress.finish();
    };
    auto sidecar = [&] {
        const double band = band_voxels > 0 ? band_voxels : double(largest) / grid.voxel_size;
        nlohmann::json json = detail::npy_sidecar(path, grid);
        json["dtype"] = "float32, distance in world units";
        json["sample_position"] =
            "voxel centres: origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size";
        json["sign_convention"] = "negative inside, positive outside";
        json["band_voxels"] = band;
        json["background"] = band * grid.voxel_size;
        return json;
    };
    detail::write_npy_with_sidecar(path, "<f4", grid, write_samples, sidecar);
}

[[noreturn]] void unknown_field_extension(const std::string& path, const std::string& extension) {
    throw OutputError("cannot write field " + path + ": unknown extension '" + extension +
                      "' (expected .npy or .vdb)");
}

// ---- Reading ----------------------------------------------------------------------------------
// Everything a .npy file says about itself is checked before anything is allocated for its data:
// the header is parsed strictly, the data length its shape implies must be exactly what the file
// holds, and the samples must fit the memory budget. Only oclvox::Error subclasses leave.

[[noreturn]] void bad_npy(const std::string& path, const std::string& why) {
    throw InputError("cannot read field " + path + ": " + why);
}

// What the header says about the data.
enum class NpyType { Float32, Float64, Uint8 };

struct NpyHeader {
    NpyType type = NpyType::Float32;
    bool fortran_order = false;
    std::array<int64_t, 3> shape{0, 0, 0};
    uint64_t data_offset = 0;  // bytes before the first sample
    uint64_t data_bytes = 0;   // what the shape implies
};

size_t item_size(NpyType type) {
    return type == NpyType::Float64 ? 8 : type == NpyType::Float32 ? 4 : 1;
}

// A strict reader for the one dict literal .npy headers hold:
// {'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }
// Keys may come in any order but each exactly once; anything else is an error.
class HeaderDict {
  public:
    HeaderDict(const std::string& text, const std::string& path) : text_(text), path_(path) {}

    void parse(NpyHeader& header) {
        bool have_descr = false, have_order = false, have_shape = false;
        expect('{');
        while (!next_is('}')) {
            const std::string key = quoted();
            expect(':');
            bool* seen = key == "descr"           ? &have_descr
                         : key == "fortran_order" ? &have_order
                         : key == "shape"         ? &have_shape
                                                  : nullptr;
            if (!seen) fail("unexpected key '" + key + "'");
            if (*seen) fail("key '" + key + "' appears twice");
            *seen = true;
            if (key == "descr") header.type = dtype(quoted());
            if (key == "fortran_order") header.fortran_order = boolean();
            if (key == "shape") header.shape = shape();
            if (!next_is('}')) expect(',');
        }
        expect('}');
        // numpy pads the header with spaces and ends it with a newline.
        for (; pos_ < text_.size(); ++pos_)
            if (!std::isspace(static_cast<unsigned char>(text_[pos_])))
                fail("unexpected text after the header dict");
        if (!have_descr || !have_order || !have_shape)
            fail("the header lacks one of 'descr', 'fortran_order', 'shape'");
    }

  private:
    [[noreturn]] void fail(const std::string& why) const {
        bad_npy(path_, "its header is not a valid .npy header (" + why + "): " + text_);
    }

    void skip_space() {
        while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
    }
    bool next_is(char c) {
        skip_space();
        return pos_ < text_.size() && text_[pos_] == c;
    }
    void expect(char c) {
        if (!next_is(c)) fail(std::string("expected '") + c + "'");
        ++pos_;
    }
    std::string quoted() {
        skip_space();
        if (pos_ >= text_.size() || (text_[pos_] != '\'' && text_[pos_] != '"'))
            fail("expected a quoted string");
        const char quote = text_[pos_++];
        const size_t end = text_.find(quote, pos_);
        if (end == std::string::npos) fail("unterminated string");
        std::string value = text_.substr(pos_, end - pos_);
        pos_ = end + 1;
        return value;
    }
    bool boolean() {
        skip_space();
        for (const char* word : {"True", "False"})
            if (text_.compare(pos_, std::strlen(word), word) == 0) {
                pos_ += std::strlen(word);
                return word[0] == 'T';
            }
        fail("fortran_order is neither True nor False");
    }
    NpyType dtype(const std::string& descr) {
        // Byte order does not matter for one-byte types; numpy writes '|' for them.
        if (descr == "|u1" || descr == "<u1" || descr == ">u1" || descr == "|b1")
            return NpyType::Uint8;
        if (descr == "<f4") return NpyType::Float32;
        if (descr == "<f8") return NpyType::Float64;
        if (descr == ">f4" || descr == ">f8")
            bad_npy(path_, "big-endian arrays are not supported (dtype '" + descr + "')");
        bad_npy(path_, "its dtype '" + descr +
                           "' is none of float32, float64 (fields) and uint8, bool (occupancy)");
    }
    // A tuple of exactly three whole numbers, each an axis length in [1, kMaxGridAxis].
    std::array<int64_t, 3> shape() {
        expect('(');
        std::vector<uint64_t> dims;
        while (!next_is(')')) {
            const size_t begin = pos_;
            while (pos_ < text_.size() && std::isdigit(static_cast<unsigned char>(text_[pos_])))
                ++pos_;
            uint64_t value = 0;
            const auto [end, error] =
                std::from_chars(text_.data() + begin, text_.data() + pos_, value);
            if (begin == pos_ || end != text_.data() + pos_)
                fail("a shape entry is not a whole number");
            if (error == std::errc::result_out_of_range || value > uint64_t(kMaxGridAxis))
                bad_npy(path_, "its shape axis " + text_.substr(begin, pos_ - begin) +
                                   " exceeds the maximum of " + std::to_string(kMaxGridAxis) +
                                   " voxels per axis");
            if (value == 0) bad_npy(path_, "its shape has an empty axis (length 0)");
            dims.push_back(value);
            if (!next_is(')')) expect(',');
        }
        expect(')');
        if (dims.size() != 3)
            bad_npy(path_, "it is not a 3-D array (its shape has " + std::to_string(dims.size()) +
                               " axes)");
        return {int64_t(dims[0]), int64_t(dims[1]), int64_t(dims[2])};
    }

    const std::string& text_;
    const std::string& path_;
    size_t pos_ = 0;
};

// Phase 1 of every read: open, parse the header, and check the data length against the file.
NpyHeader read_npy_header(const std::string& path, std::ifstream& in) {
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error))
        bad_npy(path, std::filesystem::exists(path, error) ? "it is not a regular file"
                                                           : "it does not exist");
    const uint64_t file_size = std::filesystem::file_size(path, error);
    in.open(path, std::ios::binary);
    if (error || !in) bad_npy(path, "it cannot be opened");

    // Magic, version, header length (2 bytes in version 1, 4 in versions 2 and 3).
    char preamble[8];
    if (!in.read(preamble, 8) || std::memcmp(preamble, "\x93NUMPY", 6) != 0)
        bad_npy(path, "it is not a .npy file");
    const int major = preamble[6];
    if (major < 1 || major > 3) bad_npy(path, "unsupported .npy version " + std::to_string(major));
    unsigned char length_bytes[4] = {0, 0, 0, 0};
    const int length_size = major == 1 ? 2 : 4;
    if (!in.read(reinterpret_cast<char*>(length_bytes), length_size))
        bad_npy(path, "truncated header");
    const uint64_t header_length = uint64_t(length_bytes[0]) | uint64_t(length_bytes[1]) << 8 |
                                   uint64_t(length_bytes[2]) << 16 |
                                   uint64_t(length_bytes[3]) << 24;
    NpyHeader header;
    header.data_offset = 8 + uint64_t(length_size) + header_length;
    if (header.data_offset > file_size) bad_npy(path, "truncated header");
    if (header_length > (1u << 20)) bad_npy(path, "implausible header length");
    std::string text(header_length, '\0');
    if (!in.read(text.data(), std::streamsize(header_length))) bad_npy(path, "truncated header");
    HeaderDict(text, path).parse(header);

    // The byte count cannot overflow (three axes of at most 2^20, items of at most 8 bytes), but
    // it is multiplied checked so that a larger kMaxGridAxis cannot make it wrap silently.
    uint64_t bytes = item_size(header.type);
    for (int64_t n : header.shape)
        if (__builtin_mul_overflow(bytes, uint64_t(n), &bytes))
            bad_npy(path, "its shape is too large to address");
    header.data_bytes = bytes;
    const uint64_t held = file_size - header.data_offset;
    if (held != bytes)
        bad_npy(path, "its shape (" + std::to_string(header.shape[0]) + ", " +
                          std::to_string(header.shape[1]) + ", " + std::to_string(header.shape[2]) +
                          ") needs " + std::to_string(bytes) +
                          " bytes of data but the file holds " + std::to_string(held));
    return header;
}

// The default host memory budget (the voxelizer's when none is given); an invalid
// $OCLVOX_HOST_MEMORY_MIB is an InputError naming the file, as every failure of read_npy is.
uint64_t memory_budget(const std::string& path) {
    try {
        return detail::default_host_budget();
    } catch (const GridError& e) {
        bad_npy(path, e.what());
    }
}

// What the samples will take in memory, against that budget, before anything is allocated.
void check_memory_budget(const std::string& path, uint64_t bytes, const char* what) {
    const uint64_t budget = memory_budget(path);
    if (bytes > budget)
        bad_npy(path, std::string(what) + " would need " + detail::mib_text(bytes) +
                          ", over the memory budget of " + detail::mib_text(budget) +
                          " (OCLVOX_HOST_MEMORY_MIB, default half the physical memory)");
}

// Grid placement from the sidecar `<path>.json`: origin and voxel_size are required, dims (if
// present) must agree with the array's shape. Both kinds of sidecar put origin at the corner of
// voxel (0,0,0): the field's samples sit at voxel centres, the occupancy's voxels are the boxes.
Grid read_sidecar(const std::string& path, const std::array<int64_t, 3>& shape) {
    const std::string sidecar = path + ".json";
    auto bad = [&](const std::string& why) {
        bad_npy(path, "its sidecar " + sidecar + " is not valid: " + why);
    };
    std::error_code error;
    if (!std::filesystem::is_regular_file(sidecar, error))
        bad_npy(path, "its sidecar " + sidecar + " (origin and voxel size) is missing");
    if (std::filesystem::file_size(sidecar, error) > (1u << 20) || error)
        bad("it is larger than 1 MiB or cannot be sized");
    std::ifstream in(sidecar, std::ios::binary);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in.good() && !in.eof()) bad("it cannot be read");

    const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
    if (j.is_discarded()) bad("it is not JSON");
    if (!j.is_object()) bad("it is not a JSON object");
    auto triple = [&](const char* key, bool integers) {
        const auto it = j.find(key);
        if (it == j.end()) return false;
        if (!it->is_array() || it->size() != 3)
            bad(std::string("'") + key + "' is not a list of 3");
        for (const nlohmann::json& v : *it)
            if (integers ? !v.is_number_integer() : !v.is_number())
                bad(std::string("'") + key + "' holds a value that is not a " +
                    (integers ? "whole number" : "number"));
        return true;
    };
    if (!triple("origin", false)) bad("'origin' is missing");
    const auto voxel_size = j.find("voxel_size");
    if (voxel_size == j.end() || !voxel_size->is_number()) bad("'voxel_size' is not a number");

    Grid grid;
    for (int k = 0; k < 3; ++k) grid.origin[k] = j["origin"][size_t(k)].get<double>();
    grid.voxel_size = voxel_size->get<double>();
    grid.dims = shape;
    if (!std::isfinite(grid.voxel_size) || !(grid.voxel_size > 0))
        bad("'voxel_size' must be a positive finite number");
    for (double o : grid.origin)
        if (!std::isfinite(o)) bad("'origin' is not finite");
    if (triple("dims", true))
        for (int k = 0; k < 3; ++k) {
            const nlohmann::json& d = j["dims"][size_t(k)];
            if (!(d.is_number_unsigned() && d.get<uint64_t>() == uint64_t(shape[k])))
                bad("'dims' " + j["dims"].dump() + " disagree with the array's shape");
        }
    return grid;
}

// Bytes of a C-order file's plane of constant i (ny rows of nz samples).
uint64_t c_order_plane_bytes(const NpyHeader& header) {
    return uint64_t(header.shape[1]) * uint64_t(header.shape[2]) * item_size(header.type);
}

// Planes of constant i a C-order file is read in: up to 16, so that the layers' samples are
// written 16 consecutive x at a time (a whole cache line of floats, where one sample per line made
// one thick slab twice as slow as many thin ones), within 16 MiB unless one plane is larger.
uint64_t c_order_planes_per_read(const NpyHeader& header) {
    return std::clamp<uint64_t>(
        (uint64_t(16) << 20) / std::max<uint64_t>(c_order_plane_bytes(header), 1), 1, 16);
}

// Bytes read_layers holds for its reading.
uint64_t read_buffer_bytes(const NpyHeader& header) {
    if (header.fortran_order) return uint64_t(1) << 20;
    return c_order_planes_per_read(header) * c_order_plane_bytes(header);
}

// Phase 3 of every read: the samples of layers [k0, k1), read through `buffer` (resized to
// read_buffer_bytes; no second copy of the file), each passed to `take(v, bytes)` with its
// x-fastest index v within those layers. Fortran order holds the layers one after another, so
// only theirs are read. C order (z fastest) spreads every layer over the whole file: all its
// planes of constant i are read, and the layers' part of each of their rows picked out.
template <class Take>
void read_layers(const std::string& path, std::ifstream& in, const NpyHeader& header, int64_t k0,
                 int64_t k1, std::vector<unsigned char>& buffer, Take take) {
    const uint64_t item = item_size(header.type);
    const auto nx = uint64_t(header.shape[0]), ny = uint64_t(header.shape[1]),
               nz = uint64_t(header.shape[2]);
    const uint64_t per_layer = nx * ny, first = uint64_t(k0), last = uint64_t(k1);
    buffer.resize(read_buffer_bytes(header));
    auto read = [&](uint64_t bytes) {
        if (!in.read(reinterpret_cast<char*>(buffer.data()), std::streamsize(bytes)))
            bad_npy(path, "the data is shorter than its shape says");
    };
    in.clear();
    if (header.fortran_order) {
        in.seekg(std::streamoff(header.data_offset + first * per_layer * item));
        const uint64_t count = (last - first) * per_layer, per_read = buffer.size() / item;
        for (uint64_t done = 0; done < count; done += per_read) {
            const uint64_t n = std::min(per_read, count - done);
            read(n * item);
            for (uint64_t s = 0; s < n; ++s) take(done + s, &buffer[s * item]);
        }
        return;
    }
    in.seekg(std::streamoff(header.data_offset));
    const uint64_t planes = c_order_planes_per_read(header), plane = ny * nz;
    for (uint64_t i0 = 0; i0 < nx; i0 += planes) {
        const uint64_t n = std::min(planes, nx - i0);
        read(n * plane * item);
        for (uint64_t j = 0; j < ny; ++j)
            for (uint64_t z = first; z < last; ++z) {
                const uint64_t v = (z - first) * per_layer + i0 + nx * j;
                const unsigned char* sample = &buffer[(j * nz + z) * item];
                for (uint64_t i = 0; i < n; ++i) take(v + i, sample + i * plane * item);
            }
    }
}

// Little-endian float32 or float64 bytes as a float.
float float_sample(NpyType type, const unsigned char* bytes) {
    const auto* b = reinterpret_cast<const char*>(bytes);
    return type == NpyType::Float64 ? float(detail::load_scalar<double>(b, false))
                                    : detail::load_scalar<float>(b, false);
}

ScalarField read_float_samples(const std::string& path, std::ifstream& in, const NpyHeader& header,
                               const Grid& grid) {
    ScalarField field;
    field.grid = grid;
    field.values.resize(size_t(grid.voxel_count()));
    std::vector<unsigned char> buffer;
    read_layers(path, in, header, 0, grid.dims[2], buffer,
                [&](uint64_t v, const unsigned char* bytes) {
                    field.values[size_t(v)] = float_sample(header.type, bytes);
                });
    return field;
}

SparseVoxels read_occupancy_samples(const std::string& path, std::ifstream& in,
                                    const NpyHeader& header, const Grid& grid) {
    SparseVoxels voxels(grid, VoxelizeOptions{}.brick_size);
    const int64_t nx = grid.dims[0], ny = grid.dims[1];
    std::vector<unsigned char> buffer;
    read_layers(
        path, in, header, 0, grid.dims[2], buffer, [&](uint64_t v, const unsigned char* bytes) {
            if (bytes[0] > 1)
                bad_npy(path, "occupancy value " + std::to_string(bytes[0]) + " at voxel index " +
                                  std::to_string(v) + " is neither 0 nor 1");
            if (bytes[0]) voxels.set(int64_t(v) % nx, int64_t(v) / nx % ny, int64_t(v) / (nx * ny));
        });
    return voxels;
}

// work() with any exception not of oclvox's hierarchy (an allocation failing despite the budget)
// reported as an InputError naming the file.
template <class Work>
auto with_npy_errors(const std::string& path, Work&& work) {
    try {
        return work();
    } catch (const Error&) {
        throw;
    } catch (const std::bad_alloc&) {
        bad_npy(path, "out of memory holding its samples");
    } catch (const std::exception& e) {
        bad_npy(path, e.what());
    }
}

void require_npy_extension(const std::string& path) {
    if (detail::lowercase_extension(path) != ".npy")
        throw InputError("cannot read field " + path + ": only .npy fields can be read");
}

// Both kinds, read only after every check of the header, sidecar and budget has passed.
std::variant<ScalarField, SparseVoxels> read_npy_checked(const std::string& path) {
    require_npy_extension(path);
    return with_npy_errors(path, [&]() -> std::variant<ScalarField, SparseVoxels> {
        std::ifstream in;
        const NpyHeader header = read_npy_header(path, in);
        const Grid grid = read_sidecar(path, header.shape);
        if (header.type == NpyType::Uint8) {
            // The sparse result holds at most one bit per voxel.
            check_memory_budget(path, grid.voxel_count() / 8, "its occupancy");
            return read_occupancy_samples(path, in, header, grid);
        }
        check_memory_budget(path, grid.voxel_count() * sizeof(float), "its samples");
        return read_float_samples(path, in, header, grid);
    });
}

}  // namespace

struct FieldLayerReader::Impl {
    std::string path;
    std::ifstream in;
    NpyHeader header;
    Grid grid;
    size_t per_layer = 0;
    int64_t next_layer = 0;
    int64_t thickness = 1;                 // layers a slab holds
    int64_t slab_first = 0, slab_end = 0;  // the layers in `slab`
    std::vector<float> slab;
    std::vector<unsigned char> buffer;  // read_layers' reading buffer, kept between slabs
};

FieldLayerReader::FieldLayerReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
    require_npy_extension(path);
    Impl& r = *impl_;
    r.path = path;
    with_npy_errors(path, [&] {
        r.header = read_npy_header(path, r.in);
        if (r.header.type == NpyType::Uint8)
            bad_npy(path, "it holds an occupancy (uint8 0/1), not float samples");
        r.grid = read_sidecar(path, r.header.shape);
        r.per_layer = size_t(r.grid.dims[0]) * size_t(r.grid.dims[1]);
        const uint64_t layer_bytes = r.per_layer * sizeof(float);
        check_memory_budget(path, layer_bytes + read_buffer_bytes(r.header),
                            "a layer and the reading buffer");
        // A C-order file is read whole for every slab, so its slabs are as thick as a quarter of
        // the budget allows (a file of up to that size is read once); a Fortran-order file's
        // layers lie together, so one at a time costs nothing.
        if (!r.header.fortran_order)
            r.thickness =
                detail::slab_thickness(layer_bytes, r.grid.dims[2], memory_budget(path) / 4);
        r.slab.resize(size_t(r.thickness) * r.per_layer);
        return 0;
    });
}

FieldLayerReader::~FieldLayerReader() = default;
FieldLayerReader::FieldLayerReader(FieldLayerReader&&) noexcept = default;
FieldLayerReader& FieldLayerReader::operator=(FieldLayerReader&&) noexcept = default;

const Grid& FieldLayerReader::grid() const {
    return impl_->grid;
}

void FieldLayerReader::read_layer(float* samples) {
    Impl& r = *impl_;
    if (r.next_layer == r.grid.dims[2])
        bad_npy(r.path, "it has no layer " + std::to_string(r.next_layer) + " (it has " +
                            std::to_string(r.grid.dims[2]) + ")");
    if (r.next_layer == r.slab_end) {
        r.slab_first = r.next_layer;
        r.slab_end = std::min(r.slab_first + r.thickness, r.grid.dims[2]);
        read_layers(r.path, r.in, r.header, r.slab_first, r.slab_end, r.buffer,
                    [&](uint64_t v, const unsigned char* bytes) {
                        r.slab[v] = float_sample(r.header.type, bytes);
                    });
    }
    std::copy_n(&r.slab[size_t(r.next_layer++ - r.slab_first) * r.per_layer], r.per_layer, samples);
}

SparseField read_meshing_view(const std::string& path, float iso,
                              const ProgressCallback& progress) {
    FieldLayerReader reader(path);
    const Grid& grid = reader.grid();
    MeshingViewBuilder view(grid, iso);
    detail::ProgressPhases phases(progress, "reading " + path);
    const size_t reading = phases.add(1.0);
    std::vector<float> layer(size_t(grid.dims[0]) * size_t(grid.dims[1]));
    for (int64_t k = 0; k < grid.dims[2]; ++k) {
        reader.read_layer(layer.data());
        view.add_layer(layer.data());
        phases.report(reading, uint64_t(k + 1), uint64_t(grid.dims[2]));
    }
    phases.finish();
    return view.finish();
}

bool npy_holds_field(const std::string& path) {
    require_npy_extension(path);
    return with_npy_errors(path, [&] {
        std::ifstream in;
        return read_npy_header(path, in).type != NpyType::Uint8;
    });
}

void write_field(const std::string& path, const ScalarField& field, double band_voxels,
                 const ProgressCallback& progress) {
    check_field(field, path);
    if (!(band_voxels > 0)) band_voxels = inferred_band(field);
    const size_t per_layer = size_t(field.grid.dims[0]) * size_t(field.grid.dims[1]);
    write_field(
        path, field.grid, band_voxels,
        [&](int64_t k, float* out) {
            std::copy_n(&field.values[size_t(k) * per_layer], per_layer, out);
        },
        progress);
}

void write_field(const std::string& path, const Grid& grid, double band_voxels,
                 const FieldLayer& layer, const ProgressCallback& progress) {
    validate_grid(grid);
    const std::string extension = detail::lowercase_extension(path);
    detail::ProgressPhases phases(progress, "writing " + path);
    if (extension == ".npy") {
        const size_t per_layer = size_t(grid.dims[0]) * size_t(grid.dims[1]);
        return write_npy_field(path, grid, band_voxels, phases,
                               [&](int64_t first, int64_t end, float* samples) {
                                   for (int64_t k = first; k < end; ++k)
                                       layer(k, samples + size_t(k - first) * per_layer);
                               });
    }
    if (extension == ".vdb")
        return detail::write_level_set_vdb(path, grid, band_voxels, layer, phases);
    unknown_field_extension(path, extension);
}

void write_field(const std::string& path, const SparseField& field,
                 const ProgressCallback& progress) {
    validate_grid(field.grid());
    const std::string extension = detail::lowercase_extension(path);
    detail::ProgressPhases phases(progress, "writing " + path);
    const auto& d = field.grid().dims;
    if (extension == ".npy")
        return write_npy_field(
            path, field.grid(), field.band_voxels(), phases,
            [&](int64_t first, int64_t end, float* samples) {
                field.copy_box({0, 0, first}, {d[0], d[1], end}, samples);
            },
            SparseField::kLeaf);
    if (extension == ".vdb") return detail::write_level_set_vdb(path, field, phases);
    unknown_field_extension(path, extension);
}

std::variant<ScalarField, SparseVoxels> read_npy(const std::string& path) {
    return read_npy_checked(path);
}

ScalarField read_field(const std::string& path) {
    std::variant<ScalarField, SparseVoxels> data = read_npy_checked(path);
    if (std::holds_alternative<SparseVoxels>(data))
        bad_npy(path, "it holds an occupancy (uint8 0/1), not float samples (read_npy reads both)");
    return std::get<ScalarField>(std::move(data));
}

namespace {

void require_vdb_extension(const std::string& path) {
    if (detail::lowercase_extension(path) != ".vdb")
        throw InputError("cannot read field " + path + ": only .vdb files hold sparse fields");
}

}  // namespace

SparseField read_sparse_field(const std::string& path) {
    require_vdb_extension(path);
    return detail::vdb_functions_to_read(path).read_field(path);
}

SparseField read_sparse_field(const std::string& path, const Grid& lattice, double band_voxels) {
    require_vdb_extension(path);
    return detail::vdb_functions_to_read(path).read_field_onto(path, lattice, band_voxels);
}

}  // namespace oclvox
