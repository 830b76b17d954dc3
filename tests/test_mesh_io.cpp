// Mesh loading: the real meshes load with the triangle counts, vertex counts and bounding boxes
// that the data README gives; polygons become triangles that cover exactly the polygon; and
// missing, malformed or hostile files fail fast with an InputError that names the file.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "oclvox/oclvox.hpp"

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
    // Assimp reads coordinates as float: allow that rounding, far below the fan's excess.
    EXPECT_NEAR(unsigned_area(mesh), expected.exact, 1e-6 * expected.exact);
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
                 "line 4: face index '99999999999999999999'"));
    input_error_of(write("huge-negative.obj", vertices + "f 1 2 -99999999999999999999\n"));
    input_error_of(write("zero.obj", vertices + "f 0 1 2\n"));
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
                         "line 2: vertex coordinate '1,5' is not a number"));
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
        "the file ends inside 'vertex' record 3 of the 400000000"));
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
    input_error_of(write("eleven-gon.off",
                         "OFF\n11 1 0\n0 0 0\n1 0 0\n2 1 0\n3 3 0\n2 4 0\n"
                         "1 5 0\n0 6 0\n-1 5 0\n-2 4 0\n-3 3 0\n-2 1 0\n"
                         "11 0 1 2 3 4 5 6 7 8 9 10\n"));
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

}  // namespace
