// The pieces every mesh reader shares (see mesh_reading.hpp).
#include "mesh_reading.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

namespace oclvox::mesh_reading {

void fail(const std::string& path, const std::string& problem) {
    throw InputError("mesh file '" + path + "': " + problem);
}

// ---------------------------------------------------------------------------------------------
// Files and sizes
// ---------------------------------------------------------------------------------------------

// Fails with a clear message for the problems every format shares (missing, a folder,
// unreadable, empty) before a parser sees the file and words them its own way.
namespace {

// A path that names no file, or a folder, fails by its status alone (nothing is opened).
void require_file(const std::string& path) {
    std::error_code error;
    const auto status = std::filesystem::status(path, error);
    if (!std::filesystem::exists(status)) fail(path, "the file does not exist");
    if (std::filesystem::is_directory(status)) fail(path, "this is a folder, not a mesh file");
}

}  // namespace

FileBytes read_whole_file(const std::string& path) {
    // The file is opened once: a named pipe gives its bytes to one reader only.
    require_file(path);
    std::ifstream file(path, std::ios::binary);
    if (!file) fail(path, "the file cannot be opened for reading");
    // Read straight into a string of the file's size (plus a byte, so the read that fills it
    // also meets the end): copying through a growing stream buffer cost more than parsing a
    // large OBJ. The size is only a start, so a pipe or a growing file is still read whole.
    std::error_code error;
    const uint64_t expected = std::filesystem::file_size(path, error);
    detail::FilledLaterVector<char> bytes(error ? size_t(1) << 16 : size_t(expected) + 1);
    size_t size = 0;
    while (file.read(bytes.data() + size, std::streamsize(bytes.size() - size))) {
        size = bytes.size();
        bytes.resize(2 * size);
    }
    if (file.bad() || !file.eof()) fail(path, "reading the file failed");
    bytes.resize(size + size_t(file.gcount()));
    if (bytes.empty()) fail(path, "the file is empty");
    return FileBytes(std::move(bytes));
}

void require_room(const std::string& path, uint64_t count, uint64_t min_bytes_each,
                  uint64_t bytes_left, const std::string& what) {
    if (min_bytes_each == 0 || count <= bytes_left / min_bytes_each) return;
    fail(path, "the header declares " + std::to_string(count) + " " + what + ", more than the " +
                   std::to_string(bytes_left) + " bytes that follow can hold");
}

std::string quoted(std::string_view word) {
    constexpr size_t kShown = 40;
    std::string text = "'";
    for (size_t k = 0; k < std::min(word.size(), kShown); ++k) {
        const unsigned char c = static_cast<unsigned char>(word[k]);
        if (c >= 0x20 && c < 0x7f) {
            text += char(c);
        } else {
            static const char* const kHex = "0123456789abcdef";
            text += "\\x";
            text += kHex[c >> 4];
            text += kHex[c & 15];
        }
    }
    if (word.size() > kShown) text += "...";
    return text + "'";
}

// ---------------------------------------------------------------------------------------------
// Text
// ---------------------------------------------------------------------------------------------

namespace {

// Where a strict parser takes no leading '+', which writers may emit.
const char* skip_plus(const char* first, const char* last) {
    return (*first == '+' && last - first > 1) ? first + 1 : first;
}

}  // namespace

std::string_view TextCursor::word() {
    for (;;) {
        const std::string_view found = word_on_line();
        if (!found.empty() || at_ == text_.size()) return found;
        skip_line();
    }
}

bool TextCursor::line_done() {
    skip_blanks();
    return at_ == text_.size() || text_[at_] == '\n';
}

void TextCursor::skip_line() {
    const void* const end = std::memchr(text_.data() + at_, '\n', text_.size() - at_);
    at_ = end ? size_t(static_cast<const char*>(end) - text_.data()) : text_.size();
    if (at_ < text_.size()) {
        ++at_;
        ++line_;
    }
}

bool TextCursor::next_nonblank_line() {
    while (line_done()) {
        if (at_ == text_.size()) return false;
        skip_line();
    }
    return true;
}

bool TextCursor::at_end() {
    return !next_nonblank_line();
}

void TextCursor::fail(const std::string& problem) const {
    mesh_reading::fail(path_, "line " + std::to_string(line_) + ": " + problem);
}

double TextCursor::to_double(std::string_view word, std::string_view what) const {
    if (word.empty()) fail("the " + std::string(what) + " is missing");
    const char* const last = word.data() + word.size();
    double value = 0;
    // Correctly rounded: the nearest double to the decimal text. "nan" and "inf" are numbers
    // here; validate_mesh decides whether they matter.
    const auto parsed = std::from_chars(skip_plus(word.data(), last), last, value);
    if (parsed.ec == std::errc::result_out_of_range)
        fail("the " + std::string(what) + " " + quoted(word) + " is out of the range of double");
    if (parsed.ec != std::errc() || parsed.ptr != last)
        fail("the " + std::string(what) + " " + quoted(word) + " is not a number");
    return value;
}

int64_t TextCursor::to_integer_strictly(std::string_view word, std::string_view what) const {
    if (word.empty()) fail("the " + std::string(what) + " is missing");
    const char* const last = word.data() + word.size();
    int64_t value = 0;
    const auto parsed = std::from_chars(skip_plus(word.data(), last), last, value);
    if (parsed.ec != std::errc() || parsed.ptr != last)
        fail("the " + std::string(what) + " " + quoted(word) +
             " is not a whole number that fits in 64 bits");
    return value;
}

uint64_t TextCursor::to_count(std::string_view word, std::string_view what) const {
    const int64_t value = to_integer(word, what);
    if (value < 0) fail("the " + std::string(what) + " " + quoted(word) + " is negative");
    return uint64_t(value);
}

std::vector<std::string_view> text_parts(std::string_view text) {
    std::vector<std::string_view> parts;
    for (size_t at = 0; at < text.size();) {
        size_t end = text.find('\n', std::min(text.size(), at + kTextPartBytes));
        end = end == std::string_view::npos ? text.size() : end + 1;
        parts.push_back(text.substr(at, end - at));
        at = end;
    }
    return parts;
}

bool parse_parts(const std::vector<std::string_view>& parts, uint64_t first_offset,
                 uint64_t file_bytes, const ParseReport& report,
                 const std::function<void(size_t)>& parse) {
    constexpr size_t kPartsPerWave = 16;
    std::atomic<bool> failed{false};
    uint64_t done = first_offset;
    for (size_t first = 0; first < parts.size(); first += kPartsPerWave) {
        const size_t end = std::min(parts.size(), first + kPartsPerWave);
        tbb::parallel_for(first, end, [&](size_t i) {
            try {
                parse(i);
            } catch (const InputError&) {
                failed = true;
            }
        });
        for (size_t i = first; i < end; ++i) done += parts[i].size();
        if (report) report(done, file_bytes);
    }
    return !failed;
}

bool read_records_in_parts(const std::string& path, std::string_view bytes, size_t body,
                           char comment, uint64_t records, const ParseReport& report,
                           const std::function<void(TextCursor&, uint64_t, Polygons&)>& read,
                           Polygons& out) {
    const std::vector<std::string_view> parts = text_parts(bytes.substr(body));
    std::vector<uint64_t> first_record(parts.size() + 1, 0);
    tbb::parallel_for(size_t(0), parts.size(), [&](size_t i) {
        TextCursor text(path, parts[i], comment);
        for (; text.next_nonblank_line(); text.skip_line()) ++first_record[i + 1];
    });
    for (size_t i = 0; i < parts.size(); ++i) first_record[i + 1] += first_record[i];
    if (first_record.back() < records) return false;

    std::vector<Polygons> polygons(parts.size());
    const bool parsed = parse_parts(parts, body, bytes.size(), report, [&](size_t i) {
        polygons[i].corner_counts.reserve(parts[i].size() / 8);  // "3 0 1 2\n" or longer
        polygons[i].corners.reserve(parts[i].size() / 2);
        TextCursor text(path, parts[i], comment);
        for (uint64_t r = first_record[i]; r < std::min(first_record[i + 1], records); ++r) {
            text.next_nonblank_line();
            read(text, r, polygons[i]);
            text.skip_line();
        }
    });
    if (!parsed) return false;
    std::vector<const Polygons*> joined;
    for (const Polygons& part : polygons) joined.push_back(&part);
    append_parts(out, joined);
    return true;
}

void append_parts(Polygons& out, const std::vector<const Polygons*>& parts) {
    std::vector<size_t> first_corner(parts.size() + 1, out.corners.size());
    std::vector<size_t> first_polygon(parts.size() + 1, out.corner_counts.size());
    size_t positions = out.positions.size();
    for (size_t i = 0; i < parts.size(); ++i) {
        positions += parts[i]->positions.size();
        first_corner[i + 1] = first_corner[i] + parts[i]->corners.size();
        first_polygon[i + 1] = first_polygon[i] + parts[i]->corner_counts.size();
    }
    out.positions.reserve(positions);
    for (const Polygons* part : parts)
        out.positions.insert(out.positions.end(), part->positions.begin(), part->positions.end());
    out.corners.resize(first_corner.back());
    out.corner_counts.resize(first_polygon.back());
    tbb::parallel_for(size_t(0), parts.size(), [&](size_t i) {
        std::copy(parts[i]->corners.begin(), parts[i]->corners.end(),
                  out.corners.begin() + ptrdiff_t(first_corner[i]));
        std::copy(parts[i]->corner_counts.begin(), parts[i]->corner_counts.end(),
                  out.corner_counts.begin() + ptrdiff_t(first_polygon[i]));
    });
}

// ---------------------------------------------------------------------------------------------
// Polygons
// ---------------------------------------------------------------------------------------------

namespace {

// Splits polygons into triangles that cover exactly the polygon, by ear clipping in the
// coordinate plane that the polygon faces most. A fan would be simpler, but in a concave polygon
// its triangles leave the polygon and overlap, which a voxelizer turns into voxels that are not
// part of the surface. Convex polygons get the fan from their first corner, the usual convention.
class PolygonTriangulator {
  public:
    // Appends corners.size() - 2 triangles with the polygon's winding.
    void triangulate(const std::vector<Position>& positions, const std::vector<uint32_t>& corners,
                     Mesh& out) {
        const size_t n = corners.size();
        if (n == 3) {
            out.triangles.push_back({corners[0], corners[1], corners[2]});
            return;
        }
        project(positions, corners);

        // Clip ears until a triangle is left. Starting at the second corner and staying at the
        // clipped position after each clip turns a convex polygon into the fan from corner 0. A
        // full round without an ear means a degenerate or self-crossing polygon, which has no
        // clean triangulation: then the current corner is clipped anyway, so every polygon still
        // gives n - 2 triangles.
        ring_.resize(n);
        for (size_t k = 0; k < n; ++k) ring_[k] = k;
        size_t at = 1, misses = 0;
        while (ring_.size() > 3) {
            const size_t m = ring_.size();
            at %= m;
            const size_t prev = ring_[(at + m - 1) % m], cur = ring_[at],
                         next = ring_[(at + 1) % m];
            if (misses < m && !is_ear(prev, cur, next)) {
                ++at;
                ++misses;
                continue;
            }
            out.triangles.push_back({corners[prev], corners[cur], corners[next]});
            ring_.erase(ring_.begin() + std::ptrdiff_t(at));
            misses = 0;
        }
        out.triangles.push_back({corners[ring_[0]], corners[ring_[1]], corners[ring_[2]]});
    }

