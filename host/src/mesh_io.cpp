// Loading triangle meshes (OBJ through tinyobjloader; STL, PLY and OFF through assimp) into one
// welded Mesh, and checking meshes before anything voxelizes them.
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <tiny_obj_loader.h>

#include <algorithm>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <assimp/LogStream.hpp>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>
#include <unordered_map>

#include "oclvox/oclvox.hpp"

namespace oclvox {

namespace {

using Position = std::array<double, 3>;
using Triangle = std::array<uint32_t, 3>;

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
    throw InputError("mesh file '" + path + "': " + problem);
}

std::string position_text(const Position& p) {
    std::ostringstream text;
    text.precision(9);
    text << "(" << p[0] << ", " << p[1] << ", " << p[2] << ")";
    return text.str();
}

// The extension after the last dot of the file name, lower-cased; empty if there is none.
std::string lowercase_extension(const std::string& path) {
    const std::string name = std::filesystem::path(path).filename().string();
    const size_t dot = name.rfind('.');
    if (dot == std::string::npos || dot == 0) return "";
    std::string extension = name.substr(dot + 1);
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return extension;
}

// Fails with a clear message for the problems every format shares (missing, a folder,
// unreadable, empty) before a parser sees the file and words them its own way.
void require_readable_nonempty(const std::string& path) {
    std::error_code error;
    const auto status = std::filesystem::status(path, error);
    if (!std::filesystem::exists(status)) fail(path, "the file does not exist");
    if (std::filesystem::is_directory(status)) fail(path, "this is a folder, not a mesh file");
    std::ifstream file(path, std::ios::binary);
    if (!file) fail(path, "the file cannot be opened for reading");
    if (file.peek() == std::ifstream::traits_type::eof()) fail(path, "the file is empty");
}

std::string read_whole_file(const std::string& path) {
    require_readable_nonempty(path);
    std::ifstream file(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << file.rdbuf();
    if (!file) fail(path, "reading the file failed");
    return bytes.str();
}

void append_triangle(const std::string& path, Mesh& mesh, size_t a, size_t b, size_t c) {
    if (std::max({a, b, c}) > std::numeric_limits<uint32_t>::max())
        fail(path, "more than 2^32 vertices, which 32-bit triangle indices cannot address");
    mesh.triangles.push_back({uint32_t(a), uint32_t(b), uint32_t(c)});
}

// ---------------------------------------------------------------------------------------------
// Polygons
// ---------------------------------------------------------------------------------------------

// Splits polygons into triangles that cover exactly the polygon, by ear clipping in the
// coordinate plane that the polygon faces most. A fan would be simpler, but in a concave polygon
// its triangles leave the polygon and overlap, which a voxelizer turns into voxels that are not
// part of the surface. Convex polygons get the fan from their first corner, the usual convention.
class PolygonTriangulator {
  public:
    // Appends corners.size() - 2 triangles with the polygon's winding.
    void triangulate(const std::string& path, const std::vector<Position>& positions,
                     const std::vector<size_t>& corners, Mesh& out) {
        const size_t n = corners.size();
        if (n == 3) {
            append_triangle(path, out, corners[0], corners[1], corners[2]);
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
            append_triangle(path, out, corners[prev], corners[cur], corners[next]);
            ring_.erase(ring_.begin() + std::ptrdiff_t(at));
            misses = 0;
        }
        append_triangle(path, out, corners[ring_[0]], corners[ring_[1]], corners[ring_[2]]);
    }

  private:
    // 2D coordinates of the corners in the plane that the Newell normal points most along, with
    // a sign that makes the polygon wind counter-clockwise there.
    void project(const std::vector<Position>& positions, const std::vector<size_t>& corners) {
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

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

// Materials do not matter to a voxelizer, and a missing .mtl (common in the wild) must not fail
// the load, so .mtl files are never read.
struct IgnoreMaterials : tinyobj::MaterialReader {
    bool operator()(const std::string&, std::vector<tinyobj::material_t>*,
                    std::map<std::string, int>*, std::string*, std::string*) override {
        return true;
    }
};

bool is_blank(char c) {
    return c == ' ' || c == '\t';
}

// Where a strict parser takes no leading '+', which OBJ writers may emit.
const char* skip_plus(const char* first, const char* last) {
    return (*first == '+' && last - first > 1) ? first + 1 : first;
}

Position read_vertex_line(const std::string& path, const std::string& where, const char* c,
                          const char* line_end) {
    Position p;
    for (double& coordinate : p) {
        while (c < line_end && is_blank(*c)) ++c;
        const char* token = c;
        while (c < line_end && !is_blank(*c)) ++c;
        if (token == c) fail(path, where + "a vertex has fewer than 3 coordinates");
        const auto parsed = std::from_chars(skip_plus(token, c), c, coordinate);
        const std::string shown(token, c);
        if (parsed.ec == std::errc::result_out_of_range)
            fail(path, where + "vertex coordinate '" + shown + "' is out of range");
        if (parsed.ec != std::errc() || parsed.ptr != c)
            fail(path, where + "vertex coordinate '" + shown + "' is not a number");
    }
    return p;
}

// Every index of an `f` line (v, v/vt, v//vn, v/vt/vn) must be an integer that fits an int:
// tinyobjloader reads them with atoi, which turns 99999999999999999999 into -1, a valid
// relative index.
void check_face_line(const std::string& path, const std::string& where, const char* c,
                     const char* line_end) {
    while (c < line_end) {
        const char* part = c;
        while (c < line_end && !is_blank(*c) && *c != '/') ++c;
        if (c > part) {
            int index = 0;
            const auto parsed = std::from_chars(skip_plus(part, c), c, index);
            if (parsed.ec != std::errc() || parsed.ptr != c)
                fail(path, where + "face index '" + std::string(part, c) +
                               "' is not an index that fits in 32 bits");
        }
        if (c < line_end) ++c;
    }
}

// The x, y, z of every `v` line, in file order, read strictly: tinyobjloader's number parser
// turns text it cannot read ("nan", "1.#QNAN", "1,5") into 0 without a word, which would
// silently move vertices to the origin. Face indices are checked here too. Lines are
// recognised the way tinyobjloader does, so the vertex counts agree.
std::vector<Position> read_obj_strictly(const std::string& path, const std::string& text) {
    std::vector<Position> positions;
    const char* at = text.data();
    const char* const end = at + text.size();
    for (size_t line = 1; at < end; ++line) {
        const char* line_end = at;
        while (line_end < end && *line_end != '\n' && *line_end != '\r') ++line_end;

        const char* c = at;
        while (c < line_end && is_blank(*c)) ++c;
        if (line_end - c >= 2 && (c[0] == 'v' || c[0] == 'f') && is_blank(c[1])) {
            const std::string where = "line " + std::to_string(line) + ": ";
            if (c[0] == 'v')
                positions.push_back(read_vertex_line(path, where, c + 2, line_end));
            else
                check_face_line(path, where, c + 2, line_end);
        }

        // "\r\n" ends one line; a lone "\r" or "\n" ends one too.
        at = line_end;
        if (at < end && *at++ == '\r' && at < end && *at == '\n') ++at;
    }
    return positions;
}

constexpr const char* kTooManyCorners =
    "a face has more than 255 corners, which tinyobjloader cannot represent";

Mesh read_obj(const std::string& path) {
    // Phase 1: the file's structure (faces, groups, relative indices) through tinyobjloader,
    // without its triangulation: it splits every quad along the shorter diagonal, which is wrong
    // for concave quads.
    const std::string text = read_whole_file(path);
    tinyobj::attrib_t attrib;
    std::vector<tinyobj::shape_t> shapes;
    std::vector<tinyobj::material_t> materials;
    std::string warnings, errors;
    std::istringstream stream(text);
    IgnoreMaterials no_materials;
    if (!tinyobj::LoadObj(&attrib, &shapes, &materials, &warnings, &errors, &stream, &no_materials,
                          /*triangulate=*/false, /*default_vcols_fallback=*/false)) {
        errors.erase(errors.find_last_not_of(" \n") + 1);
        fail(path, errors.empty() ? "tinyobjloader could not parse it" : errors);
    }

    // Phase 2: the coordinates, read strictly, and the face indices checked.
    Mesh mesh;
    mesh.positions = read_obj_strictly(path, text);
    if (mesh.positions.size() * 3 != attrib.vertices.size())
        fail(path, "its vertex lines could not be read consistently");

    // Phase 3: every face of every group, triangulated into one mesh.
    PolygonTriangulator triangulator;
    std::vector<size_t> corners;
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
            corners.clear();
            for (size_t k = first; k < first + corner_count; ++k) {
                const int vertex = indices[k].vertex_index;
                if (vertex < 0)
                    fail(path, "face " + std::to_string(face_number) +
                                   " has a relative vertex index that points before the first "
                                   "vertex");
                if (size_t(vertex) >= mesh.positions.size())
                    fail(path, "face " + std::to_string(face_number) + " refers to vertex " +
                                   std::to_string(int64_t(vertex) + 1) +
                                   ", but the file has only " +
                                   std::to_string(mesh.positions.size()) + " vertices");
                corners.push_back(size_t(vertex));
            }
            triangulator.triangulate(path, mesh.positions, corners, mesh);
            first += corner_count;
        }
        if (first != indices.size()) fail(path, kTooManyCorners);
    }
    return mesh;
}

// ---------------------------------------------------------------------------------------------
// STL, PLY, OFF
// ---------------------------------------------------------------------------------------------

// Assimp reports some problems only through its logger and carries on: its OFF reader clamps
// out-of-range indices and drops faces with more than 9 corners, and fills vertices missing from
// a short file with zeros. Any error logged while a file loads therefore fails the load. The
// logger is global to the process, so loads through assimp take turns.
class AssimpErrorLog : public Assimp::LogStream {
  public:
    AssimpErrorLog() : turn_(loader_mutex()) {
        owns_logger_ = Assimp::DefaultLogger::isNullLogger();
        if (owns_logger_)
            Assimp::DefaultLogger::create("", Assimp::Logger::NORMAL, /*defStreams=*/0);
        Assimp::DefaultLogger::get()->attachStream(this, Assimp::Logger::Err);
    }
    ~AssimpErrorLog() override {
        Assimp::DefaultLogger::get()->detachStream(this, Assimp::Logger::Err);
        if (owns_logger_) Assimp::DefaultLogger::kill();
    }
    AssimpErrorLog(const AssimpErrorLog&) = delete;
    AssimpErrorLog& operator=(const AssimpErrorLog&) = delete;

    // Messages look like "Error, T0: OFF: Vertex index is out of range\n"; keep the part after
    // the severity and thread tag.
    void write(const char* message) override {
        if (!first_error_.empty()) return;
        std::string text(message);
        const size_t tag_end = text.find(": ");
        if (text.rfind("Error", 0) == 0 && tag_end != std::string::npos) text.erase(0, tag_end + 2);
        text.erase(text.find_last_not_of(" \n") + 1);
        first_error_ = text;
    }
    const std::string& first_error() const { return first_error_; }

  private:
    static std::mutex& loader_mutex() {
        static std::mutex mutex;
        return mutex;
    }
    std::lock_guard<std::mutex> turn_;
    bool owns_logger_ = false;
    std::string first_error_;
};

Position transformed(const aiMatrix4x4& m, const aiVector3D& p) {
    const double x = p.x, y = p.y, z = p.z;
    return {double(m.a1) * x + double(m.a2) * y + double(m.a3) * z + double(m.a4),
            double(m.b1) * x + double(m.b2) * y + double(m.b3) * z + double(m.b4),
            double(m.c1) * x + double(m.c2) * y + double(m.c3) * z + double(m.c4)};
}

// Appends the triangles of a node and its children, in scene coordinates. A mesh that several
// nodes use is placed once per node. Points and lines are not surfaces and are skipped.
void append_node(const std::string& path, const aiScene& scene, const aiNode& node,
                 const aiMatrix4x4& parent_transform, Mesh& out) {
    const aiMatrix4x4 transform = parent_transform * node.mTransformation;
    for (unsigned n = 0; n < node.mNumMeshes; ++n) {
        const aiMesh& mesh = *scene.mMeshes[node.mMeshes[n]];
        const size_t base = out.positions.size();
        // Copied exactly when there is nothing to transform: 0 * NaN would smear one bad
        // coordinate over all three and hide which one it was.
        const bool identity = transform == aiMatrix4x4();
        for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
            const aiVector3D& p = mesh.mVertices[v];
            out.positions.push_back(identity ? Position{p.x, p.y, p.z} : transformed(transform, p));
        }
        for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
            const aiFace& face = mesh.mFaces[f];
            if (face.mNumIndices != 3) continue;
            append_triangle(path, out, base + face.mIndices[0], base + face.mIndices[1],
                            base + face.mIndices[2]);
        }
    }
    for (unsigned c = 0; c < node.mNumChildren; ++c)
        append_node(path, scene, *node.mChildren[c], transform, out);
}

