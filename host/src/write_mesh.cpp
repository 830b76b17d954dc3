// Triangle meshes to .obj (text), .ply (binary little-endian) and .stl (binary), chosen by
// extension, written atomically.
//
// OBJ and PLY keep the double coordinates exactly (shortest round-trip decimal text; 64-bit
// floats); STL is single precision by definition, with each facet's normal computed from its
// corners. Indices are checked first so a bad mesh fails before anything is written.
#include <limits>
#include <vector>

#include "atomic_file.hpp"
#include "block_writer.hpp"
#include "file_names.hpp"
#include "oclvox/field.hpp"
#include "progress.hpp"
#include "stl_format.hpp"

namespace oclvox {

namespace {

// Reports a writer's items (vertices and triangles) as they are formatted, every kStride of
// them.
class ItemProgress {
  public:
    ItemProgress(detail::ProgressPhases& progress, size_t phase, uint64_t total)
        : progress_(progress), phase_(phase), total_(total) {}
    void item() {
        if (++done_ % kStride == 0) progress_.report(phase_, done_, total_);
    }

  private:
    static constexpr uint64_t kStride = 65536;
    detail::ProgressPhases& progress_;
    size_t phase_;
    uint64_t total_, done_ = 0;
};

void write_obj(std::ostream& out, const Mesh& mesh, ItemProgress& progress) {
    detail::BlockWriter w(out);
    w.text("# oclvox: " + std::to_string(mesh.positions.size()) + " vertices, " +
           std::to_string(mesh.triangles.size()) + " triangles\n");
    for (const auto& p : mesh.positions) {
        w.character('v');
        for (double c : p) {
            w.character(' ');
            w.number(c);
        }
        w.character('\n');
        progress.item();
    }
    for (const auto& t : mesh.triangles) {  // OBJ indices start at 1
        w.character('f');
        for (uint32_t index : t) {
            w.character(' ');
            w.number(uint64_t(index) + 1);
        }
        w.character('\n');
        progress.item();
    }
    w.flush();
}

void write_ply(std::ostream& out, const Mesh& mesh, ItemProgress& progress) {
    detail::BlockWriter w(out);
    w.text("ply\nformat binary_little_endian 1.0\ncomment oclvox iso-surface\nelement vertex " +
           std::to_string(mesh.positions.size()) +
           "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
           std::to_string(mesh.triangles.size()) +
           "\nproperty list uchar int vertex_indices\nend_header\n");
    for (const auto& p : mesh.positions) {
        for (double c : p) w.little_endian(c);
        progress.item();
    }
    for (const auto& t : mesh.triangles) {
        w.character(char(3));
        for (uint32_t index : t) w.little_endian(index);
        progress.item();
    }
    w.flush();
}

void write_stl(std::ostream& out, const Mesh& mesh, ItemProgress& progress) {
    detail::BlockWriter w(out);
    detail::write_stl_header(w, "oclvox iso-surface", uint32_t(mesh.triangles.size()));
    for (const auto& t : mesh.triangles) {
        detail::write_stl_facet(w, mesh.positions[t[0]], mesh.positions[t[1]],
                                mesh.positions[t[2]]);
        progress.item();
    }
    w.flush();
}

}  // namespace

void write_mesh(const std::string& path, const Mesh& mesh, const ProgressCallback& callback) {
    // Phase 1: format and checks, before any file exists.
    const std::string ext = detail::lowercase_extension(path);
    void (*write)(std::ostream&, const Mesh&, ItemProgress&) = ext == ".obj"   ? write_obj
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
    ItemProgress items(progress, phase,
                       (ext == ".stl" ? 0 : mesh.positions.size()) + mesh.triangles.size());
    detail::write_file_atomically(path, [&](std::ostream& out) {
        write(out, mesh, items);
        progress.finish();
    });
}

}  // namespace oclvox