  private:
    // 2D coordinates of the corners in the plane that the Newell normal points most along, with
    // a sign that makes the polygon wind counter-clockwise there.
    void project(const std::vector<Position>& positions, const std::vector<uint32_t>& corners) {
        const size_t n = corners.size();
        Position normal{0, 0, 0};
        for (size_t k = 0; k < n; ++k) {
            const Position& a = positions[corners[k]];
            const Position& b = positions[corners[(k + 1) % n]];
            normal[0] += (a[1] - b[1]) * (a[2] + b[2]);
            normal[1] += (a[2] - b[2]) * (a[0] + b[0]);
            normal[2] += (a[0] - b[0]) * (a[1] + b[1]);
        }
        int drop = 0;
        for (int axis = 1; axis < 3; ++axis)
            if (std::fabs(normal[axis]) > std::fabs(normal[drop])) drop = axis;
        // With (u, v) the cyclic successors of the dropped axis, normal[drop] is twice the
        // polygon's signed area in the (u, v) plane.
        const int u = (drop + 1) % 3, v = (drop + 2) % 3;
        winding_ = normal[drop] < 0 ? -1.0 : 1.0;
        flat_.resize(n);
        for (size_t k = 0; k < n; ++k)
            flat_[k] = {positions[corners[k]][u], positions[corners[k]][v]};
    }