// Assimp allocates whatever a header declares before it reads the data: a 40-byte PLY or OFF
// that declares 400 million vertices costs it gigabytes and minutes. So declared counts that
// the rest of the file cannot hold are rejected first. The bounds are loose on purpose (every
// value takes at least one byte and a separator or a type size), so no honest file fails them.

bool parse_count(const std::string& word, uint64_t& count) {
    const auto parsed = std::from_chars(word.data(), word.data() + word.size(), count);
    return parsed.ec == std::errc() && parsed.ptr == word.data() + word.size();
}

// Bytes of a PLY scalar type; 0 for a name PLY does not define.
uint64_t ply_type_size(const std::string& type) {
    static const std::map<std::string, uint64_t> sizes = {
        {"char", 1},   {"int8", 1},    {"uchar", 1},  {"uint8", 1},  {"short", 2}, {"int16", 2},
        {"ushort", 2}, {"uint16", 2},  {"int", 4},    {"int32", 4},  {"uint", 4},  {"uint32", 4},
        {"float", 4},  {"float32", 4}, {"double", 8}, {"float64", 8}};
    const auto size = sizes.find(type);
    return size == sizes.end() ? 0 : size->second;
}

// The PLY body is walked record by record, because the length of every list is read from the
// body and assimp reserves memory for it: one lying length of 2^31 costs 16 GB.
void check_ply_sizes(const std::string& path, const std::string& bytes) {
    struct Property {
        uint64_t length_size = 0;  // bytes of a list's length; 0 for a single value
        bool length_signed = false;
        uint64_t value_size = 0;
    };
    struct Element {
        std::string name;
        uint64_t count = 0;
        std::vector<Property> properties;
    };

    // Phase 1: the header.
    std::vector<Element> elements;
    std::istringstream lines(bytes.substr(0, 64 * 1024));
    std::string line, format;
    uint64_t header_size = 0;
    bool header_complete = false;
    while (!header_complete && std::getline(lines, line)) {
        header_size += line.size() + 1;
        std::istringstream words(line);
        std::string keyword, type, value_type, count;
        words >> keyword;
        if (keyword == "format") words >> format;
        if (keyword == "element") {
            Element element;
            words >> element.name >> count;
            if (!parse_count(count, element.count)) return;  // assimp words this one
            elements.push_back(element);
        }
        if (keyword == "property" && !elements.empty()) {
            Property property;
            words >> type;
            if (type == "list") {
                words >> type >> value_type;
                property.length_size = ply_type_size(type);
                property.length_signed = type[0] != 'u';
                property.value_size = ply_type_size(value_type);
                if (property.length_size == 0) return;
            } else {
                property.value_size = ply_type_size(type);
            }
            if (property.value_size == 0) return;
            elements.back().properties.push_back(property);
        }
        header_complete = keyword == "end_header";
    }
    if (!header_complete) return;

    // Phase 2: walk the body. ASCII values are words of at least one character and a separator;
    // binary values take their type's size. Every record and every list must lie inside the file.
    const bool ascii = format == "ascii", big_endian = format == "binary_big_endian";
    uint64_t at = std::min<uint64_t>(header_size, bytes.size());
    const auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
    const auto next_word = [&]() {
        while (at < bytes.size() && is_space(bytes[at])) ++at;
        const uint64_t first = at;
        while (at < bytes.size() && !is_space(bytes[at])) ++at;
        return bytes.substr(first, at - first);
    };
    const auto skip_values = [&](uint64_t count, uint64_t size) {
        const uint64_t left = bytes.size() - at;
        if (count > (ascii ? (left + 1) / 2 : left / size)) return false;
        if (!ascii) at += count * size;
        for (uint64_t k = 0; ascii && k < count; ++k)
            if (next_word().empty()) return false;
        return true;
    };
    const auto read_length = [&](const Property& property, uint64_t& length) {
        if (ascii) return parse_count(next_word(), length);  // a negative length fails here
        if (property.length_size > bytes.size() - at) return false;
        length = 0;
        for (uint64_t b = 0; b < property.length_size; ++b)
            length = (length << 8) |
                     uint8_t(bytes[at + (big_endian ? b : property.length_size - 1 - b)]);
        at += property.length_size;
        return !(property.length_signed && length >> (8 * property.length_size - 1) != 0);
    };
    for (const Element& element : elements)
        for (uint64_t record = 0; record < element.count; ++record) {
            const std::string where = "'" + element.name + "' record " + std::to_string(record);
            const std::string cut_short = "the file ends inside " + where + " of the " +
                                          std::to_string(element.count) +
                                          " that the header declares";
            for (const Property& property : element.properties) {
                uint64_t values = 1;
                if (property.length_size > 0 && !read_length(property, values))
                    fail(path,
                         at >= bytes.size() ? cut_short : where + " has no valid list length");
                if (!skip_values(values, property.value_size)) fail(path, cut_short);
            }
        }
}

