// Pieces the mesh readers (read_*.cpp) share: what a reader produces, the file's bytes, a text
// cursor with strict number parsing, the reading of large texts in parts on all cores, the guard
// that checks declared sizes against the file before anything is allocated for them, and the one
// polygon triangulation that every format goes through.
#pragma once

#include <array>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "host_memory.hpp"
#include "little_endian.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox::mesh_reading {

using Position = std::array<double, 3>;

// A file's geometry in its own numbering: positions, and polygons as runs of vertex indices.
// Indices are kept as read (possibly negative or past the end) so that triangulated() reports
// them in the file's terms.
struct Polygons {
    std::vector<Position> positions;
    // Vertex indices, polygon after polygon, and the corners of each polygon in file order (left
    // unzeroed by resize, so parts of a file can be joined into them on all cores).
    detail::FilledLaterVector<int64_t> corners;
    detail::FilledLaterVector<uint32_t> corner_counts;
    int first_index = 0;  // how the format numbers its first vertex (OBJ: 1)

    void add_triangle(int64_t a, int64_t b, int64_t c) {
        corners.insert(corners.end(), {a, b, c});
        corner_counts.push_back(3);
    }
};

// Names of the coordinates, for messages.
inline constexpr const char* kAxisCoordinate[3] = {"x coordinate", "y coordinate", "z coordinate"};

// Faces with more corners are refused: ear clipping costs O(corners^2) and more, so one huge
// face in a hostile file would otherwise take hours.
constexpr uint32_t kMaxPolygonCorners = 4096;

// How far a reader has parsed its file's bytes: report(done, total), called every kStride steps
// of its parse loop, so the loop pays a counter per record. The report may throw (Cancelled).
using ParseReport = std::function<void(uint64_t done, uint64_t total)>;
class ParseProgress {
  public:
    ParseProgress(const ParseReport& report, uint64_t total) : report_(report), total_(total) {}
    void at(uint64_t offset) {
        if (report_ && ++steps_ % kStride == 0) report_(offset, total_);
    }

  private:
    static constexpr uint64_t kStride = 4096;
    const ParseReport& report_;
    uint64_t total_, steps_ = 0;
};

// The readers, one per file. Each throws InputError naming the file, and reports its parse
// (assimp's scenes only when done).
Polygons read_obj(const std::string& path, const ParseReport& report = {});
Polygons read_stl(const std::string& path, const ParseReport& report = {});
Polygons read_ply(const std::string& path, const ParseReport& report = {});
Polygons read_off(const std::string& path, const ParseReport& report = {});
Polygons read_scene_assimp(const std::string& path);  // glTF 2.0, GLB, 3MF

// Checks every index and splits every polygon into triangles that cover exactly the polygon (ear
// clipping in the plane the polygon faces most; a convex polygon gets the fan from its first
// corner). Polygons of fewer than 3 corners (points, lines) are not surfaces and are dropped.
Mesh triangulated(const std::string& path, Polygons polygons);

[[noreturn]] void fail(const std::string& path, const std::string& problem);

// A file's bytes, in a buffer that was not zeroed before the read filled it (for a file of many
// megabytes the zeroing and its page faults cost as much again as the read).
class FileBytes {
  public:
    explicit FileBytes(detail::FilledLaterVector<char> bytes) : bytes_(std::move(bytes)) {}
    std::string_view view() const { return {bytes_.data(), bytes_.size()}; }

  private:
    detail::FilledLaterVector<char> bytes_;
};

// The whole file, after clear failures for a missing, unreadable or empty one. Opened once, so a
// named pipe is read whole.
FileBytes read_whole_file(const std::string& path);

// Fails unless `count` items of at least `min_bytes_each` bytes fit in `bytes_left` bytes. Called
// with every count a header declares, before anything is allocated for it, so a few bytes that
// claim billions of records cost nothing.
void require_room(const std::string& path, uint64_t count, uint64_t min_bytes_each,
                  uint64_t bytes_left, const std::string& what);

