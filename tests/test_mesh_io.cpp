// Mesh loading: the real meshes load with the triangle counts, vertex counts and bounding boxes
// that the data README gives; coordinates come back bit for bit in every format, far from the
// origin too; polygons become triangles that cover exactly the polygon; scenes are placed by
// their node transforms; and missing, malformed or hostile files fail fast, without big
// allocations or leaks, with an InputError that names the file.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <malloc.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <new>
#include <sstream>
#include <thread>
#include <tuple>
#include <vector>

#include "oclvox/oclvox.hpp"

// Every operator new of the process (the library's and assimp's included) goes through here, so
// that a test can see the largest single request, and the bytes still held, around a load.
namespace allocation_tracking {
std::atomic<bool> measuring{false};
std::atomic<size_t> largest{0};
std::atomic<int64_t> live_bytes{0};
}  // namespace allocation_tracking

void* operator new(std::size_t size) {
    if (allocation_tracking::measuring && size > allocation_tracking::largest)
        allocation_tracking::largest = size;
    void* memory = std::malloc(size == 0 ? 1 : size);
    if (!memory) throw std::bad_alloc();
    allocation_tracking::live_bytes += int64_t(malloc_usable_size(memory));
    return memory;
}
void operator delete(void* memory) noexcept {
    if (!memory) return;
    allocation_tracking::live_bytes -= int64_t(malloc_usable_size(memory));
    std::free(memory);
}
void operator delete(void* memory, std::size_t) noexcept {
    operator delete(memory);
}
void* operator new[](std::size_t size) {
    return operator new(size);
}
void operator delete[](void* memory) noexcept {
    operator delete(memory);
}
void operator delete[](void* memory, std::size_t) noexcept {
    operator delete(memory);
}

namespace {

using oclvox::InputError;
using oclvox::Mesh;
using Vec3 = std::array<double, 3>;
namespace fs = std::filesystem;

const std::string kMeshDir = OCLVOX_MESH_DIR;
const std::string kSampleDir = OCLVOX_SAMPLE_DIR;

Vec3 sub(const Vec3& a, const Vec3& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double length(const Vec3& a) {
    return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
}

// Twice the vector area of triangle t.
Vec3 doubled_normal(const Mesh& mesh, const std::array<uint32_t, 3>& t) {
    const Vec3 &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
    return cross(sub(b, a), sub(c, a));
}

// Sum of the unsigned triangle areas: overlapping triangles count twice.
double unsigned_area(const Mesh& mesh) {
    double area = 0;
    for (const auto& t : mesh.triangles) area += 0.5 * length(doubled_normal(mesh, t));
    return area;
}

// The message of the InputError that loading `path` throws; a test failure if it throws
// anything else or nothing.
// Whether both sets hold the same voxel indices (their grids may be placed differently).
bool same_voxel_indices(const oclvox::SparseVoxels& a, const oclvox::SparseVoxels& b) {
    if (a.brick_indices() != b.brick_indices()) return false;
    for (const uint64_t index : a.brick_indices())
        if (!std::equal(a.brick_blocks(index), a.brick_blocks(index) + a.blocks_per_brick(),
                        b.brick_blocks(index)))
            return false;
    return true;
}

std::string input_error_of(const std::string& path) {
    try {
        oclvox::load_mesh(path);
    } catch (const InputError& error) {
        return error.what();
    } catch (const std::exception& error) {
        ADD_FAILURE() << path << " threw something other than InputError: " << error.what();
        return "";
    }
    ADD_FAILURE() << path << " loaded without an error";
    return "";
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

// A fresh folder for files a test writes, removed afterwards.
class MeshFiles : public testing::Test {
  protected:
    void SetUp() override {
        const auto* info = testing::UnitTest::GetInstance()->current_test_info();
        folder_ = fs::temp_directory_path() /
                  ("oclvox_mesh_io_" + std::to_string(getpid()) + "_" + info->name());
        fs::remove_all(folder_);
        fs::create_directories(folder_);
    }
    void TearDown() override { fs::remove_all(folder_); }

    std::string write(const std::string& name, const std::string& bytes) {
        const std::string path = (folder_ / name).string();
        std::ofstream(path, std::ios::binary) << bytes;
        return path;
    }

    fs::path folder_;
};

// ---------------------------------------------------------------------------------------------
// The shared real meshes against the README table
// ---------------------------------------------------------------------------------------------

struct ReadmeRow {
    const char* file;
    size_t tris, verts;  // "tris", and the welded "verts" (distinct positions that faces use)
    Vec3 lo, hi;         // "bbox min .. max"
};

const ReadmeRow kReadmeTable[] = {
    {"bunny00.off", 75408, 37706, {-0.49896, -0.49343, -0.38649}, {0.49922, 0.49377, 0.38609}},
    {"stanford-bunny.obj",
     69451,
     34834,
     {-0.09469, 0.032987, -0.061874},
     {0.061009, 0.187321, 0.0588}},
    {"spot.obj", 5856, 2930, {-0.47155, -0.73678, -0.66891}, {0.47155, 0.95365, 1.049}},
    {"spot_quadrangulated.obj",
     5856,
     2930,
     {-0.47155, -0.73678, -0.66891},
     {0.47155, 0.95365, 1.049}},
    {"double-torus-example.off", 466, 231, {-5.8483, -3.7842, -1.5863}, {3.4197, 4.0699, 3.2455}},
    {"mug.obj", 24544, 12272, {-4.4693, 0.000127, -4.4692}, {7.8527, 7.1925, 4.4692}},
    {"TR12J_OCC.stl", 26966, 13441, {-244.5, -256, 0}, {261.5, 244.5, 320.5}},
    {"flange.stl", 6468, 3228, {-0.026009, -0.0275, -0.02375}, {0.026009, 0.0225, 0.00225}},
    {"horse.ply", 96966, 48485, {-0.042003, -0.09167, -0.076418}, {0.042003, 0.09167, 0.076418}},
    {"motorBike.obj", 331653, 132871, {-0.29167, -0.35029, -4.2e-05}, {1.7512, 0.33227, 1.3515}},
    {"buildings.obj", 400020, 200035, {8.1902, 18.604, 0}, {237.28, 158.66, 76}},
    {"Sterngarten_Wien_innerArea.obj",
     71673,
     71772,
     {-66.61, -55.51, -5.83},
     {75.12, 85.80, 17.52}},
};

class ReadmeMesh : public testing::TestWithParam<ReadmeRow> {};

TEST_P(ReadmeMesh, LoadsWithTheReadmeCountsAndBoundingBox) {
    const ReadmeRow& row = GetParam();
    const Mesh mesh = oclvox::load_mesh(kMeshDir + "/" + row.file);
    EXPECT_EQ(mesh.triangles.size(), row.tris);
    // Loading welds equal positions and drops unused ones, as the README's count does.
    EXPECT_EQ(mesh.positions.size(), row.verts);

    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (const auto& t : mesh.triangles)
        for (uint32_t v : t)
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], mesh.positions[v][k]);
                hi[k] = std::max(hi[k], mesh.positions[v][k]);
            }
    // The README rounds to about 5 significant digits, so "1e-4 relative" is taken relative to
    // the box size: a bound of 0.000127 in a 12-unit box is then not held to 1e-8.
    double extent = 0;
    for (int k = 0; k < 3; ++k) extent = std::max(extent, row.hi[k] - row.lo[k]);
    for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(lo[k], row.lo[k], 1e-4 * extent) << "min, axis " << k;
        EXPECT_NEAR(hi[k], row.hi[k], 1e-4 * extent) << "max, axis " << k;
    }
}

INSTANTIATE_TEST_SUITE_P(DataReadme, ReadmeMesh, testing::ValuesIn(kReadmeTable),
                         [](const testing::TestParamInfo<ReadmeRow>& info) {
                             std::string name = info.param.file;
                             for (char& c : name)
                                 if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                             return name;
                         });

TEST(BundledSample, SpotLoadsLikeTheSharedCopy) {
    const Mesh sample = oclvox::load_mesh(kSampleDir + "/spot.obj");
    const Mesh shared = oclvox::load_mesh(kMeshDir + "/spot.obj");
    EXPECT_EQ(sample.triangles, shared.triangles);
    EXPECT_EQ(sample.positions, shared.positions);
    EXPECT_EQ(sample.triangles.size(), 5856u);
}

// ---------------------------------------------------------------------------------------------
// Polygons
// ---------------------------------------------------------------------------------------------

// Polygons of an OFF file read independently: positions and corner lists.
struct OffPolygons {
    std::vector<Vec3> positions;
    std::vector<std::vector<size_t>> faces;
};

OffPolygons read_off_text(const std::string& path) {
    std::ifstream file(path);
    std::string keyword;
    size_t vertex_count = 0, face_count = 0, edge_count = 0;
    file >> keyword >> vertex_count >> face_count >> edge_count;
    OffPolygons off;
    off.positions.resize(vertex_count);
    for (Vec3& p : off.positions) file >> p[0] >> p[1] >> p[2];
    off.faces.resize(face_count);
    for (auto& face : off.faces) {
        size_t n = 0;
        file >> n;
        face.resize(n);
        for (size_t& corner : face) file >> corner;
    }
    return off;
}

// Area of a planar polygon: half the length of its Newell vector.
double polygon_area(const std::vector<Vec3>& positions, const std::vector<size_t>& face) {
    Vec3 sum{0, 0, 0};
    for (size_t k = 0; k < face.size(); ++k) {
        const Vec3 c = cross(positions[face[k]], positions[face[(k + 1) % face.size()]]);
        for (int a = 0; a < 3; ++a) sum[a] += c[a];
    }
    return 0.5 * length(sum);
}

double fan_area(const std::vector<Vec3>& positions, const std::vector<size_t>& face) {
    double area = 0;
    for (size_t k = 1; k + 1 < face.size(); ++k)
        area += 0.5 * length(cross(sub(positions[face[k]], positions[face[0]]),
                                   sub(positions[face[k + 1]], positions[face[0]])));
    return area;
}

struct PolygonAreas {
    double exact = 0, fan = 0;
    size_t triangles = 0;
};

PolygonAreas areas_of(const OffPolygons& off) {
    PolygonAreas areas;
    for (const auto& face : off.faces) {
        areas.exact += polygon_area(off.positions, face);
        areas.fan += fan_area(off.positions, face);
        areas.triangles += face.size() - 2;
    }
    return areas;
}

TEST(Polygons, ConcaveOffPolygonsTriangulateToTheirOwnArea) {
    const std::string path = kMeshDir + "/double-torus-example.off";
    const PolygonAreas expected = areas_of(read_off_text(path));
    // The file's concave polygons make a fan overlap, so this test can tell the two apart.
    ASSERT_GT(expected.fan - expected.exact, 1e-3);

    const Mesh mesh = oclvox::load_mesh(path);
    EXPECT_EQ(mesh.triangles.size(), expected.triangles);
    EXPECT_NEAR(unsigned_area(mesh), expected.exact, 1e-9 * expected.exact);
}