void check_off_counts(const std::string& path, const std::string& bytes) {
    const uint64_t file_size = bytes.size();
    // The header: an optional keyword ending in "OFF" ("COFF", "nOFF", ...; with 'n' a dimension
    // follows), then the vertex and face counts; '#' starts a comment.
    std::vector<std::string> words;
    std::istringstream lines(bytes.substr(0, 64 * 1024));
    std::string line;
    while (words.size() < 4 && std::getline(lines, line)) {
        std::istringstream line_words(line.substr(0, line.find('#')));
        std::string word;
        while (line_words >> word) words.push_back(word);
    }
    size_t first_count = 0;
    if (!words.empty() && words[0].size() >= 3 &&
        words[0].compare(words[0].size() - 3, 3, "OFF") == 0)
        first_count = words[0].find('n') < words[0].size() - 3 ? 2 : 1;
    uint64_t vertices = 0, faces = 0;
    if (words.size() < first_count + 2 || !parse_count(words[first_count], vertices) ||
        !parse_count(words[first_count + 1], faces))
        return;  // assimp words a malformed header
    // Each vertex and each face takes at least a number and a separator.
    if (vertices > file_size / 2 || faces > file_size / 2 || vertices + faces > file_size / 2)
        fail(path, "the header declares " + std::to_string(vertices) + " vertices and " +
                       std::to_string(faces) + " faces, more than a file of " +
                       std::to_string(file_size) + " bytes can hold");
}

