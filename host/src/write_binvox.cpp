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
// Streaming: the file order is x slowest, then z, with y fastest, so each row (x, z) is gathered
// from the bit words of the stored bricks it crosses into a bit mask along y (a 4x4x4 block gives
// four of its voxels at once) and its runs are found a machine word at a time; a row through no
// stored brick is one run of empty voxels. Nothing dense is made, and the cost follows the rows
// of the stored bricks, not the grid volume.
//
// Placement: binvox maps voxel (i,j,k) to the point translate + scale * (i,j,k) / D (plus half a
// voxel for centres), so translate = grid origin and scale = D * voxel_size reproduce our grid.
#include <tbb/parallel_for.h>

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
    // Adds the voxels of bits [0, n) of `words` (bit i of words[i / 64]), run by run.
    void take_bits(const uint64_t* words, uint64_t n) {
        for (uint64_t i = 0; i < n;) {
            const bool value = words[i / 64] >> (i % 64) & 1;
            const uint64_t end = run_end(words, i, n, value);
            add(uint8_t(value), end - i);
            i = end;
        }
    }
    const std::vector<std::pair<uint8_t, uint64_t>>& runs() const { return runs_; }

  private:
    // The end of the run of `value` that starts at bit i, at most n: a word at a time.
    static uint64_t run_end(const uint64_t* words, uint64_t i, uint64_t n, bool value) {
        while (i < n) {
            // Set bits where the run stops; the shift brings in zeros, which continue it.
            const uint64_t stops = (value ? ~words[i / 64] : words[i / 64]) >> (i % 64);
            if (stops) return std::min(n, i + uint64_t(__builtin_ctzll(stops)));
            i = (i / 64 + 1) * 64;
        }
        return n;
    }

    std::vector<std::pair<uint8_t, uint64_t>> runs_;
};

// The runs of `count` (1 to 4) planes from x, which lie in one column of 4x4x4 blocks, in file
// order (y fastest, then z), each row padded to the cube's `dim` and each plane to dim rows. A
// block word of the bricks at (x, ., z) is read once for its 4 x 4 rows along y: bits
// x % 4 + 16 (z % 4) + {0, 4, 8, 12} are the row's voxels y % 4 = 0..3, moved next to each other
// by one multiplication (the products' bits land on distinct positions, so nothing carries).
void encode_planes(const SparseVoxels& voxels, int64_t x, int64_t count, int64_t dim, Runs* runs) {
    const Grid& grid = voxels.grid();
    const int64_t ny = grid.dims[1], nz = grid.dims[2];
    const int64_t b = voxels.brick_size(), per_axis = voxels.blocks_per_brick_axis();
    const auto nbricks = voxels.brick_dims();
    const int64_t wx = x % b / 4, words_per_row = (nbricks[1] * b + 63) / 64;
    // The bricks along y at (x, z), and the bits along y of rows (x + i, z + j), row 4j + i, with
    // the words each row's set bits reach (first > last: none). Only those words are scanned for
    // runs and cleared again: most rows of a surface's grid are empty, and scanning and clearing
    // whole rows was most of the writing.
    std::vector<const uint64_t*> bricks(static_cast<size_t>(nbricks[1]));
    std::vector<uint64_t> rows(static_cast<size_t>(16 * words_per_row), 0);
    int64_t first_word[16], last_word[16];
    for (int64_t z = 0; z < nz; z += 4) {
        const int64_t rows_z = std::min<int64_t>(4, nz - z);
        if (z % b == 0) {  // the next layer of bricks
            for (int64_t by = 0; by < nbricks[1]; ++by)
                bricks[size_t(by)] =
                    voxels.brick_blocks(uint64_t(x / b + nbricks[0] * (by + nbricks[1] * (z / b))));
        }
        std::fill_n(first_word, 16, words_per_row);
        std::fill_n(last_word, 16, -1);
        const int64_t wz = z % b / 4;
        for (int64_t by = 0; by < nbricks[1]; ++by) {
            const uint64_t* blocks = bricks[size_t(by)];
            if (!blocks) continue;
            for (int64_t wy = 0; wy < per_axis; ++wy) {
                const uint64_t word = blocks[wx + per_axis * (wy + per_axis * wz)];
                if (!word) continue;
                const int64_t y = by * b + 4 * wy;       // a multiple of 4: the 4 bits share a word
                const bool full = word == ~uint64_t(0);  // a solid's inside: all 4 of every row
                for (int64_t j = 0; j < rows_z; ++j)
                    for (int64_t i = 0; i < count; ++i) {
                        const uint64_t bits =
                            full ? 0xF
                                 : (word >> ((x + i) % 4 + 16 * j) & 0x1111) * 0x1248 >> 12 & 0xF;
                        if (!bits) continue;
                        const int64_t row = 4 * j + i;
                        rows[size_t(row * words_per_row + y / 64)] |= bits << (y % 64);
                        first_word[row] = std::min(first_word[row], y / 64);
                        last_word[row] = std::max(last_word[row], y / 64);
                    }
            }
        }
        for (int64_t i = 0; i < count; ++i)
            for (int64_t j = 0; j < rows_z; ++j) {
                const int64_t row = 4 * j + i;
                if (first_word[row] > last_word[row]) {
                    runs[i].add(0, uint64_t(dim));
                    continue;
                }
                uint64_t* words = &rows[size_t(row * words_per_row + first_word[row])];
                const int64_t from = 64 * first_word[row];
                const int64_t to = std::min(ny, 64 * (last_word[row] + 1));
                runs[i].add(0, uint64_t(from));
                runs[i].take_bits(words, uint64_t(to - from));
                runs[i].add(0, uint64_t(dim - to));
                std::fill(words, words + (last_word[row] - first_word[row] + 1), 0);
            }
    }
    for (int64_t i = 0; i < count; ++i) runs[i].add(0, uint64_t(dim - nz) * uint64_t(dim));
}

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

        // Phase 2: the planes x in file order, each padded to the cube, then the padding planes
        // beyond nx. A slab of planes (as many as `slab_bytes` of dense bytes would hold) is
        // encoded in parallel, each plane into its own runs, while a task writes the slab before
        // in plane order: the runs are the same as one pass's.
        const int64_t nx = grid.dims[0];
        const int64_t thickness =
            slab_thickness(uint64_t(grid.dims[1] * grid.dims[2]), nx, slab_bytes);
        RunWriter runs(out);
        stream_slabs<std::vector<Runs>>(
            nx, thickness,
            [&](std::vector<Runs>& plane_runs, int64_t x0, int64_t x_end) {
                plane_runs.assign(size_t(x_end - x0), Runs());
                // One task per column of blocks the slab's planes meet (up to 4 planes of it).
                std::vector<int64_t> firsts;
                for (int64_t x = x0; x < x_end; x = (x / 4 + 1) * 4) firsts.push_back(x);
                tbb::parallel_for(size_t(0), firsts.size(), [&](size_t group) {
                    const int64_t first = firsts[group];
                    const int64_t count = std::min((first / 4 + 1) * 4, x_end) - first;
                    encode_planes(voxels, first, count, dim, &plane_runs[size_t(first - x0)]);
                });
            },
            [&](const std::vector<Runs>& plane_runs, int64_t, int64_t) {
                for (const Runs& plane_run : plane_runs) runs.add(plane_run);
            },
            [&](int64_t x0) { progress.report(planes, uint64_t(x0), uint64_t(nx)); });
        runs.add(0, uint64_t(dim - nx) * uint64_t(dim) * uint64_t(dim));
        runs.finish();
        progress.finish();
    });
}

}  // namespace oclvox::detail
