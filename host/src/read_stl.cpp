// STL, ASCII and binary. Every facet keeps its own three corners here; load_mesh welds equal
// positions afterwards, which is what gives an STL mesh a shared topology.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

#include "file_names.hpp"
#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

constexpr uint64_t kBinaryHeaderBytes = 84;  // 80 bytes of anything, then the facet count
constexpr uint64_t kBinaryFacetBytes = 50;   // normal, 3 corners (12 floats), attribute word

bool same_keyword(std::string_view word, std::string_view keyword) {
    return word.size() == keyword.size() &&
           std::equal(word.begin(), word.end(), keyword.begin(),
                      [](char a, char b) { return detail::ascii_lower(a) == b; });
}

void expect(const TextCursor& text, std::string_view word, std::string_view keyword) {
    if (same_keyword(word, keyword)) return;
    if (word.empty()) text.fail("expected '" + std::string(keyword) + "', but the file ends");
    text.fail("expected '" + std::string(keyword) + "', found " + quoted(word));
}

// Every corner is its own position (load_mesh welds them): corner k is position k.
void number_corners(Polygons& out) {
    out.corners.resize(out.positions.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, out.corners.size(), 65536),
                      [&](const tbb::blocked_range<size_t>& range) {
                          for (size_t k = range.begin(); k < range.end(); ++k)
                              out.corners[k] = int64_t(k);
                      });
}

// Facet f of a binary file into its place in out. Binary floats are exact in double, so the
// corners are the file's values bit for bit; the stored normal (the first 12 bytes) is ignored:
// the corners define the facet.
void read_binary_facet(std::string_view bytes, size_t f, Polygons& out) {
    const char* const facet = bytes.data() + kBinaryHeaderBytes + f * kBinaryFacetBytes;
    for (size_t corner = 0; corner < 3; ++corner) {
        Position& p = out.positions[3 * f + corner];
        for (size_t axis = 0; axis < 3; ++axis)
            p[axis] = load_scalar<float>(facet + 12 + 12 * corner + 4 * axis, false);
    }
    out.corner_counts[f] = 3;
}

Polygons read_binary(const std::string& path, std::string_view bytes, ParseProgress& progress) {
    if (bytes.size() < kBinaryHeaderBytes)
        fail(path, "the file does not start with 'solid' (ASCII STL) and is shorter than the " +
                       std::to_string(kBinaryHeaderBytes) + "-byte header of a binary STL");
    const uint32_t facets = load_scalar<uint32_t>(&bytes[80], false);
    require_room(path, facets, kBinaryFacetBytes, bytes.size() - kBinaryHeaderBytes,
                 "facets (binary STL)");

    // Facets of one size, read where they lie, on all cores a wave at a time (the progress
    // between waves, as a serial read would report it).
    Polygons out;
    out.positions.resize(size_t(facets) * 3);
    out.corner_counts.resize(facets);
    constexpr size_t kWave = 65536;
    for (size_t first = 0; first < facets; first += kWave) {
        const size_t end = std::min<size_t>(facets, first + kWave);
        tbb::parallel_for(tbb::blocked_range<size_t>(first, end, 4096),
                          [&](const tbb::blocked_range<size_t>& range) {
                              for (size_t f = range.begin(); f < range.end(); ++f)
                                  read_binary_facet(bytes, f, out);
                          });
        for (size_t f = first; f < end; ++f)
            progress.at(kBinaryHeaderBytes + (f + 1) * kBinaryFacetBytes);
    }
    number_corners(out);
    return out;
}

// solid NAME / facet normal N N N / outer loop / vertex X Y Z (3 or more) / endloop / endfacet
// ... / endsolid NAME, several solids in a row; keywords in any case. Coordinates are parsed
// correctly rounded. The normal's words are not parsed: writers put "nan" there for slivers.
// Corners are numbered afterwards (number_corners): a facet's are its positions, in order.

// The rest of a facet after its "facet" keyword: its corners' positions and its corner count.
void read_facet(TextCursor& cursor, Polygons& out) {
    expect(cursor, cursor.word(), "normal");
    for (int axis = 0; axis < 3; ++axis)
        if (cursor.word().empty()) cursor.fail("the file ends inside a facet normal");
    expect(cursor, cursor.word(), "outer");
    expect(cursor, cursor.word(), "loop");
    uint32_t corners = 0;
    std::string_view word = cursor.word();
    for (; same_keyword(word, "vertex"); word = cursor.word(), ++corners) {
        Position& p = out.positions.emplace_back();
        for (int axis = 0; axis < 3; ++axis) p[axis] = cursor.double_on_line(kAxisCoordinate[axis]);
    }
    expect(cursor, word, "endloop");
    expect(cursor, cursor.word(), "endfacet");
    if (corners < 3)
        cursor.fail("a facet has " + std::to_string(corners) + " vertices; it needs 3");
    out.corner_counts.push_back(corners);
}