Mesh read_with_assimp(const std::string& path, const std::string& extension) {
    // Phase 1: the sizes that assimp would trust.
    require_readable_nonempty(path);
    if (extension == "ply") check_ply_sizes(path, read_whole_file(path));
    if (extension == "off") check_off_counts(path, read_whole_file(path));

    // Phase 2: import. Validation runs first and rejects out-of-range indices before triangulation
    // uses them. Identical vertices are joined later, for all formats at once; degenerate triangles
    // are kept, since they are real geometry to a voxelizer.
    AssimpErrorLog errors;
    Assimp::Importer importer;
    const aiScene* scene =
        importer.ReadFile(path, aiProcess_ValidateDataStructure | aiProcess_Triangulate);
    if (!scene)
        fail(path, errors.first_error().empty() ? importer.GetErrorString() : errors.first_error());
    if (!errors.first_error().empty()) fail(path, errors.first_error());
    if (!scene->mRootNode) fail(path, "the file holds no scene");

    // Phase 3: all meshes of the scene graph, in scene coordinates.
    Mesh mesh;
    append_node(path, *scene, *scene->mRootNode, aiMatrix4x4(), mesh);
    return mesh;
}

// ---------------------------------------------------------------------------------------------
// Welding
// ---------------------------------------------------------------------------------------------

