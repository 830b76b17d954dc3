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
// there; the largest buffer is one slab. Only row pieces inside stored bricks are scanned, runs
// are found a machine word at a time, and scanned set bytes are cleared as they are encoded, so
// the cost follows the stored bricks, not the grid volume.
//
// Placement: binvox maps voxel (i,j,k) to the point translate + scale * (i,j,k) / D (plus half a
// voxel for centres), so translate = grid origin and scale = D * voxel_size reproduce our grid.
#include <tbb/parallel_for.h>

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

// The maximal runs of voxel values of a stretch of the file, in order: what one plane of a slab
// encodes to, independently of (and in parallel with) the other planes.
class Runs {
  public:
    void add(uint8_t value, uint64_t count) {
        if (count == 0) return;
        if (!runs_.empty() && runs_.back().first == value)
            runs_.back().second += count;
        else
            runs_.emplace_back(value, count);
    }
    // Adds the voxels bytes[0, n) (each 0 or 1), run by run, and zeroes them: the caller's
    // buffer is all zero again afterwards at a cost proportional to the set voxels, not to the
    // buffer.
    void take_bytes(uint8_t* bytes, size_t n) {
        for (size_t start = 0; start < n;) {
            const uint8_t value = bytes[start];
            const size_t length = run_length(bytes + start, n - start, value);
            add(value, length);
            if (value) std::memset(bytes + start, 0, length);
            start += length;
        }
    }
    const std::vector<std::pair<uint8_t, uint64_t>>& runs() const { return runs_; }

  private:
    // Length of the run of `value` at the start of bytes[0, n). Empty space, most of a surface
    // grid, is skipped 64 bytes at a time, set runs 8 at a time.
    static size_t run_length(const uint8_t* bytes, size_t n, uint8_t value) {
        size_t i = 0;
        if (value == 0) {
            for (; i + 64 <= n; i += 64) {
                uint64_t words[8], any = 0;
                std::memcpy(words, bytes + i, 64);
                for (uint64_t word : words) any |= word;
                if (any) break;
            }
        }
        const uint64_t same = value ? 0x0101010101010101u : 0;
        for (uint64_t word; i + 8 <= n; i += 8) {
            std::memcpy(&word, bytes + i, 8);
            if (word != same) break;
        }
        while (i < n && bytes[i] == value) ++i;
        return i;
    }

    std::vector<std::pair<uint8_t, uint64_t>> runs_;
};

// Joins runs into maximal ones and writes them as (value, count) pairs, count <= 255, in large
// pieces.
class RunWriter {
  public:
    explicit RunWriter(std::ostream& out) : out_(out) { buffer_.reserve(kFlushBytes); }

    void add(uint8_t value, uint64_t count) {
        if (count == 0) return;
        if (value != value_) {
            emit();
            value_ = value;
        }
        pending_ += count;
    }
    void add(const Runs& runs) {
        for (const auto& [value, count] : runs.runs()) add(value, count);
    }
    void finish() {
        emit();
        flush();
    }

  private:
    // Writes the pending run as pairs: full (value, 255) pairs first, filled a buffer at a time
    // (the padding of a large cube is tens of millions of them), then the remainder.
    void emit() {
        while (pending_ >= 255) {
            if (buffer_.size() + 2 > kFlushBytes) flush();
            const uint64_t room = (kFlushBytes - buffer_.size()) / 2;
            const uint64_t pairs = std::min(pending_ / 255, room);
            const size_t at = buffer_.size();
            buffer_.resize(at + 2 * pairs);
            for (uint64_t p = 0; p < pairs; ++p) {
                buffer_[at + 2 * p] = char(value_);
                buffer_[at + 2 * p + 1] = char(255);
            }
            pending_ -= 255 * pairs;
        }
        if (pending_ > 0) {
            if (buffer_.size() + 2 > kFlushBytes) flush();
            buffer_.push_back(char(value_));
            buffer_.push_back(char(pending_));
            pending_ = 0;
        }
    }
    void flush() {
        out_.write(buffer_.data(), std::streamsize(buffer_.size()));
        buffer_.clear();
    }

