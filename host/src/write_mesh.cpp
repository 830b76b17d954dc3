// Triangle meshes to .obj (text), .ply (binary little-endian) and .stl (binary), chosen by
// extension, written atomically.
//
// OBJ and PLY keep the double coordinates exactly (shortest round-trip decimal text; 64-bit
// floats); STL is single precision by definition, with each facet's normal computed from its
// corners. Indices are checked first so a bad mesh fails before anything is written.
#include <cmath>
#include <cstring>
#include <limits>

#include "atomic_file.hpp"
#include "file_names.hpp"
#include "little_endian.hpp"
#include "number_text.hpp"
#include "oclvox/field.hpp"

namespace oclvox {

namespace {

void write_obj(std::ostream& out, const Mesh& mesh) {
    out << "# oclvox: " << mesh.positions.size() << " vertices, " << mesh.triangles.size()
        << " triangles\n";
    for (const auto& p : mesh.positions) {
        out << 'v';
        for (double c : p) {
            out << ' ';
            detail::write_shortest_number(out, c);
        }
        out << '\n';
    }
    for (const auto& t : mesh.triangles)  // OBJ indices start at 1
        out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
}

void write_ply(std::ostream& out, const Mesh& mesh) {
    out << "ply\nformat binary_little_endian 1.0\ncomment oclvox iso-surface\n"
        << "element vertex " << mesh.positions.size() << '\n'
        << "property double x\nproperty double y\nproperty double z\n"
        << "element face " << mesh.triangles.size() << '\n'
        << "property list uchar int vertex_indices\nend_header\n";
    for (const auto& p : mesh.positions)
        for (double c : p) detail::write_le(out, c);
    for (const auto& t : mesh.triangles) {
        out.put(char(3));
        for (uint32_t index : t) detail::write_le(out, index);
    }
}

void write_stl(std::ostream& out, const Mesh& mesh) {
    char header[80] = {};
    std::strncpy(header, "oclvox iso-surface", sizeof header);
    out.write(header, sizeof header);
    detail::write_le(out, uint32_t(mesh.triangles.size()));
    for (const auto& t : mesh.triangles) {
        const auto& a = mesh.positions[t[0]];
        const auto& b = mesh.positions[t[1]];
        const auto& c = mesh.positions[t[2]];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                       u[0] * v[1] - u[1] * v[0]};
        const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (double& x : n) x = length > 0 ? x / length : 0.0;  // degenerate facets: zero normal
        for (double x : n) detail::write_le(out, float(x));
        for (const auto* p : {&a, &b, &c})
            for (double x : *p) detail::write_le(out, float(x));
        detail::write_le(out, uint16_t(0));
    }
}

}  // namespace

void write_mesh(const std::string& path, const Mesh& mesh) {
    // Phase 1: format and checks, before any file exists.
    const std::string ext = detail::lowercase_extension(path);
    void (*write)(std::ostream&, const Mesh&) = ext == ".obj"   ? write_obj
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

    // Phase 2: the bytes, through a temporary file renamed into place.
    detail::write_file_atomically(path, [&](std::ostream& out) { write(out, mesh); });
}

}  // namespace oclvox
