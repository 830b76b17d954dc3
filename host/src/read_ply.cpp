// PLY: ascii, binary_little_endian and binary_big_endian. The vertex element's x, y and z may be
// of any scalar type and stand anywhere among its properties; the face element's corner list is
// named vertex_indices or vertex_index, with any integer length and index types. Every other
// element and property, lists included, is read past. Coordinates become doubles exactly (binary)
// or correctly rounded from their text (ascii, whatever type the header gives them).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>

#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

enum class Format { Ascii, BinaryLittleEndian, BinaryBigEndian };

enum class Scalar { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

struct ScalarName {
    const char* name;
    Scalar type;
};

// Both spellings of every type the PLY format defines.
constexpr ScalarName kScalarNames[] = {
    {"char", Scalar::Int8},       {"int8", Scalar::Int8},       {"uchar", Scalar::UInt8},
    {"uint8", Scalar::UInt8},     {"short", Scalar::Int16},     {"int16", Scalar::Int16},
    {"ushort", Scalar::UInt16},   {"uint16", Scalar::UInt16},   {"int", Scalar::Int32},
    {"int32", Scalar::Int32},     {"uint", Scalar::UInt32},     {"uint32", Scalar::UInt32},
    {"float", Scalar::Float32},   {"float32", Scalar::Float32}, {"double", Scalar::Float64},
    {"float64", Scalar::Float64},
};

uint64_t size_of(Scalar type) {
    switch (type) {
        case Scalar::Int8:
        case Scalar::UInt8:
            return 1;
        case Scalar::Int16:
        case Scalar::UInt16:
            return 2;
        case Scalar::Int32:
        case Scalar::UInt32:
        case Scalar::Float32:
            return 4;
        case Scalar::Float64:
            return 8;
    }
    return 0;
}

bool is_floating(Scalar type) {
    return type == Scalar::Float32 || type == Scalar::Float64;
}

// What the reader does with a property's values.
enum class Role { Skip, X, Y, Z, Corners };

struct Property {
    std::string name;
    std::string described;           // "'name' value", for messages
    Scalar value = Scalar::Float32;  // the scalar's type, or the type of a list's entries
    bool is_list = false;
    Scalar length = Scalar::UInt8;  // lists: the type of the entry count
    Role role = Role::Skip;
};

struct Element {
    std::string name;
    uint64_t count = 0;
    std::vector<Property> properties;
};

struct Header {
    Format format = Format::Ascii;
    std::vector<Element> elements;
    size_t body_offset = 0;  // first byte after "end_header\n"
    size_t body_line = 0;    // its line number, for ascii messages
};

// ---------------------------------------------------------------------------------------------
// Header
// ---------------------------------------------------------------------------------------------

Scalar scalar_type(const TextCursor& text, std::string_view name) {
    for (const ScalarName& known : kScalarNames)
        if (name == known.name) return known.type;
    text.fail(name.empty() ? "a property has no type" : quoted(name) + " is not a PLY type");
}

Property read_property(TextCursor& text) {
    Property property;
    const std::string_view type = text.word_on_line();
    if (type == "list") {
        property.is_list = true;
        property.length = scalar_type(text, text.word_on_line());
        if (is_floating(property.length)) text.fail("a list's length type must be an integer type");
    }
    property.value = scalar_type(text, property.is_list ? text.word_on_line() : type);
    property.name = std::string(text.word_on_line());
    if (property.name.empty()) text.fail("a property has no name");
    property.described = "'" + property.name + "' value";
    return property;
}

// Marks the properties the reader needs and fails on files that cannot give a mesh.
void assign_roles(const TextCursor& text, std::vector<Element>& elements) {
    bool has_vertices = false, has_faces = false;
    for (Element& element : elements) {
        if (element.name == "vertex") {
            if (has_vertices) text.fail("the header declares two 'vertex' elements");
            has_vertices = true;
            for (const auto& [axis, role] :
                 {std::pair{"x", Role::X}, {"y", Role::Y}, {"z", Role::Z}}) {
                Property* found = nullptr;
                for (Property& property : element.properties)
                    if (property.name == axis) found = &property;
                if (!found)
                    text.fail("the 'vertex' element has no '" + std::string(axis) + "' property");
                if (found->is_list)
                    text.fail("the vertex property '" + std::string(axis) + "' is a list");
                found->role = role;
            }
        } else if (element.name == "face") {
            if (has_faces) text.fail("the header declares two 'face' elements");
            has_faces = true;
            Property* found = nullptr;
            for (Property& property : element.properties)
                if (property.name == "vertex_indices" || property.name == "vertex_index") {
                    if (found) text.fail("the 'face' element has two vertex index lists");
                    found = &property;
                }
            if (!found || !found->is_list)
                text.fail(
                    "the 'face' element has no list property 'vertex_indices' or 'vertex_index'");
            if (is_floating(found->value))
                text.fail("the face list '" + found->name +
                          "' holds floating-point values, not vertex indices");
            found->role = Role::Corners;
        } else if (element.name == "tristrips" && element.count > 0) {
            text.fail("triangle strips (the 'tristrips' element) are not supported");
        }
    }
    if (!has_vertices) text.fail("the header declares no 'vertex' element");
}

Header read_header(const std::string& path, std::string_view bytes) {
    TextCursor text(path, bytes);
    if (text.word_on_line() != "ply" || !text.line_done())
        text.fail("this is not a PLY file: it does not start with the line 'ply'");
    text.skip_line();

    Header header;
    bool has_format = false;
    for (;;) {
        if (text.bytes_left() == 0) text.fail("the header has no 'end_header' line");
        const std::string_view keyword = text.word_on_line();
        if (keyword == "end_header") {
            text.skip_line();
            break;
        }
        if (keyword == "format") {
            const std::string_view format = text.word_on_line();
            if (format == "ascii")
                header.format = Format::Ascii;
            else if (format == "binary_little_endian")
                header.format = Format::BinaryLittleEndian;
            else if (format == "binary_big_endian")
                header.format = Format::BinaryBigEndian;
            else
                text.fail("unknown PLY format " + quoted(format));
            has_format = true;
        } else if (keyword == "element") {
            Element element;
            element.name = std::string(text.word_on_line());
            element.count = text.to_count(text.word_on_line(), "count of '" + element.name + "'");
            header.elements.push_back(element);
        } else if (keyword == "property") {
            if (header.elements.empty()) text.fail("a property comes before any element");
            header.elements.back().properties.push_back(read_property(text));
        } else if (!keyword.empty() && keyword != "comment" && keyword != "obj_info") {
            text.fail("unknown header keyword " + quoted(keyword));
        }
        text.skip_line();
    }
    if (!has_format) text.fail("the header has no 'format' line");
    assign_roles(text, header.elements);
    header.body_offset = text.offset();
    header.body_line = text.line();
    return header;
}

// Every record takes at least its scalars' bytes and its lists' length fields (binary), or a word
// and a separator per property (ascii), so the declared counts are checked against the body size
// before anything is allocated for them.
void check_counts_fit(const std::string& path, const Header& header, uint64_t body_bytes) {
    const bool ascii = header.format == Format::Ascii;
    uint64_t left = ascii ? body_bytes + 1 : body_bytes;  // the last ascii word needs no separator
    for (const Element& element : header.elements) {
        uint64_t record_bytes = 0;
        for (const Property& property : element.properties)
            record_bytes +=
                ascii ? 2 : size_of(property.is_list ? property.length : property.value);
        require_room(path, element.count, record_bytes, left, "'" + element.name + "' records");
        left -= element.count * record_bytes;
    }
}

// ---------------------------------------------------------------------------------------------
// Body
// ---------------------------------------------------------------------------------------------

// One value of any PLY scalar type, as Value (double for coordinates; int64_t for list lengths and
// indices, which the header has already checked are of integer types).
template <typename Value>
Value binary_scalar(Scalar type, const char* bytes, bool big_endian) {
    switch (type) {
        case Scalar::Int8:
            return Value(load_scalar<int8_t>(bytes, big_endian));
        case Scalar::UInt8:
            return Value(load_scalar<uint8_t>(bytes, big_endian));
        case Scalar::Int16:
            return Value(load_scalar<int16_t>(bytes, big_endian));
        case Scalar::UInt16:
            return Value(load_scalar<uint16_t>(bytes, big_endian));
        case Scalar::Int32:
            return Value(load_scalar<int32_t>(bytes, big_endian));
        case Scalar::UInt32:
            return Value(load_scalar<uint32_t>(bytes, big_endian));
        case Scalar::Float32:
            return Value(load_scalar<float>(bytes, big_endian));
        case Scalar::Float64:
            return Value(load_scalar<double>(bytes, big_endian));
    }
    return 0;
}

std::string record_name(const Element& element, uint64_t record) {
    return "'" + element.name + "' record " + std::to_string(record) + " (of " +
           std::to_string(element.count) + ")";
}

// A binary element whose properties are all scalars: every record has the same size, so the
// records can be read where they lie, on all cores (a scan's vertices, most of a binary file).
// Returns the offset past the element; fails naming the first record the file cannot hold.
const char* read_fixed_records(const std::string& path, const Element& element, bool big_endian,
                               const char* at, const char* end, Polygons& out) {
    uint64_t record_size = 0;
    struct Coordinate {
        uint64_t offset;
        Scalar type;
        int axis;
    };
    std::vector<Coordinate> coordinates;
    for (const Property& property : element.properties) {
        if (property.role != Role::Skip)
            coordinates.push_back({record_size, property.value, int(property.role) - int(Role::X)});
        record_size += size_of(property.value);
    }
    const uint64_t fit = uint64_t(end - at) / record_size;
    if (element.count > fit) fail(path, "the file ends inside " + record_name(element, fit));
    if (element.name == "vertex") {
        const size_t first = out.positions.size();
        out.positions.resize(first + size_t(element.count), Position{0, 0, 0});
        tbb::parallel_for(tbb::blocked_range<uint64_t>(0, element.count, 4096),
                          [&](const tbb::blocked_range<uint64_t>& records) {
                              for (uint64_t r = records.begin(); r < records.end(); ++r) {
                                  const char* const record = at + r * record_size;
                                  Position& position = out.positions[first + size_t(r)];
                                  for (const Coordinate& c : coordinates)
                                      position[c.axis] = binary_scalar<double>(
                                          c.type, record + c.offset, big_endian);
                              }
                          });
    }
    return at + element.count * record_size;
}

void read_binary_body(const std::string& path, const Header& header, std::string_view bytes,
                      Polygons& out, ParseProgress& progress) {
    const bool big_endian = header.format == Format::BinaryBigEndian;
    const char* at = bytes.data() + header.body_offset;
    const char* const end = bytes.data() + bytes.size();
    for (const Element& element : header.elements) {
        if (element.properties.empty()) continue;  // its records take no bytes
        if (std::none_of(element.properties.begin(), element.properties.end(),
                         [](const Property& property) { return property.is_list; })) {
            at = read_fixed_records(path, element, big_endian, at, end, out);
            progress.at(uint64_t(at - bytes.data()));
            continue;
        }
        // Records with lists (faces), one after the other: each one's size is known only once
        // its lists' lengths are read.
        const bool is_vertex = element.name == "vertex";
        for (uint64_t record = 0; record < element.count; ++record) {
            const auto need = [&](uint64_t count, uint64_t size) {
                if (count > uint64_t(end - at) / size)
                    fail(path, "the file ends inside " + record_name(element, record));
            };
            Position position{0, 0, 0};
            for (const Property& property : element.properties) {
                if (!property.is_list) {
                    const uint64_t size = size_of(property.value);
                    need(1, size);
                    if (property.role != Role::Skip)
                        position[int(property.role) - int(Role::X)] =
                            binary_scalar<double>(property.value, at, big_endian);
                    at += size;
                    continue;
                }
                need(1, size_of(property.length));
                const int64_t length = binary_scalar<int64_t>(property.length, at, big_endian);
                at += size_of(property.length);
                if (length < 0)
                    fail(path, record_name(element, record) + " has a negative list length");
                const uint64_t entry_size = size_of(property.value);
                need(uint64_t(length), entry_size);
                if (property.role == Role::Corners) {
                    if (uint64_t(length) > std::numeric_limits<uint32_t>::max())
                        fail(path, record_name(element, record) + " has too many corners");
                    for (int64_t k = 0; k < length; ++k)
                        out.corners.push_back(binary_scalar<int64_t>(
                            property.value, at + k * entry_size, big_endian));
                    out.corner_counts.push_back(uint32_t(length));
                }
                at += uint64_t(length) * entry_size;
            }
            if (is_vertex) out.positions.push_back(position);
            progress.at(uint64_t(at - bytes.data()));
        }
    }
}

// One ascii record, on the line the cursor is at: its values in the header's order, the vertex
// element's coordinates into `position` and the face list's corners into out. A line with fewer
// or more values than the header declares is an error, not a shifted read (as the format's
// reference implementation reads it).
void read_ascii_record(TextCursor& text, const Element& element, uint64_t record,
                       Position& position, Polygons& out) {
    const auto next_word = [&]() {
        const std::string_view word = text.word_on_line();
        if (word.empty())
            text.fail(record_name(element, record) + " has fewer values than the header declares");
        return word;
    };
    // A coordinate, read in one pass where it is a plain number, else strictly.
    const auto coordinate = [&](const Property& property) {
        const bool floating = is_floating(property.value);
        double quick;
        int64_t quick_whole;
        if (floating ? text.quick_double(&quick) : text.quick_integer(&quick_whole))
            return floating ? quick : double(quick_whole);
        const std::string_view word = next_word();
        return floating ? text.to_double(word, property.described)
                        : double(text.to_integer(word, property.described));
    };
    for (const Property& property : element.properties) {
        if (!property.is_list) {
            if (property.role == Role::Skip)
                next_word();
            else
                position[int(property.role) - int(Role::X)] = coordinate(property);
            continue;
        }
        uint64_t length;
        if (!text.quick_count(&length)) length = text.to_count(next_word(), "list length");
        if (property.role == Role::Corners && length > std::numeric_limits<uint32_t>::max())
            text.fail(record_name(element, record) + " has too many corners");
        for (uint64_t k = 0; k < length; ++k) {
            if (property.role != Role::Corners) {
                next_word();
                continue;
            }
            int64_t index;
            if (!text.quick_integer(&index)) index = text.to_integer(next_word(), "vertex index");
            out.corners.push_back(index);
        }
        if (property.role == Role::Corners) out.corner_counts.push_back(uint32_t(length));
    }
    if (!text.line_done())
        text.fail(record_name(element, record) + " has more values than the header declares");
}

// A large ascii body in parts on all cores (read_records_in_parts): the elements that take
// lines (those with properties) one after the other, vertices into their places. False, with
// out as it was, where that fails.
bool read_ascii_body_in_parts(const std::string& path, const Header& header, std::string_view bytes,
                              const ParseReport& report, Polygons& out) {
    std::vector<uint64_t> first_record;  // of each element that takes lines
    std::vector<const Element*> elements;
    const Element* vertex_element = nullptr;
    uint64_t records = 0, vertex_first = 0;
    for (const Element& element : header.elements) {
        if (element.properties.empty()) continue;
        if (element.name == "vertex") {
            vertex_element = &element;
            vertex_first = records;
        }
        first_record.push_back(records);
        elements.push_back(&element);
        records += element.count;
    }
    out.positions.resize(vertex_element ? vertex_element->count : 0);
    const bool read = read_records_in_parts(
        path, bytes, header.body_offset, 0, records, report,
        [&](TextCursor& text, uint64_t r, Polygons& faces) {
            const size_t e = size_t(std::upper_bound(first_record.begin(), first_record.end(), r) -
                                    first_record.begin()) -
                             1;
            Position position{0, 0, 0};
            read_ascii_record(text, *elements[e], r - first_record[e], position, faces);
            if (elements[e] == vertex_element) out.positions[r - vertex_first] = position;
        },
        out);
    if (!read) out.positions.clear();
    return read;
}

// The ascii body in one pass: record after record, element after element.
void read_ascii_body(const std::string& path, const Header& header, std::string_view bytes,
                     Polygons& out, ParseProgress& progress) {
    TextCursor text(path, bytes.substr(header.body_offset), 0, header.body_line);
    for (const Element& element : header.elements) {
        if (element.properties.empty()) continue;
        for (uint64_t record = 0; record < element.count; ++record) {
            if (!text.next_nonblank_line())
                text.fail("the file ends before " + record_name(element, record));
            Position position{0, 0, 0};
            read_ascii_record(text, element, record, position, out);
            text.skip_line();
            if (element.name == "vertex") out.positions.push_back(position);
            progress.at(header.body_offset + text.offset());
        }
    }
}

}  // namespace