// A word as it may be quoted in a message: non-printable bytes escaped, long words cut.
std::string quoted(std::string_view word);

// The number from_chars reads at `first` (after a '+' sign, which writers may emit and the strict
// readings skip too) into *value; the end of it, or nullptr where none is read. The one-pass
// readings (TextCursor::quick_double, OBJ's common lines) then check that a word ends there.
inline const char* plain_double(const char* first, const char* last, double* value) {
    const auto parsed =
        std::from_chars(first != last && *first == '+' ? first + 1 : first, last, *value);
    return parsed.ec == std::errc() ? parsed.ptr : nullptr;
}

// The whole number at `first`: an optional sign, then 1 to 18 digits (which cannot overflow),
// read as from_chars would read them, into *value; the end of the digits read, or nullptr where
// there are none. Where the word goes on (more digits, other characters) the caller takes its
// strict reading.
inline const char* plain_integer(const char* first, const char* last, int64_t* value) {
    const bool negative = first != last && *first == '-';
    if (first != last && (*first == '-' || *first == '+')) ++first;
    const char* c = first;
    int64_t read = 0;
    for (; c != last && unsigned(*c) - unsigned('0') <= 9 && c - first < 18; ++c)
        read = 10 * read + int64_t(*c - '0');
    if (c == first) return nullptr;
    *value = negative ? -read : read;
    return c;
}

// Whitespace-separated words of a text file, with the line number for messages. Only space,
// tab, CR, VT and FF separate words, so a NUL byte is part of a word and fails its parse.
class TextCursor {
  public:
    // `comment` starts a comment that runs to the end of the line (0: none); `first_line` is the
    // number of the text's first line in the file.
    TextCursor(const std::string& path, std::string_view text, char comment = 0,
               size_t first_line = 1)
        : path_(path), text_(text), comment_(comment), line_(first_line) {}

    // The next word on the current line; empty at the end of the line. Inline, with the blank
    // test below, as it runs for every word of a file: called out of line with a branch per
    // character class it was a fifth of an OBJ parse.
    std::string_view word_on_line() {
        skip_blanks();
        const size_t first = at_;
        while (at_ < text_.size() && !ends_word(text_[at_])) ++at_;
        return text_.substr(first, at_ - first);
    }
    // The next word, moving over line ends; empty at the end of the text.
    std::string_view word();
    // True when the current line has no more words.
    bool line_done();
    // Moves past the end of the current line (whatever words are left on it).
    void skip_line();
    // Moves to the start of the next line that has a word; false at the end of the text.
    bool next_nonblank_line();
    bool at_end();

    size_t line() const { return line_; }
    size_t offset() const { return at_; }
    size_t bytes_left() const { return text_.size() - at_; }

    // Strict conversions of a whole word; `what` names the value in the message. A missing
    // word, trailing characters or a value out of range fail with the file and line.
    double to_double(std::string_view word, std::string_view what) const;
    int64_t to_integer(std::string_view word, std::string_view what) const {
        // A plain whole number is read here; anything else, errors included, the strict way.
        const char* const last = word.data() + word.size();
        int64_t value = 0;
        if (plain_integer(word.data(), last, &value) == last && !word.empty()) return value;
        return to_integer_strictly(word, what);
    }
    uint64_t to_count(std::string_view word, std::string_view what) const;

