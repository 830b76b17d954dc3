// How thick a slab the streaming writers cut the grid into: as many layers as fit a fixed byte
// budget, a multiple of the 4-voxel block edge when more than one fits, so each slab reads
// whole blocks from the bricks.
#pragma once

#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "block_writer.hpp"

namespace oclvox::detail {

// Bytes of one dense slab buffer: small next to any grid worth streaming, large enough that the
// per-slab brick lookups and write calls are negligible.
constexpr uint64_t kSlabBytes = uint64_t(32) << 20;

// Bytes of a dense slab that is filled and then copied out whole (the `.npy` writer's bytes into
// the page cache): small enough to stay in a core's cache between the two, and to fault in few
// fresh pages. bunny00's surface at 512^3 to `.npy`: 32 MiB slabs 74-88 ms, 2 MiB 37-41 ms.
constexpr uint64_t kCachedSlabBytes = uint64_t(2) << 20;

// Layers (of `layer_bytes` each) per slab of at most `slab_bytes` for an axis of `layers` voxels;
// at least one.
inline int64_t slab_thickness(uint64_t layer_bytes, int64_t layers, uint64_t slab_bytes) {
    int64_t thickness = int64_t(slab_bytes / std::max<uint64_t>(layer_bytes, 1));
    if (thickness >= 4) thickness -= thickness % 4;
    return std::clamp<int64_t>(thickness, 1, std::max<int64_t>(layers, 1));
}

// Streams `layers` layers a slab of `thickness` at a time through two Slab buffers: fill(slab,
// first, end) makes layers [first, end) on this thread (and the cores it spreads to) while a task
// writes the slab before with write(slab, first, end), so the copy into the page cache overlaps
// the making of the next slab. Writes come in order; report(first) is called on this thread before
// each slab's write starts (it may throw, as a cancel does: the write under way is waited for).
template <class Slab, class Fill, class Write, class Report>
void stream_slabs(int64_t layers, int64_t thickness, Fill&& fill, Write&& write, Report&& report) {
    Slab slabs[2];
    tbb::task_group writing;  // destroyed first: it waits for a write still under way
    for (int64_t first = 0, i = 0; first < layers; first += thickness, ++i) {
        const int64_t end = std::min(layers, first + thickness);
        Slab& slab = slabs[i % 2];
        fill(slab, first, end);
        writing.wait();  // the slab before is written, and the other buffer free
        report(first);
        writing.run([&write, &slab, first, end] { write(slab, first, end); });
    }
    writing.wait();
}

// A file's parts, each formatted on its own into bytes kept in memory (BlockWriter without a
// stream), written to `out` in order (nothing without `out`: a walk that only counts):
// stream_slabs with `slab_parts` parts a slab, where fill(slab, first, end) makes parts
// [first, end) of `slab` on any core (slab.bytes[i] is part first + i, cleared before) while a
// task writes the slab before. report as stream_slabs'.
struct PartsSlab {
    std::vector<BlockWriter> bytes;
};
template <class Slab, class Fill, class Report>
void stream_parts(std::ostream* out, int64_t parts, int64_t slab_parts, Fill&& fill,
                  Report&& report) {
    stream_slabs<Slab>(
        parts, slab_parts,
        [&](Slab& slab, int64_t first, int64_t end) {
            slab.bytes.resize(size_t(end - first));
            for (BlockWriter& bytes : slab.bytes) bytes.clear();
            fill(slab, first, end);
        },
        [&](const Slab& slab, int64_t, int64_t) {
            if (out)
                for (const BlockWriter& bytes : slab.bytes)
                    out->write(bytes.data(), std::streamsize(bytes.size()));
        },
        report);
}

// Parts a slab for stream_parts, of parts of about `part_bytes`: about kCachedSlabBytes of them,
// so that the task copies a slab's bytes while they are still in cache and few of its pages are
// fresh (bunny00's solid at 512^3 to .vox, parts of up to 1 MiB: slabs of 16 parts 0.038-0.040 s,
// of 2 parts 0.028-0.029 s), and at least one per core.
inline int64_t parts_per_slab(uint64_t part_bytes) {
    return std::max<int64_t>(int64_t(tbb::this_task_arena::max_concurrency()),
                             int64_t(kCachedSlabBytes / std::max<uint64_t>(part_bytes, 1)));
}

// Dense formats cost a byte or more per voxel on disk; past this many bytes (64 GiB) a sparse
// format is the only sensible one, so the writer refuses before creating anything.
constexpr uint64_t kMaxDenseBytes = uint64_t(1) << 36;

// Throws OutputError naming `path` if a dense file of `bytes` is over kMaxDenseBytes or larger
// than the free space of its folder.
void check_dense_size(const std::string& path, uint64_t bytes, const std::string& what);

}  // namespace oclvox::detail
