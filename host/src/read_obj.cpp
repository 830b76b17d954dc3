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
//
// Large files are read in parts of whole lines on all cores (number parsing is most of a load),
// and the parts joined in order; relative indices are resolved once the vertices before each part
// are known. A part that fails sends the whole file through the plain one-pass parse, so an error
// is the first one in the file, with its line number.

#include <limits>

#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

// Relative indices met in a part of the file parsed on its own, whose vertices before it are not
// known yet: the places in Polygons::corners holding one, as `value + vertices read so far in
// the part` (negative when it points into an earlier part).
using RelativeCorners = std::vector<size_t>;

// The 0-based vertex index of one face corner (Polygons::first_index = 1 makes triangulated() name
// out-of-range indices as the file numbers them). The texture and normal indices are checked as
// integers too, as a corrupt file shows there as much as anywhere. A relative index counts back
// from vertices_so_far; with `relative`, it is only recorded there (the caller resolves it).
int64_t corner_index(const TextCursor& line, std::string_view corner, size_t vertices_so_far,
                     size_t face_number, bool* relative) {
    int64_t vertex = 0;
    for (size_t at = 0, part = 0; at <= corner.size(); ++part) {
        size_t slash = at;  // (a plain scan: find calls memchr, costly on words this short)
        while (slash < corner.size() && corner[slash] != '/') ++slash;
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
    if (relative) {
        *relative = true;
        return vertex;
    }
    if (vertex < 0)
        line.fail("face " + std::to_string(face_number) +
                  " has a relative vertex index that points before the first vertex");
    return vertex;
}

// The common lines, "v x y z ..." and "f a b c ..." with indices of up to 9 digits, none of them
// relative or signed, read in one pass over their characters: each number is parsed where it
// starts and its end checked to be a word's, where the strict reading below first finds the line's
// end, then its words, then parses each word. Returns the offset of the line's end (its '\n' or
// '\r', or the end of the text), having added the line's vertex or face to out; or npos, with out
// as it was, for every other line (keywords skipped, comments, relative indices, anything
// malformed), which the strict reading then reads or names the problem of. Both accept the same
// lines with the same values: a number ends where a word does (no blank, '#' or line end can be
// part of one), and a vertex coordinate is from_chars' reading either way.
size_t quick_line(std::string_view text, size_t at, Polygons& out, size_t* face_number) {
    constexpr size_t kNot = std::string_view::npos;
    const char* p = text.data() + at;
    const char* const end = text.data() + text.size();
    // A blank, the comment sign or a line end ends a word (TextCursor's word ends).
    auto at_word_end = [&](const char* q) {
        return q == end || TextCursor::is_blank(*q) || *q == '\n' || *q == '#';
    };
    auto skip_blanks = [&] {  // (TextCursor's blanks, but for the CR that ends a line here)
        while (p != end && TextCursor::is_blank(*p) && *p != '\r') ++p;
    };
    auto line_end = [&] {
        while (p != end && *p != '\n' && *p != '\r') ++p;
        return size_t(p - text.data());
    };
    skip_blanks();
    if (p == end || (*p != 'v' && *p != 'f') || !at_word_end(p + 1)) return kNot;
    if (*p++ == 'v') {
        Position position;
        for (double& coordinate : position) {
            skip_blanks();
            const char* const number_end = plain_double(p, end, &coordinate);
            if (!number_end || !at_word_end(number_end)) return kNot;
            p = number_end;
        }
        out.positions.push_back(position);
        return line_end();
    }
    const size_t corners_before = out.corners.size();
    uint32_t corners = 0;
    for (skip_blanks(); p != end && !at_word_end(p); skip_blanks()) {
        // v, v/vt, v//vn or v/vt/vn (or more parts, as corner_index reads them): unsigned digits
        // each, all but the vertex's possibly empty, none zero, within 32 bits.
        int64_t vertex = 0;
        for (int part = 0;; ++part) {
            const bool sign = p != end && (*p == '-' || *p == '+');  // (relative: strict)
            int64_t value = 0;
            const char* const digits_end = sign ? nullptr : plain_integer(p, end, &value);
            if (sign || (digits_end ? value == 0 || value > std::numeric_limits<int32_t>::max()
                                    : part == 0)) {
                out.corners.resize(corners_before);
                return kNot;
            }
            if (digits_end) p = digits_end;
            if (part == 0) vertex = value;
            if (p == end || *p != '/') break;
            ++p;
        }
        if (!at_word_end(p)) {
            out.corners.resize(corners_before);
            return kNot;
        }
        out.corners.push_back(vertex - 1);
        ++corners;
    }
    out.corner_counts.push_back(corners);
    ++*face_number;
    return line_end();
}

// Parses the whole lines of `text` into out. Line by line; "\r\n", "\n" or a lone "\r" ends one,
// and '#' starts a comment. With `relative` (a part of the file), relative indices are recorded
// there instead of resolved, and line and face numbers count from the part's start.
void parse_lines(const std::string& path, std::string_view text, Polygons& out,
                 RelativeCorners* relative, ParseProgress* progress) {
    size_t face_number = 0;
    size_t at = 0;
    for (size_t line_number = 1; at < text.size(); ++line_number) {
        size_t line_end = quick_line(text, at, out, &face_number);
        if (line_end == std::string_view::npos) {
            // The strict reading. A plain scan: string_view::find_first_of calls memchr on the
            // two-character set once per character of the text.
            line_end = at;
            while (line_end < text.size() && text[line_end] != '\n' && text[line_end] != '\r')
                ++line_end;
            TextCursor line(path, text.substr(at, line_end - at), '#', line_number);
            // Keywords compared as characters: == on a string_view calls memcmp.
            const std::string_view keyword = line.word_on_line();
            const char key = keyword.size() == 1 ? keyword[0] : '\0';
            if (key == 'v') {
                // x y z, read strictly and correctly rounded; a w or a vertex colour may follow.
                Position p;
                for (double& coordinate : p) {
                    const std::string_view word = line.word_on_line();
                    if (word.empty()) line.fail("a vertex has fewer than 3 coordinates");
                    coordinate = line.to_double(word, "vertex coordinate");
                }
                out.positions.push_back(p);
            } else if (key == 'f') {
                ++face_number;
                uint32_t corners = 0;
                for (std::string_view corner = line.word_on_line(); !corner.empty();
                     corner = line.word_on_line()) {
                    bool is_relative = false;
                    out.corners.push_back(corner_index(line, corner, out.positions.size(),
                                                       face_number,
                                                       relative ? &is_relative : nullptr));
                    if (is_relative) relative->push_back(out.corners.size() - 1);
                    ++corners;
                }
                out.corner_counts.push_back(corners);
            }
        }
        at = line_end;
        if (at < text.size() && text[at++] == '\r' && at < text.size() && text[at] == '\n') ++at;
        if (progress) progress->at(at);
    }
}

struct Part {
    Polygons polygons;
    RelativeCorners relative;
};

}  // namespace