    // The next word on the line as a number, read where it starts, in one pass, when it is a plain
    // one (the common case): the value from_chars gives (a decimal, or for integers up to 18
    // digits) and the word ends where the number does. Otherwise the cursor stays, and the strict
    // reading of the word (to_double, to_integer) either reads it the same or names the problem.
    bool quick_double(double* value) {
        skip_blanks();
        const char* const end =
            plain_double(text_.data() + at_, text_.data() + text_.size(), value);
        if (!end || !ends_number(end)) return false;
        at_ = size_t(end - text_.data());
        return true;
    }
    bool quick_integer(int64_t* value) {
        skip_blanks();
        const char* const end =
            plain_integer(text_.data() + at_, text_.data() + text_.size(), value);
        if (!end || !ends_number(end)) return false;
        at_ = size_t(end - text_.data());
        return true;
    }
    double double_on_line(std::string_view what) {
        double value;
        return quick_double(&value) ? value : to_double(word_on_line(), what);
    }
    int64_t integer_on_line(std::string_view what) {
        int64_t value;
        return quick_integer(&value) ? value : to_integer(word_on_line(), what);
    }
    bool quick_count(uint64_t* value) {
        const size_t start = at_;
        int64_t read;
        if (!quick_integer(&read) || read < 0) {
            at_ = start;  // to_count names a negative count
            return false;
        }
        *value = uint64_t(read);
        return true;
    }
    uint64_t count_on_line(std::string_view what) {
        uint64_t value;
        return quick_count(&value) ? value : to_count(word_on_line(), what);
    }

    [[noreturn]] void fail(const std::string& problem) const;

    // Space, tab, CR, VT and FF: what separates words on a line.
    static bool is_blank(char c) { return c == ' ' || (c >= '\t' && c <= '\r' && c != '\n'); }

  private:
    bool ends_word(char c) const { return c == '\n' || is_blank(c) || c == comment_; }
    bool ends_number(const char* c) const {
        return c == text_.data() + text_.size() || ends_word(*c);
    }
    void skip_blanks() {
        while (at_ < text_.size() && is_blank(text_[at_])) ++at_;
        if (comment_ != 0 && at_ < text_.size() && text_[at_] == comment_)
            while (at_ < text_.size() && text_[at_] != '\n') ++at_;
    }
    int64_t to_integer_strictly(std::string_view word, std::string_view what) const;

    const std::string& path_;
    std::string_view text_;
    char comment_;
    size_t line_;
    size_t at_ = 0;
};

// Large text files are parsed in parts of about kTextPartBytes on all cores. text_parts cuts the
// text into parts that each end after a '\n' (so no part splits a line, nor a "\r\n"; a text
// without one is a single part).
constexpr size_t kTextPartBytes = size_t(1) << 20;
std::vector<std::string_view> text_parts(std::string_view text);

// Calls parse(i) for every part on all cores, a wave of parts at a time, and after each wave
// reports the file offset its parts reach (`first_offset` is the first part's; the report may
// throw Cancelled). Returns false if parse threw InputError for any part: the caller then parses
// the whole file in one pass, so that the error is the first in the file, with its line number.
bool parse_parts(const std::vector<std::string_view>& parts, uint64_t first_offset,
                 uint64_t file_bytes, const ParseReport& report,
                 const std::function<void(size_t)>& parse);

// Reads a text body of one record a line (the lines TextCursor finds a word on, after
// `comment`), the first `records` of them, in parts on all cores: each part's records are counted
// first, so that read(text, r, polygons) is called for every record with its number r, the cursor
// on its line (in order within a part, each part's faces into a polygons of its own; the parts'
// polygons are then appended to out in order). Lines past the records are not read, as in one
// pass. False where a part fails (InputError) or the records are fewer: the caller then reads the
// body in one pass, which names the problem (out then holds nothing more).
bool read_records_in_parts(const std::string& path, std::string_view bytes, size_t body,
                           char comment, uint64_t records, const ParseReport& report,
                           const std::function<void(TextCursor&, uint64_t, Polygons&)>& read,
                           Polygons& out);

// Appends the parts' positions, corners and corner counts to out, part after part (the corners
// and counts, most of the bytes, on all cores: fresh pages fault in at a few microseconds each).
void append_parts(Polygons& out, const std::vector<const Polygons*>& parts);

using detail::load_scalar;

}  // namespace oclvox::mesh_reading
