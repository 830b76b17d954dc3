// Output writers: every format is read back by a minimal reader written here from the format's
// specification (not from the writer), and must give back exactly the voxels that were written.
#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <locale>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "atomic_file.hpp"
#include "oclvox/field.hpp"
#include "oclvox/oclvox.hpp"
#include "openvdb_reference.hpp"
#include "test_support.hpp"
#include "writers.hpp"

namespace fs = std::filesystem;
using oclvox::Grid;
using oclvox::OutputError;
using oclvox::SparseVoxels;

namespace {

using Voxel = std::array<int64_t, 3>;
using VoxelSet = std::set<Voxel>;

// ---------------------------------------------------------------------------------------------
// Fixtures and helpers
// ---------------------------------------------------------------------------------------------

// A fresh empty folder per test, removed afterwards.
class WriterTest : public ::testing::Test {
  protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = fs::temp_directory_path() /
               ("oclvox_test_writers_" + std::to_string(getpid()) + "_" + info->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    std::string path(const std::string& name) const { return (dir_ / name).string(); }

    // Names in the folder, sorted: shows leftover temporary files.
    std::vector<std::string> entries() const {
        std::vector<std::string> names;
        for (const auto& entry : fs::directory_iterator(dir_))
            names.push_back(entry.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    }

    fs::path dir_;
};

std::string read_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot open " + path);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

SparseVoxels make_voxels(const Grid& grid, const VoxelSet& set, int brick_size = 4) {
    SparseVoxels voxels(grid, brick_size);
    for (const Voxel& v : set) voxels.set(v[0], v[1], v[2]);
    return voxels;
}

Grid make_grid(std::array<int64_t, 3> dims, std::array<double, 3> origin = {0, 0, 0},
               double voxel_size = 1.0) {
    Grid grid;
    grid.dims = dims;
    grid.origin = origin;
    grid.voxel_size = voxel_size;
    return grid;
}

// A non-cubic 5x3x7 grid (several 4^3 bricks) with all eight corners, a solid 2x2x3 block
// (internal faces) and a scattered pattern.
Grid odd_grid() {
    return make_grid({5, 3, 7}, {-1.5, 2.0, 0.25}, 0.5);
}
VoxelSet odd_pattern() {
    VoxelSet set;
    for (int64_t i : {0, 4})
        for (int64_t j : {0, 2})
            for (int64_t k : {0, 6}) set.insert({i, j, k});
    for (int64_t i = 0; i < 2; ++i)
        for (int64_t j = 0; j < 2; ++j)
            for (int64_t k = 2; k < 5; ++k) set.insert({i, j, k});
    for (int64_t i = 0; i < 5; ++i)
        for (int64_t j = 0; j < 3; ++j)
            for (int64_t k = 0; k < 7; ++k)
                if ((i * 7 + j * 3 + k * 5) % 4 == 0) set.insert({i, j, k});
    return set;
}

// Little-endian reads from a byte string, with bounds checks.
struct ByteReader {
    const std::string& bytes;
    size_t pos = 0;

    void need(size_t n) const {
        if (pos + n > bytes.size()) throw std::runtime_error("file ends early");
    }
    uint64_t uint(int n) {
        need(size_t(n));
        uint64_t value = 0;
        for (int b = 0; b < n; ++b) value |= uint64_t(uint8_t(bytes[pos + size_t(b)])) << (8 * b);
        pos += size_t(n);
        return value;
    }
    int32_t i32() { return int32_t(uint32_t(uint(4))); }
    double f64() {
        const uint64_t bits = uint(8);
        double value;
        std::memcpy(&value, &bits, 8);
        return value;
    }
    std::string text(size_t n) {
        need(n);
        std::string s = bytes.substr(pos, n);
        pos += n;
        return s;
    }
    std::string line() {
        const size_t end = bytes.find('\n', pos);
        if (end == std::string::npos) throw std::runtime_error("missing end of line");
        std::string s = bytes.substr(pos, end - pos);
        pos = end + 1;
        return s;
    }
};

// ---------------------------------------------------------------------------------------------
// binvox reader (patrickmin.com/binvox/binvox.html): header lines, then (value, count) pairs in
// the order index = x*wxh + z*width + y.
// ---------------------------------------------------------------------------------------------
struct Binvox {
    int64_t dim = 0;
    std::array<double, 3> translate{};
    double scale = 0;
    std::vector<std::pair<int, int>> runs;
    VoxelSet set;
};

Binvox read_binvox(const std::string& bytes) {
    ByteReader in{bytes};
    if (in.line() != "#binvox 1") throw std::runtime_error("bad binvox magic");
    Binvox file;
    for (std::string line = in.line(); line != "data"; line = in.line()) {
        std::istringstream fields(line);
        std::string key;
        fields >> key;
        if (key == "dim") {
            int64_t d, w, h;
            fields >> d >> w >> h;
            if (d != w || d != h) throw std::runtime_error("binvox dims are not cubic");
            file.dim = d;
        } else if (key == "translate") {
            fields >> file.translate[0] >> file.translate[1] >> file.translate[2];
        } else if (key == "scale") {
            fields >> file.scale;
        } else {
            throw std::runtime_error("unknown binvox header line: " + line);
        }
    }
    const int64_t d = file.dim, total = d * d * d;
    int64_t index = 0;
    while (in.pos < bytes.size()) {
        const int value = int(in.uint(1)), count = int(in.uint(1));
        if (value > 1 || count < 1) throw std::runtime_error("bad binvox run");
        file.runs.push_back({value, count});
        for (int c = 0; c < count; ++c, ++index) {
            if (index >= total) throw std::runtime_error("binvox runs exceed the grid");
            if (value) file.set.insert({index / (d * d), index % d, index / d % d});
        }
    }
    if (index != total) throw std::runtime_error("binvox runs do not cover the grid");
    return file;
}

// ---------------------------------------------------------------------------------------------
// NPY reader (NEP 1): magic, version, header length, Python dict, raw data.
// ---------------------------------------------------------------------------------------------
struct Npy {
    size_t data_offset = 0;
    std::array<int64_t, 3> shape{};
    VoxelSet set;
};

Npy read_npy(const std::string& bytes) {
    ByteReader in{bytes};
    if (in.text(6) != "\x93NUMPY") throw std::runtime_error("bad npy magic");
    if (in.uint(1) != 1 || in.uint(1) != 0) throw std::runtime_error("not npy version 1.0");
    const size_t header_length = size_t(in.uint(2));
    const std::string header = in.text(header_length);
    if (header.back() != '\n') throw std::runtime_error("npy header does not end in a newline");
    if (header.find("'descr': '|u1'") == std::string::npos ||
        header.find("'fortran_order': True") == std::string::npos)
        throw std::runtime_error("unexpected npy header " + header);
    Npy file;
    file.data_offset = in.pos;
    const std::string shape_key = "'shape': (";
    const size_t shape_at = header.find(shape_key);
    if (shape_at == std::string::npos) throw std::runtime_error("no shape in npy header " + header);
    std::istringstream shape(header.substr(shape_at + shape_key.size()));
    char comma1 = 0, comma2 = 0, close = 0;
    shape >> file.shape[0] >> comma1 >> file.shape[1] >> comma2 >> file.shape[2] >> close;
    if (!shape || comma1 != ',' || comma2 != ',' || close != ')')
        throw std::runtime_error("no 3-d shape in npy header " + header);
    const int64_t nx = file.shape[0], ny = file.shape[1], nz = file.shape[2];
    if (int64_t(bytes.size() - in.pos) != nx * ny * nz)
        throw std::runtime_error("npy data size does not match the shape");
    // Fortran order: the first index varies fastest.
    for (int64_t k = 0; k < nz; ++k)
        for (int64_t j = 0; j < ny; ++j)
            for (int64_t i = 0; i < nx; ++i) {
                const uint8_t value = uint8_t(bytes[in.pos + size_t(i + nx * j + nx * ny * k)]);
                if (value > 1) throw std::runtime_error("npy value is not 0 or 1");
                if (value) file.set.insert({i, j, k});
            }
    return file;
}

// ---------------------------------------------------------------------------------------------
// MagicaVoxel reader (ephtracy/voxel-model): chunks, models, and the scene graph's translations.
// A model's voxel v lands at the sum of the _t on its path minus floor(size / 2), plus v.
// ---------------------------------------------------------------------------------------------
struct VoxModel {
    std::array<int64_t, 3> size{};
    std::vector<std::array<uint8_t, 4>> voxels;  // x, y, z, colour index
};

struct Vox {
    std::vector<VoxModel> models;
    VoxelSet world;
    int32_t pack_models = -1;                     // PACK chunk's model count, -1 if absent
    std::set<int32_t> layers_used, layers_named;  // nTRN layer ids (not -1), LAYR ids
};

std::map<std::string, std::string> read_dict(ByteReader& in) {
    std::map<std::string, std::string> dict;
    for (int32_t n = in.i32(); n > 0; --n) {
        const std::string key = in.text(size_t(in.i32()));
        dict[key] = in.text(size_t(in.i32()));
    }
    return dict;
}

Vox read_vox(const std::string& bytes) {
    ByteReader in{bytes};
    if (in.text(4) != "VOX ") throw std::runtime_error("bad vox magic");
    const int32_t version = in.i32();
    if (version != 150 && version != 200) throw std::runtime_error("unexpected vox version");
    if (in.text(4) != "MAIN" || in.i32() != 0) throw std::runtime_error("bad MAIN chunk");
    if (size_t(in.i32()) != bytes.size() - in.pos) throw std::runtime_error("bad MAIN size");

    Vox file;
    struct Node {
        char kind;
        std::array<int64_t, 3> translation{};
        std::vector<int32_t> children;  // node ids, or the model id for a shape
    };
    std::map<int32_t, Node> nodes;
    while (in.pos < bytes.size()) {
        const std::string id = in.text(4);
        const size_t content = size_t(in.i32());
        if (in.i32() != 0) throw std::runtime_error("unexpected nested chunk in " + id);
        const size_t end = in.pos + content;
        if (id == "SIZE") {
            VoxModel model;
            for (auto& s : model.size) s = in.i32();
            file.models.push_back(model);
        } else if (id == "XYZI") {
            if (file.models.empty()) throw std::runtime_error("XYZI before SIZE");
            for (int32_t n = in.i32(); n > 0; --n) {
                std::array<uint8_t, 4> v;
                for (auto& b : v) b = uint8_t(in.uint(1));
                file.models.back().voxels.push_back(v);
            }
        } else if (id == "nTRN") {
            const int32_t node = in.i32();
            read_dict(in);
            Node transform{'T', {}, {}};
            transform.children.push_back(in.i32());
            if (in.i32() != -1) throw std::runtime_error("nTRN reserved id is not -1");
            if (const int32_t layer = in.i32(); layer != -1) file.layers_used.insert(layer);
            if (in.i32() != 1) throw std::runtime_error("nTRN must have one frame");
            const auto frame = read_dict(in);
            if (frame.count("_t")) {
                std::istringstream t(frame.at("_t"));
                t >> transform.translation[0] >> transform.translation[1] >>
                    transform.translation[2];
            }
            nodes[node] = transform;
        } else if (id == "PACK") {
            if (!file.models.empty()) throw std::runtime_error("PACK after a model");
            file.pack_models = in.i32();
        } else if (id == "LAYR") {
            file.layers_named.insert(in.i32());
        } else if (id == "nGRP") {
            const int32_t node = in.i32();
            read_dict(in);
            Node group{'G', {}, {}};
            for (int32_t n = in.i32(); n > 0; --n) group.children.push_back(in.i32());
            nodes[node] = group;
        } else if (id == "nSHP") {
            const int32_t node = in.i32();
            read_dict(in);
            if (in.i32() != 1) throw std::runtime_error("nSHP must have one model");
            Node shape{'S', {}, {}};
            shape.children.push_back(in.i32());
            read_dict(in);
            nodes[node] = shape;
        }
        if (in.pos > end) throw std::runtime_error(id + " content overruns its size");
        in.pos = end;
    }

    // Walk the scene graph from the root transform (node 0), adding translations.
    std::vector<int> placed(file.models.size(), 0);
    std::function<void(int32_t, std::array<int64_t, 3>)> walk = [&](int32_t id,
                                                                    std::array<int64_t, 3> t) {
        const Node& node = nodes.at(id);
        if (node.kind == 'T') {
            for (int a = 0; a < 3; ++a) t[size_t(a)] += node.translation[size_t(a)];
            walk(node.children.at(0), t);
        } else if (node.kind == 'G') {
            for (int32_t child : node.children) walk(child, t);
        } else {
            const VoxModel& model = file.models.at(size_t(node.children.at(0)));
            ++placed[size_t(node.children.at(0))];
            for (const auto& v : model.voxels) {
                if (v[3] != 1) throw std::runtime_error("voxel colour index is not 1");
                Voxel world;
                for (int a = 0; a < 3; ++a) {
                    if (v[size_t(a)] >= model.size[size_t(a)])
                        throw std::runtime_error("voxel outside its model");
                    world[size_t(a)] = t[size_t(a)] - model.size[size_t(a)] / 2 + v[size_t(a)];
                }
                if (!file.world.insert(world).second)
                    throw std::runtime_error("voxel placed twice");
            }
        }
    };
    walk(0, {0, 0, 0});
    if (std::count(placed.begin(), placed.end(), 1) != int64_t(placed.size()))
        throw std::runtime_error("a model is not placed exactly once");
    return file;
}

// ---------------------------------------------------------------------------------------------
// Mesh readers (OBJ text; PLY binary little-endian) and an exposed-face check by brute force.
// ---------------------------------------------------------------------------------------------
struct PolygonMesh {
    std::vector<std::array<double, 3>> positions;
    std::vector<std::vector<size_t>> faces;  // 0-based
};

PolygonMesh read_obj(const std::string& bytes) {
    PolygonMesh mesh;
    std::istringstream in(bytes);
    for (std::string line; std::getline(in, line);) {
        std::istringstream fields(line);
        std::string tag;
        fields >> tag;
        if (tag == "v") {
            std::array<double, 3> p;
            fields >> p[0] >> p[1] >> p[2];
            mesh.positions.push_back(p);
        } else if (tag == "f") {
            std::vector<size_t> face;
            for (long index; fields >> index;) {
                if (index < 1 || size_t(index) > mesh.positions.size())
                    throw std::runtime_error("OBJ face index out of range");
                face.push_back(size_t(index - 1));
            }
            mesh.faces.push_back(face);
        } else if (!tag.empty() && tag != "#") {
            throw std::runtime_error("unexpected OBJ line: " + line);
        }
    }
    return mesh;
}

PolygonMesh read_ply(const std::string& bytes) {
    ByteReader in{bytes};
    const std::vector<std::string> expected_header = {"ply",
                                                      "format binary_little_endian 1.0",
                                                      "element vertex #",
                                                      "property double x",
                                                      "property double y",
                                                      "property double z",
                                                      "element face #",
                                                      "property list uchar int vertex_indices",
                                                      "end_header"};
    size_t vertices = 0, faces = 0;
    size_t expected = 0;
    for (std::string line = in.line(); expected < expected_header.size(); line = in.line()) {
        if (line.rfind("comment", 0) == 0) continue;
        const std::string& want = expected_header[expected++];
        if (want.back() == '#') {
            const std::string prefix = want.substr(0, want.size() - 1);
            if (line.rfind(prefix, 0) != 0) throw std::runtime_error("bad PLY line " + line);
            (prefix == "element vertex " ? vertices : faces) =
                std::stoul(line.substr(prefix.size()));
        } else if (line != want) {
            throw std::runtime_error("bad PLY line " + line);
        }
        if (want == "end_header") break;
    }
    PolygonMesh mesh;
    for (size_t v = 0; v < vertices; ++v) mesh.positions.push_back({in.f64(), in.f64(), in.f64()});
    for (size_t f = 0; f < faces; ++f) {
        std::vector<size_t> face(in.uint(1));
        for (auto& index : face) {
            const int32_t i = in.i32();
            if (i < 0 || size_t(i) >= vertices) throw std::runtime_error("PLY index out of range");
            index = size_t(i);
        }
        mesh.faces.push_back(face);
    }
    if (in.pos != bytes.size()) throw std::runtime_error("trailing bytes after PLY data");
    return mesh;
}

// (i, j, k, direction), direction = 2*axis + (0 for +axis, 1 for -axis).
using Face = std::array<int64_t, 4>;

std::set<Face> exposed_faces_by_brute_force(const VoxelSet& set) {
    std::set<Face> faces;
    for (const Voxel& v : set)
        for (int64_t direction = 0; direction < 6; ++direction) {
            Voxel n = v;
            n[size_t(direction / 2)] += direction % 2 == 0 ? 1 : -1;
            if (!set.count(n)) faces.insert({v[0], v[1], v[2], direction});
        }
    return faces;
}

// Every polygon must be a unit lattice square, wound so its normal points from a set voxel to an
// empty one, and each exposed face must appear exactly once. Returns the faces found.
std::set<Face> check_exposed_face_mesh(const PolygonMesh& mesh, const Grid& grid,
                                       const VoxelSet& set) {
    // Vertices are shared: no position appears twice.
    std::set<std::array<double, 3>> unique(mesh.positions.begin(), mesh.positions.end());
    EXPECT_EQ(unique.size(), mesh.positions.size()) << "duplicate vertex positions";

    auto lattice = [&](const std::array<double, 3>& p) {
        Voxel l;
        for (int a = 0; a < 3; ++a) {
            const double x = (p[size_t(a)] - grid.origin[size_t(a)]) / grid.voxel_size;
            l[size_t(a)] = std::llround(x);
            if (std::abs(x - double(l[size_t(a)])) > 1e-9)
                throw std::runtime_error("vertex is not on the voxel lattice");
        }
        return l;
    };
    auto cross = [](const Voxel& a, const Voxel& b) {
        return Voxel{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]};
    };
    auto minus = [](const Voxel& a, const Voxel& b) {
        return Voxel{a[0] - b[0], a[1] - b[1], a[2] - b[2]};
    };

    std::set<Face> found;
    for (const auto& polygon : mesh.faces) {
        if (polygon.size() != 4) throw std::runtime_error("face is not a quad");
        std::array<Voxel, 4> c;
        for (int q = 0; q < 4; ++q) c[size_t(q)] = lattice(mesh.positions[polygon[size_t(q)]]);
        // Edges of length one, and both triangles (0,1,2), (0,2,3) with the same unit normal.
        for (int q = 0; q < 4; ++q) {
            const Voxel e = minus(c[size_t((q + 1) % 4)], c[size_t(q)]);
            if (std::abs(e[0]) + std::abs(e[1]) + std::abs(e[2]) != 1)
                throw std::runtime_error("quad edge is not one voxel long");
        }
        const Voxel normal = cross(minus(c[1], c[0]), minus(c[2], c[0]));
        if (normal != cross(minus(c[2], c[0]), minus(c[3], c[0])))
            throw std::runtime_error("quad is twisted");
        int axis = -1;
        for (int a = 0; a < 3; ++a)
            if (normal[size_t(a)] != 0) axis = a;
        if (axis < 0 || std::abs(normal[size_t(axis)]) != 1)
            throw std::runtime_error("quad normal is not axis aligned");
        const bool positive = normal[size_t(axis)] > 0;
        // The voxel behind the face: the corners' minimum, stepped back along a +axis normal.
        Voxel behind = c[0];
        for (const Voxel& corner : c)
            for (int a = 0; a < 3; ++a)
                behind[size_t(a)] = std::min(behind[size_t(a)], corner[size_t(a)]);
        if (positive) behind[size_t(axis)] -= 1;
        const Face face{behind[0], behind[1], behind[2], 2 * axis + (positive ? 0 : 1)};
        if (!found.insert(face).second) throw std::runtime_error("face emitted twice");
    }
    EXPECT_EQ(found, exposed_faces_by_brute_force(set));
    return found;
}

// ---------------------------------------------------------------------------------------------
// OpenVDB occupancy reader: OpenVDB's own C++ API, tiles expanded to their voxels
// ---------------------------------------------------------------------------------------------
struct VdbOccupancy {
    VoxelSet active;  // tiles expanded to their voxels
    uint64_t active_count = 0;
    bool all_true = true;
    openvdb::math::Transform::Ptr transform;
    openvdb::Vec3d origin;
    openvdb::Vec3i dims;
};

// The "occupancy" grid of a .vdb, read by OpenVDB.
openvdb::BoolGrid::Ptr read_occupancy_grid(const std::string& path) {
    openvdb::initialize();
    openvdb::io::File file(path);
    file.open();
    const openvdb::BoolGrid::Ptr grid =
        openvdb::gridPtrCast<openvdb::BoolGrid>(file.readGrid("occupancy"));
    file.close();
    if (!grid) throw std::runtime_error("occupancy is not a BoolGrid");
    return grid;
}

VdbOccupancy read_vdb_occupancy(const std::string& path, bool expand = true) {
    const openvdb::BoolGrid::Ptr grid = read_occupancy_grid(path);
    VdbOccupancy result;
    result.active_count = grid->activeVoxelCount();
    for (auto it = grid->cbeginValueOn(); it; ++it) {
        result.all_true = result.all_true && *it;
        if (!expand) continue;
        const openvdb::CoordBBox box = it.getBoundingBox();
        for (auto c = box.begin(); c; ++c) result.active.insert({(*c)[0], (*c)[1], (*c)[2]});
    }
    result.transform = grid->transformPtr();
    result.origin = grid->metaValue<openvdb::Vec3d>("oclvox_origin");
    result.dims = grid->metaValue<openvdb::Vec3i>("oclvox_dims");
    return result;
}

// ---------------------------------------------------------------------------------------------
// binvox
// ---------------------------------------------------------------------------------------------
TEST_F(WriterTest, BinvoxNonCubicGridIsPaddedToACubeWithTheSameVoxels) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.binvox"), make_voxels(odd_grid(), set));