TEST_F(MeshFiles, ConcaveObjPolygonsTriangulateToTheirOwnArea) {
    // The same concave 5/6/7-gons, written as OBJ, go through oclvox's own triangulation.
    const OffPolygons off = read_off_text(kMeshDir + "/double-torus-example.off");
    std::ostringstream obj;
    obj.precision(17);
    for (const Vec3& p : off.positions) obj << "v " << p[0] << " " << p[1] << " " << p[2] << "\n";
    for (const auto& face : off.faces) {
        obj << "f";
        for (size_t corner : face) obj << " " << corner + 1;
        obj << "\n";
    }
    const PolygonAreas expected = areas_of(off);
    const Mesh mesh = oclvox::load_mesh(write("double-torus.obj", obj.str()));
    EXPECT_EQ(mesh.triangles.size(), expected.triangles);
    EXPECT_NEAR(unsigned_area(mesh), expected.exact, 1e-9 * expected.exact);
}

TEST_F(MeshFiles, ObjQuadGivesTwoTrianglesWithTheQuadsArea) {
    // A 2 x 3 rectangle, tilted out of the coordinate planes: area 6.
    const Mesh mesh = oclvox::load_mesh(write("quad.obj",
                                              "v 0 0 0\n"
                                              "v 2 0 0\n"
                                              "v 2 3 3\n"
                                              "v 0 3 3\n"
                                              "f 1 2 3 4\n"));
    ASSERT_EQ(mesh.triangles.size(), 2u);
    EXPECT_NEAR(unsigned_area(mesh), 2 * std::sqrt(18.0), 1e-12);
}

TEST_F(MeshFiles, ConcaveQuadIsSplitThroughItsReflexCorner) {
    // An arrowhead: corner 4 at (0.5, -0.1) is reflex. The diagonal 1-3 is the shorter one but
    // runs outside the quad; the area is 0.5*1*10 - 0.5*1*0.1 = 4.95.
    const Mesh mesh = oclvox::load_mesh(write("dart.obj",
                                              "v 0 0 0\n"
                                              "v 0.5 -10 0\n"
                                              "v 1 0 0\n"
                                              "v 0.5 -0.1 0\n"
                                              "f 1 2 3 4\n"));
    ASSERT_EQ(mesh.triangles.size(), 2u);
    EXPECT_NEAR(unsigned_area(mesh), 4.95, 1e-12);
    // The quad winds counter-clockwise seen from +z; both triangles must keep that winding.
    for (const auto& t : mesh.triangles) EXPECT_GT(doubled_normal(mesh, t)[2], 0);
}

TEST_F(MeshFiles, ConcaveHexagonKeepsItsAreaAndWinding) {
    // An L shape, counter-clockwise in the xy plane: 2x2 square minus a 1x1 corner, area 3.
    const Mesh mesh = oclvox::load_mesh(write("ell.obj",
                                              "v 0 0 5\nv 2 0 5\nv 2 1 5\n"
                                              "v 1 1 5\nv 1 2 5\nv 0 2 5\n"
                                              "f 1 2 3 4 5 6\n"));
    ASSERT_EQ(mesh.triangles.size(), 4u);
    EXPECT_NEAR(unsigned_area(mesh), 3.0, 1e-12);
    for (const auto& t : mesh.triangles) EXPECT_GT(doubled_normal(mesh, t)[2], 0);
}

TEST_F(MeshFiles, GroupsObjectsAndRelativeIndicesMergeIntoOneMesh) {
    const Mesh mesh = oclvox::load_mesh(write("groups.obj",
                                              "o first\n"
                                              "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                              "f 1 2 3\n"
                                              "g second\n"
                                              "v 0 0 1\nv 1 0 1\nv 0 1 1\n"
                                              "f -3 -2 -1\n"));
    ASSERT_EQ(mesh.triangles.size(), 2u);
    ASSERT_EQ(mesh.positions.size(), 6u);
    for (uint32_t v : mesh.triangles[1]) EXPECT_EQ(mesh.positions[v][2], 1.0);
}

