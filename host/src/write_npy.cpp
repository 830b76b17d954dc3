// NumPy .npy writer (format version 1.0, numpy.org/neps/nep-0001-npy-format.html) and its JSON
// sidecar.
//
// The array is dense uint8 (0 or 1) of shape (nx, ny, nz) in Fortran order, so numpy's
// arr[i, j, k] is voxel (x=i, y=j, z=k). Fortran order of that shape means x fastest, so the
// file is a sequence of z-layers: it is streamed a z-slab at a time from the bricks, and the
// largest buffer is one slab, never the whole grid.
//
// Most of a surface's grid is empty, and an empty page of the file costs the page cache and the
// disk as much as a full one: runs of at least 64 KiB of whole empty file pages are left as holes
// (seeked over; they read as zeros on every file system, and take no space on those that keep
// holes). bunny00's surface at 1024^3: 803 -> 495 MB on disk, the write 1.55 -> 0.72 s.
//
// The .npy format has no place for the grid's position, so `<path>.json` (e.g. out.npy.json)
// records origin, voxel size, dims and axis order. Appending ".json" to the full name, rather
// than replacing ".npy", keeps it from colliding with another output called out.json.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "npy_format.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

constexpr uint64_t kPage = 4096;

// The file pages that bytes [at, at + size) of a file fall in, piece by piece (the first and last
// may be partial): whether each holds a byte other than zero. Found on the cores that marked the
// slab, in parallel, so that the thread writing the file does nothing but write.
void find_pages_with_data(const uint8_t* data, size_t size, uint64_t at,
                          std::vector<uint8_t>& with_data) {
    const size_t first = size_t(at / kPage), end = size_t((at + size + kPage - 1) / kPage);
    with_data.resize(end - first);
    tbb::parallel_for(size_t(0), end - first, [&](size_t n) {
        const uint64_t lo = std::max<uint64_t>(at, (first + n) * kPage);
        const uint64_t hi = std::min<uint64_t>(at + size, (first + n + 1) * kPage);
        const uint8_t* p = data + (lo - at);
        with_data[n] = *p != 0 || std::memcmp(p, p + 1, size_t(hi - lo - 1)) != 0;
    });
}

// Writes bytes to a seekable stream in order, seeking over each run of at least kMinHole bytes of
// whole zero pages (file pages: from the stream's position when made) instead of writing it;
// shorter runs are written, as a seek costs more than a few pages. finish() writes the last
// byte of a file that ends in a hole, which gives the file its size.
class HoleSkippingWriter {
  public:
    explicit HoleSkippingWriter(std::ostream& out) : out_(out), at_(uint64_t(out.tellp())) {}

    // The file position of the next byte to write.
    uint64_t position() const { return at_; }

    // Writes `size` bytes whose pages, from position(), find_pages_with_data described.
    void write(const uint8_t* data, size_t size, const std::vector<uint8_t>& with_data) {
        // [run_start, zero_start): bytes not yet written; [zero_start, done): zero pages after
        // them, which may grow into a hole.
        size_t done = 0, run_start = 0, zero_start = 0;
        for (size_t page = 0; done < size; ++page) {
            const size_t n = size_t(std::min<uint64_t>(kPage - at_ % kPage, size - done));
            if (with_data[page]) {
                if (done - zero_start >= kMinHole) {
                    write_run(data + run_start, zero_start - run_start);
                    skipped_ += done - zero_start;
                    run_start = done;
                }
                zero_start = done + n;
            }
            done += n;
            at_ += n;
        }
        // Trailing zero pages wait: the next call may continue them into a hole.
        write_run(data + run_start, zero_start - run_start);
        skipped_ += size - zero_start;
    }

    void finish() {
        if (skipped_ == 0) return;
        out_.seekp(std::streamoff(skipped_ - 1), std::ios::cur);
        out_.put(0);
        skipped_ = 0;
    }

  private:
    static constexpr size_t kMinHole = 16 * kPage;
    static constexpr char kZeros[kMinHole] = {};

    void write_run(const uint8_t* data, size_t size) {
        if (size == 0) return;
        // Zeros held back from earlier calls come first: a hole if long, else written.
        if (skipped_ >= kMinHole)
            out_.seekp(std::streamoff(skipped_), std::ios::cur);
        else
            out_.write(kZeros, std::streamsize(skipped_));
        skipped_ = 0;
        out_.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    }

    std::ostream& out_;
    uint64_t at_;           // the file position of the next byte offered
    uint64_t skipped_ = 0;  // zero bytes offered and not yet written or seeked over
};

}  // namespace

void write_npy(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress,
               uint64_t slab_bytes) {
    const Grid& grid = voxels.grid();
    check_dense_size(path, grid.voxel_count(), "a .npy");
    const size_t layers = progress.add(1);
    auto write_layers = [&](std::ostream& out) {
        const int64_t nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
        const int64_t layer = nx * ny;
        // At least a block's 4 layers, whatever the slab's bytes: a thinner slab visits each
        // block of the bricks more than once (bunny00 at 1024^3: 2-layer slabs took 2.2x as long).
        const int64_t thickness = slab_thickness(
            uint64_t(layer), nz, std::max<uint64_t>(slab_bytes, 4 * uint64_t(layer)));
        // The cores mark a slab from the bricks and find its pages with data while a task copies
        // the slab before into the file (the copy into the page cache is the longer part).
        struct Slab {
            std::vector<uint8_t> bytes, pages_with_data;
        };
        HoleSkippingWriter file(out);
        const uint64_t data_start = file.position();
        stream_slabs<Slab>(
            nz, thickness,
            [&](Slab& slab, int64_t first, int64_t end) {
                slab.bytes.assign(size_t(layer * thickness), 0);
                voxels.mark_box({0, 0, first}, {nx, ny, end}, {1, nx, layer}, slab.bytes.data());
                find_pages_with_data(slab.bytes.data(), size_t(layer * (end - first)),
                                     data_start + uint64_t(first * layer), slab.pages_with_data);
            },
            [&](const Slab& slab, int64_t first, int64_t end) {
                file.write(slab.bytes.data(), size_t(layer * (end - first)), slab.pages_with_data);
            },
            [&](int64_t first) { progress.report(layers, uint64_t(first), uint64_t(nz)); });
        file.finish();
        progress.finish();
    };
    nlohmann::json sidecar = npy_sidecar(path, grid);
    sidecar["dtype"] = "uint8, 1 = voxel set, 0 = empty";
    sidecar["voxel_box"] =
        "voxel (i,j,k) is the closed box [origin + (i,j,k)*voxel_size, "
        "origin + (i+1,j+1,k+1)*voxel_size]";
    sidecar["voxels_set"] = voxels.count();
    write_npy_with_sidecar(path, "|u1", grid, write_layers, [&] { return sidecar; });
}

}  // namespace oclvox::detail