    const Binvox file = read_binvox(read_bytes(path("out.binvox")));
    EXPECT_EQ(file.dim, 7);  // max(5, 3, 7)
    EXPECT_EQ(file.set, set);
    // Hand-worked: translate = origin, scale = dim * voxel_size = 7 * 0.5.
    EXPECT_EQ(file.translate, (std::array<double, 3>{-1.5, 2.0, 0.25}));
    EXPECT_EQ(file.scale, 3.5);
    EXPECT_EQ(entries(), std::vector<std::string>{"out.binvox"});
}

TEST_F(WriterTest, BinvoxRunsLongerThan255AreSplit) {
    // The whole x = 0 slab of a 20^3 grid is 400 consecutive voxels in binvox order (x slowest),
    // followed by 7600 empty ones: runs 255 + 145 set, then 29 * 255 + 205 empty.
    VoxelSet set;
    for (int64_t j = 0; j < 20; ++j)
        for (int64_t k = 0; k < 20; ++k) set.insert({0, j, k});
    oclvox::write_voxels(path("slab.binvox"), make_voxels(make_grid({20, 20, 20}), set, 8));

    const Binvox file = read_binvox(read_bytes(path("slab.binvox")));
    EXPECT_EQ(file.set, set);
    ASSERT_EQ(file.runs.size(), 2u + 30u);
    EXPECT_EQ(file.runs[0], std::make_pair(1, 255));
    EXPECT_EQ(file.runs[1], std::make_pair(1, 145));
    EXPECT_EQ(file.runs.back(), std::make_pair(0, 205));
}

TEST_F(WriterTest, BinvoxVoxelOrderIsYFastestThenZThenX) {
    // A single voxel at (x, y, z) = (1, 2, 3) in a 4^3 grid has binvox index 1*16 + 3*4 + 2 = 30.
    oclvox::write_voxels(path("one.binvox"), make_voxels(make_grid({4, 4, 4}), {{1, 2, 3}}));
    const Binvox file = read_binvox(read_bytes(path("one.binvox")));
    ASSERT_EQ(file.runs.size(), 3u);
    EXPECT_EQ(file.runs[0], std::make_pair(0, 30));
    EXPECT_EQ(file.runs[1], std::make_pair(1, 1));
    EXPECT_EQ(file.runs[2], std::make_pair(0, 64 - 31));
}

// ---------------------------------------------------------------------------------------------
// npy
// ---------------------------------------------------------------------------------------------
TEST_F(WriterTest, NpyIndexIJKIsVoxelXYZAndDataIs64ByteAligned) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.npy"), make_voxels(odd_grid(), set));