TEST_F(MeshFiles, DegenerateTrianglesAreKept) {
    const Mesh obj = oclvox::load_mesh(write("degenerate.obj",
                                             "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                             "f 1 2 3\nf 1 2 2\n"));
    EXPECT_EQ(obj.triangles.size(), 2u);
    const Mesh stl = oclvox::load_mesh(write("degenerate.stl",
                                             "solid s\n"
                                             "facet normal 0 0 1\nouter loop\n"
                                             "vertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                             "endloop\nendfacet\n"
                                             "facet normal 0 0 1\nouter loop\n"
                                             "vertex 0 0 0\nvertex 1 0 0\nvertex 1 0 0\n"
                                             "endloop\nendfacet\n"
                                             "endsolid s\n"));
    EXPECT_EQ(stl.triangles.size(), 2u);
    const Mesh off = oclvox::load_mesh(write("degenerate.off",
                                             "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n2 0 0\n"
                                             "3 0 1 2\n3 0 1 3\n"));
    EXPECT_EQ(off.triangles.size(), 2u);
}

// ---------------------------------------------------------------------------------------------
// Formats
// ---------------------------------------------------------------------------------------------

std::string binary_stl(const std::vector<std::array<float, 9>>& facets, uint32_t declared) {
    std::string bytes(80, ' ');
    bytes.append(reinterpret_cast<const char*>(&declared), 4);  // little-endian host
    for (const auto& facet : facets) {
        const float normal[3] = {0, 0, 1};
        bytes.append(reinterpret_cast<const char*>(normal), sizeof normal);
        bytes.append(reinterpret_cast<const char*>(facet.data()), 9 * sizeof(float));
        bytes.append(2, '\0');
    }
    return bytes;
}

TEST_F(MeshFiles, BinaryStlFacetsAreWeldedAtSharedCorners) {
    // Two facets sharing the edge (0,0,0)-(1,1,0): 6 corners, 4 distinct positions.
    const std::string path =
        write("square.stl",
              binary_stl({{0, 0, 0, 1, 0, 0, 1, 1, 0}, {0, 0, 0, 1, 1, 0, 0, 1, 0.25f}}, 2));
    const Mesh mesh = oclvox::load_mesh(path);
    ASSERT_EQ(mesh.triangles.size(), 2u);
    EXPECT_EQ(mesh.positions.size(), 4u);
    EXPECT_EQ(mesh.triangles[0][0], mesh.triangles[1][0]);
    EXPECT_EQ(mesh.triangles[0][2], mesh.triangles[1][1]);
    EXPECT_EQ(mesh.positions[mesh.triangles[1][2]], (Vec3{0, 1, 0.25}));
}

TEST_F(MeshFiles, WeldingNumbersPositionsInTheOrderTheTrianglesMeetThem) {
    // Vertices 1 and 5 share a place, 3 and 6 differ only by the sign of a zero, 4 is unused.
    // The triangles meet the places in the order 7 (vertex 7), 2, 1=5, 3=6: so they are welded
    // vertices 0, 1, 2, 3, holding the coordinates of the first vertex met at each place.
    const std::string obj =
        "v 1 0 0\nv 0 1 0\nv -0.0 0 2\nv 9 9 9\nv 1 0 0\nv 0 0 2\nv 0 0 7\n"
        "f 7 2 1\nf 5 3 2\nf 6 7 5\n";
    const Mesh mesh = oclvox::load_mesh(write("weld_order.obj", obj));
    ASSERT_EQ(mesh.positions.size(), 4u);
    EXPECT_EQ(mesh.positions[0], (Vec3{0, 0, 7}));
    EXPECT_EQ(mesh.positions[1], (Vec3{0, 1, 0}));
    EXPECT_EQ(mesh.positions[2], (Vec3{1, 0, 0}));
    EXPECT_TRUE(std::signbit(mesh.positions[3][0]));  // vertex 3's -0.0, met before vertex 6
    const std::vector<std::array<uint32_t, 3>> expected = {{0, 1, 2}, {2, 3, 1}, {3, 0, 2}};
    ASSERT_EQ(mesh.triangles.size(), expected.size());
    for (size_t t = 0; t < expected.size(); ++t)
        for (int c = 0; c < 3; ++c) EXPECT_EQ(mesh.triangles[t][c], expected[t][c]) << t << c;
}

// Files over a mebibyte are parsed in parts in parallel: relative indices reaching back into
// earlier parts, and errors in late parts, read as in one pass. Quads of 4 vertices and one face
// each: with relative indices the mesh equals the one written with absolute indices, whether the
// parts (cut after a line end, about a mebibyte apart) split quads or, with each face line padded
// by a long comment, fall between them; an error on a late line names that line.
TEST_F(MeshFiles, LargeObjReadsInPartsAsInOnePass) {
    auto obj = [](int quads, bool relative, size_t pad, int bad_quad, const char* bad_face) {
        std::string text;
        for (int q = 0; q < quads; ++q) {
            for (int v = 0; v < 4; ++v)
                text += "v " + std::to_string(q) + "." + std::to_string(v) + "25 " +
                        std::to_string(v & 1) + " " + std::to_string(v >> 1) + "\n";
            if (q == bad_quad)
                text += bad_face;
            else if (relative)
                text += "f -4 -3/1 -2//1 -1/1/1";
            else
                text += "f " + std::to_string(4 * q + 1) + " " + std::to_string(4 * q + 2) + " " +
                        std::to_string(4 * q + 3) + " " + std::to_string(4 * q + 4);
            text += (pad ? " # " + std::string(pad, 'x') : "") + "\n";
        }
        return text;
    };
    for (const auto& [quads, pad] : {std::pair<int, size_t>{60000, 0}, {200, 20000}}) {
        SCOPED_TRACE(std::to_string(quads) + " quads, comments of " + std::to_string(pad));
        const std::string relative = obj(quads, true, pad, -1, "");
        ASSERT_GT(relative.size(), size_t(3) << 20);
        const Mesh a = oclvox::load_mesh(write("relative.obj", relative));
        const Mesh b = oclvox::load_mesh(write("absolute.obj", obj(quads, false, pad, -1, "")));
        EXPECT_EQ(a.triangles.size(), size_t(2 * quads));
        EXPECT_EQ(a.positions, b.positions);
        EXPECT_EQ(a.triangles, b.triangles);
    }
    // Quad 50000's face is line 5 * 50000 + 5 and face 50001, after 200004 vertices.
    const std::string bad =
        input_error_of(write("bad.obj", obj(60000, true, 0, 50000, "f -1 -2 x")));
    EXPECT_TRUE(contains(bad, "line 250005:")) << bad;
    const std::string before =
        input_error_of(write("before.obj", obj(60000, true, 0, 50000, "f -1 -2 -200005")));
    EXPECT_TRUE(contains(before, "line 250005: face 50001 has a relative vertex index")) << before;
}

TEST_F(MeshFiles, AsciiStlWithSeveralSolidsLoadsEverySolid) {
    std::string text;
    for (const char* z : {"0", "1", "2"})
        text += std::string("solid part") + z + "\nfacet normal 0 0 1\nouter loop\n" +
                "vertex 0 0 " + z + "\nvertex 1 0 " + z + "\nvertex 0 1 " + z +
                "\nendloop\nendfacet\nendsolid part" + z + "\n";
    const Mesh mesh = oclvox::load_mesh(write("solids.stl", text));
    EXPECT_EQ(mesh.triangles.size(), 3u);
}

TEST_F(MeshFiles, ExtensionIsCaseInsensitive) {
    const std::string triangle_obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    EXPECT_EQ(oclvox::load_mesh(write("upper.OBJ", triangle_obj)).triangles.size(), 1u);
    EXPECT_EQ(oclvox::load_mesh(write("mixed.Off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"))
                  .triangles.size(),
              1u);
    EXPECT_EQ(oclvox::load_mesh(write("upper.STL", binary_stl({{0, 0, 0, 1, 0, 0, 0, 1, 0}}, 1)))
                  .triangles.size(),
              1u);
}

TEST_F(MeshFiles, MissingMaterialLibraryDoesNotFailTheLoad) {
    const Mesh mesh = oclvox::load_mesh(write("materials.obj",
                                              "mtllib does-not-exist.mtl\n"
                                              "usemtl red\n"
                                              "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"));
    EXPECT_EQ(mesh.triangles.size(), 1u);
}

// ---------------------------------------------------------------------------------------------
// Non-finite coordinates
// ---------------------------------------------------------------------------------------------

TEST_F(MeshFiles, NanInAUsedObjVertexFailsTheLoad) {
    const std::string path = write("nan.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
    const std::string message = input_error_of(path);
    EXPECT_TRUE(contains(message, path)) << message;
    EXPECT_TRUE(contains(message, "vertex 1")) << message;
    EXPECT_TRUE(contains(message, "triangle 0")) << message;
}

TEST_F(MeshFiles, InfinityInAUsedObjVertexFailsTheLoad) {
    const std::string path = write("inf.obj", "v 0 0 0\nv 1 0 -inf\nv 0 1 0\nf 1 2 3\n");
    EXPECT_TRUE(contains(input_error_of(path), "not a finite number"));
}

TEST_F(MeshFiles, NanInAnUnusedObjVertexIsHarmless) {
    const Mesh mesh = oclvox::load_mesh(
        write("unused-nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan nan nan\nf 1 2 3\n"));
    EXPECT_EQ(mesh.triangles.size(), 1u);
    for (const Vec3& p : mesh.positions)
        for (double c : p) EXPECT_TRUE(std::isfinite(c));
}

TEST_F(MeshFiles, NanInAnOffVertexFailsTheLoad) {
    const std::string path = write("nan.off", "OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n");
    EXPECT_TRUE(contains(input_error_of(path), "vertex 1"));
}

// ---------------------------------------------------------------------------------------------
// Files that cannot be loaded
// ---------------------------------------------------------------------------------------------

TEST_F(MeshFiles, MissingFileFails) {
    const std::string path = (folder_ / "absent.obj").string();
    const std::string message = input_error_of(path);
    EXPECT_TRUE(contains(message, path)) << message;
    EXPECT_TRUE(contains(message, "does not exist")) << message;
}

TEST_F(MeshFiles, FolderFails) {
    fs::create_directory(folder_ / "folder.stl");
    EXPECT_TRUE(contains(input_error_of((folder_ / "folder.stl").string()), "folder"));
}

TEST_F(MeshFiles, UnreadableFileFails) {
    const std::string path = write("locked.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    chmod(path.c_str(), 0);
    if (std::ifstream(path).good()) GTEST_SKIP() << "running with rights that read any file";
    EXPECT_TRUE(contains(input_error_of(path), "cannot be opened")) << input_error_of(path);
}

TEST_F(MeshFiles, EmptyFileFailsInEveryFormat) {
    for (const char* name : {"empty.obj", "empty.stl", "empty.ply", "empty.off"}) {
        const std::string path = write(name, "");
        const std::string message = input_error_of(path);
        EXPECT_TRUE(contains(message, path) && contains(message, "empty")) << message;
    }
}

TEST_F(MeshFiles, UnknownOrMissingExtensionFails) {
    EXPECT_TRUE(contains(input_error_of(write("mesh.3ds", "data")), "unknown extension '.3ds'"));
    EXPECT_TRUE(contains(input_error_of(write("mesh", "data")), "no extension"));
}

TEST_F(MeshFiles, FileWithoutTrianglesFails) {
    EXPECT_TRUE(contains(input_error_of(write("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")),
                         "no triangles"));
    EXPECT_TRUE(contains(input_error_of(write("lines.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\n")),
                         "no triangles"));
    input_error_of(write("empty-solid.stl", "solid nothing\nendsolid nothing\n"));
    input_error_of(write("no-faces.stl", binary_stl({}, 0)));
}

TEST_F(MeshFiles, ObjFaceIndexOutOfRangeFails) {
    const std::string vertices = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    EXPECT_TRUE(contains(input_error_of(write("past-end.obj", vertices + "f 1 2 4\n")),
                         "refers to vertex 4"));
    EXPECT_TRUE(contains(input_error_of(write("before-start.obj", vertices + "f 1 2 -9\n")),
                         "before the first vertex"));
    // atoi would read this as -1, a valid relative index.
    EXPECT_TRUE(
        contains(input_error_of(write("huge.obj", vertices + "f 1 2 99999999999999999999\n")),
                 "line 4: the face index '99999999999999999999'"));
    input_error_of(write("huge-negative.obj", vertices + "f 1 2 -99999999999999999999\n"));
    input_error_of(write("zero.obj", vertices + "f 0 1 2\n"));
}

// Face indices are read as a strict whole-number parse reads them, whichever way they are
// written: a sign, leading zeros, up to 18 digits (read inline) and more (read by from_chars),
// relative or not; anything else in the word fails. Worked out by hand from the file.
TEST_F(MeshFiles, ObjFaceIndicesReadAsWholeNumbersWhateverTheirDigits) {
    const std::string vertices = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n";
    const oclvox::Mesh mesh = oclvox::load_mesh(
        write("digits.obj", vertices + "f +1 002 000000000000000003\n"
                                       "f 0000000000000000001 -1 -000000000000000002\n"
                                       "f 4/1/1 +3//2 -4/+1\n"));
    const std::vector<std::array<uint32_t, 3>> expected{{0, 1, 2}, {0, 3, 2}, {3, 2, 0}};
    EXPECT_EQ(mesh.triangles, expected);
    for (const char* word : {"3x", "+", "-", "3.0", "1e0", "++3", "-+3", "0x3", "3/a", "3//b"})
        EXPECT_TRUE(contains(
            input_error_of(write("bad.obj", vertices + "f 1 2 " + std::string(word) + "\n")),
            "line 5: "))
            << word;
}

// Vertex and face lines read the same whatever separates their words (spaces, tabs, vertical
// tabs, form feeds), however their lines end ("\n", "\r\n", a lone "\r", the end of the file),
// wherever a comment starts (right after a number too), and whichever way an index is written (up
// to nine digits and more, a sign, empty texture or normal parts, more parts than three, relative):
// the common spellings take a quicker reading than the rest, and the two must agree. Expected
// positions worked out by hand from the text.
TEST_F(MeshFiles, ObjLinesReadTheSameWhateverTheirSpacingAndLineEnds) {
    const std::string text =
        "v 1 2 3\n"                       // vertex 1
        "v\t+4.5\t-0\t6e1 1.0 # a w\r\n"  // vertex 2: (4.5, -0, 60)
        "v 7\v8\f9#comment\r"             // vertex 3, a lone CR
        "vn 0 0 1\n"                      // skipped
        "v1 9 9 9\n"                      // keyword v1: skipped
        "  v   0.125   0.25   0.5  \n"    // vertex 4
        "f 1 2 3\n"                       // (1, 2, 3)
        "f 1/ 2// 3/1/1/1#x\n"            // (1, 2, 3)
        "f\t+1 000000002 -1\n"            // (1, 2, 4)
        "f 000000000004 3 000000002\r\n"  // (4, 3, 2)
        "fo 1 2 3\n"                      // keyword fo: skipped
        "f 4/1 1//1\v2";                  // (4, 1, 2), no line end
    const Mesh mesh = oclvox::load_mesh(write("spellings.obj", text));
    const Vec3 vertex[5] = {{}, {1, 2, 3}, {4.5, -0.0, 60}, {7, 8, 9}, {0.125, 0.25, 0.5}};
    const std::vector<std::array<int, 3>> faces = {
        {1, 2, 3}, {1, 2, 3}, {1, 2, 4}, {4, 3, 2}, {4, 1, 2}};
    ASSERT_EQ(mesh.triangles.size(), faces.size());
    for (size_t t = 0; t < faces.size(); ++t)
        for (int c = 0; c < 3; ++c)
            EXPECT_EQ(mesh.positions[mesh.triangles[t][c]], vertex[faces[t][c]]) << t << " " << c;
    // Broken words fail on their line whatever precedes them on it.
    const std::string three = "v 0 0 0\nv 1 0 0\r\nv 0 1 0\r";
    for (const char* line : {"f 1 2 3x", "f 1 2 3/x", "f 1 2 0", "f 1/0 2 3", "f 1 2 3#\nv 1 2 3e",
                             "f 1 2 1234567890x", "f 1 2 +", "f 1 2\v3/x", "v 1 2", "v 1 2 #3",
                             "v 1 2 0x1", "v 1 2 1e999"}) {
        const std::string message = input_error_of(write("broken.obj", three + line + "\n"));
        EXPECT_TRUE(contains(
            message, std::string(line).find('\n') != std::string::npos ? "line 5: " : "line 4: "))
            << line << ": " << message;
    }
}

// OFF and ascii PLY numbers read the same whether they take the one-pass reading (a plain number
// ending where its word does) or the strict one (a comment right after a number, 19 digits, a
// sign, other blanks). Expected positions worked out by hand from the text.
TEST_F(MeshFiles, OffAndAsciiPlyNumbersReadTheSameWhateverTheirSpelling) {
    const Vec3 expected[4] = {{1, 2, 3}, {4.5, -0.0, 60}, {7, 8, 9}, {0.125, 0.25, 0.5}};
    const std::string off =
        "OFF\n4 2 0\n"
        "1 2 3\n"
        "+4.5\t-0\v6e1#comment\n"
        "7\f8 9 1 0 0 # a normal after x y z\r\n"
        "0.125 0.25 +0.5\n"
        "3 0 1 +2\n"
        "0000000000000000003 0000000000000000000 2 3#x\n";
    const std::string ply =
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty uchar red\nproperty float x\n"
        "property double y\nproperty int z\nelement face 2\n"
        "property list uchar int vertex_indices\nend_header\n"
        "1.5 1 2 3\n"  // red is skipped, unread
        "0 +4.5\t-0\v60\n"
        "0 7\f8 9\r\n"
        "0 0.125 0.25 +000000000000000000000000000000000001\n"
        "3 0 1 +2\n"
        "0000000000000000003 0000000000000000000 2 3\n";
    for (const auto& [name, text] : {std::pair{"spellings.off", off}, {"spellings.ply", ply}}) {
        SCOPED_TRACE(name);
        const Mesh mesh = oclvox::load_mesh(write(name, text));
        ASSERT_EQ(mesh.triangles.size(), 2u);
        const int corners[2][3] = {{0, 1, 2}, {0, 2, 3}};
        for (int t = 0; t < 2; ++t)
            for (int c = 0; c < 3; ++c) {
                Vec3 want = expected[corners[t][c]];
                if (name == std::string("spellings.ply") && corners[t][c] == 3) want[2] = 1;
                EXPECT_EQ(mesh.positions[mesh.triangles[t][c]], want) << t << " " << c;
            }
    }
}

TEST_F(MeshFiles, OffAndPlyFaceIndexOutOfRangeFails) {
    EXPECT_TRUE(
        contains(input_error_of(write("index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n")),
                 "out of range"));
    const std::string ply_header =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n";
    EXPECT_TRUE(
        contains(input_error_of(write("index.ply", ply_header + "3 0 1 7\n")), "out of range"));
    input_error_of(write("negative.ply", ply_header + "3 0 1 -5\n"));
}

TEST_F(MeshFiles, MalformedContentFails) {
    EXPECT_TRUE(contains(input_error_of(write("comma.obj",
                                              "v 0 0 0\nv 1,5 0 0\nv 0 1 0\n"
                                              "f 1 2 3\n")),
                         "line 2: the vertex coordinate '1,5' is not a number"));
    EXPECT_TRUE(contains(input_error_of(write("short.obj", "v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")),
                         "fewer than 3 coordinates"));
    const std::string garbage("\x00\xff\x12 not a mesh \x7f", 17);
    for (const char* name : {"garbage.stl", "garbage.ply", "garbage.off"})
        input_error_of(write(name, garbage));
    input_error_of(write("bad-number.stl",
                         "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                         "vertex 1 abc 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid s\n"));
}

TEST_F(MeshFiles, HostileFilesFailFastWithoutCrashing) {
    std::string truncated = binary_stl({{0, 0, 0, 1, 0, 0, 0, 1, 0}}, 100);
    input_error_of(write("truncated.stl", truncated));
    input_error_of(write("cut-mid-facet.stl", truncated.substr(0, 100)));
    input_error_of(write("count-4e9.stl", binary_stl({}, 4000000000u)));
    input_error_of(write("cut.stl",
                         "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                         "vertex 1 0"));

    // Headers and list lengths that declare far more than the file holds. Assimp would
    // allocate for the declared sizes: gigabytes and minutes for these few bytes.
    const std::string binary_header =
        "ply\nformat binary_little_endian 1.0\nelement vertex 400000000\nproperty float x\n"
        "property float y\nproperty float z\nelement face 400000000\n"
        "property list uchar int vertex_indices\nend_header\n";
    const float corners[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    EXPECT_TRUE(contains(
        input_error_of(write(
            "lying.ply",
            binary_header + std::string(reinterpret_cast<const char*>(corners), sizeof corners))),
        "declares 400000000 'vertex' records"));
    input_error_of(write("lying-ascii.ply",
                         "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\n"
                         "property float y\nproperty float z\nelement face 3\n"
                         "property list uchar int vertex_indices\nend_header\n"
                         "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
    EXPECT_TRUE(
        contains(input_error_of(
                     write("long-list.ply",
                           "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
                           "property float x\nproperty float y\nproperty float z\nelement face 1\n"
                           "property list uint int vertex_indices\nend_header\n" +
                               std::string(reinterpret_cast<const char*>(corners), sizeof corners) +
                               std::string("\xff\xff\xff\x7f", 4))),
                 "the file ends inside 'face' record 0"));
    // Records of one size, read where they lie, after a list that took more than its length byte:
    // the third vertex's last coordinate is missing.
    const std::string face = std::string("\x03", 1) + std::string(12, '\0');
    EXPECT_TRUE(contains(
        input_error_of(write("short-vertices.ply",
                             "ply\nformat binary_little_endian 1.0\nelement face 1\n"
                             "property list uchar int vertex_indices\nelement vertex 3\n"
                             "property float x\nproperty float y\nproperty float z\nend_header\n" +
                                 face +
                                 std::string(reinterpret_cast<const char*>(corners),
                                             sizeof corners - sizeof(float)))),
        "the file ends inside 'vertex' record 2 (of 3)"));
    input_error_of(write("long-list-ascii.ply",
                         "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                         "property float y\nproperty float z\nelement face 1\n"
                         "property list uint int vertex_indices\nend_header\n"
                         "0 0 0\n1 0 0\n0 1 0\n2000000000 0 1 2\n"));
    EXPECT_TRUE(contains(input_error_of(write("lying.off",
                                              "OFF\n400000000 400000000 0\n0 0 0\n"
                                              "1 0 0\n0 1 0\n3 0 1 2\n")),
                         "declares 400000000 vertices"));
    input_error_of(write("short.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n"));
}

// ---------------------------------------------------------------------------------------------
// Hostile input found by fuzzing (issue 11): no big allocation, no leak, only InputError
// ---------------------------------------------------------------------------------------------

// The largest single request to operator new while `load` runs.
template <class Load>
size_t largest_allocation_during(Load load) {
    allocation_tracking::largest = 0;
    allocation_tracking::measuring = true;
    load();
    allocation_tracking::measuring = false;
    return allocation_tracking::largest;
}

// Loads that fail, so that the message (allocated by the exception) does not count.
void load_expecting_input_error(const std::string& path) {
    try {
        oclvox::load_mesh(path);
        ADD_FAILURE() << path << " loaded without an error";
    } catch (const InputError&) {
    }
}

TEST_F(MeshFiles, OffCountWordsParseStrictlyAndAllocateNothingBig) {
    // A count word with trailing junk or an embedded NUL used to skip the header-count guard, and
    // the loader allocated for its leading digits (10-15 GB, or a bare std::bad_alloc).
    const std::string cases[] = {std::string("5 666666666\0006", 13), "9 0977853853f",
                                 "9 4000000000f"};
    for (const std::string& bytes : cases) {
        const std::string path = write("count.off", bytes);
        const std::string message = input_error_of(path);
        EXPECT_TRUE(contains(message, path) && contains(message, "face count")) << message;
        EXPECT_LT(largest_allocation_during([&] { load_expecting_input_error(path); }), 1u << 20)
            << message;
    }
    EXPECT_TRUE(contains(input_error_of(write("nul.off", std::string("5 666666666\0006", 13))),
                         "line 1: the face count '666666666\\x006'"));
}

TEST_F(MeshFiles, DeclaredCountsAreCheckedBeforeAllocating) {
    // Each declares far more than its few bytes hold; none may cost more than a megabyte.
    const std::string paths[] = {
        write("off.off", "OFF\n100000000 1 0\n0 0 0\n"),
        write("ply.ply",
              "ply\nformat binary_little_endian 1.0\nelement vertex 100000000\n"
              "property double x\nproperty double y\nproperty double z\nend_header\n"),
        write("ply-ascii.ply",
              "ply\nformat ascii 1.0\nelement vertex 100000000\nproperty double x\n"
              "property double y\nproperty double z\nend_header\n0 0 0\n"),
        write("stl.stl", std::string(80, 'x') + std::string("\xff\xff\xff\x0f", 4)),
    };
    for (const std::string& path : paths) {
        EXPECT_TRUE(contains(input_error_of(path), "the header declares")) << input_error_of(path);
        EXPECT_LT(largest_allocation_during([&] { load_expecting_input_error(path); }), 1u << 20)
            << path;
    }
}

TEST_F(MeshFiles, FailedLoadsLeakNothing) {
    // The ASCII STL error path used to leak the facets read so far.
    const std::string paths[] = {
        write("cut.stl", "solid\nfacet normal"),
        write("cut2.stl", "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"),
        write("bad.ply",
              "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
              "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 x\n"),
        write("bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n"),
        write("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
        write("bad.gltf", "{\"asset\":{\"version\":\"2.0\"},\"meshes\":[{\"primitives\":[]}]"),
    };
    for (const std::string& path : paths) {
        load_expecting_input_error(path);  // first use: lazily built statics
        const int64_t live_before = allocation_tracking::live_bytes;
        load_expecting_input_error(path);
        EXPECT_EQ(allocation_tracking::live_bytes - live_before, 0) << path;
    }
    EXPECT_TRUE(contains(input_error_of(paths[0]), "line 2: the file ends inside a facet normal"))
        << input_error_of(paths[0]);
}

TEST_F(MeshFiles, NegativeOffIndexFails) {
    // Assimp read it as vertex 0.
    const std::string path = write("negative.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n");
    const std::string message = input_error_of(path);
    EXPECT_TRUE(contains(message, path) && contains(message, "face 1 refers to vertex -1"))
        << message;
}

TEST_F(MeshFiles, MalformedPlyAndOffBodiesFailInsteadOfShifting) {
    const std::string header =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const std::string off_vertices = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n";
    const std::tuple<const char*, std::string, const char*> cases[] = {
        {"short-line.ply", header + "0 0\n0 1 0 0\n0 1 0\n3 0 1 2\n",
         "line 10: 'vertex' record 0 (of 3) has fewer values"},
        {"long-line.ply", header + "0 0 0 7\n1 0 0\n0 1 0\n3 0 1 2\n",
         "line 10: 'vertex' record 0 (of 3) has more values"},
        {"junk.off", "OFF\n3 1 0\n0 0 0\n1 0x 0\n0 1 0\n3 0 1 2\n",
         "line 4: the y coordinate '0x' is not a number"},
        {"missing.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
         "the file ends after 1 of the 2 faces"},
        {"negative.off", off_vertices + "-3 0 1 2\n", "line 6: the corner count '-3' is negative"},
        {"comment.off", "OFF\n3 1 0\n0 0 0\n1 0#0\n0 1 0\n3 0 1 2\n",
         "line 4: the z coordinate is missing"},
    };
    for (const auto& [name, text, message] : cases) {
        const std::string error = input_error_of(write(name, text));
        EXPECT_TRUE(contains(error, message)) << name << ": " << error;
    }
}

// ---------------------------------------------------------------------------------------------
// Exact coordinates: a mesh far from the origin, in every format
// ---------------------------------------------------------------------------------------------

// A lumpy closed sphere of radius about 18 around the origin, its coordinates rounded to
// multiples of `step` (so they stay exact once translated by a few million).
Mesh lumpy_sphere(double step) {
    constexpr int kRings = 7, kSegments = 10;
    constexpr double kPi = 3.14159265358979323846;
    const auto rounded = [&](double value) { return std::round(value / step) * step; };
    Mesh mesh;
    mesh.positions.push_back({0, 0, 18});
    for (int ring = 1; ring <= kRings; ++ring)
        for (int segment = 0; segment < kSegments; ++segment) {
            const double theta = kPi * ring / (kRings + 1), phi = 2 * kPi * segment / kSegments;
            const double r = 18 + 1.3 * std::sin(3 * theta) * std::cos(2 * phi);
            mesh.positions.push_back({rounded(r * std::sin(theta) * std::cos(phi)),
                                      rounded(r * std::sin(theta) * std::sin(phi)),
                                      rounded(r * std::cos(theta))});
        }
    mesh.positions.push_back({0, 0, -18});
    const auto at = [&](int ring, int segment) {
        return uint32_t(1 + (ring - 1) * kSegments + segment % kSegments);
    };
    const uint32_t south = uint32_t(mesh.positions.size() - 1);
    for (int s = 0; s < kSegments; ++s) {
        mesh.triangles.push_back({0, at(1, s), at(1, s + 1)});
        for (int ring = 1; ring < kRings; ++ring) {
            mesh.triangles.push_back({at(ring, s), at(ring + 1, s), at(ring + 1, s + 1)});
            mesh.triangles.push_back({at(ring, s), at(ring + 1, s + 1), at(ring, s + 1)});
        }
        mesh.triangles.push_back({at(kRings, s), south, at(kRings, s + 1)});
    }
    return mesh;
}

Mesh translated(Mesh mesh, const Vec3& offset) {
    for (Vec3& p : mesh.positions)
        for (int k = 0; k < 3; ++k) p[k] += offset[k];
    return mesh;
}

// Independent writers, from the formats' specifications.
std::string text_of(double value) {
    std::ostringstream text;
    text.precision(17);
    text << value;
    return text.str();
}

template <class T>
void put(std::string& out, T value, bool big_endian) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if (big_endian) std::reverse(bytes, bytes + sizeof(T));
    out.append(bytes, sizeof(T));
}

std::string obj_text(const Mesh& mesh) {
    std::string text;
    for (const Vec3& p : mesh.positions)
        text += "v " + text_of(p[0]) + " " + text_of(p[1]) + " " + text_of(p[2]) + "\n";
    for (const auto& t : mesh.triangles)
        text += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " +
                std::to_string(t[2] + 1) + "\n";
    return text;
}

std::string ascii_stl_text(const Mesh& mesh) {
    std::string text = "solid lumpy\n";
    for (const auto& t : mesh.triangles) {
        text += "  facet normal 0 0 0\n    outer loop\n";
        for (uint32_t v : t) {
            const Vec3& p = mesh.positions[v];
            text +=
                "      vertex " + text_of(p[0]) + " " + text_of(p[1]) + " " + text_of(p[2]) + "\n";
        }
        text += "    endloop\n  endfacet\n";
    }
    return text + "endsolid lumpy\n";
}

std::string binary_stl_bytes(const Mesh& mesh) {
    std::string bytes = "solid but binary";  // binary writers often start the header so
    bytes.resize(80, ' ');
    put<uint32_t>(bytes, uint32_t(mesh.triangles.size()), false);
    for (const auto& t : mesh.triangles) {
        for (int k = 0; k < 3; ++k) put<float>(bytes, 0, false);
        for (uint32_t v : t)
            for (double c : mesh.positions[v]) put<float>(bytes, float(c), false);
        put<uint16_t>(bytes, 0, false);
    }
    return bytes;
}

enum class PlyEncoding { Ascii, BinaryLittleEndian, BinaryBigEndian };

std::string ply_bytes(const Mesh& mesh, PlyEncoding encoding, bool doubles) {
    const char* const formats[] = {"ascii", "binary_little_endian", "binary_big_endian"};
    const char* type = doubles ? "double" : "float";
    std::string bytes = std::string("ply\nformat ") + formats[int(encoding)] +
                        " 1.0\ncomment written by test_mesh_io\nelement vertex " +
                        std::to_string(mesh.positions.size()) + "\nproperty " + type +
                        " x\nproperty " + type + " y\nproperty " + type + " z\nelement face " +
                        std::to_string(mesh.triangles.size()) +
                        "\nproperty list uchar int vertex_indices\nend_header\n";
    const bool big = encoding == PlyEncoding::BinaryBigEndian;
    for (const Vec3& p : mesh.positions) {
        if (encoding == PlyEncoding::Ascii)
            bytes += text_of(p[0]) + " " + text_of(p[1]) + " " + text_of(p[2]) + "\n";
        else
            for (double c : p)
                doubles ? put<double>(bytes, c, big) : put<float>(bytes, float(c), big);
    }
    for (const auto& t : mesh.triangles) {
        if (encoding == PlyEncoding::Ascii) {
            bytes += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " +
                     std::to_string(t[2]) + "\n";
        } else {
            put<uint8_t>(bytes, 3, big);
            for (uint32_t v : t) put<int32_t>(bytes, int32_t(v), big);
        }
    }
    return bytes;
}

std::string off_text(const Mesh& mesh) {
    std::string text = "OFF\n# a comment\n" + std::to_string(mesh.positions.size()) + " " +
                       std::to_string(mesh.triangles.size()) + " 0\n";
    for (const Vec3& p : mesh.positions)
        text += text_of(p[0]) + " " + text_of(p[1]) + " " + text_of(p[2]) + "\n";
    for (const auto& t : mesh.triangles)
        text += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " +
                std::to_string(t[2]) + "\n";
    return text;
}

// Triangle by triangle, corner by corner, the same coordinates bit for bit (loading keeps the
// triangle order and welds only equal positions).
void expect_same_triangles(const Mesh& loaded, const Mesh& expected, const std::string& what) {
    ASSERT_EQ(loaded.triangles.size(), expected.triangles.size()) << what;
    size_t differing = 0;
    for (size_t t = 0; t < expected.triangles.size(); ++t)
        for (int c = 0; c < 3; ++c) {
            const Vec3& a = loaded.positions[loaded.triangles[t][c]];
            const Vec3& b = expected.positions[expected.triangles[t][c]];
            differing += std::memcmp(a.data(), b.data(), sizeof a) != 0;
        }
    EXPECT_EQ(differing, 0u) << what << ": corners that differ from the written coordinates";
}

// A named pipe hands its bytes to one reader once: the load must open it once and read it all,
// past the first read's buffer (the text is about 200 KB) and without knowing its size.
TEST_F(MeshFiles, NamedPipeIsReadWhole) {
    Mesh many;
    for (int copy = 0; copy < 40; ++copy) {
        const Mesh sphere = translated(lumpy_sphere(1.0 / 64), {40.0 * copy, 0, 0});
        const auto base = uint32_t(many.positions.size());
        many.positions.insert(many.positions.end(), sphere.positions.begin(),
                              sphere.positions.end());
        for (const auto& t : sphere.triangles)
            many.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
    }
    const std::string text = obj_text(many);
    ASSERT_GT(text.size(), size_t(1) << 17);
    const std::string pipe = (folder_ / "pipe.obj").string();
    ASSERT_EQ(mkfifo(pipe.c_str(), 0600), 0);
    std::signal(SIGPIPE, SIG_IGN);  // a reader that leaves early fails the writer, not the test
    std::thread writer([&] { std::ofstream(pipe, std::ios::binary) << text; });
    Mesh from_pipe;
    std::string error;
    try {
        from_pipe = oclvox::load_mesh(pipe);
    } catch (const InputError& e) {
        error = e.what();
    }
    writer.join();
    EXPECT_EQ(error, "");
    const Mesh from_file = oclvox::load_mesh(write("same.obj", text));
    EXPECT_EQ(from_pipe.positions, from_file.positions);
    EXPECT_EQ(from_pipe.triangles, from_file.triangles);
    EXPECT_EQ(from_file.triangles.size(), many.triangles.size());
}

TEST_F(MeshFiles, MeshFarFromTheOriginReadsBackExactlyInEveryFormat) {
    // UTM-like metres: every coordinate is exact in double (multiples of 1/64 near 5e6) or, for
    // the float formats, in float (multiples of 1/2 below 2^23).
    const Vec3 offset{5000000, 4800000, 5200000};
    const Mesh fine = lumpy_sphere(1.0 / 64), coarse = lumpy_sphere(0.5);
    struct Case {
        std::string name, bytes;
        const Mesh* original;
    };
    const Mesh far_fine = translated(fine, offset), far_coarse = translated(coarse, offset);
    const std::vector<Case> cases = {
        {"far.obj", obj_text(far_fine), &fine},
        {"far-ascii.stl", ascii_stl_text(far_fine), &fine},
        {"far-binary.stl", binary_stl_bytes(far_coarse), &coarse},
        {"far-ascii-double.ply", ply_bytes(far_fine, PlyEncoding::Ascii, true), &fine},
        // ascii text is read in double whatever type the header gives it
        {"far-ascii-float.ply", ply_bytes(far_fine, PlyEncoding::Ascii, false), &fine},
        {"far-binary-double.ply", ply_bytes(far_fine, PlyEncoding::BinaryLittleEndian, true),
         &fine},
        {"far-binary-float.ply", ply_bytes(far_coarse, PlyEncoding::BinaryLittleEndian, false),
         &coarse},
        {"far-big-endian-double.ply", ply_bytes(far_fine, PlyEncoding::BinaryBigEndian, true),
         &fine},
        {"far-big-endian-float.ply", ply_bytes(far_coarse, PlyEncoding::BinaryBigEndian, false),
         &coarse},
        {"far.off", off_text(far_fine), &fine},
    };

    // The voxels of the untranslated meshes on a grid around the origin...
    oclvox::Grid near_grid;
    near_grid.origin = {-21, -21, -21};
    near_grid.voxel_size = 0.75;
    near_grid.dims = {56, 56, 56};
    oclvox::Grid far_grid = near_grid;
    for (int k = 0; k < 3; ++k) far_grid.origin[k] += offset[k];
    const oclvox::VoxelizeOptions options;
    const oclvox::SparseVoxels near_fine = oclvox::voxelize_reference(fine, near_grid, options);
    const oclvox::SparseVoxels near_coarse = oclvox::voxelize_reference(coarse, near_grid, options);
    ASSERT_GT(near_fine.count(), 1000u);

    // ...equal those of every file read back, on the translated grid.
    for (const Case& c : cases) {
        const Mesh loaded = oclvox::load_mesh(write(c.name, c.bytes));
        expect_same_triangles(loaded, translated(*c.original, offset), c.name);
        const oclvox::SparseVoxels voxels = oclvox::voxelize_reference(loaded, far_grid, options);
        const oclvox::SparseVoxels& expected = c.original == &fine ? near_fine : near_coarse;
        EXPECT_EQ(voxels.count(), expected.count()) << c.name;
        EXPECT_TRUE(same_voxel_indices(voxels, expected)) << c.name << ": other voxels";
    }
}

TEST_F(MeshFiles, AsciiCoordinatesAreCorrectlyRounded) {
    // Decimal texts that a float or approximate parser gets wrong: the nearest doubles are
    // 0.1, the smallest normal double's neighbour, and a 17-digit value near 4.8e6.
    const Mesh mesh = oclvox::load_mesh(write("rounding.off",
                                              "OFF\n3 1 0\n0.1 2.2250738585072014e-308 0\n"
                                              "4812345.6789012345 0 1\n0 1 0\n3 0 1 2\n"));
    ASSERT_EQ(mesh.positions.size(), 3u);
    EXPECT_EQ(mesh.positions[0][0], 0.1);
    EXPECT_EQ(mesh.positions[0][1], 2.2250738585072014e-308);
    EXPECT_EQ(mesh.positions[1][0], 4812345.6789012345);
}

// ---------------------------------------------------------------------------------------------
// PLY layouts
// ---------------------------------------------------------------------------------------------

// A unit square (a quad) and a concave pentagon beside it, in a PLY whose header does what the
// format allows: elements before and after the ones read, faces before vertices, x/y/z of
// different types out of order among other properties, lists to skip in every element, and a
// face list named vertex_index with unusual length and index types.
std::string unusual_ply(PlyEncoding encoding) {
    const char* const formats[] = {"ascii", "binary_little_endian", "binary_big_endian"};
    std::string bytes = std::string("ply\r\nformat ") + formats[int(encoding)] +
                        " 1.0\r\n"
                        "comment elements and properties that a reader must step over\n"
                        "obj_info made by hand\n"
                        "element camera 1\nproperty float view\n"
                        "property list uint8 double stuff\n"
                        "element face 2\nproperty uchar flags\n"
                        "property list uint16 uint32 vertex_index\n"
                        "property list uchar float texcoord\n"
                        "element vertex 9\nproperty uchar red\nproperty double z\n"
                        "property list int16 float weights\nproperty float x\n"
                        "property int16 flags\nproperty int y\n"
                        "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                        "end_header\n";
    const bool big = encoding == PlyEncoding::BinaryBigEndian;
    const bool ascii = encoding == PlyEncoding::Ascii;
    // camera: view 1.5, stuff [2.5, -3]
    if (ascii)
        bytes += "1.5 2 2.5 -3\n";
    else {
        put<float>(bytes, 1.5f, big);
        put<uint8_t>(bytes, 2, big);
        put<double>(bytes, 2.5, big);
        put<double>(bytes, -3, big);
    }
    // faces: the quad 0-3, the pentagon 4-8
    const std::vector<std::vector<uint32_t>> faces = {{0, 1, 2, 3}, {4, 5, 6, 7, 8}};
    for (const auto& face : faces) {
        if (ascii) {
            bytes += "7 " + std::to_string(face.size());
            for (uint32_t v : face) bytes += " " + std::to_string(v);
            bytes += " 2 0.25 0.75\n";
        } else {
            put<uint8_t>(bytes, 7, big);
            put<uint16_t>(bytes, uint16_t(face.size()), big);
            for (uint32_t v : face) put<uint32_t>(bytes, v, big);
            put<uint8_t>(bytes, 2, big);
            put<float>(bytes, 0.25f, big);
            put<float>(bytes, 0.75f, big);
        }
    }
    // vertices (x, y, z) = (float, int, double), with red, weights and flags between them.
    const double z = 0.1;  // not a float: the double property must come through exactly
    const std::vector<std::array<double, 2>> xy = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {2, 0},
                                                   {6, 0}, {6, 4}, {4, 1}, {2, 4}};
    for (const auto& p : xy) {
        if (ascii) {
            bytes += "200 " + text_of(z) + " 1 0.5 " + text_of(p[0]) + " -7 " +
                     std::to_string(int(p[1])) + "\n";
        } else {
            put<uint8_t>(bytes, 200, big);
            put<double>(bytes, z, big);
            put<int16_t>(bytes, 1, big);
            put<float>(bytes, 0.5f, big);
            put<float>(bytes, float(p[0]), big);
            put<int16_t>(bytes, -7, big);
            put<int32_t>(bytes, int32_t(p[1]), big);
        }
    }
    if (ascii)
        bytes += "0 1\n";
    else {
        put<int32_t>(bytes, 0, big);
        put<int32_t>(bytes, 1, big);
    }
    return bytes;
}

TEST_F(MeshFiles, PlyWithUnusualLayoutsReadsTheSameInEveryEncoding) {
    // Square: area 1, 2 triangles. Pentagon (2,0) (6,0) (6,4) (4,1) (2,4), concave at (4,1):
    // shoelace area 10, 3 triangles; a fan from (2,0) would overlap and give more.
    const std::string names[] = {"unusual-ascii.ply", "unusual-little.ply", "unusual-big.ply"};
    for (PlyEncoding encoding :
         {PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian, PlyEncoding::BinaryBigEndian}) {
        const std::string& name = names[int(encoding)];
        const Mesh mesh = oclvox::load_mesh(write(name, unusual_ply(encoding)));
        ASSERT_EQ(mesh.triangles.size(), 5u) << name;
        EXPECT_EQ(mesh.positions.size(), 9u) << name;
        EXPECT_NEAR(unsigned_area(mesh), 11.0, 1e-12) << name;
        for (const auto& t : mesh.triangles) {
            EXPECT_GT(doubled_normal(mesh, t)[2], 0) << name << ": winding";
            for (uint32_t v : t) EXPECT_EQ(mesh.positions[v][2], 0.1) << name;
        }
    }
}

TEST_F(MeshFiles, PlyHeaderProblemsAreNamed) {
    const std::string vertex = "element vertex 1\nproperty float x\nproperty float y\n";
    EXPECT_TRUE(contains(
        input_error_of(write("noz.ply", "ply\nformat ascii 1.0\n" + vertex + "end_header\n0 0\n")),
        "no 'z' property"));
    EXPECT_TRUE(contains(input_error_of(write("type.ply", "ply\nformat ascii 1.0\n" + vertex +
                                                              "property quad z\nend_header\n")),
                         "line 6: 'quad' is not a PLY type"));
    EXPECT_TRUE(
        contains(input_error_of(write("count.ply", "ply\nformat ascii 1.0\nelement vertex 3x\n")),
                 "line 3: the count of 'vertex' '3x'"));
    EXPECT_TRUE(contains(input_error_of(write("nothing.ply", "ply\nformat ascii 1.0\n")),
                         "no 'end_header'"));
    EXPECT_TRUE(contains(input_error_of(write("notply.ply", "plyx\n")), "not a PLY file"));
}

// ---------------------------------------------------------------------------------------------
// Polygons in every format
// ---------------------------------------------------------------------------------------------

TEST_F(MeshFiles, OffPolygonsOfAnySizeAreTriangulatedExactly) {
    // An eleven-gon (assimp dropped faces of more than 9 corners), concave at (0,6) and (2,1),
    // in a COFF file with comments, a vertex colour and a face colour.
    const std::vector<Vec3> corners = {{0, 0, 0},  {1, 0, 0},  {2, 1, 0}, {3, 3, 0},
                                       {2, 4, 0},  {1, 5, 0},  {0, 6, 0}, {-1, 5, 0},
                                       {-2, 4, 0}, {-3, 3, 0}, {-2, 1, 0}};
    const std::string path = write("eleven-gon.off",
                                   "COFF\n# eleven corners\n11 1 0\n"
                                   "0 0 0 255 0 0 255\n1 0 0\n2 1 0\n3 3 0\n2 4 0\n"
                                   "1 5 0\n0 6 0\n-1 5 0\n-2 4 0\n-3 3 0\n-2 1 0 # last\n"
                                   "11 0 1 2 3 4 5 6 7 8 9 10  0.5 0.5 0.5\n");
    const Mesh mesh = oclvox::load_mesh(path);
    ASSERT_EQ(mesh.triangles.size(), 9u);
    EXPECT_NEAR(unsigned_area(mesh), polygon_area(corners, {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10}),
                1e-12);
}

TEST_F(MeshFiles, OffKeywordVariantsAreRead) {
    const std::string body = "0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n";
    for (const std::string& header :
         {std::string("NOFF\n3 1 0\n"), std::string("STCNOFF 3 1\n"),
          std::string("nOFF\n3\n3 1 0\n"), std::string("# no keyword\n3 1 0\n")}) {
        const Mesh mesh = oclvox::load_mesh(write("variant.off", header + body));
        EXPECT_EQ(mesh.triangles.size(), 1u) << header;
        EXPECT_EQ(mesh.positions.size(), 3u) << header;
    }
    EXPECT_TRUE(contains(input_error_of(write("4d.off", "nOFF 4\n3 1 0\n" + body)),
                         "dimension 4 are not supported"));
    EXPECT_TRUE(contains(input_error_of(write("binary.off", "OFF BINARY\n" + body)),
                         "binary OFF is not supported"));
    EXPECT_TRUE(contains(input_error_of(write("xoff.off", "XOFF\n3 1 0\n" + body)),
                         "unknown OFF keyword 'XOFF'"));
}

TEST_F(MeshFiles, AsciiStlLoopsOfMoreThanThreeVerticesAreTriangulated) {
    const Mesh mesh = oclvox::load_mesh(write("quad.stl",
                                              "SOLID upper case\nFACET NORMAL 0 0 1\nOUTER LOOP\n"
                                              "VERTEX 0 0 0\nVERTEX 2 0 0\nVERTEX 2 3 0\n"
                                              "VERTEX 0 3 0\nENDLOOP\nENDFACET\nENDSOLID\n"));
    ASSERT_EQ(mesh.triangles.size(), 2u);
    EXPECT_NEAR(unsigned_area(mesh), 6.0, 1e-12);
}

TEST_F(MeshFiles, FacesOfMoreThanTheCornerLimitFail) {
    std::string off = "OFF\n5000 1 0\n";
    for (int k = 0; k < 5000; ++k) off += std::to_string(k) + " " + std::to_string(k % 7) + " 0\n";
    off += "5000";
    for (int k = 0; k < 5000; ++k) off += " " + std::to_string(k);
    EXPECT_TRUE(
        contains(input_error_of(write("huge-face.off", off + "\n")), "face 1 has 5000 corners"));
}

// ---------------------------------------------------------------------------------------------
// Scenes through assimp: glTF 2.0, GLB, 3MF
// ---------------------------------------------------------------------------------------------

std::string base64(const std::string& bytes) {
    static const char* const kAlphabet =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string text;
    for (size_t k = 0; k < bytes.size(); k += 3) {
        const size_t n = std::min<size_t>(3, bytes.size() - k);  // n bytes give n + 1 letters
        uint32_t group = 0;
        for (size_t b = 0; b < n; ++b) group |= uint32_t(uint8_t(bytes[k + b])) << (16 - 8 * b);
        for (size_t c = 0; c < 4; ++c)
            text += c <= n ? kAlphabet[(group >> (18 - 6 * c)) & 63] : '=';
    }
    return text;
}

// One triangle (0,0,0) (1,0,0) (0,1,0) as mesh 0 and the triangle (0,0,5) (1,0,5) (0,1,5) as
// mesh 1, in a buffer of 2 x 3 float vertices and 2 x 3 uint16 indices.
std::string gltf_buffer() {
    std::string bytes;
    const float positions[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 5, 1, 0, 5, 0, 1, 5};
    for (float v : positions) put<float>(bytes, v, false);
    for (uint16_t i : {0, 1, 2, 0, 1, 2}) put<uint16_t>(bytes, i, false);
    return bytes;  // 72 + 12 = 84 bytes
}

// Node "a": translation (10, 20, 30) and scale 2, with mesh 0 and the child "b"; "b": a matrix
// that turns 90 degrees about z and moves 1 along x, with mesh 0 again; node "c": mesh 1 alone.
std::string gltf_json(const std::string& buffer_uri) {
    const std::string uri = buffer_uri.empty() ? "" : ",\"uri\":\"" + buffer_uri + "\"";
    return R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0,2]}],)"
           R"("nodes":[{"name":"a","mesh":0,"translation":[10,20,30],"scale":[2,2,2],)"
           R"("children":[1]},)"
           R"({"name":"b","mesh":0,"matrix":[0,1,0,0,-1,0,0,0,0,0,1,0,1,0,0,1]},)"
           R"({"name":"c","mesh":1}],)"
           R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":2}]},)"
           R"({"primitives":[{"attributes":{"POSITION":1},"indices":3}]}],)"
           R"("accessors":[)"
           R"({"bufferView":0,"byteOffset":0,"componentType":5126,"count":3,"type":"VEC3",)"
           R"("min":[0,0,0],"max":[1,1,0]},)"
           R"({"bufferView":0,"byteOffset":36,"componentType":5126,"count":3,"type":"VEC3",)"
           R"("min":[0,0,5],"max":[1,1,5]},)"
           R"({"bufferView":1,"byteOffset":0,"componentType":5123,"count":3,"type":"SCALAR"},)"
           R"({"bufferView":1,"byteOffset":6,"componentType":5123,"count":3,"type":"SCALAR"}],)"
           R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":72},)"
           R"({"buffer":0,"byteOffset":72,"byteLength":12}],)"
           R"("buffers":[{"byteLength":84)" +
           uri + "}]}";
}

std::string glb_bytes() {
    std::string json = gltf_json("");
    json.resize((json.size() + 3) / 4 * 4, ' ');
    std::string bin = gltf_buffer();
    bin.resize((bin.size() + 3) / 4 * 4, '\0');
    std::string bytes = "glTF";
    put<uint32_t>(bytes, 2, false);
    put<uint32_t>(bytes, uint32_t(12 + 8 + json.size() + 8 + bin.size()), false);
    put<uint32_t>(bytes, uint32_t(json.size()), false);
    bytes += "JSON" + json;
    put<uint32_t>(bytes, uint32_t(bin.size()), false);
    bytes += std::string("BIN\0", 4) + bin;
    return bytes;
}

// The three placed triangles, worked out by hand: a(p) = 2p + (10,20,30); b(p) = a(Rz p +
// (1,0,0)) with Rz (x,y) -> (-y,x); c(p) = p.
std::vector<std::array<Vec3, 3>> expected_scene_triangles() {
    return {{Vec3{10, 20, 30}, Vec3{12, 20, 30}, Vec3{10, 22, 30}},
            {Vec3{12, 20, 30}, Vec3{12, 22, 30}, Vec3{10, 20, 30}},
            {Vec3{0, 0, 5}, Vec3{1, 0, 5}, Vec3{0, 1, 5}}};
}

std::vector<std::array<Vec3, 3>> sorted_triangles(const Mesh& mesh) {
    std::vector<std::array<Vec3, 3>> triangles;
    for (const auto& t : mesh.triangles)
        triangles.push_back({mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]});
    std::sort(triangles.begin(), triangles.end());
    return triangles;
}

TEST_F(MeshFiles, GltfNodesAreAllPlacedByTheirWorldMatrices) {
    auto expected = expected_scene_triangles();
    std::sort(expected.begin(), expected.end());
    const std::string gltf =
        gltf_json("data:application/octet-stream;base64," + base64(gltf_buffer()));
    EXPECT_EQ(sorted_triangles(oclvox::load_mesh(write("scene.gltf", gltf))), expected);
    EXPECT_EQ(sorted_triangles(oclvox::load_mesh(write("scene.glb", glb_bytes()))), expected);
}

// Assimp reads the scene from the bytes oclvox read, once: a .glb or a .gltf from a named pipe
// is read whole, and the .gltf's buffer file is still found beside it.
TEST_F(MeshFiles, GltfFromANamedPipeIsReadWhole) {
    auto expected = expected_scene_triangles();
    std::sort(expected.begin(), expected.end());
    write("scene.bin", gltf_buffer());
    std::signal(SIGPIPE, SIG_IGN);  // a reader that leaves early fails the writer, not the test
    for (const auto& [name, bytes] : std::vector<std::pair<std::string, std::string>>{
             {"pipe.glb", glb_bytes()}, {"pipe.gltf", gltf_json("scene.bin")}}) {
        SCOPED_TRACE(name);
        const std::string pipe = (folder_ / name).string();
        ASSERT_EQ(mkfifo(pipe.c_str(), 0600), 0);
        std::atomic<bool> loaded{false};
        std::thread writer([&] {
            std::ofstream(pipe, std::ios::binary) << bytes;
            // A reader that opens the pipe again would wait for a writer for ever: after 10 s,
            // writers that write nothing let every such open see the end, and the load fail.
            for (int wait = 0; !loaded; ++wait) {
                std::this_thread::sleep_for(std::chrono::milliseconds(100));
                if (wait >= 100) close(open(pipe.c_str(), O_WRONLY | O_NONBLOCK));
            }
        });
        std::vector<std::array<Vec3, 3>> triangles;
        std::string error;
        try {
            triangles = sorted_triangles(oclvox::load_mesh(pipe));
        } catch (const InputError& e) {
            error = e.what();
        }
        loaded = true;
        writer.join();
        EXPECT_EQ(error, "");
        EXPECT_EQ(triangles, expected);
    }
}

TEST_F(MeshFiles, BrokenGltfFailsWithAnInputError) {
    input_error_of(write("truncated.gltf", gltf_json("").substr(0, 50)));
    input_error_of(write("no-buffer.gltf", gltf_json("missing.bin")));
    input_error_of(write("truncated.glb", glb_bytes().substr(0, 100)));
}

uint32_t crc32_of(const std::string& bytes) {
    uint32_t crc = 0xffffffffu;
    for (char c : bytes) {
        crc ^= uint8_t(c);
        for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1)));
    }
    return ~crc;
}

// A zip archive of stored (uncompressed) files, as the 3MF container is.
std::string zip_of(const std::vector<std::pair<std::string, std::string>>& files) {
    std::string archive, directory;
    for (const auto& [name, data] : files) {
        const uint32_t offset = uint32_t(archive.size()), crc = crc32_of(data);
        const auto common = [&](std::string& out) {
            put<uint16_t>(out, 20, false);    // version needed
            put<uint16_t>(out, 0, false);     // flags
            put<uint16_t>(out, 0, false);     // stored
            put<uint16_t>(out, 0, false);     // time
            put<uint16_t>(out, 0x21, false);  // date (1980-01-01)
            put<uint32_t>(out, crc, false);
            put<uint32_t>(out, uint32_t(data.size()), false);
            put<uint32_t>(out, uint32_t(data.size()), false);
            put<uint16_t>(out, uint16_t(name.size()), false);
            put<uint16_t>(out, 0, false);  // extra length
        };
        put<uint32_t>(archive, 0x04034b50, false);
        common(archive);
        archive += name + data;
        put<uint32_t>(directory, 0x02014b50, false);
        put<uint16_t>(directory, 20, false);  // version made by
        common(directory);
        put<uint16_t>(directory, 0, false);  // comment length
        put<uint16_t>(directory, 0, false);  // disk
        put<uint16_t>(directory, 0, false);  // internal attributes
        put<uint32_t>(directory, 0, false);  // external attributes
        put<uint32_t>(directory, offset, false);
        directory += name;
    }
    const uint32_t directory_offset = uint32_t(archive.size());
    archive += directory;
    put<uint32_t>(archive, 0x06054b50, false);
    put<uint16_t>(archive, 0, false);
    put<uint16_t>(archive, 0, false);
    put<uint16_t>(archive, uint16_t(files.size()), false);
    put<uint16_t>(archive, uint16_t(files.size()), false);
    put<uint32_t>(archive, uint32_t(directory.size()), false);
    put<uint32_t>(archive, directory_offset, false);
    put<uint16_t>(archive, 0, false);
    return archive;
}

TEST_F(MeshFiles, ThreeMfMeshIsRead) {
    const std::string model =
        R"(<?xml version="1.0" encoding="UTF-8"?>)"
        R"(<model unit="millimeter" xml:lang="en-US" )"
        R"(xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">)"
        R"(<resources><object id="1" type="model"><mesh><vertices>)"
        R"(<vertex x="0" y="0" z="0"/><vertex x="4" y="0" z="0"/><vertex x="4" y="3" z="0"/>)"
        R"(<vertex x="0" y="0" z="2"/></vertices><triangles>)"
        R"(<triangle v1="0" v2="2" v3="1"/><triangle v1="0" v2="1" v3="3"/>)"
        R"(<triangle v1="1" v2="2" v3="3"/><triangle v1="2" v2="0" v3="3"/>)"
        R"(</triangles></mesh></object></resources>)"
        R"(<build><item objectid="1" transform="1 0 0 0 1 0 0 0 1 10 20 30"/></build></model>)";
    const std::string types =
        R"(<?xml version="1.0" encoding="UTF-8"?>)"
        R"(<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">)"
        R"(<Default Extension="rels" )"
        R"(ContentType="application/vnd.openxmlformats-package.relationships+xml"/>)"
        R"(<Default Extension="model" )"
        R"(ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/></Types>)";
    const std::string relationships =
        R"(<?xml version="1.0" encoding="UTF-8"?>)"
        R"(<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">)"
        R"(<Relationship Target="/3D/3dmodel.model" Id="rel0" )"
        R"(Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>)"
        R"(</Relationships>)";
    const Mesh mesh = oclvox::load_mesh(write("tetra.3mf", zip_of({{"[Content_Types].xml", types},
                                                                   {"_rels/.rels", relationships},
                                                                   {"3D/3dmodel.model", model}})));
    ASSERT_EQ(mesh.triangles.size(), 4u);
    EXPECT_EQ(mesh.positions.size(), 4u);
    // Face areas by hand: z = 0: 6; y = 0: 4; BCD: |(0,3,0) x (-4,0,2)| / 2 = |(6,0,12)| / 2;
    // CAD: |(-4,-3,0) x (-4,-3,2)| / 2 = |(-6,8,0)| / 2 = 5.
    EXPECT_NEAR(unsigned_area(mesh), 6 + 4 + 0.5 * std::sqrt(180.0) + 5, 1e-12);
    // The build item's transform moves the object by (10, 20, 30).
    std::vector<Vec3> positions = mesh.positions;
    std::sort(positions.begin(), positions.end());
    EXPECT_EQ(positions,
              (std::vector<Vec3>{{10, 20, 30}, {10, 20, 32}, {14, 20, 30}, {14, 23, 30}}));
}

