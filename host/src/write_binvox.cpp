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
// Streaming: the file order is x slowest, so the grid is read from the bricks an x-slab at a
// time into a buffer laid out in file order (y fastest, then z) and run-length encoded from
// there; the largest buffer is one slab. Runs are found a machine word at a time.
//
// Placement: binvox maps voxel (i,j,k) to the point translate + scale * (i,j,k) / D (plus half a
// voxel for centres), so translate = grid origin and scale = D * voxel_size reproduce our grid.
#include <algorithm>
#include <cstring>
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

// Collects voxels into maximal runs and writes them as (value, count) pairs, count <= 255, in
// large pieces.
class RunWriter {
  public:
    explicit RunWriter(std::ostream& out) : out_(out) {}

    void add(uint8_t value, uint64_t count) {
        if (count == 0) return;
        if (value != value_) {
            emit();
            value_ = value;
        }
        pending_ += count;
    }
    // Adds the voxels bytes[0, n) (each 0 or 1), run by run.
    void add_bytes(const uint8_t* bytes, size_t n) {
        for (size_t start = 0; start < n;) {
            const size_t length = run_length(bytes + start, n - start, bytes[start]);
            add(bytes[start], length);
            start += length;
        }
    }
    void finish() {
        emit();
        out_.write(buffer_.data(), std::streamsize(buffer_.size()));
        buffer_.clear();
    }

  private:
    // Length of the run of `value` at the start of bytes[0, n), comparing eight bytes at once.
    static size_t run_length(const uint8_t* bytes, size_t n, uint8_t value) {
        const uint64_t same = value ? 0x0101010101010101u : 0;
        size_t i = 0;
        for (uint64_t word; i + 8 <= n; i += 8) {
            std::memcpy(&word, bytes + i, 8);
            if (word != same) break;
        }
        while (i < n && bytes[i] == value) ++i;
        return i;
    }
    void emit() {
        while (pending_ > 0) {
            const uint64_t run = std::min<uint64_t>(pending_, 255);
            buffer_.push_back(char(value_));
            buffer_.push_back(char(run));
            pending_ -= run;
        }
        if (buffer_.size() >= kFlushBytes) {
            out_.write(buffer_.data(), std::streamsize(buffer_.size()));
            buffer_.clear();
        }
    }

    static constexpr size_t kFlushBytes = size_t(1) << 20;
    std::ostream& out_;
    std::string buffer_;
    uint8_t value_ = 0;
    uint64_t pending_ = 0;  // voxels of value_ not yet written
};

}  // namespace

void write_binvox(const std::string& path, const SparseVoxels& voxels, uint64_t slab_bytes) {
    const Grid& grid = voxels.grid();
    const int64_t dim = std::max({grid.dims[0], grid.dims[1], grid.dims[2]});
    if (dim > kMaxBinvoxDim)
        throw OutputError("cannot write " + path + ": binvox grids are cubic and this grid needs " +
                          std::to_string(dim) + "^3 voxels, more than the " +
                          std::to_string(kMaxBinvoxDim) +
                          "^3 this writer allows; use .vdb, .vox, .obj or .ply for large grids");

    write_file_atomically(path, [&](std::ostream& out) {
        // Phase 1: header, with enough digits that the numbers read back exactly.
        out << "#binvox 1\n";
        out << "dim " << dim << ' ' << dim << ' ' << dim << '\n';
        out << std::setprecision(std::numeric_limits<double>::max_digits10);
        out << "translate " << grid.origin[0] << ' ' << grid.origin[1] << ' ' << grid.origin[2]
            << '\n';
        out << "scale " << double(dim) * grid.voxel_size << '\n';
        out << "data\n";

        // Phase 2: x-slabs of the grid in file order (plane x, then y fastest, then z), each
        // followed by its padding up to the cube; then the padding planes beyond nx.
        const int64_t nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
        const int64_t plane = ny * nz;
        const int64_t thickness = slab_thickness(uint64_t(plane), nx, slab_bytes);
        std::vector<uint8_t> slab(size_t(plane * thickness));
        RunWriter runs(out);
        for (int64_t x0 = 0; x0 < nx; x0 += thickness) {
            const int64_t depth = std::min(thickness, nx - x0);
            std::fill(slab.begin(), slab.end(), uint8_t(0));
            voxels.mark_box({x0, 0, 0}, {x0 + depth, ny, nz}, {plane, 1, ny}, slab.data());
            for (int64_t x = 0; x < depth; ++x) {
                const uint8_t* rows = slab.data() + x * plane;
                if (ny == dim) {  // rows are contiguous in the file too
                    runs.add_bytes(rows, size_t(plane));
                } else {
                    for (int64_t z = 0; z < nz; ++z) {
                        runs.add_bytes(rows + z * ny, size_t(ny));
                        runs.add(0, uint64_t(dim - ny));
                    }
                }
                runs.add(0, uint64_t(dim - nz) * uint64_t(dim));
            }
        }
        runs.add(0, uint64_t(dim - nx) * uint64_t(dim) * uint64_t(dim));
        runs.finish();
    });
}

}  // namespace oclvox::detail