    const Npy file = read_npy(read_bytes(path("out.npy")));
    EXPECT_EQ(file.shape, (std::array<int64_t, 3>{5, 3, 7}));
    EXPECT_EQ(file.data_offset % 64, 0u);
    EXPECT_EQ(file.set, set);
    EXPECT_EQ(entries(), (std::vector<std::string>{"out.npy", "out.npy.json"}));
}

TEST_F(WriterTest, NpySidecarRecordsGridPlacement) {
    oclvox::write_voxels(path("out.npy"), make_voxels(odd_grid(), odd_pattern()));

    const auto sidecar = nlohmann::json::parse(read_bytes(path("out.npy.json")));
    EXPECT_EQ(sidecar.at("file"), "out.npy");
    EXPECT_EQ(sidecar.at("dims").get<std::vector<int64_t>>(), (std::vector<int64_t>{5, 3, 7}));
    EXPECT_EQ(sidecar.at("origin").get<std::vector<double>>(),
              (std::vector<double>{-1.5, 2.0, 0.25}));
    EXPECT_EQ(sidecar.at("voxel_size").get<double>(), 0.5);
    EXPECT_EQ(sidecar.at("voxels_set").get<uint64_t>(), odd_pattern().size());
    EXPECT_NE(sidecar.at("axis_order").get<std::string>().find("arr[i, j, k]"), std::string::npos);
    EXPECT_NE(sidecar.at("voxel_box").get<std::string>().find("closed box"), std::string::npos);
}

TEST_F(WriterTest, NpyIsRemovedWhenItsSidecarCannotBeWritten) {
    // A folder where the sidecar should go makes its rename fail.
    fs::create_directories(path("out.npy.json") + "/blocker");
    EXPECT_THROW(oclvox::write_voxels(path("out.npy"), make_voxels(odd_grid(), odd_pattern())),
                 OutputError);
    EXPECT_EQ(entries(), std::vector<std::string>{"out.npy.json"});
}

// ---------------------------------------------------------------------------------------------
// MagicaVoxel
// ---------------------------------------------------------------------------------------------
TEST_F(WriterTest, VoxSmallGridIsOneModelCentredByTranslation) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.vox"), make_voxels(odd_grid(), set));

    const Vox file = read_vox(read_bytes(path("out.vox")));
    ASSERT_EQ(file.models.size(), 1u);
    EXPECT_EQ(file.models[0].size, (std::array<int64_t, 3>{5, 3, 7}));
    EXPECT_EQ(file.world, set);
}

TEST_F(WriterTest, VoxLargeGridIsSplitInto256CubedModelsThatLineUp) {
    // 300x260x520 spans 2x2x3 tiles; these voxels touch six of them (hand-counted).
    const VoxelSet set = {{0, 0, 0},     {255, 255, 255}, {299, 259, 519}, {256, 0, 0},
                          {299, 0, 519}, {0, 259, 0},     {128, 130, 300}};
    oclvox::write_voxels(path("big.vox"), make_voxels(make_grid({300, 260, 520}), set, 64));

    const Vox file = read_vox(read_bytes(path("big.vox")));
    EXPECT_EQ(file.models.size(), 6u);
    std::set<std::array<int64_t, 3>> sizes;
    for (const VoxModel& model : file.models) {
        for (int64_t s : model.size) EXPECT_LE(s, 256);
        sizes.insert(model.size);
    }
    // The far corner tile is what is left of the grid: 300-256, 260-256, 520-512.
    EXPECT_TRUE(sizes.count({44, 4, 8}));
    EXPECT_EQ(file.world, set);
}

// ---------------------------------------------------------------------------------------------
// Cube meshes
// ---------------------------------------------------------------------------------------------
TEST_F(WriterTest, CubeOf8VoxelsGives24QuadsOn26Vertices) {
    // 2x2x2 voxels: 4 quads per cube side, and a 3x3x3 lattice minus its hidden centre point.
    VoxelSet set;
    for (int64_t i = 1; i < 3; ++i)
        for (int64_t j = 1; j < 3; ++j)
            for (int64_t k = 1; k < 3; ++k) set.insert({i, j, k});
    const SparseVoxels voxels = make_voxels(make_grid({4, 4, 4}), set);
    oclvox::write_voxels(path("cube.obj"), voxels);
    oclvox::write_voxels(path("cube.ply"), voxels);

    for (const PolygonMesh& mesh :
         {read_obj(read_bytes(path("cube.obj"))), read_ply(read_bytes(path("cube.ply")))}) {
        EXPECT_EQ(mesh.faces.size(), 24u);
        EXPECT_EQ(mesh.positions.size(), 26u);
        EXPECT_EQ(check_exposed_face_mesh(mesh, make_grid({4, 4, 4}), set).size(), 24u);
    }
}

TEST_F(WriterTest, ObjHasExactlyTheExposedFacesInWorldCoordinates) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.obj"), make_voxels(odd_grid(), set));
    check_exposed_face_mesh(read_obj(read_bytes(path("out.obj"))), odd_grid(), set);
}

TEST_F(WriterTest, PlyHasExactlyTheExposedFacesInWorldCoordinates) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.ply"), make_voxels(odd_grid(), set));
    check_exposed_face_mesh(read_ply(read_bytes(path("out.ply"))), odd_grid(), set);
}

TEST_F(WriterTest, MeshFileDoesNotDependOnBrickSize) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("a.obj"), make_voxels(odd_grid(), set, 4));
    oclvox::write_voxels(path("b.obj"), make_voxels(odd_grid(), set, 8));
    EXPECT_EQ(read_bytes(path("a.obj")), read_bytes(path("b.obj")));
}