    // Twice the area of (a, b, c), positive when it turns the way the polygon winds.
    double turn(size_t a, size_t b, size_t c) const {
        const auto &pa = flat_[a], &pb = flat_[b], &pc = flat_[c];
        return winding_ * ((pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0]));
    }

    // A strictly convex corner whose triangle holds no other remaining corner. Corners that
    // coincide with one of the triangle's (a polygon touching itself) do not block it.
    bool is_ear(size_t prev, size_t cur, size_t next) const {
        if (!(turn(prev, cur, next) > 0)) return false;
        for (size_t other : ring_) {
            if (other == prev || other == cur || other == next) continue;
            const auto& p = flat_[other];
            if (p == flat_[prev] || p == flat_[cur] || p == flat_[next]) continue;
            if (turn(prev, cur, other) >= 0 && turn(cur, next, other) >= 0 &&
                turn(next, prev, other) >= 0)
                return false;
        }
        return true;
    }

    std::vector<std::array<double, 2>> flat_;
    std::vector<size_t> ring_;
    double winding_ = 1;
};

}  // namespace

Mesh triangulated(const std::string& path, Polygons polygons) {
    const uint64_t vertex_count = polygons.positions.size();
    if (vertex_count > std::numeric_limits<uint32_t>::max())
        fail(path, "more than 2^32 vertices, which 32-bit triangle indices cannot address");

    Mesh mesh;
    mesh.positions = std::move(polygons.positions);
    size_t triangles = 0;
    bool only_triangles = true;
    for (const uint32_t count : polygons.corner_counts) {
        triangles += count >= 3 ? count - 2 : 0;
        only_triangles = only_triangles && count == 3;
    }
    // A file of triangles only (most large ones) is taken over on all cores once every index is
    // known to be in range; otherwise the loop below finds the first bad one and names it.
    if (only_triangles && tbb::parallel_reduce(
                              tbb::blocked_range<size_t>(0, polygons.corners.size()), true,
                              [&](const tbb::blocked_range<size_t>& corners, bool valid) {
                                  for (size_t k = corners.begin(); k < corners.end(); ++k)
                                      valid = valid && uint64_t(polygons.corners[k]) < vertex_count;
                                  return valid;
                              },
                              [](bool a, bool b) { return a && b; })) {
        mesh.triangles.resize(triangles);
        tbb::parallel_for(size_t(0), triangles, [&](size_t t) {
            for (int c = 0; c < 3; ++c)
                mesh.triangles[t][c] = uint32_t(polygons.corners[3 * t + size_t(c)]);
        });
        return mesh;
    }
    mesh.triangles.reserve(triangles);
    PolygonTriangulator triangulator;
    std::vector<uint32_t> corners;
    size_t first = 0;
    for (size_t face = 0; face < polygons.corner_counts.size(); ++face) {
        const uint32_t count = polygons.corner_counts[face];
        // Messages are made only on failure: a string per face and corner was two thirds of
        // this loop's time.
        auto face_name = [&] { return "face " + std::to_string(face + 1); };
        if (count > kMaxPolygonCorners)
            fail(path, face_name() + " has " + std::to_string(count) +
                           " corners; oclvox triangulates faces of up to " +
                           std::to_string(kMaxPolygonCorners));
        corners.clear();
        for (size_t k = first; k < first + count; ++k) {
            const int64_t index = polygons.corners[k];
            auto shown = [&] { return std::to_string(index + polygons.first_index); };
            if (index < 0)
                fail(path, face_name() + " refers to vertex " + shown() +
                               ", which is out of range: a vertex index cannot be negative");
            if (uint64_t(index) >= vertex_count)
                fail(path, face_name() + " refers to vertex " + shown() +
                               ", which is out of range: the file has " +
                               std::to_string(vertex_count) + " vertices, numbered from " +
                               std::to_string(polygons.first_index));
            corners.push_back(uint32_t(index));
        }
        if (count >= 3) triangulator.triangulate(mesh.positions, corners, mesh);
        first += count;
    }
    return mesh;
}

}  // namespace oclvox::mesh_reading