// Files on which the fuzzer (scripts/fuzz.sh) found assimp itself failing: aborting the process on
// an assertion in its zip reader, asking for 3.7 GB for a 616-byte .glb, leaking. Each must be an
// InputError naming the file, with this process alive and its memory untouched (the importer
// runs in a child process under a memory limit).
TEST(FuzzFindings, AssimpFailuresAreInputErrorsOfAChildProcess) {
    const std::string folder = std::string(OCLVOX_TEST_DATA_DIR) + "/fuzz_findings/";
    for (const char* name : {"assimp_zip_assert_abort.3mf", "assimp_glb_3700MB_allocation.glb",
                             "assimp_gltf_leak_on_error.gltf"}) {
        SCOPED_TRACE(name);
        const std::string message = input_error_of(folder + name);
        EXPECT_TRUE(contains(message, name)) << message;
    }
    EXPECT_TRUE(
        contains(input_error_of(folder + "assimp_zip_assert_abort.3mf"), "killed by signal 6"));
    // A scene that imports to nothing comes back as empty arrays (the sanitizer build once found
    // a memcpy from a null pointer there).
    EXPECT_TRUE(contains(input_error_of(folder + "gltf_mesh_without_primitives.gltf"),
                         "contains no triangles"));
    // The 3.7 GB request failed in the child, under its limit: no child got near it.
    rusage children{};
    ASSERT_EQ(getrusage(RUSAGE_CHILDREN, &children), 0);
    EXPECT_LT(children.ru_maxrss, 1536L << 10);  // KiB
}