// Rows of several words and a partial last word (bricks of 100 and 200 voxels), bricks
// narrower than a word and a grid edge inside a brick: each brick size's mesh has exactly the
// exposed faces, and all are the same file. And voxels of consecutive layers at consecutive x in
// the same row, whose corners must not carry from one layer to the next.
TEST_F(WriterTest, CubeMeshHasTheExposedFacesForEveryRowWidth) {
    const Grid grid = make_grid({150, 70, 9}, {0.5, -3, 1}, 0.25);
    VoxelSet set;
    std::mt19937 rng(5);
    for (int64_t k = 0; k < 9; ++k)
        for (int64_t j = 0; j < 70; ++j)
            for (int64_t i = 0; i < 150; ++i)
                if (rng() % 100 < (k < 5 ? 30u : 2u)) set.insert({i, j, k});
    std::string first;
    for (const int brick : {4, 12, 64, 100, 200}) {
        const SparseVoxels voxels = make_voxels(grid, set, brick);
        oclvox::write_voxels(path("stairs.obj"), voxels);
        oclvox::write_voxels(path("stairs.ply"), voxels);
        const std::string obj = read_bytes(path("stairs.obj"));
        check_exposed_face_mesh(read_obj(obj), grid, set);
        check_exposed_face_mesh(read_ply(read_bytes(path("stairs.ply"))), grid, set);
        if (first.empty()) first = obj;
        EXPECT_EQ(obj, first) << "brick size " << brick;
    }
    // A staircase, one voxel a layer, each at the x after the layer below's in the same row.
    const VoxelSet stairs = {{1, 2, 0}, {2, 2, 1}, {3, 2, 2}, {4, 2, 3}};
    oclvox::write_voxels(path("stairs.obj"), make_voxels(make_grid({8, 8, 4}), stairs));
    check_exposed_face_mesh(read_obj(read_bytes(path("stairs.obj"))), make_grid({8, 8, 4}), stairs);
}

// The layers are made a slab at a time, each layer on its own, and numbered across the slabs'
// boundaries: for slabs of 1, 2, 3 and 7 layers and the default, and bricks of 4 and 12, every
// .obj and .ply has exactly the exposed faces on shared corners (a corner numbered again at a
// slab boundary is a duplicate position), the .stl twice their count in triangles, and each
// format is one file whatever the slabs.
TEST_F(WriterTest, CubeMeshFilesDoNotDependOnTheSlabsTheLayersAreMadeIn) {
    const Grid grid = make_grid({23, 17, 31}, {-1, 2, 0.5}, 0.5);
    VoxelSet set;
    std::mt19937 rng(11);
    for (int64_t k = 0; k < 31; ++k)
        for (int64_t j = 0; j < 17; ++j)
            for (int64_t i = 0; i < 23; ++i)
                if (rng() % 100 < (k % 9 < 3 ? 60u : k % 9 == 5 ? 0u : 15u)) set.insert({i, j, k});
    const size_t faces = exposed_faces_by_brute_force(set).size();
    std::map<std::string, std::string> first;
    for (const int brick : {4, 12})
        for (const int64_t slab : {int64_t(1), int64_t(2), int64_t(3), int64_t(7), int64_t(0)}) {
            SCOPED_TRACE("brick " + std::to_string(brick) + ", slab " + std::to_string(slab));
            const SparseVoxels voxels = make_voxels(grid, set, brick);
            oclvox::detail::ProgressPhases none({}, "writing");
            oclvox::detail::write_cube_mesh_obj(path("s.obj"), voxels, none, slab);
            oclvox::detail::write_cube_mesh_ply(path("s.ply"), voxels, none, slab);
            oclvox::detail::write_cube_mesh_stl(path("s.stl"), voxels, none, slab);
            const std::map<std::string, std::string> files = {{"obj", read_bytes(path("s.obj"))},
                                                              {"ply", read_bytes(path("s.ply"))},
                                                              {"stl", read_bytes(path("s.stl"))}};
            check_exposed_face_mesh(read_obj(files.at("obj")), grid, set);
            check_exposed_face_mesh(read_ply(files.at("ply")), grid, set);
            ByteReader stl{files.at("stl")};
            stl.pos = 80;
            EXPECT_EQ(stl.uint(4), 2 * faces);
            if (first.empty()) first = files;
            for (const auto& [format, bytes] : files)
                EXPECT_TRUE(bytes == first.at(format)) << format;
        }
}

TEST_F(WriterTest, GridWithNoSetVoxelsWritesValidEmptyFiles) {
    const SparseVoxels empty(make_grid({3, 4, 5}), 4);
    for (const char* name : {"e.binvox", "e.npy", "e.vox", "e.obj", "e.ply", "e.stl", "e.vdb"})
        oclvox::write_voxels(path(name), empty);

    EXPECT_TRUE(read_binvox(read_bytes(path("e.binvox"))).set.empty());
    EXPECT_TRUE(read_npy(read_bytes(path("e.npy"))).set.empty());
    const Vox vox = read_vox(read_bytes(path("e.vox")));
    ASSERT_EQ(vox.models.size(), 1u);  // readers expect at least one model
    EXPECT_EQ(vox.models[0].size, (std::array<int64_t, 3>{3, 4, 5}));
    EXPECT_TRUE(vox.world.empty());
    EXPECT_TRUE(read_obj(read_bytes(path("e.obj"))).faces.empty());
    EXPECT_TRUE(read_ply(read_bytes(path("e.ply"))).faces.empty());
    EXPECT_EQ(read_bytes(path("e.stl")).size(), 84u);  // header and a zero triangle count
    EXPECT_EQ(read_vdb_occupancy(path("e.vdb")).active_count, 0u);
}

TEST_F(WriterTest, HugeSparseGridWorksForSparseFormatsAndFailsCleanlyForDenseOnes) {
    // 2^20 x 2^20 x 64 voxels: far too many for a dense copy, two set voxels far apart.
    const Grid grid = make_grid({int64_t(1) << 20, int64_t(1) << 20, 64});
    const VoxelSet set = {{0, 0, 0}, {(int64_t(1) << 20) - 1, (int64_t(1) << 20) - 1, 63}};
    const SparseVoxels voxels = make_voxels(grid, set, 64);

    for (const char* name : {"huge.binvox", "huge.npy"})
        EXPECT_THROW(oclvox::write_voxels(path(name), voxels), OutputError) << name;
    EXPECT_TRUE(entries().empty());

    oclvox::write_voxels(path("huge.vox"), voxels);
    EXPECT_EQ(read_vox(read_bytes(path("huge.vox"))).world, set);
    oclvox::write_voxels(path("huge.obj"), voxels);
    EXPECT_EQ(read_obj(read_bytes(path("huge.obj"))).faces.size(), 12u);
}

// ---------------------------------------------------------------------------------------------
// Choosing the format, and failures
// ---------------------------------------------------------------------------------------------
// A program's global C++ locale does not reach the files: under one with a decimal comma and
// thousands separators every format's bytes are those written under the classic locale (the
// binvox header's translate and scale, the mesh headers' counts were written through it).
TEST_F(WriterTest, FilesDoNotDependOnTheGlobalLocale) {
    struct CommaNumbers : std::numpunct<char> {
        char do_decimal_point() const override { return ','; }
        char do_thousands_sep() const override { return '.'; }
        std::string do_grouping() const override { return "\3"; }
    };
    const Grid grid = make_grid({10, 10, 10}, {0.5, -2.25, 3.125}, 0.25);
    VoxelSet set;
    for (int64_t k = 0; k < 10; ++k)
        for (int64_t j = 0; j < 10; ++j)
            for (int64_t i = 0; i < 10; ++i) set.insert({i, j, k});  // 1,000 voxels
    const SparseVoxels voxels = make_voxels(grid, set, 8);
    oclvox::Mesh mesh;  // 1,200 vertices, 400 triangles
    for (uint32_t t = 0; t < 400; ++t) {
        for (int v = 0; v < 3; ++v) mesh.positions.push_back({0.5 * t, 0.25 * v, -1.5});
        mesh.triangles.push_back({3 * t, 3 * t + 1, 3 * t + 2});
    }
    auto write_all = [&] {
        std::map<std::string, std::string> files;
        for (const std::string ext : {".binvox", ".npy", ".vox", ".obj", ".ply", ".stl"}) {
            oclvox::write_voxels(path("v" + ext), voxels);
            files["voxels" + ext] = read_bytes(path("v" + ext));
        }
        files["voxels.npy.json"] = read_bytes(path("v.npy.json"));
        for (const std::string ext : {".obj", ".ply", ".stl"}) {
            oclvox::write_mesh(path("m" + ext), mesh);
            files["mesh" + ext] = read_bytes(path("m" + ext));
        }
        return files;
    };
    const std::map<std::string, std::string> classic = write_all();
    const std::locale before =
        std::locale::global(std::locale(std::locale::classic(), new CommaNumbers));
    std::map<std::string, std::string> comma;
    try {
        comma = write_all();
    } catch (...) {
        std::locale::global(before);
        throw;
    }
    std::locale::global(before);
    for (const auto& [name, bytes] : classic) EXPECT_TRUE(comma.at(name) == bytes) << name;
}

TEST_F(WriterTest, ExtensionIsCaseInsensitive) {
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("OUT.BinVox"), make_voxels(odd_grid(), set));
    EXPECT_EQ(read_binvox(read_bytes(path("OUT.BinVox"))).set, set);
}

TEST_F(WriterTest, UnknownExtensionThrowsOutputErrorListingSupportedOnes) {
    try {
        oclvox::write_voxels(path("out.xyz"), make_voxels(odd_grid(), odd_pattern()));
        FAIL() << "no exception";
    } catch (const OutputError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(".xyz"), std::string::npos) << what;
        for (const char* supported : {".vdb", ".binvox", ".npy", ".vox", ".obj", ".ply", ".stl"})
            EXPECT_NE(what.find(supported), std::string::npos) << what;
    }
    EXPECT_TRUE(entries().empty());
}