Polygons read_obj(const std::string& path, const ParseReport& report) {
    const FileBytes file = read_whole_file(path);
    const std::string_view text = file.view();
    Polygons out;
    out.first_index = 1;

    // Phase 1: parts of whole lines (text_parts); one part takes the plain parse, with its
    // progress.
    const std::vector<std::string_view> texts = text_parts(text);
    if (texts.size() <= 1) {
        ParseProgress progress(report, text.size());
        parse_lines(path, text, out, nullptr, &progress);
        return out;
    }

    // Phase 2: the parts in parallel, relative indices recorded (the vertices before a part are
    // not known yet).
    std::vector<Part> parts(texts.size());
    bool parsed = parse_parts(texts, 0, text.size(), report, [&](size_t i) {
        // Room for the vertices and corners of a part made only of vertex lines of 16 bytes or
        // more, or only of corners of 6 bytes or faces of 16 (real files' are longer): pages of
        // it that stay unused are never touched, where growing the vectors would copy and fault
        // in each size again. A denser part grows as it needs (the bounds a part's bytes set, 7
        // bytes a vertex and 2 a corner, would reserve address space of eight times the file).
        const size_t bytes = texts[i].size();
        parts[i].polygons.positions.reserve(bytes / 16 + 1);
        parts[i].polygons.corners.reserve(bytes / 6 + 1);
        parts[i].polygons.corner_counts.reserve(bytes / 16 + 1);
        parse_lines(path, texts[i], parts[i].polygons, &parts[i].relative, nullptr);
    });

    // Phase 3: relative indices counted back from all the vertices before their part, and the
    // parts joined. A failed part, or a relative index before the first vertex, sends the whole
    // file through the plain parse, which fails where the part did, with the line's number.
    size_t vertices = 0;
    for (Part& part : parts) {
        for (const size_t c : part.relative) {
            part.polygons.corners[c] += int64_t(vertices);
            parsed = parsed && part.polygons.corners[c] >= 0;
        }
        vertices += part.polygons.positions.size();
    }
    if (!parsed) {
        Polygons again;
        again.first_index = 1;
        parse_lines(path, text, again, nullptr, nullptr);
        return again;
    }
    std::vector<const Polygons*> joined;
    for (const Part& part : parts) joined.push_back(&part.polygons);
    append_parts(out, joined);
    return out;
}

}  // namespace oclvox::mesh_reading
