#include "preview.hpp"

#include <png.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <vector>

namespace oclvox_cli {

namespace {

constexpr uint8_t kBackground = 24, kEmpty = 64, kSet = 255, kBar = 255;
constexpr int kMargin = 8, kBarThickness = 3;

// The three projections at block resolution (one cell per voxels_per_pixel^2 voxels).
struct Projections {
    oclvox::Grid grid;
    int64_t voxels_per_pixel = 1, pixels_per_voxel = 1;
    std::array<int64_t, 3> cells{};  // ceil(dims / voxels_per_pixel)
    // Panel p looks along axis p; its horizontal and vertical axes are the other two in order.
    std::array<std::vector<uint8_t>, 3> lit;

    static constexpr int kAxes[3][2] = {{1, 2}, {0, 2}, {0, 1}};

    explicit Projections(const oclvox::Grid& g) : grid(g) {
        const int64_t longest = std::max({g.dims[0], g.dims[1], g.dims[2]});
        if (longest <= 256)
            pixels_per_voxel = 256 / longest;
        else
            voxels_per_pixel = (longest + 511) / 512;
        for (int a = 0; a < 3; ++a)
            cells[a] = (g.dims[a] + voxels_per_pixel - 1) / voxels_per_pixel;
        for (int p = 0; p < 3; ++p)
            lit[p].assign(size_t(cells[kAxes[p][0]] * cells[kAxes[p][1]]), 0);
    }

    void mark(int64_t i, int64_t j, int64_t k) {
        const int64_t c[3] = {i / voxels_per_pixel, j / voxels_per_pixel, k / voxels_per_pixel};
        for (int p = 0; p < 3; ++p) {
            const int h = kAxes[p][0], v = kAxes[p][1];
            lit[p][size_t(c[h] + cells[h] * c[v])] = 1;
        }
    }
};

// The largest 1, 2 or 5 times a power of ten that is at most `limit`.
double round_length(double limit) {
    const double power = std::pow(10.0, std::floor(std::log10(limit)));
    for (double step : {5.0, 2.0, 1.0})
        if (step * power <= limit) return step * power;
    return power;
}

void append_png_bytes(png_structp png, png_bytep data, png_size_t length) {
    auto* out = static_cast<std::string*>(png_get_io_ptr(png));
    out->append(reinterpret_cast<const char*>(data), length);
}

[[noreturn]] void png_failed(png_structp, png_const_charp message) {
    throw oclvox::OutputError(std::string("libpng: ") + message);
}

// Grey 8-bit PNG bytes of `image` (width x height, row 0 at the top) with one text chunk.
std::string encode_png(const std::vector<uint8_t>& image, int width, int height,
                       const std::string& layout) {
    std::string bytes;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, png_failed, nullptr);
    if (!png) throw oclvox::OutputError("libpng: cannot start a PNG");
    png_infop info = png_create_info_struct(png);
    try {
        if (!info) throw oclvox::OutputError("libpng: cannot start a PNG");
        png_set_write_fn(png, &bytes, append_png_bytes, nullptr);
        png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_GRAY,
                     PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        png_text text{};
        text.compression = PNG_TEXT_COMPRESSION_NONE;
        text.key = const_cast<char*>("oclvox-layout");
        text.text = const_cast<char*>(layout.c_str());
        png_set_text(png, info, &text, 1);
        png_write_info(png, info);
        for (int row = 0; row < height; ++row)
            png_write_row(png, image.data() + size_t(row) * size_t(width));
        png_write_end(png, info);
    } catch (...) {
        png_destroy_write_struct(&png, &info);
        throw;
    }
    png_destroy_write_struct(&png, &info);
    return bytes;
}

void write_projections(const std::string& path, const Projections& p) {
    // Phase 1: the layout: panels left to right, the scale bar under the first one.
    const int64_t s = p.pixels_per_voxel;
    std::array<int64_t, 3> left{}, width{}, height{};
    int64_t x = kMargin, tallest = 0;
    for (int panel = 0; panel < 3; ++panel) {
        left[panel] = x;
        width[panel] = p.cells[Projections::kAxes[panel][0]] * s;
        height[panel] = p.cells[Projections::kAxes[panel][1]] * s;
        x += width[panel] + kMargin;
        tallest = std::max(tallest, height[panel]);
    }
    const double pixel_length = p.grid.voxel_size * double(p.voxels_per_pixel) / double(s);
    const double bar_length =
        round_length(double(std::max<int64_t>(width[0] / 3, 1)) * pixel_length);
    const int64_t bar_pixels = std::max<int64_t>(1, std::llround(bar_length / pixel_length));
    const int64_t bar_top = kMargin + tallest + kMargin;
    const int64_t image_width = std::max(x, kMargin + bar_pixels + kMargin);
    const int64_t image_height = bar_top + kBarThickness + kMargin;

    // Phase 2: the pixels. Vertical axes point up, so row 0 is the highest cell.
    std::vector<uint8_t> image(size_t(image_width * image_height), kBackground);
    for (int panel = 0; panel < 3; ++panel) {
        const int64_t columns = p.cells[Projections::kAxes[panel][0]];
        const int64_t rows = p.cells[Projections::kAxes[panel][1]];
        for (int64_t py = 0; py < height[panel]; ++py)
            for (int64_t px = 0; px < width[panel]; ++px) {
                const int64_t h = px / s, v = rows - 1 - py / s;
                image[size_t((kMargin + py) * image_width + left[panel] + px)] =
                    p.lit[panel][size_t(h + columns * v)] ? kSet : kEmpty;
            }
    }
    for (int64_t row = bar_top; row < bar_top + kBarThickness; ++row)
        std::fill_n(image.begin() + row * image_width + kMargin, bar_pixels, kBar);

    // Phase 3: the layout for readers, and the file.
    nlohmann::ordered_json layout;
    layout["pixels_per_voxel"] = s;
    layout["voxels_per_pixel"] = p.voxels_per_pixel;
    const char* names[3] = {"x", "y", "z"};
    for (int panel = 0; panel < 3; ++panel)
        layout["panels"].push_back({{"along", names[panel]},
                                    {"right", names[Projections::kAxes[panel][0]]},
                                    {"up", names[Projections::kAxes[panel][1]]},
                                    {"left", left[panel]},
                                    {"top", kMargin},
                                    {"width", width[panel]},
                                    {"height", height[panel]}});
    layout["scale_bar"] = {
        {"left", kMargin}, {"top", bar_top}, {"pixels", bar_pixels}, {"length", bar_length}};
    const std::string png = encode_png(image, int(image_width), int(image_height), layout.dump());
    oclvox::write_text_file(path, png);
}

}  // namespace