TEST_F(WriterTest, EmptyGridThrowsOutputError) {
    EXPECT_THROW(oclvox::write_voxels(path("out.binvox"), SparseVoxels()), OutputError);
    EXPECT_TRUE(entries().empty());
}

TEST_F(WriterTest, MissingFolderThrowsOutputErrorAndLeavesNothing) {
    for (const char* name : {"out.binvox", "out.npy", "out.vox", "out.obj", "out.ply"}) {
        const std::string target = path("missing/") + name;
        try {
            oclvox::write_voxels(target, make_voxels(odd_grid(), odd_pattern()));
            FAIL() << "no exception for " << name;
        } catch (const OutputError& e) {
            EXPECT_NE(std::string(e.what()).find(target), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(std::strerror(ENOENT)), std::string::npos)
                << e.what();
        }
    }
    EXPECT_TRUE(entries().empty());
}

TEST_F(WriterTest, ExceptionInsideWriteLeavesNoTemporaryAndNoFinalFile) {
    try {
        oclvox::detail::write_file_atomically(path("out.bin"), [](std::ostream& out) {
            out << std::string(100000, 'x');  // more than one stream buffer reaches the disk
            throw std::runtime_error("format failed halfway");
        });
        FAIL() << "no exception";
    } catch (const OutputError& e) {
        EXPECT_NE(std::string(e.what()).find("format failed halfway"), std::string::npos);
    }
    EXPECT_TRUE(entries().empty());
}

TEST_F(WriterTest, FailedWriteKeepsThePreviousFile) {
    oclvox::detail::write_file_atomically(path("out.bin"), [](std::ostream& out) { out << "old"; });
    EXPECT_THROW(oclvox::detail::write_file_atomically(path("out.bin"),
                                                       [](std::ostream& out) {
                                                           out << "new";
                                                           throw std::runtime_error("stop");
                                                       }),
                 OutputError);
    EXPECT_EQ(read_bytes(path("out.bin")), "old");
    EXPECT_EQ(entries(), std::vector<std::string>{"out.bin"});
}

TEST_F(WriterTest, OverwritingReplacesTheWholeFile) {
    oclvox::detail::write_file_atomically(path("out.bin"),
                                          [](std::ostream& out) { out << std::string(5000, 'o'); });
    oclvox::detail::write_file_atomically(path("out.bin"), [](std::ostream& out) { out << "new"; });
    EXPECT_EQ(read_bytes(path("out.bin")), "new");

    // The same through a format: the reader rejects any byte left over from the old file.
    std::ofstream(path("out.binvox")) << std::string(100000, 'z');
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.binvox"), make_voxels(odd_grid(), set));
    EXPECT_EQ(read_binvox(read_bytes(path("out.binvox"))).set, set);
    EXPECT_EQ(entries(), (std::vector<std::string>{"out.bin", "out.binvox"}));
}

TEST_F(WriterTest, FailedRenameRemovesTheTemporaryFile) {
    // A non-empty folder cannot be replaced by a file.
    fs::create_directories(path("out.obj") + "/inside");
    EXPECT_THROW(oclvox::write_voxels(path("out.obj"), make_voxels(odd_grid(), odd_pattern())),
                 OutputError);
    EXPECT_EQ(entries(), std::vector<std::string>{"out.obj"});
    EXPECT_TRUE(fs::is_directory(path("out.obj")));
}

// ---------------------------------------------------------------------------------------------
// Streamed dense formats against their definitions, built here voxel by voxel from
// SparseVoxels::get (not from the bricks the writers read)
// ---------------------------------------------------------------------------------------------

// A solid box [lo, hi) and noise below layer noise_end (a voxel in about noise_in_256 of 256),
// from a fixed sequence.
SparseVoxels box_and_noise(const Grid& grid, int brick_size, const std::array<int64_t, 3>& lo,
                           const std::array<int64_t, 3>& hi, int64_t noise_end,
                           uint32_t noise_in_256, uint32_t seed) {
    SparseVoxels voxels(grid, brick_size);
    uint32_t state = seed;
    for (int64_t k = 0; k < grid.dims[2]; ++k)
        for (int64_t j = 0; j < grid.dims[1]; ++j)
            for (int64_t i = 0; i < grid.dims[0]; ++i) {
                state = state * 1664525u + 1013904223u;
                const bool box =
                    i >= lo[0] && i < hi[0] && j >= lo[1] && j < hi[1] && k >= lo[2] && k < hi[2];
                if (box || (k < noise_end && (state >> 24) < noise_in_256)) voxels.set(i, j, k);
            }
    return voxels;
}

// A pattern with long runs (a solid box, > 255 voxels per run), empty stretches and noise, on a
// non-cubic grid that is not a multiple of any brick size used.
SparseVoxels mixed_voxels(int brick_size) {
    return box_and_noise(make_grid({37, 21, 45}, {0.5, -2.0, 3.0}, 0.25), brick_size, {3, 2, 10},
                         {30, 21, 40}, 8, 80, 12345);
}

// The .npy data section: uint8, Fortran order (x fastest).
std::string npy_data_by_definition(const SparseVoxels& voxels) {
    const auto& d = voxels.grid().dims;
    std::string data;
    for (int64_t k = 0; k < d[2]; ++k)
        for (int64_t j = 0; j < d[1]; ++j)
            for (int64_t i = 0; i < d[0]; ++i) data.push_back(char(voxels.get(i, j, k)));
    return data;
}

// The binvox data section: the cube of side max(dims) in x, z, y order (y fastest), as maximal
// runs of at most 255.
std::string binvox_data_by_definition(const SparseVoxels& voxels) {
    const auto& d = voxels.grid().dims;
    const int64_t side = std::max({d[0], d[1], d[2]});
    std::string data;
    int value = -1, count = 0;
    auto flush = [&] {
        if (count > 0) data += std::string{char(value), char(count)};
    };
    for (int64_t x = 0; x < side; ++x)
        for (int64_t z = 0; z < side; ++z)
            for (int64_t y = 0; y < side; ++y) {
                const int v = voxels.get(x, y, z) ? 1 : 0;
                if (v != value || count == 255) {
                    flush();
                    value = v;
                    count = 0;
                }
                ++count;
            }
    flush();
    return data;
}

std::string after(const std::string& bytes, const std::string& marker) {
    const size_t at = bytes.find(marker);
    if (at == std::string::npos) throw std::runtime_error("no " + marker);
    return bytes.substr(at + marker.size());
}

VoxelSet set_of(const SparseVoxels& voxels) {
    VoxelSet set;
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) { set.insert({i, j, k}); });
    return set;
}

TEST_F(WriterTest, StreamedNpyAndBinvoxEqualTheDenseDefinitionForAnySlabAndBrickSize) {
    for (int brick : {4, 12, 64}) {
        const SparseVoxels voxels = mixed_voxels(brick);
        const std::string npy = npy_data_by_definition(voxels);
        const std::string binvox = binvox_data_by_definition(voxels);
        // 1 byte: the thinnest slabs (.npy: a block's 4 layers, the last one layer; .binvox: one
        // plane); 3000: .binvox 3 planes, not a multiple of 4; kSlabBytes: one slab.
        for (uint64_t slab : {uint64_t(1), uint64_t(3000), oclvox::detail::kSlabBytes}) {
            SCOPED_TRACE("brick " + std::to_string(brick) + ", slab " + std::to_string(slab));
            oclvox::detail::ProgressPhases none({}, "writing");
            oclvox::detail::write_npy(path("s.npy"), voxels, none, slab);
            const std::string npy_file = read_bytes(path("s.npy"));
            const Npy parsed = read_npy(npy_file);
            EXPECT_EQ(npy_file.substr(parsed.data_offset), npy);
            oclvox::detail::write_binvox(path("s.binvox"), voxels, none, slab);
            EXPECT_EQ(after(read_bytes(path("s.binvox")), "data\n"), binvox);
        }
    }
}

// Rows along y of several 64-bit words, whose set voxels start and end in any word (or there are
// none): the binvox writer scans only the words a row's voxels reach, and the file is still the
// dense definition's, for bricks that hold a row in one word and in several.
TEST_F(WriterTest, BinvoxRowsOfSeveralWordsEqualTheDenseDefinition) {
    const Grid grid = make_grid({9, 150, 13});  // rows of 3 words along y
    VoxelSet set;
    uint32_t state = 777;
    for (int64_t k = 0; k < 13; ++k)
        for (int64_t i = 0; i < 9; ++i) {
            // Each (x, z) row: empty, one word's voxels (the first, middle or last word), or a
            // span from one word into another.
            state = state * 1664525u + 1013904223u;
            const int64_t kind = (state >> 24) % 5;
            if (kind == 0) continue;
            const int64_t from = kind == 1 ? 3 : kind == 2 ? 70 : kind == 3 ? 130 : 60;
            const int64_t to = kind == 1 ? 40 : kind == 2 ? 100 : kind == 3 ? 149 : 135;
            for (int64_t j = from; j <= to; j += 1 + int64_t(state >> 28)) set.insert({i, j, k});
        }
    for (int brick : {4, 16, 64}) {
        SCOPED_TRACE("brick " + std::to_string(brick));
        const SparseVoxels voxels = make_voxels(grid, set, brick);
        oclvox::detail::ProgressPhases none({}, "writing");
        oclvox::detail::write_binvox(path("r.binvox"), voxels, none);
        EXPECT_EQ(after(read_bytes(path("r.binvox")), "data\n"), binvox_data_by_definition(voxels));
    }
}