struct PositionKey {
    std::array<uint64_t, 3> bits;
    bool operator==(const PositionKey& other) const { return bits == other.bits; }
};

struct PositionKeyHash {
    size_t operator()(const PositionKey& key) const {
        uint64_t h = 0x9e3779b97f4a7c15ull;
        for (uint64_t b : key.bits) {
            h ^= b + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
            h *= 0xff51afd7ed558ccdull;
        }
        return size_t(h ^ (h >> 33));
    }
};

PositionKey key_of(const Position& p) {
    PositionKey key;
    for (int k = 0; k < 3; ++k) {
        const double value = p[k] + 0.0;  // -0.0 and 0.0 are the same place
        std::memcpy(&key.bits[k], &value, sizeof value);
    }
    return key;
}

// Merges vertices at equal coordinates and drops those no triangle uses. STL stores three
// corners per facet and assimp keeps the solids of one file in separate meshes, so this is what
// gives them a shared topology. Positions are unchanged, so the geometry is too.
Mesh welded(const Mesh& raw) {
    Mesh mesh;
    std::unordered_map<PositionKey, uint32_t, PositionKeyHash> index_at;
    index_at.reserve(raw.positions.size());
    constexpr uint32_t kUnseen = std::numeric_limits<uint32_t>::max();
    std::vector<uint32_t> new_index(raw.positions.size(), kUnseen);
    mesh.triangles.reserve(raw.triangles.size());
    for (const Triangle& triangle : raw.triangles) {
        Triangle renumbered;
        for (int c = 0; c < 3; ++c) {
            uint32_t& index = new_index[triangle[c]];
            if (index == kUnseen) {
                const Position& p = raw.positions[triangle[c]];
                const auto inserted = index_at.emplace(key_of(p), uint32_t(mesh.positions.size()));
                if (inserted.second) mesh.positions.push_back(p);
                index = inserted.first->second;
            }
            renumbered[c] = index;
        }
        mesh.triangles.push_back(renumbered);
    }
    return mesh;
}

}  // namespace

