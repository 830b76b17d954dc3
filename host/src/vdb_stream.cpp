// OpenVDB's file layout, the parts the .vdb files we serialize share (see vdb_stream.hpp).
#include "vdb_stream.hpp"

#include <algorithm>
#include <random>

#include "bit_count.hpp"
#include "writers.hpp"

namespace oclvox::detail::vdb_stream {

namespace {

// The file format laid out here, and the library whose writer it follows.
constexpr uint32_t kFileVersion = 224, kLibraryMajor = 10, kLibraryMinor = 0;
constexpr uint32_t kCompressActiveMask = 0x2;  // io::COMPRESS_ACTIVE_MASK

void put_string(BlockWriter& sink, const std::string& text) {
    sink.little_endian(int32_t(text.size()));
    sink.text(text);
}

// A random (version 4) UUID in lowercase hex, as OpenVDB puts one in every file it writes.
std::string random_uuid() {
    std::random_device entropy;
    std::array<uint8_t, 16> bits{};
    for (uint8_t& b : bits) b = uint8_t(entropy());
    bits[6] = uint8_t((bits[6] & 0x0f) | 0x40);  // version 4
    bits[8] = uint8_t((bits[8] & 0x3f) | 0x80);  // the RFC 4122 variant
    static const char kHex[] = "0123456789abcdef";
    std::string text;
    for (size_t i = 0; i < bits.size(); ++i) {
        if (i == 4 || i == 6 || i == 8 || i == 10) text += '-';
        text += kHex[bits[i] >> 4];
        text += kHex[bits[i] & 15];
    }
    return text;
}

}  // namespace

uint64_t leaf_key(int64_t x, int64_t y, int64_t z) {
    const uint64_t root = uint64_t(x >> 12) << 16 | uint64_t(y >> 12) << 8 | uint64_t(z >> 12);
    const uint64_t upper =
        uint64_t(x >> 7 & 31) << 10 | uint64_t(y >> 7 & 31) << 5 | uint64_t(z >> 7 & 31);
    const uint64_t lower =
        uint64_t(x >> 3 & 15) << 8 | uint64_t(y >> 3 & 15) << 4 | uint64_t(z >> 3 & 15);
    return root << (kUpperBits + kLowerBits) | upper << kLowerBits | lower;
}

std::array<int32_t, 3> leaf_origin(uint64_t key) {
    const uint64_t root = key >> (kUpperBits + kLowerBits), upper = key >> kLowerBits & 32767,
                   lower = key & 4095;
    return {int32_t((root >> 16) << 12 | (upper >> 10) << 7 | (lower >> 8) << 3),
            int32_t((root >> 8 & 255) << 12 | (upper >> 5 & 31) << 7 | (lower >> 4 & 15) << 3),
            int32_t((root & 255) << 12 | (upper & 31) << 7 | (lower & 15) << 3)};
}

TreeShape tree_shape(size_t count, const std::function<uint64_t(size_t)>& key_of,
                     const std::function<bool(size_t)>& full_of) {
    TreeShape shape;
    for (size_t i = 0; i < count; ++i) {
        const uint64_t lower_key = key_of(i) >> kLowerBits;
        if (shape.lowers.empty() || shape.lowers.back().key != lower_key)
            shape.lowers.push_back({lower_key, i, i});
        LowerNode& lower = shape.lowers.back();
        lower.end = i + 1;
        lower.full_leaves += full_of(i);
    }
    for (size_t i = 0; i < shape.lowers.size(); ++i) {
        const uint64_t upper_key = shape.lowers[i].key >> kUpperBits;
        if (shape.uppers.empty() || shape.uppers.back().key != upper_key)
            shape.uppers.push_back({upper_key, i, i});
        UpperNode& upper = shape.uppers.back();
        upper.end = i + 1;
        upper.full_lowers += shape.lowers[i].full();
    }
    return shape;
}

void TreeStatistics::add_leaf(uint64_t key, const uint64_t* words) {
    const auto o = leaf_origin(key);
    uint64_t yz = 0;
    int x_lo = 8, x_hi = -1;
    for (int x = 0; x < 8; ++x) {
        if (!words[x]) continue;
        x_lo = std::min(x_lo, x);
        x_hi = x;
        yz |= words[x];
        active += uint64_t(popcount64(words[x]));
    }
    if (x_hi < 0) return;
    int y_lo = 8, y_hi = -1;
    uint64_t z_bits = 0;
    for (int y = 0; y < 8; ++y) {
        const uint64_t row = yz >> (8 * y) & 255;
        if (!row) continue;
        y_lo = std::min(y_lo, y);
        y_hi = y;
        z_bits |= row;
    }
    const int z_lo = __builtin_ctzll(z_bits), z_hi = 63 - __builtin_clzll(z_bits);
    const std::array<int32_t, 3> lo{o[0] + x_lo, o[1] + y_lo, o[2] + z_lo},
        hi{o[0] + x_hi, o[1] + y_hi, o[2] + z_hi};
    for (int a = 0; a < 3; ++a) {
        box_min[a] = std::min(box_min[a], lo[a]);
        box_max[a] = std::max(box_max[a], hi[a]);
    }
}

// Everything before the tree: header, grid descriptor, compression, metadata, transform.
void put_grid_prefix(BlockWriter& sink, const Grid& grid, const GridDescription& description,
                     const TreeStatistics& stats) {
    sink.little_endian(int64_t(0x56444220));  // " BDV"
    sink.little_endian(kFileVersion);
    sink.little_endian(kLibraryMajor);
    sink.little_endian(kLibraryMinor);
    sink.little_endian(uint8_t(0));  // no grid offsets
    sink.text(random_uuid());
    sink.little_endian(int32_t(0));  // file metadata
    sink.little_endian(int32_t(1));  // grids
    put_string(sink, description.name);
    put_string(sink, description.tree_type);
    put_string(sink, "");
    for (int i = 0; i < 3; ++i) sink.little_endian(int64_t(0));
    sink.little_endian(kCompressActiveMask);

    // The grid's metadata, in name order (OpenVDB keeps them in a std::map).
    auto put_entry = [&](const char* key, const char* type, size_t size) {
        put_string(sink, key);
        put_string(sink, type);
        sink.little_endian(int32_t(size));
    };
    auto put_text = [&](const char* key, const std::string& value) {
        put_entry(key, "string", value.size());
        sink.text(value);
    };
    auto put_vec3i = [&](const char* key, const std::array<int32_t, 3>& value) {
        put_entry(key, "vec3i", 12);
        for (const int32_t v : value) sink.little_endian(v);
    };
    auto put_int64 = [&](const char* key, uint64_t value) {
        put_entry(key, "int64", 8);
        sink.little_endian(int64_t(value));
    };
    const bool band = description.band_voxels > 0;
    sink.little_endian(int32_t(band ? 11 : 10));
    put_text("class", description.grid_class);
    put_vec3i("file_bbox_max", stats.box_max);
    put_vec3i("file_bbox_min", stats.box_min);
    put_text("file_compression", "active values");
    put_int64("file_mem_bytes", stats.memory);
    put_int64("file_voxel_count", stats.active);
    put_text("name", description.name);
    if (band) {
        put_entry("oclvox_band_voxels", "double", 8);
        sink.little_endian(description.band_voxels);
    }
    put_vec3i("oclvox_dims", {int32_t(grid.dims[0]), int32_t(grid.dims[1]), int32_t(grid.dims[2])});
    put_entry("oclvox_origin", "vec3d", 24);
    for (const double v : grid.origin) sink.little_endian(v);
    put_entry("oclvox_voxel_size", "double", 8);
    sink.little_endian(grid.voxel_size);

    // The transform: OpenVDB's UniformScaleTranslateMap with its derived values, computed as
    // its constructor computes them.
    put_string(sink, "UniformScaleTranslateMap");
    const double scale = grid.voxel_size, inverse = 1.0 / scale;
    for (const double t : vdb_index_origin(grid)) sink.little_endian(t);
    for (const double v :
         {scale, scale, scale, scale, scale, scale, inverse, inverse, inverse, inverse * inverse,
          inverse * inverse, inverse * inverse, inverse / 2, inverse / 2, inverse / 2})
        sink.little_endian(v);
}

}  // namespace oclvox::detail::vdb_stream
