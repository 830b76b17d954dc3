// OBJ (Wavefront): `v` lines give the positions, `f` lines the polygons; every other statement
// (vt, vn, g, o, s, usemtl, mtllib, l, p, ...) is skipped, so groups and objects merge into one
// mesh and materials, which do not matter to a voxelizer, are never read (a missing .mtl, common
// in the wild, cannot fail the load).
//
// Why not tinyobjloader, which this reader used before: it turns text it cannot read into 0 and
// face indices into ints with atoi (99999999999999999999 becomes -1, a valid relative index)
// without a word, so every coordinate and index had to be read again strictly anyway, and its
// parse of the structure then cost as much as the strict reading: half the load of a large file.
// The structure is small: a face corner is v, v/vt, v//vn or v/vt/vn, and a negative index counts
// back from the last vertex read so far.
#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

// The 0-based vertex index of one face corner (Polygons::first_index = 1 makes triangulated() name
// out-of-range indices as the file numbers them). The texture and normal indices are checked as
// integers too, as a corrupt file shows there as much as anywhere.
int64_t corner_index(const TextCursor& line, std::string_view corner, size_t vertices_so_far,
                     size_t face_number) {
    int64_t vertex = 0;
    for (size_t at = 0, part = 0; at <= corner.size(); ++part) {
        const size_t slash = std::min(corner.find('/', at), corner.size());
        const std::string_view index = corner.substr(at, slash - at);
        if (part == 0 || !index.empty()) {
            const int64_t value = line.to_integer(index, "face index");
            if (value != int32_t(value))
                line.fail("the face index " + quoted(index) + " does not fit in 32 bits");
            if (value == 0) line.fail("a face index is 0: OBJ counts vertices from 1");
            if (part == 0) vertex = value;
        }
        at = slash + 1;
    }
    if (vertex > 0) return vertex - 1;
    vertex += int64_t(vertices_so_far);  // -1 is the last vertex read so far
    if (vertex < 0)
        line.fail("face " + std::to_string(face_number) +
                  " has a relative vertex index that points before the first vertex");
    return vertex;
}

}  // namespace

Polygons read_obj(const std::string& path, const ParseReport& report) {
    const std::string bytes = read_whole_file(path);
    const std::string_view text(bytes);
    ParseProgress progress(report, text.size());
    Polygons out;
    out.first_index = 1;

    // Line by line; "\r\n", "\n" or a lone "\r" ends one, and '#' starts a comment.
    size_t face_number = 0;
    size_t at = 0;
    for (size_t line_number = 1; at < text.size(); ++line_number) {
        // A plain scan: string_view::find_first_of calls memchr on the two-character set once
        // per character of the text, which was a fifth of the load.
        size_t line_end = at;
        while (line_end < text.size() && text[line_end] != '\n' && text[line_end] != '\r')
            ++line_end;
        TextCursor line(path, text.substr(at, line_end - at), '#', line_number);
        const std::string_view keyword = line.word_on_line();
        if (keyword == "v") {
            // x y z, read strictly and correctly rounded; a w or a vertex colour may follow.
            Position p;
            for (double& coordinate : p) {
                const std::string_view word = line.word_on_line();
                if (word.empty()) line.fail("a vertex has fewer than 3 coordinates");
                coordinate = line.to_double(word, "vertex coordinate");
            }
            out.positions.push_back(p);
        } else if (keyword == "f") {
            ++face_number;
            uint32_t corners = 0;
            for (std::string_view corner = line.word_on_line(); !corner.empty();
                 corner = line.word_on_line()) {
                out.corners.push_back(
                    corner_index(line, corner, out.positions.size(), face_number));
                ++corners;
            }
            out.corner_counts.push_back(corners);
        }
        at = line_end;
        if (at < text.size() && text[at++] == '\r' && at < text.size() && text[at] == '\n') ++at;
        progress.at(at);
    }
    return out;
}

}  // namespace oclvox::mesh_reading