// The dense writers' slab stream: every slab is made and written once, in order, with the layers
// it covers (the last one short); the write of a slab never overlaps the making of the buffer it
// reads from; and a failing write, or a report that throws (as a cancel does), stops the stream
// with that exception only once no write is under way.
TEST(SlabStream, WritesEverySlabInOrderAndStopsAtAFailureOnlyWhenNoWriteIsUnderWay) {
    struct Slab {
        int64_t first = -1, end = -1;
        bool being_written = false;
    };
    std::vector<std::pair<int64_t, int64_t>> written;
    bool overlapped = false;
    oclvox::detail::stream_slabs<Slab>(
        10, 3,
        [&](Slab& slab, int64_t first, int64_t end) {
            overlapped = overlapped || slab.being_written;
            slab.first = first;
            slab.end = end;
        },
        [&](Slab& slab, int64_t first, int64_t end) {
            slab.being_written = true;
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
            if (slab.first != first || slab.end != end) written.push_back({-1, -1});
            written.push_back({first, end});
            slab.being_written = false;
        },
        [](int64_t) {});
    const std::vector<std::pair<int64_t, int64_t>> expected = {{0, 3}, {3, 6}, {6, 9}, {9, 10}};
    EXPECT_EQ(written, expected);
    EXPECT_FALSE(overlapped);

    // A write that throws: its exception, and no slab after it is written.
    written.clear();
    EXPECT_THROW(oclvox::detail::stream_slabs<Slab>(
                     10, 3, [](Slab&, int64_t, int64_t) {},
                     [&](const Slab&, int64_t first, int64_t end) {
                         if (first == 3) throw std::runtime_error("disk gone");
                         written.push_back({first, end});
                     },
                     [](int64_t) {}),
                 std::runtime_error);
    EXPECT_EQ(written, (std::vector<std::pair<int64_t, int64_t>>{{0, 3}}));

    // A report that throws while a slab is being written: the exception only once it is done.
    bool finished = false;
    EXPECT_THROW(oclvox::detail::stream_slabs<Slab>(
                     10, 3, [](Slab&, int64_t, int64_t) {},
                     [&](const Slab&, int64_t first, int64_t) {
                         std::this_thread::sleep_for(std::chrono::milliseconds(20));
                         finished = first == 0;
                     },
                     [&](int64_t first) {
                         if (first == 3) throw oclvox::Cancelled("stopped");
                     }),
                 oclvox::Cancelled);
    EXPECT_TRUE(finished);
}

// Bytes a file takes on its file system (holes take none).
uint64_t allocated_bytes(const std::string& file) {
    struct stat info;
    if (stat(file.c_str(), &info) != 0) throw std::runtime_error("cannot stat " + file);
    return uint64_t(info.st_blocks) * 512;
}

// Long runs of empty pages in a .npy are left as holes: the file reads exactly as the dense
// definition, whichever run starts or ends it, wherever slabs cut the runs, and (on a file system
// that keeps holes, probed first) it takes far less space than its size.
TEST_F(WriterTest, NpyLeavesLongEmptyRunsAsHolesAndReadsAsTheDenseDefinition) {
    const Grid grid = make_grid({128, 128, 64});  // 16 KiB a layer, 1 MiB in all
    // Voxels at the start, a few in the middle, near the end; then also in the very last byte;
    // then also five whole layers, over 64 KiB of ones (pages of equal bytes are not empty); and
    // none at all.
    const VoxelSet scattered = {{0, 0, 0}, {5, 7, 1}, {100, 3, 30}, {64, 64, 31}, {1, 120, 50}};
    VoxelSet to_the_end = scattered;
    to_the_end.insert({127, 127, 63});
    VoxelSet full_pages = scattered;
    for (int64_t k = 40; k < 45; ++k)
        for (int64_t j = 0; j < 128; ++j)
            for (int64_t i = 0; i < 128; ++i) full_pages.insert({i, j, k});
    {
        std::ofstream probe(path("probe"), std::ios::binary);
        probe.seekp(std::streamoff(1) << 20);
        probe.put(0);
    }
    const bool keeps_holes = allocated_bytes(path("probe")) < (uint64_t(1) << 19);
    for (const VoxelSet& set : {scattered, to_the_end, full_pages, VoxelSet{}})
        for (uint64_t slab : {uint64_t(1), uint64_t(200000), oclvox::detail::kCachedSlabBytes}) {
            SCOPED_TRACE(std::to_string(set.size()) + " voxels, slab " + std::to_string(slab));
            const SparseVoxels voxels = make_voxels(grid, set, 16);
            oclvox::detail::ProgressPhases none({}, "writing");
            oclvox::detail::write_npy(path("h.npy"), voxels, none, slab);
            const std::string file = read_bytes(path("h.npy"));
            const Npy parsed = read_npy(file);
            EXPECT_EQ(file.substr(parsed.data_offset), npy_data_by_definition(voxels));
            if (keeps_holes) EXPECT_LT(allocated_bytes(path("h.npy")), file.size() / 2);
        }
}

// ---- progress ----

// Every format: the counts never go back, the total is fixed, the last call has done == total and
// comes before the file takes its name (the callback looks for it), and the file is complete.
TEST_F(WriterTest, ProgressEndsAtTotalBeforeTheFileAppears) {
    const SparseVoxels voxels = mixed_voxels(12);
    for (const char* name : {"p.vdb", "p.binvox", "p.npy", "p.vox", "p.obj", "p.ply", "p.stl"}) {
        SCOPED_TRACE(name);
        std::vector<std::pair<uint64_t, uint64_t>> calls;
        bool file_before_last = true;
        oclvox::write_voxels(path(name), voxels, [&](uint64_t done, uint64_t total) {
            calls.push_back({done, total});
            if (done == total) file_before_last = fs::exists(path(name));
            return true;
        });
        ASSERT_FALSE(calls.empty());
        EXPECT_EQ(calls.back().first, calls.back().second);
        EXPECT_FALSE(file_before_last) << "the file existed before the last progress call";
        for (size_t i = 1; i < calls.size(); ++i) {
            EXPECT_EQ(calls[i].second, calls[0].second);
            EXPECT_LE(calls[i - 1].first, calls[i].first);
        }
        EXPECT_TRUE(fs::exists(path(name)));
    }
    const std::string npy = read_bytes(path("p.npy"));
    EXPECT_EQ(npy.substr(read_npy(npy).data_offset), npy_data_by_definition(voxels));
}

// A slab at a time: with one layer per slab and calls spaced past the reporting interval, every
// slab is reported, in order.
TEST_F(WriterTest, StreamedWritersReportEverySlab) {
    const SparseVoxels voxels = mixed_voxels(12);
    std::vector<uint64_t> done_per_call;
    oclvox::detail::ProgressPhases progress(
        [&](uint64_t done, uint64_t) {
            done_per_call.push_back(done);
            std::this_thread::sleep_for(std::chrono::milliseconds(60));
            return true;
        },
        "writing");
    oclvox::detail::write_npy(path("s.npy"), voxels, progress, 1);
    // One report per slab of the thinnest kind, a block's 4 z layers (the first passes at once,
    // the others after the sleep), plus the last.
    EXPECT_EQ(done_per_call.size(), size_t(voxels.grid().dims[2] + 3) / 4 + 1);
    EXPECT_TRUE(std::is_sorted(done_per_call.begin(), done_per_call.end()));
    EXPECT_EQ(done_per_call.back(), oclvox::detail::kPhasedProgressTotal);
}

// False from the callback, early or at the very end: Cancelled, and neither the file nor a
// temporary is left; a previous file of that name is kept as it was.
TEST_F(WriterTest, CancelledWriteLeavesNoFileAndKeepsThePreviousOne) {
    const SparseVoxels voxels = mixed_voxels(12);
    for (const char* name : {"c.vdb", "c.binvox", "c.npy", "c.vox", "c.obj", "c.ply"}) {
        SCOPED_TRACE(name);
        for (const bool at_end : {false, true}) {
            fs::remove_all(path(name));
            EXPECT_THROW(oclvox::write_voxels(path(name), voxels,
                                              [&](uint64_t done, uint64_t total) {
                                                  return at_end ? done != total : false;
                                              }),
                         oclvox::Cancelled);
            EXPECT_TRUE(entries().empty()) << "left: " << (entries().empty() ? "" : entries()[0]);
        }
    }
    oclvox::write_voxels(path("keep.binvox"), voxels);
    const std::string before = read_bytes(path("keep.binvox"));
    EXPECT_THROW(oclvox::write_voxels(path("keep.binvox"), mixed_voxels(4),
                                      [](uint64_t, uint64_t) { return false; }),
                 oclvox::Cancelled);
    EXPECT_EQ(read_bytes(path("keep.binvox")), before);
    EXPECT_EQ(entries(), std::vector<std::string>{"keep.binvox"});
}

TEST_F(WriterTest, NpyReadsBackThroughNumpy) {
    if (std::system("/usr/bin/python3 -c 'import numpy' 2>/dev/null") != 0)
        GTEST_SKIP() << "python3-numpy is not installed (scripts/install_deps.sh installs it)";
    const SparseVoxels voxels = mixed_voxels(12);
    oclvox::write_voxels(path("n.npy"), voxels);
    const std::string listing = path("n.txt");
    const std::string command = "/usr/bin/python3 -c \"import numpy; a = numpy.load('" +
                                path("n.npy") +
                                "'); assert a.dtype == numpy.uint8 and a.shape == (37, 21, 45); "
                                "[print(i, j, k) for i, j, k in numpy.argwhere(a)]\" > " +
                                listing;
    ASSERT_EQ(std::system(command.c_str()), 0);
    VoxelSet from_numpy;
    std::istringstream lines(read_bytes(listing));
    for (Voxel v; lines >> v[0] >> v[1] >> v[2];) from_numpy.insert(v);
    EXPECT_EQ(from_numpy, set_of(voxels));
}

TEST_F(WriterTest, StreamedVoxMatchesTheVoxelsAcrossTilesWithBricksStraddlingThem) {
    // Bricks of 12 do not divide 256, so bricks straddle tile borders; the box crosses x = 256.
    const Grid grid = make_grid({300, 20, 270});
    VoxelSet set;
    for (int64_t i = 250; i < 262; ++i)
        for (int64_t j = 3; j < 9; ++j)
            for (int64_t k = 250; k < 260; ++k) set.insert({i, j, k});
    set.insert({0, 0, 0});
    set.insert({299, 19, 269});
    oclvox::write_voxels(path("t.vox"), make_voxels(grid, set, 12));
    oclvox::write_voxels(path("u.vox"), make_voxels(grid, set, 64));

    const Vox file = read_vox(read_bytes(path("t.vox")));
    EXPECT_EQ(file.world, set);
    EXPECT_EQ(file.models.size(), 4u);  // tiles (0,0,0), (1,0,0), (0,0,1), (1,0,1)
    EXPECT_EQ(file.pack_models, int32_t(file.models.size()));
    EXPECT_FALSE(file.layers_used.empty());
    EXPECT_EQ(file.layers_used, file.layers_named);
    EXPECT_EQ(read_bytes(path("t.vox")), read_bytes(path("u.vox")));  // brick size invisible
}

