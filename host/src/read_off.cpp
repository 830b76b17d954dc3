// OFF (Object File Format), with the optional [ST][C][N][n]OFF keywords, '#' comments and
// polygons of any size. One vertex and one face per line, as writers put them: values after a
// vertex's x y z (normals, colours, texture coordinates) and after a face's indices (a colour)
// are read past.
#include <algorithm>
#include <limits>

#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

constexpr uint64_t kMinVertexBytes = 6;  // "0 0 0\n"
constexpr uint64_t kMinFaceBytes = 2;    // "0\n", a face without corners

bool ends_with_off(std::string_view word) {
    return word.size() >= 3 && word.substr(word.size() - 3) == "OFF";
}

// Checks the keyword's prefix letters; true for "nOFF", where the vertex dimension follows.
bool read_keyword(const TextCursor& text, std::string_view keyword) {
    std::string_view prefix = keyword.substr(0, keyword.size() - 3);
    for (const std::string_view letters : {"ST", "C", "N"})
        if (prefix.substr(0, letters.size()) == letters) prefix.remove_prefix(letters.size());
    if (prefix.substr(0, 1) == "4")
        text.fail("4-dimensional OFF (" + quoted(keyword) + ") is not supported");
    if (!prefix.empty() && prefix != "n") text.fail("unknown OFF keyword " + quoted(keyword));
    return prefix == "n";
}

// The next word, on this line or a later one.
std::string_view next_header_word(TextCursor& text, const char* what) {
    if (!text.next_nonblank_line()) text.fail(std::string("the file ends before the ") + what);
    return text.word_on_line();
}

// A vertex record: x y z, correctly rounded (the values after them are read past).
void read_vertex(TextCursor& text, Position& position) {
    for (int axis = 0; axis < 3; ++axis)
        position[axis] = text.double_on_line(kAxisCoordinate[axis]);
}

// A face record: the corner count, then the corners' indices, which are checked (negative, past
// the end) when they are triangulated.
void read_face(TextCursor& text, Polygons& out) {
    const uint64_t corners = text.count_on_line("corner count");
    if (corners > std::numeric_limits<uint32_t>::max())
        text.fail("a face has " + std::to_string(corners) + " corners");
    for (uint64_t k = 0; k < corners; ++k)
        out.corners.push_back(text.integer_on_line("vertex index"));
    out.corner_counts.push_back(uint32_t(corners));
}

}  // namespace

Polygons read_off(const std::string& path, const ParseReport& report) {
    const FileBytes file = read_whole_file(path);
    const std::string_view bytes = file.view();
    ParseProgress progress(report, bytes.size());
    TextCursor text(path, bytes, '#');

    // Phase 1: the header: an optional keyword, then the vertex, face and (optional) edge
    // counts, each parsed strictly.
    if (!text.next_nonblank_line()) text.fail("the file has no header, only comments");
    std::string_view word = text.word_on_line();
    if (ends_with_off(word)) {
        const bool has_dimension = read_keyword(text, word);
        word = next_header_word(text, "vertex count");
        if (word == "BINARY") text.fail("binary OFF is not supported");
        if (has_dimension) {
            // Only vertices of dimension 3 give a surface mesh.
            const uint64_t dimension = text.to_count(word, "vertex dimension");
            if (dimension != 3)
                text.fail("vertices of dimension " + std::to_string(dimension) +
                          " are not supported");
            word = next_header_word(text, "vertex count");
        }
    }
    const uint64_t vertex_count = text.to_count(word, "vertex count");
    const uint64_t face_count = text.to_count(text.word_on_line(), "face count");
    if (!text.line_done()) text.to_count(text.word_on_line(), "edge count");
    if (!text.line_done()) text.fail("the counts line has more than three values");
    text.skip_line();

    // Phase 2: the counts against the bytes left, before anything is allocated for them.
    const uint64_t left = text.bytes_left() + 1;  // the last line needs no line end
    require_room(path, vertex_count, kMinVertexBytes, left, "vertices");
    require_room(path, face_count, kMinFaceBytes, left - vertex_count * kMinVertexBytes, "faces");
    if (vertex_count > std::numeric_limits<uint32_t>::max())
        fail(path, "more than 2^32 vertices, which 32-bit triangle indices cannot address");
    Polygons out;
    out.positions.reserve(vertex_count);
    out.corner_counts.reserve(face_count);
    out.corners.reserve(std::min(3 * face_count, left / 2));  // a corner takes 2 bytes or more

    // Phase 3: the records, in parts on all cores where the body is large, else (or where that
    // fails) in one pass.
    if (bytes.size() - text.offset() > kTextPartBytes) {
        out.positions.resize(vertex_count);
        if (read_records_in_parts(
                path, bytes, text.offset(), '#', vertex_count + face_count, report,
                [&](TextCursor& line, uint64_t r, Polygons& faces) {
                    if (r < vertex_count)
                        read_vertex(line, out.positions[r]);
                    else
                        read_face(line, faces);
                },
                out))
            return out;
        out.positions.clear();
    }
    for (uint64_t v = 0; v < vertex_count; ++v) {
        if (!text.next_nonblank_line())
            text.fail("the file ends after " + std::to_string(v) + " of the " +
                      std::to_string(vertex_count) + " vertices that the header declares");
        out.positions.emplace_back();
        read_vertex(text, out.positions.back());
        text.skip_line();
        progress.at(text.offset());
    }
    for (uint64_t f = 0; f < face_count; ++f) {
        if (!text.next_nonblank_line())
            text.fail("the file ends after " + std::to_string(f) + " of the " +
                      std::to_string(face_count) + " faces that the header declares");
        read_face(text, out);
        text.skip_line();
        progress.at(text.offset());
    }
    return out;
}

}  // namespace oclvox::mesh_reading