// ---------------------------------------------------------------------------------------------
// validate_mesh
// ---------------------------------------------------------------------------------------------

Mesh one_triangle() {
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    mesh.triangles = {{0, 1, 2}};
    return mesh;
}

std::string validation_error_of(const Mesh& mesh) {
    try {
        oclvox::validate_mesh(mesh);
    } catch (const InputError& error) {
        return error.what();
    }
    ADD_FAILURE() << "the mesh passed validation";
    return "";
}

TEST(ValidateMesh, AcceptsAPlainTriangle) {
    EXPECT_NO_THROW(oclvox::validate_mesh(one_triangle()));
}

TEST(ValidateMesh, RejectsAMeshWithoutTriangles) {
    Mesh mesh = one_triangle();
    mesh.triangles.clear();
    EXPECT_TRUE(contains(validation_error_of(mesh), "no triangles"));
}

TEST(ValidateMesh, RejectsAnIndexPastTheVertices) {
    Mesh mesh = one_triangle();
    mesh.triangles.push_back({0, 2, 3});
    const std::string message = validation_error_of(mesh);
    EXPECT_TRUE(contains(message, "triangle 1 refers to vertex 3")) << message;
}

TEST(ValidateMesh, RejectsANonFiniteUsedVertexNamingVertexAndTriangle) {
    Mesh mesh = one_triangle();
    mesh.positions.push_back({0, 0, INFINITY});
    mesh.triangles.push_back({0, 1, 3});
    const std::string message = validation_error_of(mesh);
    EXPECT_TRUE(contains(message, "vertex 3") && contains(message, "triangle 1")) << message;
}