TEST_F(WriterTest, StlCubeMeshEnclosesExactlyTheVoxelVolumeFacingOutwards) {
    // Divergence theorem: the signed volume of a closed, outward-wound triangle mesh is the
    // volume it encloses; a flipped or missing triangle changes it.
    const VoxelSet set = odd_pattern();
    oclvox::write_voxels(path("out.stl"), make_voxels(odd_grid(), set));
    const std::string bytes = read_bytes(path("out.stl"));
    ByteReader in{bytes};
    in.pos = 80;
    const uint64_t triangles = in.uint(4);
    ASSERT_EQ(bytes.size(), 84 + 50 * triangles);
    EXPECT_EQ(triangles, 2 * exposed_faces_by_brute_force(set).size());
    double volume = 0;
    for (uint64_t t = 0; t < triangles; ++t) {
        in.pos += 12;  // normal
        std::array<std::array<double, 3>, 3> p{};
        for (auto& corner : p)
            for (double& c : corner) {
                const uint32_t bits = uint32_t(in.uint(4));
                float f;
                std::memcpy(&f, &bits, 4);
                c = f;
            }
        in.pos += 2;
        volume += (p[0][0] * (p[1][1] * p[2][2] - p[1][2] * p[2][1]) -
                   p[0][1] * (p[1][0] * p[2][2] - p[1][2] * p[2][0]) +
                   p[0][2] * (p[1][0] * p[2][1] - p[1][1] * p[2][0])) /
                  6;
    }
    EXPECT_NEAR(volume, double(set.size()) * 0.125, 1e-9);
}

// ---------------------------------------------------------------------------------------------
// OpenVDB occupancy, read back through OpenVDB's own API
// ---------------------------------------------------------------------------------------------
// Writes `voxels` to `file` and reads it back through OpenVDB, expecting exactly their voxels
// active and true.
VdbOccupancy written_vdb_holding_exactly(const std::string& file, const SparseVoxels& voxels) {
    oclvox::write_voxels(file, voxels);
    VdbOccupancy vdb = read_vdb_occupancy(file);
    const VoxelSet expected = set_of(voxels);
    EXPECT_EQ(vdb.active_count, expected.size());
    EXPECT_EQ(vdb.active, expected);
    EXPECT_TRUE(vdb.all_true);
    return vdb;
}

TEST_F(WriterTest, VdbActiveVoxelsAreExactlyTheSetVoxelsWithCentresInWorldUnits) {
    // Bricks of 4 and 12 share leaves between bricks (merged after sorting); 8, 16 and 64 hold
    // whole leaves.
    for (int brick : {4, 8, 12, 16, 64}) {
        SCOPED_TRACE("brick " + std::to_string(brick));
        // The mixed pattern has whole 8^3 leaves (pruned to tiles) and partial ones.
        const SparseVoxels voxels = mixed_voxels(brick);
        const VdbOccupancy vdb = written_vdb_holding_exactly(path("o.vdb"), voxels);

        const Grid& g = voxels.grid();
        for (const Voxel& v : {Voxel{0, 0, 0}, Voxel{36, 20, 44}, Voxel{5, 17, 30}}) {
            const openvdb::Vec3d world =
                vdb.transform->indexToWorld(openvdb::Coord(int(v[0]), int(v[1]), int(v[2])));
            for (int a = 0; a < 3; ++a)
                EXPECT_NEAR(world[a], g.origin[a] + (double(v[a]) + 0.5) * g.voxel_size, 1e-12);
        }
        EXPECT_EQ(vdb.origin, openvdb::Vec3d(0.5, -2.0, 3.0));
        EXPECT_EQ(vdb.dims, openvdb::Vec3i(37, 21, 45));
    }
}

// A grid of over a thousand active bricks of 8 (sparse noise in every brick and a solid box
// pruned to tiles) reads back with exactly its voxels.
TEST_F(WriterTest, VdbOfManyBrickGroupsHasExactlyTheSetVoxels) {
    const SparseVoxels voxels =
        box_and_noise(make_grid({130, 70, 90}), 8, {16, 8, 24}, {48, 40, 64}, 90, 4, 99);
    ASSERT_GT(voxels.brick_indices().size(), 3 * 256u);
    written_vdb_holding_exactly(path("groups.vdb"), voxels);
}

// The file OpenVDB's own writer makes of the same voxels: a BoolGrid named "occupancy" of class
// "unknown", voxel (i, j, k) at index (i, j, k) centred in world space at origin + (i + 0.5) *
// voxel_size, our grid's metadata, set voxel by voxel through OpenVDB's API, pruned, and written
// by io::Stream with the active-mask compression (its statistics metadata worked out by OpenVDB).
// Built from the grid alone, not from our file, so a wrong transform or metadata value shows.
std::string openvdb_written_occupancy(const SparseVoxels& voxels) {
    const Grid& g = voxels.grid();
    const openvdb::BoolGrid::Ptr grid = openvdb::BoolGrid::create(false);
    oclvox::test::place_as_our_vdb_files_do(*grid, g, "occupancy", openvdb::GRID_UNKNOWN);
    openvdb::BoolGrid::Accessor access = grid->getAccessor();
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
        access.setValueOn(openvdb::Coord(int(i), int(j), int(k)), true);
    });
    grid->tree().prune();
    return oclvox::test::written_by_openvdb(grid);
}

// The bytes of our .vdb are those of OpenVDB's writer for the same voxels but for the file's
// random UUID (36 characters after the 21 header bytes): the tree, its order, its tiles and the
// statistics metadata are laid out as OpenVDB lays them out.
void expect_vdb_bytes_of_openvdbs_writer(const std::string& file, const SparseVoxels& voxels) {
    oclvox::write_voxels(file, voxels);
    oclvox::test::expect_vdb_bytes_equal_but_uuid(read_bytes(file),
                                                  openvdb_written_occupancy(voxels));
}

TEST_F(WriterTest, VdbIsByteForByteWhatOpenVdbsWriterMakesOfTheSameVoxels) {
    openvdb::initialize();
    // Bricks of 4 and 12 share leaves between bricks; 8, 16 and 64 hold whole ones. The mixed
    // pattern has full leaves (tiles) and partial ones.
    for (int brick : {4, 8, 12, 16, 64}) {
        SCOPED_TRACE("brick " + std::to_string(brick));
        expect_vdb_bytes_of_openvdbs_writer(path("m.vdb"), mixed_voxels(brick));
    }
    // Several root entries (a grid over 4096 voxels along x) and upper nodes.
    {
        SCOPED_TRACE("far apart");
        const SparseVoxels voxels = make_voxels(
            make_grid({5000, 300, 20}),
            {{0, 0, 0}, {4095, 0, 0}, {4096, 299, 19}, {4999, 128, 7}, {130, 5, 9}}, 64);
        expect_vdb_bytes_of_openvdbs_writer(path("far.vdb"), voxels);
    }
    // A full lower node (128^3 aligned) is a tile of its upper node, beside partial ones.
    {
        SCOPED_TRACE("full lower node");
        SparseVoxels voxels(make_grid({140, 136, 130}), 32);
        voxels.set_box({0, 0, 0}, {128, 128, 128});
        voxels.set_box({128, 3, 5}, {140, 136, 9});
        voxels.set(139, 135, 129);
        expect_vdb_bytes_of_openvdbs_writer(path("full.vdb"), voxels);
    }
    {
        SCOPED_TRACE("no voxels");
        expect_vdb_bytes_of_openvdbs_writer(path("empty.vdb"),
                                            SparseVoxels(make_grid({9, 9, 9}), 8));
    }
}

TEST_F(WriterTest, VdbReadsBackThroughOpenVdbsPythonModule) {
    if (std::system("/usr/bin/python3 -c 'import pyopenvdb' 2>/dev/null") != 0)
        GTEST_SKIP() << "python3-openvdb is not installed (scripts/install_deps.sh installs it)";
    const SparseVoxels voxels = mixed_voxels(12);
    oclvox::write_voxels(path("p.vdb"), voxels);
    const std::string listing = path("p.txt");
    // Prints the transform's image of index (1, 2, 3), then every active voxel (tiles expanded).
    const std::string script =
        "import pyopenvdb as vdb, itertools\n"
        "g = vdb.read('" +
        path("p.vdb") +
        "', 'occupancy')\n"
        "assert g.valueTypeName == 'bool', g.valueTypeName\n"
        "print(*g.transform.indexToWorld((1, 2, 3)))\n"
        "for v in g.citerOnValues():\n"
        "    assert v['value']\n"
        "    lo, hi = v['min'], v['max']\n"
        "    for c in itertools.product(*(range(lo[a], hi[a] + 1) for a in range(3))):\n"
        "        print(*c)\n";
    std::ofstream(path("p.py")) << script;
    ASSERT_EQ(std::system(("/usr/bin/python3 " + path("p.py") + " > " + listing).c_str()), 0);
    std::istringstream lines(read_bytes(listing));
    std::array<double, 3> world{};
    lines >> world[0] >> world[1] >> world[2];
    EXPECT_NEAR(world[0], 0.5 + 1.5 * 0.25, 1e-12);
    EXPECT_NEAR(world[1], -2.0 + 2.5 * 0.25, 1e-12);
    EXPECT_NEAR(world[2], 3.0 + 3.5 * 0.25, 1e-12);
    VoxelSet from_python;
    for (Voxel v; lines >> v[0] >> v[1] >> v[2];) from_python.insert(v);
    EXPECT_EQ(from_python, set_of(voxels));
}

