// Triangle meshes to .obj (text), .ply (binary little-endian) and .stl (binary), chosen by
// extension, written atomically.
//
// OBJ and PLY keep the double coordinates exactly (shortest round-trip decimal text; 64-bit
// floats); STL is single precision by definition, with each facet's normal computed from its
// corners. Indices are checked first so a bad mesh fails before anything is written.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <utility>
#include <vector>

#include "atomic_file.hpp"
#include "block_writer.hpp"
#include "file_names.hpp"
#include "oclvox/field.hpp"
#include "progress.hpp"
#include "slabs.hpp"
#include "stl_format.hpp"

namespace oclvox {

namespace {

// Each format is a header, then parts of kPartItems vertices or triangles formatted on any core
// (stream_parts): formatting doubles as shortest round-trip text costs most of writing an OBJ.
// A slab of parts (about 64 k items on 2 cores) is reported at a time.
constexpr uint64_t kPartItems = 4096;
constexpr uint64_t kItemBytes = 32;  // about a vertex's or a triangle's bytes, in any format

uint64_t parts_of(uint64_t items) {
    return (items + kPartItems - 1) / kPartItems;
}

// The items [begin, end) of part `part` of `items`.
std::pair<size_t, size_t> part_items(int64_t part, size_t items) {
    const size_t begin = size_t(part) * kPartItems;
    return {begin, std::min<size_t>(items, begin + kPartItems)};
}

// Streams the vertex parts, then the triangle parts: vertices(begin, end, bytes) and
// triangles(begin, end, bytes) format a part; reports the parts done as `phase`.
template <class Vertices, class Triangles>
void stream_mesh_parts(std::ostream& out, const Mesh& mesh, uint64_t vertex_parts,
                       detail::ProgressPhases& progress, size_t phase, Vertices&& vertices,
                       Triangles&& triangles) {
    const int64_t parts = int64_t(vertex_parts + parts_of(mesh.triangles.size()));
    detail::stream_parts<detail::PartsSlab>(
        &out, parts, detail::parts_per_slab(kPartItems * kItemBytes),
        [&](detail::PartsSlab& slab, int64_t first, int64_t end) {
            tbb::parallel_for(first, end, [&](int64_t part) {
                detail::BlockWriter& bytes = slab.bytes[size_t(part - first)];
                if (uint64_t(part) < vertex_parts) {
                    const auto [begin, stop] = part_items(part, mesh.positions.size());
                    vertices(begin, stop, bytes);
                } else {
                    const auto [begin, stop] =
                        part_items(part - int64_t(vertex_parts), mesh.triangles.size());
                    triangles(begin, stop, bytes);
                }
            });
        },
        [&](int64_t first) { progress.report(phase, uint64_t(first), uint64_t(parts)); });
}

void write_obj(std::ostream& out, const Mesh& mesh, detail::ProgressPhases& progress,
               size_t phase) {
    out << "# oclvox: " << mesh.positions.size() << " vertices, " << mesh.triangles.size()
        << " triangles\n";
    stream_mesh_parts(
        out, mesh, parts_of(mesh.positions.size()), progress, phase,
        [&](size_t begin, size_t end, detail::BlockWriter& w) {
            for (size_t v = begin; v < end; ++v) {
                w.character('v');
                for (double c : mesh.positions[v]) {
                    w.character(' ');
                    w.number(c);
                }
                w.character('\n');
            }
        },
        [&](size_t begin, size_t end, detail::BlockWriter& w) {
            for (size_t t = begin; t < end; ++t) {  // OBJ indices start at 1
                w.character('f');
                for (uint32_t index : mesh.triangles[t]) {
                    w.character(' ');
                    w.number(uint64_t(index) + 1);
                }
                w.character('\n');
            }
        });
}

void write_ply(std::ostream& out, const Mesh& mesh, detail::ProgressPhases& progress,
               size_t phase) {
    out << "ply\nformat binary_little_endian 1.0\ncomment oclvox iso-surface\nelement vertex "
        << mesh.positions.size()
        << "\nproperty double x\nproperty double y\nproperty double z\nelement face "
        << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
    stream_mesh_parts(
        out, mesh, parts_of(mesh.positions.size()), progress, phase,
        [&](size_t begin, size_t end, detail::BlockWriter& w) {
            for (size_t v = begin; v < end; ++v)
                for (double c : mesh.positions[v]) w.little_endian(c);
        },
        [&](size_t begin, size_t end, detail::BlockWriter& w) {
            for (size_t t = begin; t < end; ++t) {
                w.character(char(3));
                for (uint32_t index : mesh.triangles[t]) w.little_endian(index);
            }
        });
}

void write_stl(std::ostream& out, const Mesh& mesh, detail::ProgressPhases& progress,
               size_t phase) {
    {
        detail::BlockWriter w(out);
        detail::write_stl_header(w, "oclvox iso-surface", uint32_t(mesh.triangles.size()));
        w.flush();
    }
    stream_mesh_parts(
        out, mesh, 0, progress, phase, [](size_t, size_t, detail::BlockWriter&) {},
        [&](size_t begin, size_t end, detail::BlockWriter& w) {
            for (size_t t = begin; t < end; ++t) {
                const auto& triangle = mesh.triangles[t];
                detail::write_stl_facet(w, mesh.positions[triangle[0]], mesh.positions[triangle[1]],
                                        mesh.positions[triangle[2]]);
            }
        });
}

}  // namespace

void write_mesh(const std::string& path, const Mesh& mesh, const ProgressCallback& callback) {
    // Phase 1: format and checks, before any file exists.
    const std::string ext = detail::lowercase_extension(path);
    void (*write)(std::ostream&, const Mesh&, detail::ProgressPhases&, size_t) =
        ext == ".obj"   ? write_obj
        : ext == ".ply" ? write_ply
        : ext == ".stl" ? write_stl
                        : nullptr;
    if (!write)
        throw OutputError("cannot write " + path + ": unknown mesh extension '" + ext +
                          "' (use .obj, .ply or .stl)");
    // PLY indices are signed 32-bit; the other formats share the limit to keep one rule.
    if (mesh.positions.size() > size_t(std::numeric_limits<int32_t>::max()) ||
        mesh.triangles.size() > size_t(std::numeric_limits<uint32_t>::max()))
        throw OutputError("cannot write " + path + ": the mesh is too large for the format");
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
        for (uint32_t index : mesh.triangles[t])
            if (index >= mesh.positions.size())
                throw OutputError("cannot write " + path + ": triangle " + std::to_string(t) +
                                  " uses vertex " + std::to_string(index) + " of only " +
                                  std::to_string(mesh.positions.size()));

    // Phase 2: the bytes, through a temporary file renamed into place; the last report comes
    // before the rename, so a cancel leaves no file.
    detail::ProgressPhases progress(callback, "writing " + path);
    const size_t phase = progress.add(1);
    detail::write_file_atomically(path, [&](std::ostream& out) {
        write(out, mesh, progress, phase);
        progress.finish();
    });
}

}  // namespace oclvox
