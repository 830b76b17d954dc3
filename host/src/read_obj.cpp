// OBJ through tinyobjloader (the file's structure: groups, faces, relative indices), with the
// coordinates read again strictly: tinyobjloader turns text it cannot read into 0 without a word.
#include <tiny_obj_loader.h>

#include <algorithm>
#include <map>
#include <sstream>

#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

// Materials do not matter to a voxelizer, and a missing .mtl (common in the wild) must not fail
// the load, so .mtl files are never read.
struct IgnoreMaterials : tinyobj::MaterialReader {
    bool operator()(const std::string&, std::vector<tinyobj::material_t>*,
                    std::map<std::string, int>*, std::string*, std::string*) override {
        return true;
    }
};

// Every index of an `f` line (v, v/vt, v//vn, v/vt/vn) must be an integer that fits an int:
// tinyobjloader reads them with atoi, which turns 99999999999999999999 into -1, a valid
// relative index.
void check_face_line(TextCursor& line) {
    for (std::string_view corner = line.word_on_line(); !corner.empty();
         corner = line.word_on_line()) {
        for (size_t at = 0; at <= corner.size();) {
            const size_t slash = std::min(corner.find('/', at), corner.size());
            const std::string_view index = corner.substr(at, slash - at);
            if (!index.empty()) {
                const int64_t value = line.to_integer(index, "face index");
                if (value != int(value))
                    line.fail("the face index " + quoted(index) + " does not fit in 32 bits");
            }
            at = slash + 1;
        }
    }
}

// The x, y, z of every `v` line, in file order, read strictly and correctly rounded; face
// indices are checked too. Lines are recognised the way tinyobjloader does ("\r\n", "\n" or a
// lone "\r" ends one), so the vertex counts agree.
std::vector<Position> read_positions_strictly(const std::string& path, const std::string& bytes) {
    std::vector<Position> positions;
    const std::string_view text(bytes);
    size_t at = 0;
    for (size_t line_number = 1; at < text.size(); ++line_number) {
        const size_t line_end = std::min(text.find_first_of("\r\n", at), text.size());
        TextCursor line(path, text.substr(at, line_end - at), 0, line_number);
        const std::string_view keyword = line.word_on_line();
        if (keyword == "v") {
            Position p;
            for (double& coordinate : p) {
                const std::string_view word = line.word_on_line();
                if (word.empty()) line.fail("a vertex has fewer than 3 coordinates");
                coordinate = line.to_double(word, "vertex coordinate");
            }
            positions.push_back(p);
        } else if (keyword == "f") {
            check_face_line(line);
        }
        at = line_end;
        if (at < text.size() && text[at++] == '\r' && at < text.size() && text[at] == '\n') ++at;
    }
    return positions;
}

constexpr const char* kTooManyCorners =
    "a face has more than 255 corners, which tinyobjloader cannot represent";

}  // namespace

Polygons read_obj(const std::string& path) {
    // Phase 1: the file's structure (faces, groups, relative indices) through tinyobjloader,
    // without its triangulation (it splits every quad along the shorter diagonal, which is wrong
    // for concave quads); polygons go through the shared ear clipping.
    const std::string bytes = read_whole_file(path);
    tinyobj::attrib_t attrib;
    std::vector<tinyobj::shape_t> shapes;
    std::vector<tinyobj::material_t> materials;
    std::string warnings, errors;
    std::istringstream stream(bytes);
    IgnoreMaterials no_materials;
    if (!tinyobj::LoadObj(&attrib, &shapes, &materials, &warnings, &errors, &stream, &no_materials,
                          /*triangulate=*/false, /*default_vcols_fallback=*/false)) {
        errors.erase(errors.find_last_not_of(" \n") + 1);
        fail(path, errors.empty() ? "tinyobjloader could not parse it" : errors);
    }

    // Phase 2: the coordinates, read strictly, and the face indices checked.
    Polygons out;
    out.first_index = 1;
    out.positions = read_positions_strictly(path, bytes);
    if (out.positions.size() * 3 != attrib.vertices.size())
        fail(path, "its vertex lines could not be read consistently");

    // Phase 3: every face of every group, in the file's order.
    size_t face_number = 0;
    for (const tinyobj::shape_t& shape : shapes) {
        const auto& indices = shape.mesh.indices;
        size_t first = 0;
        for (const unsigned char corner_count : shape.mesh.num_face_vertices) {
            ++face_number;
            // tinyobjloader stores corner counts in a byte, so a face with 256 or more corners
            // cannot be told apart from a smaller one; the counts then no longer add up.
            if (corner_count < 3 || first + corner_count > indices.size())
                fail(path, kTooManyCorners);
            for (size_t k = first; k < first + corner_count; ++k) {
                // tinyobjloader has resolved relative indices; one still negative pointed before
                // the first vertex.
                const int vertex = indices[k].vertex_index;
                if (vertex < 0)
                    fail(path, "face " + std::to_string(face_number) +
                                   " has a relative vertex index that points before the first "
                                   "vertex");
                out.corners.push_back(vertex);
            }
            out.corner_counts.push_back(corner_count);
            first += corner_count;
        }
        if (first != indices.size()) fail(path, kTooManyCorners);
    }
    return out;
}

}  // namespace oclvox::mesh_reading
