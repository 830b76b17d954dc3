// binvox writer (format by Patrick Min / Michael Kazhdan, patrickmin.com/binvox/binvox.html).
//
// The file is an ASCII header
//     #binvox 1 / dim D D D / translate tx ty tz / scale s / data
// followed by (value, count) byte pairs, count 1..255, covering all D^3 voxels with y fastest,
// then z, then x: index = x*D*D + z*D + y.
//
// Non-cubic grids: the format page says the three dimensions "should all be equal", viewvox
// assumes so, and readers disagree on how to order unequal ones (binvox-rw-py reshapes by the
// header order, others read them as depth/height/width). So the grid is written as a cube of
// D = max(nx, ny, nz) voxels with ours in the low corner and the rest empty. Every reader then
// agrees on every voxel, and the runs of padding cost two bytes per 255 voxels.
//
// Placement: binvox maps voxel (i,j,k) to the point translate + scale * (i,j,k) / D (plus half a
// voxel for centres), so translate = grid origin and scale = D * voxel_size reproduce our grid.
#include <algorithm>
#include <iomanip>
#include <limits>
#include <vector>

#include "atomic_file.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// binvox is dense: the run-length data alone of a 4096^3 cube of padding is half a gigabyte,
// and readers expand it to one byte (or bit) per voxel.
constexpr int64_t kMaxBinvoxDim = 4096;

// Appends run-length pairs to a buffer that is written out in large pieces.
class RunWriter {
  public:
    explicit RunWriter(std::ostream& out) : out_(out) {}

    void add(uint8_t value, uint64_t count) {
        while (count > 0) {
            const uint64_t run = std::min<uint64_t>(count, 255);
            buffer_.push_back(char(value));
            buffer_.push_back(char(run));
            count -= run;
            if (buffer_.size() >= kFlushBytes) flush();
        }
    }
    void flush() {
        out_.write(buffer_.data(), std::streamsize(buffer_.size()));
        buffer_.clear();
    }

  private:
    static constexpr size_t kFlushBytes = size_t(1) << 20;
    std::ostream& out_;
    std::string buffer_;
};

}  // namespace

void write_binvox(const std::string& path, const SparseVoxels& voxels) {
    const Grid& grid = voxels.grid();
    const int64_t dim = std::max({grid.dims[0], grid.dims[1], grid.dims[2]});
    if (dim > kMaxBinvoxDim)
        throw OutputError("cannot write " + path + ": binvox grids are cubic and this grid needs " +
                          std::to_string(dim) + "^3 voxels, more than the " +
                          std::to_string(kMaxBinvoxDim) +
                          "^3 this writer allows; use .vox, .obj or .ply for large grids");

    // Phase 1: binvox indices of the set voxels, in file order. Sorting the sparse set avoids a
    // dense copy of the grid.
    const uint64_t d = uint64_t(dim);
    std::vector<uint64_t> set_indices;
    set_indices.reserve(voxels.count());
    voxels.for_each([&](int64_t x, int64_t y, int64_t z) {
        set_indices.push_back(uint64_t(x) * d * d + uint64_t(z) * d + uint64_t(y));
    });
    std::sort(set_indices.begin(), set_indices.end());

    write_file_atomically(path, [&](std::ostream& out) {
        // Phase 2: header, with enough digits that the numbers read back exactly.
        out << "#binvox 1\n";
        out << "dim " << dim << ' ' << dim << ' ' << dim << '\n';
        out << std::setprecision(std::numeric_limits<double>::max_digits10);
        out << "translate " << grid.origin[0] << ' ' << grid.origin[1] << ' ' << grid.origin[2]
            << '\n';
        out << "scale " << double(dim) * grid.voxel_size << '\n';
        out << "data\n";

        // Phase 3: alternate runs of empty and set voxels up to the end of the cube.
        RunWriter runs(out);
        uint64_t next = 0;  // first voxel index not yet covered by a run
        for (size_t s = 0; s < set_indices.size();) {
            size_t end = s + 1;
            while (end < set_indices.size() && set_indices[end] == set_indices[end - 1] + 1) ++end;
            runs.add(0, set_indices[s] - next);
            runs.add(1, end - s);
            next = set_indices[end - 1] + 1;
            s = end;
        }
        runs.add(0, d * d * d - next);
        runs.flush();
    });
}

}  // namespace oclvox::detail
