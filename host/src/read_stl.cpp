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

// Facet f of a binary file into its place in out. Binary floats are exact in double, so the
// corners are the file's values bit for bit; the stored normal (the first 12 bytes) is ignored:
// the corners define the facet.
void read_binary_facet(std::string_view bytes, size_t f, Polygons& out) {
    const char* const facet = bytes.data() + kBinaryHeaderBytes + f * kBinaryFacetBytes;
    for (size_t corner = 0; corner < 3; ++corner) {
        Position& p = out.positions[3 * f + corner];
        for (size_t axis = 0; axis < 3; ++axis)
            p[axis] = load_scalar<float>(facet + 12 + 12 * corner + 4 * axis, false);
        out.corners[3 * f + corner] = int64_t(3 * f + corner);
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
    out.corners.resize(size_t(facets) * 3);
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
    return out;
}

// solid NAME / facet normal N N N / outer loop / vertex X Y Z (3 or more) / endloop / endfacet
// ... / endsolid NAME, several solids in a row; keywords in any case. Coordinates are parsed
// correctly rounded. The normal's words are not parsed: writers put "nan" there for slivers.
Polygons read_ascii(const std::string& path, std::string_view text, ParseProgress& progress) {
    TextCursor cursor(path, text);
    Polygons out;
    while (!cursor.at_end()) {
        expect(cursor, cursor.word(), "solid");
        cursor.skip_line();  // the solid's name
        for (;;) {
            const std::string_view keyword = cursor.word();
            if (same_keyword(keyword, "endsolid")) {
                cursor.skip_line();
                break;
            }
            if (!same_keyword(keyword, "facet"))
                cursor.fail(keyword.empty()
                                ? "the file ends inside a solid (no 'endsolid')"
                                : "expected 'facet' or 'endsolid', found " + quoted(keyword));
            expect(cursor, cursor.word(), "normal");
            for (int axis = 0; axis < 3; ++axis)
                if (cursor.word().empty()) cursor.fail("the file ends inside a facet normal");
            expect(cursor, cursor.word(), "outer");
            expect(cursor, cursor.word(), "loop");

            uint32_t corners = 0;
            std::string_view word = cursor.word();
            for (; same_keyword(word, "vertex"); word = cursor.word(), ++corners) {
                Position p;
                for (int axis = 0; axis < 3; ++axis)
                    p[axis] = cursor.double_on_line(kAxisCoordinate[axis]);
                out.positions.push_back(p);
            }
            expect(cursor, word, "endloop");
            expect(cursor, cursor.word(), "endfacet");
            if (corners < 3)
                cursor.fail("a facet has " + std::to_string(corners) + " vertices; it needs 3");
            const size_t first = out.positions.size() - corners;
            for (size_t k = first; k < out.positions.size(); ++k) out.corners.push_back(int64_t(k));
            out.corner_counts.push_back(corners);
            progress.at(cursor.offset());
        }
    }
    return out;
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
    if (start != std::string_view::npos && same_keyword(bytes.substr(start, 5), "solid"))
        return read_ascii(path, bytes, progress);
    return read_binary(path, bytes, progress);
}

}  // namespace oclvox::mesh_reading