TEST(ValidateMesh, IgnoresNanInAnUnusedVertex) {
    Mesh mesh = one_triangle();
    mesh.positions.push_back({NAN, NAN, NAN});
    EXPECT_NO_THROW(oclvox::validate_mesh(mesh));
}

// Worked by hand: vertices 0..4, triangles A = (0 1 2), B = (2 3 4), C = (4 1 0).
TEST(Submesh, KeepsTheGivenTrianglesAndOnlyTheirVerticesInOrder) {
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}, {4, 0, 0}};
    mesh.triangles = {{0, 1, 2}, {2, 3, 4}, {4, 1, 0}};
    const Mesh part = oclvox::submesh(mesh, {2, 1});  // C, B: vertices 0, 1, 2, 3, 4 all used
    EXPECT_EQ(part.positions, mesh.positions);
    EXPECT_EQ(part.triangles, (std::vector<std::array<uint32_t, 3>>{{4, 1, 0}, {2, 3, 4}}));
    const Mesh b = oclvox::submesh(mesh, {1});  // vertices 2, 3, 4 become 0, 1, 2
    EXPECT_EQ(b.positions, (std::vector<std::array<double, 3>>{{2, 0, 0}, {3, 0, 0}, {4, 0, 0}}));
    EXPECT_EQ(b.triangles, (std::vector<std::array<uint32_t, 3>>{{0, 1, 2}}));
    EXPECT_TRUE(oclvox::submesh(mesh, {}).triangles.empty());
}