void validate_mesh(const Mesh& mesh) {
    if (mesh.triangles.empty()) throw InputError("the mesh has no triangles");
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
        for (const uint32_t v : mesh.triangles[t]) {
            if (v >= mesh.positions.size())
                throw InputError("triangle " + std::to_string(t) + " refers to vertex " +
                                 std::to_string(v) + ", but the mesh has only " +
                                 std::to_string(mesh.positions.size()) + " vertices");
            const Position& p = mesh.positions[v];
            if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
                throw InputError("vertex " + std::to_string(v) + " " + position_text(p) +
                                 ", used by triangle " + std::to_string(t) +
                                 ", has a coordinate that is not a finite number");
        }
}

Mesh load_mesh(const std::string& path) {
    // Phase 1: read the file as it is, with its own vertex numbering, so that problems are
    // reported in the file's terms.
    const std::string extension = lowercase_extension(path);
    Mesh raw;
    if (extension == "obj")
        raw = read_obj(path);
    else if (extension == "stl" || extension == "ply" || extension == "off")
        raw = read_with_assimp(path, extension);
    else if (extension.empty())
        fail(path, "the file name has no extension; expected .obj, .stl, .ply or .off");
    else
        fail(path, "unknown extension '." + extension + "'; expected .obj, .stl, .ply or .off");

    // Phase 2: check, then weld.
    if (raw.triangles.empty()) fail(path, "the file contains no triangles");
    try {
        validate_mesh(raw);
    } catch (const InputError& error) {
        fail(path, error.what());
    }
    return welded(raw);
}

}  // namespace oclvox