void write_preview(const std::string& path, const oclvox::SparseVoxels& voxels) {
    Projections projections(voxels.grid());
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) { projections.mark(i, j, k); });
    write_projections(path, projections);
}

void write_preview(const std::string& path, const oclvox::SparseField& field, float iso) {
    const float background = field.background();
    if (!(-background < iso) || background < iso) {  // every sample outside the leaves alike
        write_preview(path, field.to_dense(), iso);
        return;
    }
    // The samples outside the stored leaves are inside exactly at the inside voxels; those in
    // the leaves by their values. A bit per leaf tells the two apart.
    Projections projections(field.grid());
    const auto nb = field.leaf_dims();
    std::vector<bool> stored(size_t(nb[0] * nb[1] * nb[2]), false);
    for (uint64_t leaf : field.leaf_indices()) stored[size_t(leaf)] = true;
    const int64_t leaf = oclvox::SparseField::kLeaf;
    field.inside().for_each([&](int64_t i, int64_t j, int64_t k) {
        if (!stored[size_t(i / leaf + nb[0] * (j / leaf + nb[1] * (k / leaf)))])
            projections.mark(i, j, k);
    });
    const auto& d = field.grid().dims;
    for (size_t n = 0; n < field.leaf_count(); ++n) {
        const auto o = field.leaf_origin(field.leaf_indices()[n]);
        const float* samples = field.leaf_samples(n);
        for (int64_t z = 0; z < std::min(leaf, d[2] - o[2]); ++z)
            for (int64_t y = 0; y < std::min(leaf, d[1] - o[1]); ++y)
                for (int64_t x = 0; x < std::min(leaf, d[0] - o[0]); ++x)
                    if (samples[x + leaf * (y + leaf * z)] < iso)
                        projections.mark(o[0] + x, o[1] + y, o[2] + z);
    }
    write_projections(path, projections);
}

void write_preview(const std::string& path, const oclvox::ScalarField& field, float iso) {
    Projections projections(field.grid);
    const auto& d = field.grid.dims;
    size_t index = 0;
    for (int64_t k = 0; k < d[2]; ++k)
        for (int64_t j = 0; j < d[1]; ++j)
            for (int64_t i = 0; i < d[0]; ++i)
                if (field.values[index++] < iso) projections.mark(i, j, k);
    write_projections(path, projections);
}

}  // namespace oclvox_cli