TEST(Submesh, IndexOutOfRangeIsAnInputError) {
    const Mesh mesh = one_triangle();
    EXPECT_THROW(oclvox::submesh(mesh, {1}), oclvox::InputError);
    Mesh broken = one_triangle();
    broken.triangles[0][2] = 7;
    EXPECT_THROW(oclvox::submesh(broken, {0}), oclvox::InputError);
}

// An n x n sheet of quads as triangles: 2 n^2 triangles on (n + 1)^2 vertices, enough records
// for the readers to report their parse several times.
Mesh sheet(int n) {
    Mesh mesh;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i)
            mesh.positions.push_back({i * 0.5, j * 0.25, (i * j) % 7 * 0.125});
    const auto at = [&](int i, int j) { return uint32_t(i + (n + 1) * j); };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            mesh.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
            mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
        }
    return mesh;
}

// Progress while loading keeps the runs' contract (one total, never back, ending at it) in every
// format, reports inside the parse, changes nothing loaded, and a false answer cancels.
TEST_F(MeshFiles, LoadingReportsProgressInEveryFormatAndCancels) {
    const Mesh mesh = sheet(100);
    const std::vector<std::pair<std::string, std::string>> files = {
        {"sheet.obj", obj_text(mesh)},
        {"sheet-ascii.stl", ascii_stl_text(mesh)},
        {"sheet-binary.stl", binary_stl_bytes(mesh)},
        {"sheet-ascii.ply", ply_bytes(mesh, PlyEncoding::Ascii, true)},
        {"sheet-binary.ply", ply_bytes(mesh, PlyEncoding::BinaryLittleEndian, true)},
        {"sheet.off", off_text(mesh)},
    };
    for (const auto& [name, bytes] : files) {
        const std::string path = write(name, bytes);
        const Mesh plain = oclvox::load_mesh(path);
        std::vector<std::pair<uint64_t, uint64_t>> calls;
        auto log = [&](uint64_t done, uint64_t total) {
            calls.push_back({done, total});
            std::this_thread::sleep_for(std::chrono::milliseconds(55));  // past the thinning
            return true;
        };
        const Mesh reported = oclvox::load_mesh(path, log);
        EXPECT_EQ(reported.positions, plain.positions) << name;
        EXPECT_EQ(reported.triangles, plain.triangles) << name;
        ASSERT_FALSE(calls.empty()) << name;
        size_t inside_the_parse = 0;
        for (size_t i = 0; i < calls.size(); ++i) {
            EXPECT_EQ(calls[i].second, calls[0].second) << name;
            if (i) EXPECT_GE(calls[i].first, calls[i - 1].first) << name;
            // The parse is the first 4/7 of the total.
            inside_the_parse += calls[i].first > 0 && calls[i].first * 7 < calls[i].second * 4;
        }
        EXPECT_EQ(calls.back().first, calls.back().second) << name;
        EXPECT_GE(inside_the_parse, 2u) << name;
        for (double at : {0.0, 0.3}) {
            auto cancel = [&](uint64_t done, uint64_t total) { return done < at * total; };
            EXPECT_THROW(oclvox::load_mesh(path, cancel), oclvox::Cancelled) << name << " " << at;
        }
    }
}