// The words from the cursor on, solids and their facets, into out; `inside`: whether they start
// inside a solid (between facets), left saying where they ended. The whole file must end outside
// a solid; a part of it (Ending::Anywhere) may end inside one, where the next part goes on.
enum class Ending { OutsideSolids, Anywhere };
void read_solids(TextCursor& cursor, bool& inside, Polygons& out, Ending ending,
                 ParseProgress* progress) {
    for (;;) {
        if (!inside) {
            if (cursor.at_end()) return;
            expect(cursor, cursor.word(), "solid");
            cursor.skip_line();  // the solid's name
            inside = true;
        }
        const std::string_view keyword = cursor.word();
        if (same_keyword(keyword, "endsolid")) {
            cursor.skip_line();
            inside = false;
            continue;
        }
        if (keyword.empty() && ending == Ending::Anywhere) return;
        if (!same_keyword(keyword, "facet"))
            cursor.fail(keyword.empty()
                            ? "the file ends inside a solid (no 'endsolid')"
                            : "expected 'facet' or 'endsolid', found " + quoted(keyword));
        read_facet(cursor, out);
        if (progress) progress->at(cursor.offset());
    }
}

Polygons read_ascii(const std::string& path, std::string_view text, ParseProgress& progress) {
    TextCursor cursor(path, text);
    Polygons out;
    bool inside = false;
    read_solids(cursor, inside, out, Ending::OutsideSolids, &progress);
    number_corners(out);
    return out;
}

// Whether the line at `line` starts (after blanks) with the word "facet", in any case.
bool starts_with_facet(std::string_view text, size_t line) {
    size_t at = line;
    while (at < text.size() && TextCursor::is_blank(text[at])) ++at;
    return same_keyword(text.substr(at, 5), "facet") &&
           (at + 5 == text.size() || TextCursor::is_blank(text[at + 5]) || text[at + 5] == '\n');
}

// An ASCII file of several parts (text_parts) on all cores: each part from its first line that
// starts with "facet" (the first part from the file's start) to the next part's, each read on its
// own, all but the first starting inside a solid between facets. A cut is where one pass stands
// between two facets exactly when the part before it reads to its end that way, so the parts give
// what one pass gives; anything else (a part that fails, or ends elsewhere) returns false, and one
// pass then names the problem.
bool read_ascii_in_parts(const std::string& path, std::string_view text, const ParseReport& report,
                         Polygons& out) {
    const std::vector<std::string_view> lines = text_parts(text);
    std::vector<size_t> cuts{0};
    for (size_t i = 1; i < lines.size(); ++i) {
        const size_t first = size_t(lines[i].data() - text.data());
        const size_t end = first + lines[i].size();
        for (size_t line = first; line < end;) {
            if (starts_with_facet(text, line)) {
                cuts.push_back(line);
                break;
            }
            const size_t next = text.find('\n', line);
            line = next == std::string_view::npos ? end : next + 1;
        }
    }
    std::vector<std::string_view> parts;
    for (size_t i = 0; i < cuts.size(); ++i)
        parts.push_back(
            text.substr(cuts[i], (i + 1 < cuts.size() ? cuts[i + 1] : text.size()) - cuts[i]));
    std::vector<Polygons> polygons(parts.size());
    std::vector<char> ends_inside(parts.size());
    const bool parsed = parse_parts(parts, 0, text.size(), report, [&](size_t i) {
        TextCursor cursor(path, parts[i]);
        bool inside = i > 0;
        read_solids(cursor, inside, polygons[i], Ending::Anywhere, nullptr);
        ends_inside[i] = inside;
    });
    if (!parsed) return false;
    for (size_t i = 0; i < parts.size(); ++i)
        if (bool(ends_inside[i]) != (i + 1 < parts.size())) return false;
    std::vector<const Polygons*> joined;
    for (const Polygons& part : polygons) joined.push_back(&part);
    append_parts(out, joined);
    number_corners(out);
    return true;
}

}  // namespace

Polygons read_stl(const std::string& path, const ParseReport& report) {
    const FileBytes file = read_whole_file(path);
    const std::string_view bytes = file.view();
    ParseProgress progress(report, bytes.size());
    // A binary file is recognised by its size, which its facet count fixes: many binary writers
    // start the header with "solid" too.
    if (bytes.size() >= kBinaryHeaderBytes) {
        const uint64_t facets = load_scalar<uint32_t>(&bytes[80], false);
        if (bytes.size() == kBinaryHeaderBytes + kBinaryFacetBytes * facets)
            return read_binary(path, bytes, progress);
    }
    const size_t start = bytes.find_first_not_of(" \t\r\n");
    if (start != std::string_view::npos && same_keyword(bytes.substr(start, 5), "solid")) {
        if (bytes.size() > kTextPartBytes) {
            Polygons out;
            if (read_ascii_in_parts(path, bytes, report, out)) return out;
        }
        return read_ascii(path, bytes, progress);
    }
    return read_binary(path, bytes, progress);
}

}  // namespace oclvox::mesh_reading