Polygons read_ply(const std::string& path, const ParseReport& report) {
    // Phase 1: the header, and the declared counts against the file size.
    const FileBytes file = read_whole_file(path);
    const std::string_view bytes = file.view();
    ParseProgress progress(report, bytes.size());
    const Header header = read_header(path, bytes);
    check_counts_fit(path, header, bytes.size() - header.body_offset);
    Polygons out;
    for (const Element& element : header.elements)
        if (element.name == "vertex") {
            if (element.count > std::numeric_limits<uint32_t>::max())
                fail(path, "more than 2^32 vertices, which 32-bit triangle indices cannot address");
            out.positions.reserve(element.count);
        } else if (element.name == "face" && header.format != Format::Ascii) {
            // Room for triangles, which most files hold, up to the corners the body can hold (the
            // header's count is checked only against a byte a record).
            out.corner_counts.reserve(element.count);
            uint64_t entry_size = 1;
            for (const Property& property : element.properties)
                if (property.role == Role::Corners) entry_size = size_of(property.value);
            out.corners.reserve(
                std::min(3 * element.count, (bytes.size() - header.body_offset) / entry_size));
        }

    // Phase 2: the body, in element order (faces may come before vertices); a large ascii body
    // in parts on all cores, or in one pass where that fails.
    if (header.format == Format::Ascii) {
        if (bytes.size() - header.body_offset <= kTextPartBytes ||
            !read_ascii_body_in_parts(path, header, bytes, report, out))
            read_ascii_body(path, header, bytes, out, progress);
    } else
        read_binary_body(path, header, bytes, out, progress);
    return out;
}

}  // namespace oclvox::mesh_reading