TEST_F(WriterTest, GridTooLargeForADenseCopyStillWritesVdb) {
    // 2^20 x 2^20 x 64 voxels (2^46 bytes dense) with a 16^3 solid block and two far corners.
    const int64_t n = int64_t(1) << 20;
    const Grid grid = make_grid({n, n, 64});
    VoxelSet set = {{0, 0, 0}, {n - 1, n - 1, 63}};
    for (int64_t i = 0; i < 16; ++i)
        for (int64_t j = 0; j < 16; ++j)
            for (int64_t k = 0; k < 16; ++k) set.insert({n / 2 + i, 7 + j, 40 + k});
    const SparseVoxels voxels = make_voxels(grid, set, 64);
    EXPECT_THROW(voxels.to_dense(), oclvox::GridError);

    oclvox::write_voxels(path("huge.vdb"), voxels);
    const VdbOccupancy vdb = read_vdb_occupancy(path("huge.vdb"));
    EXPECT_EQ(vdb.active, set);
    EXPECT_EQ(vdb.dims, openvdb::Vec3i(int(n), int(n), 64));
}

}  // namespace

// ---- boxes of the sparse storage (the windows writers and sparse fields read) -------------------

namespace {

// Random voxels in a grid of 8^3 bricks, and random boxes, some reaching beyond the grid:
// count_box is the voxel-by-voxel count of get(), set_box sets exactly the box's voxels.
// `count` random voxels set on a 37 x 29 x 41 grid of 8^3 bricks.
SparseVoxels random_voxels(int count, std::mt19937& rng) {
    Grid g;
    g.dims = {37, 29, 41};
    SparseVoxels voxels(g, 8);
    for (int n = 0; n < count; ++n)
        voxels.set(int64_t(rng() % 37), int64_t(rng() % 29), int64_t(rng() % 41));
    return voxels;
}

TEST(SparseVoxelBoxes, CountAndSetAgreeWithVoxelByVoxelReadsOnRandomBoxes) {
    std::mt19937 rng(3);
    const SparseVoxels voxels = random_voxels(3000, rng);
    const Grid& g = voxels.grid();
    for (int trial = 0; trial < 200; ++trial) {
        std::array<int64_t, 3> lo, hi;
        for (int a = 0; a < 3; ++a) {
            lo[a] = int64_t(rng() % uint32_t(g.dims[a] + 6)) - 3;
            hi[a] = lo[a] + int64_t(rng() % 20);
        }
        uint64_t expected = 0;
        for (int64_t k = lo[2]; k < hi[2]; ++k)
            for (int64_t j = lo[1]; j < hi[1]; ++j)
                for (int64_t i = lo[0]; i < hi[0]; ++i) expected += voxels.get(i, j, k);
        ASSERT_EQ(voxels.count_box(lo, hi), expected) << trial;
        if (trial % 20) continue;
        SparseVoxels filled = voxels;
        filled.set_box(lo, hi);
        for (int64_t k = 0; k < g.dims[2]; ++k)
            for (int64_t j = 0; j < g.dims[1]; ++j)
                for (int64_t i = 0; i < g.dims[0]; ++i) {
                    const bool in_box = i >= lo[0] && i < hi[0] && j >= lo[1] && j < hi[1] &&
                                        k >= lo[2] && k < hi[2];
                    ASSERT_EQ(filled.get(i, j, k), in_box || voxels.get(i, j, k)) << trial;
                }
    }
}

// merge_bricks fills bricks on several threads and puts them in place as merge_brick would one
// after another: units naming the same brick OR together, all-zero units store nothing. Checked
// voxel by voxel against a dense copy of the random voxels each unit was given; a unit outside
// the grid is refused before anything is merged.
TEST(SparseVoxelMerges, ManyBricksAtOnceHoldTheVoxelsOfEveryUnit) {
    std::mt19937 rng(11);
    Grid g;
    g.dims = {37, 29, 41};
    SparseVoxels merged(g, 8);
    const size_t blocks = merged.blocks_per_brick();
    const auto nb = merged.brick_dims();
    const uint64_t bricks = uint64_t(nb[0] * nb[1] * nb[2]);
    std::vector<uint8_t> expected(size_t(g.dims[0] * g.dims[1] * g.dims[2]), 0);
    // 300 units over the grid's 120 bricks (so most bricks come several times), each with a few
    // random voxels of its brick that lie in the grid, and every fifth unit empty.
    std::vector<uint64_t> unit_brick(300);
    std::vector<std::vector<uint64_t>> unit_blocks(300, std::vector<uint64_t>(blocks, 0));
    for (size_t u = 0; u < unit_brick.size(); ++u) {
        const uint64_t brick = rng() % bricks;
        unit_brick[u] = brick;
        if (u % 5 == 0) continue;
        const int64_t b[3] = {int64_t(brick % uint64_t(nb[0])),
                              int64_t(brick / uint64_t(nb[0]) % uint64_t(nb[1])),
                              int64_t(brick / uint64_t(nb[0] * nb[1]))};
        for (int n = 0; n < 20; ++n) {
            int64_t local[3], v[3];
            for (int a = 0; a < 3; ++a) {
                local[a] = int64_t(rng() % 8);
                v[a] = 8 * b[a] + local[a];
            }
            if (v[0] >= g.dims[0] || v[1] >= g.dims[1] || v[2] >= g.dims[2]) continue;
            unit_blocks[u][size_t(local[0] / 4 + 2 * (local[1] / 4 + 2 * (local[2] / 4)))] |=
                uint64_t(1) << (local[0] % 4 + 4 * (local[1] % 4 + 4 * (local[2] % 4)));
            expected[size_t(v[0] + g.dims[0] * (v[1] + g.dims[1] * v[2]))] = 1;
        }
    }
    merged.merge_bricks(
        unit_brick.size(), [&](size_t u) { return unit_brick[u]; },
        [&](size_t u, uint64_t* out) { std::copy_n(unit_blocks[u].data(), blocks, out); });
    for (int64_t k = 0; k < g.dims[2]; ++k)
        for (int64_t j = 0; j < g.dims[1]; ++j)
            for (int64_t i = 0; i < g.dims[0]; ++i)
                ASSERT_EQ(merged.get(i, j, k),
                          expected[size_t(i + g.dims[0] * (j + g.dims[1] * k))] != 0)
                    << i << " " << j << " " << k;
    for (const uint64_t brick : merged.brick_indices()) {
        const uint64_t* words = merged.brick_blocks(brick);
        EXPECT_TRUE(std::any_of(words, words + blocks, [](uint64_t w) { return w != 0; }));
    }

    const SparseVoxels before = merged;
    EXPECT_THROW(merged.merge_bricks(
                     2, [&](size_t u) { return u == 0 ? uint64_t(0) : bricks; },
                     [&](size_t, uint64_t* out) { out[0] = 1; }),
                 oclvox::GridError);
    EXPECT_TRUE(merged.same_voxels(before));
}

// mark_box writes a window of any orientation: each axis contiguous in turn (a block's row of 4
// then goes as one word where it lies inside the box) and none. Checked voxel by voxel against
// get(), with bytes outside the marks (and a guard before the window) left as they were.
TEST(SparseVoxelBoxes, MarkBoxWindowsAreTheVoxelsInEveryOrientation) {
    std::mt19937 rng(5);
    SparseVoxels voxels = random_voxels(6000, rng);
    const Grid& g = voxels.grid();
    voxels.set_box({8, 4, 12}, {20, 16, 24});  // whole blocks, full rows
    for (int trial = 0; trial < 120; ++trial) {
        std::array<int64_t, 3> lo, hi, size;
        for (int a = 0; a < 3; ++a) {
            lo[a] = int64_t(rng() % uint32_t(g.dims[a] + 6)) - 3;
            hi[a] = lo[a] + 1 + int64_t(rng() % 24);
            size[a] = hi[a] - lo[a];
        }
        // Axis order of the window: the first is contiguous (stride 1) unless trial % 4 == 3.
        const int order = trial % 4;
        std::array<int64_t, 3> strides{};
        const int first_axis = order == 3 ? 0 : order;
        const int second = (first_axis + 1) % 3, third = (first_axis + 2) % 3;
        const int64_t unit = order == 3 ? 2 : 1;  // every other byte: no axis contiguous
        strides[first_axis] = unit;
        strides[second] = unit * size[first_axis];
        strides[third] = unit * size[first_axis] * size[second];
        // A guard before the window; none after it, so that a write past its end is out of bounds
        // (the sanitizer build of this test, scripts/sanitize.sh, reports it).
        const int64_t guard = 8, bytes = unit * size[0] * size[1] * size[2];
        std::vector<uint8_t> window(size_t(guard + bytes), 7);
        voxels.mark_box(lo, hi, strides, window.data() + guard);
        for (int64_t g0 = 0; g0 < guard; ++g0) ASSERT_EQ(window[size_t(g0)], 7) << trial;
        for (int64_t k = lo[2]; k < hi[2]; ++k)
            for (int64_t j = lo[1]; j < hi[1]; ++j)
                for (int64_t i = lo[0]; i < hi[0]; ++i) {
                    const int64_t at = guard + (i - lo[0]) * strides[0] + (j - lo[1]) * strides[1] +
                                       (k - lo[2]) * strides[2];
                    ASSERT_EQ(window[size_t(at)], voxels.get(i, j, k) ? 1 : 7)
                        << trial << " " << i << " " << j << " " << k;
                }
    }
}

// A face of a grid of 2^20 x 2^20 x 3 voxels meets 2^30 bricks; counting it walks the few stored
// bricks instead.
TEST(SparseVoxelBoxes, CountOfAHugeThinBoxWalksTheStoredBricks) {
    Grid g;
    g.dims = {int64_t(1) << 20, int64_t(1) << 20, 3};
    SparseVoxels voxels(g, 32);
    voxels.set(5, 7, 0);
    voxels.set((int64_t(1) << 20) - 1, 123456, 0);
    voxels.set(99, 99, 1);
    voxels.set_box({1000, 1000, 0}, {1010, 1020, 1});
    EXPECT_EQ(voxels.count_box({0, 0, 0}, {g.dims[0], g.dims[1], 1}), 2u + 200u);
    EXPECT_EQ(voxels.count(), 203u);
}

}  // namespace