    static constexpr size_t kFlushBytes = size_t(1) << 20;
    std::ostream& out_;
    std::string buffer_;
    uint8_t value_ = 0;
    uint64_t pending_ = 0;  // voxels of value_ not yet written
};

}  // namespace

void write_binvox(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress,
                  uint64_t slab_bytes) {
    const Grid& grid = voxels.grid();
    const int64_t dim = std::max({grid.dims[0], grid.dims[1], grid.dims[2]});
    if (dim > kMaxBinvoxDim)
        throw OutputError("cannot write " + path + ": binvox grids are cubic and this grid needs " +
                          std::to_string(dim) + "^3 voxels, more than the " +
                          std::to_string(kMaxBinvoxDim) +
                          "^3 this writer allows; use .vdb, .vox, .obj or .ply for large grids");

    const size_t planes = progress.add(1);
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
        // followed by its padding up to the cube; then the padding planes beyond nx. Only the
        // row pieces that lie in a stored brick are scanned: the rest is known to be empty.
        const int64_t nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
        const int64_t plane = ny * nz;
        const int64_t thickness = slab_thickness(uint64_t(plane), nx, slab_bytes);
        const int64_t b = voxels.brick_size();
        const auto nbricks = voxels.brick_dims();
        std::vector<uint8_t> slab(size_t(plane * thickness), 0);  // all zero between slabs
        // Per brick row bz: the y ranges [begin, end) of the stored bricks in the slab, merged.
        std::vector<std::vector<std::pair<int64_t, int64_t>>> stored(
            static_cast<size_t>(nbricks[2]));
        RunWriter runs(out);
        std::vector<Runs> plane_runs;
        for (int64_t x0 = 0; x0 < nx; x0 += thickness) {
            const int64_t depth = std::min(thickness, nx - x0);
            voxels.mark_box({x0, 0, 0}, {x0 + depth, ny, nz}, {plane, 1, ny}, slab.data());
            for (int64_t bz = 0; bz < nbricks[2]; ++bz) {
                auto& ranges = stored[size_t(bz)];
                ranges.clear();
                for (int64_t by = 0; by < nbricks[1]; ++by) {
                    bool any = false;
                    for (int64_t bx = x0 / b; bx <= (x0 + depth - 1) / b && !any; ++bx)
                        any = voxels.brick_blocks(
                                  uint64_t(bx + nbricks[0] * (by + nbricks[1] * bz))) != nullptr;
                    if (!any) continue;
                    const int64_t end = std::min((by + 1) * b, ny);
                    if (!ranges.empty() && ranges.back().second == by * b)
                        ranges.back().second = end;
                    else
                        ranges.push_back({by * b, end});
                }
            }
            // The slab's planes are encoded in parallel, each into its own runs, which are then
            // written in plane order: the runs are the same as one pass's.
            plane_runs.assign(size_t(depth), Runs());
            tbb::parallel_for(int64_t(0), depth, [&](int64_t x) {
                Runs& plane_run = plane_runs[size_t(x)];
                uint8_t* rows = slab.data() + x * plane;
                for (int64_t z = 0; z < nz; ++z) {
                    int64_t y = 0;  // the row is encoded up to here
                    for (const auto& [begin, end] : stored[size_t(z / b)]) {
                        plane_run.add(0, uint64_t(begin - y));
                        plane_run.take_bytes(rows + z * ny + begin, size_t(end - begin));
                        y = end;
                    }
                    plane_run.add(0, uint64_t(dim - y));
                }
                plane_run.add(0, uint64_t(dim - nz) * uint64_t(dim));
            });
            for (const Runs& plane_run : plane_runs) runs.add(plane_run);
            progress.report(planes, uint64_t(x0 + depth), uint64_t(nx));
        }
        runs.add(0, uint64_t(dim - nx) * uint64_t(dim) * uint64_t(dim));
        runs.finish();
        progress.finish();
    });
}

}  // namespace oclvox::detail