// Large OFF and ascii PLY bodies are read in parts on all cores: the mesh is the one written, and
// a bad value on the last line, or a file one face short, is named as one pass names it.
TEST_F(MeshFiles, LargeOffAndAsciiPlyReadInPartsAsInOnePass) {
    const Mesh mesh = sheet(300);
    const std::string texts[] = {off_text(mesh), ply_bytes(mesh, PlyEncoding::Ascii, true)};
    const char* const names[] = {"large.off", "large.ply"};
    const std::string short_messages[] = {"the file ends after 179999 of the 180000 faces",
                                          "the file ends before 'face' record 179999 (of 180000)"};
    for (int f = 0; f < 2; ++f) {
        SCOPED_TRACE(names[f]);
        const std::string& text = texts[f];
        ASSERT_GT(text.size(), size_t(3) << 20);
        expect_same_triangles(oclvox::load_mesh(write(names[f], text)), mesh, names[f]);
        // The last line, "3 a b c\n", its last index made a word that is no number.
        const size_t last_line = size_t(std::count(text.begin(), text.end(), '\n'));
        const std::string bad = text.substr(0, text.size() - 1) + "x\n";
        const std::string message = input_error_of(write(names[f], bad));
        EXPECT_TRUE(contains(message, "line " + std::to_string(last_line) + ": ")) << message;
        const size_t before_last = text.rfind('\n', text.size() - 2) + 1;
        EXPECT_TRUE(contains(input_error_of(write(names[f], text.substr(0, before_last))),
                             short_messages[f]));
    }
}

// A large ASCII STL is read in parts on all cores, cut where a line starts with "facet": the
// mesh is the one written, whether as one solid or as many (solid boundaries inside parts), and
// a file whose last facet lacks a corner, or that ends inside a solid, fails as one pass fails.
TEST_F(MeshFiles, LargeAsciiStlReadsInPartsAsInOnePass) {
    const Mesh mesh = sheet(100);
    const std::string one_solid = ascii_stl_text(mesh);
    ASSERT_GT(one_solid.size(), size_t(2) << 20);
    // The same facets as 20 solids: an "endsolid" and a "solid" line before every 1000th facet.
    std::string solids;
    size_t facet = 0;
    for (size_t at = one_solid.find("  facet"); at != std::string::npos;) {
        const size_t next = one_solid.find("  facet", at + 1);
        if (facet > 0 && facet % 1000 == 0) solids += "endsolid a\nsolid b\n";
        solids += one_solid.substr(
            at, next == std::string::npos ? one_solid.rfind("endsolid") - at : next - at);
        at = next;
        ++facet;
    }
    solids = "solid a\n" + solids + "endsolid b\n";
    for (const auto& [name, text] : {std::pair{"one.stl", one_solid}, {"many.stl", solids}}) {
        SCOPED_TRACE(name);
        expect_same_triangles(oclvox::load_mesh(write(name, text)), mesh, name);
    }
    // The last facet's last corner removed (7 lines a facet, then "endsolid").
    const size_t last_vertex = one_solid.rfind("      vertex");
    const std::string short_facet =
        one_solid.substr(0, last_vertex) + one_solid.substr(one_solid.find('\n', last_vertex) + 1);
    EXPECT_TRUE(contains(input_error_of(write("short.stl", short_facet)),
                         "a facet has 2 vertices; it needs 3"));
    EXPECT_TRUE(contains(
        input_error_of(write("open.stl", one_solid.substr(0, one_solid.rfind("endsolid")))),
        "the file ends inside a solid (no 'endsolid')"));
}

}  // namespace
