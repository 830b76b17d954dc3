// glTF 2.0 (.gltf, .glb) and 3MF through assimp: every mesh of the scene graph, placed by the
// world matrix of each node that uses it (composed in double), merged into one polygon set.
// Assimp stores vertices and matrices in float, so these formats are exact only to float.
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <array>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <assimp/LogStream.hpp>
#include <mutex>

#include "mesh_reading.hpp"

namespace oclvox::mesh_reading {

namespace {

// Assimp reports some problems only through its logger and carries on. Any error logged while a
// file loads therefore fails the load. The logger is global to the process, so loads through
// assimp take turns.
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

    // Messages look like "Error, T0: glTF2: ...\n"; keep the part after the severity and thread
    // tag.
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

// A row-major affine 4x4 matrix in double.
using Matrix = std::array<std::array<double, 4>, 4>;

Matrix to_double(const aiMatrix4x4& m) {
    return {{{m.a1, m.a2, m.a3, m.a4},
             {m.b1, m.b2, m.b3, m.b4},
             {m.c1, m.c2, m.c3, m.c4},
             {m.d1, m.d2, m.d3, m.d4}}};
}

Matrix product(const Matrix& a, const Matrix& b) {
    Matrix c{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) c[i][j] += a[i][k] * b[k][j];
    return c;
}

const Matrix kIdentity = {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}};

Position transformed(const Matrix& m, const aiVector3D& p) {
    // Copied exactly when there is nothing to transform: 0 * NaN would smear one bad coordinate
    // over all three and hide which one it was.
    if (m == kIdentity) return {p.x, p.y, p.z};
    const double x = p.x, y = p.y, z = p.z;
    return {m[0][0] * x + m[0][1] * y + m[0][2] * z + m[0][3],
            m[1][0] * x + m[1][1] * y + m[1][2] * z + m[1][3],
            m[2][0] * x + m[2][1] * y + m[2][2] * z + m[2][3]};
}

// Appends the polygons of a node and its children, in scene coordinates. A mesh that several
// nodes use is placed once per node.
void append_node(const aiScene& scene, const aiNode& node, const Matrix& parent_world,
                 Polygons& out) {
    const Matrix world = product(parent_world, to_double(node.mTransformation));
    for (unsigned n = 0; n < node.mNumMeshes; ++n) {
        const aiMesh& mesh = *scene.mMeshes[node.mMeshes[n]];
        const int64_t base = int64_t(out.positions.size());
        for (unsigned v = 0; v < mesh.mNumVertices; ++v)
            out.positions.push_back(transformed(world, mesh.mVertices[v]));
        for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
            const aiFace& face = mesh.mFaces[f];
            for (unsigned k = 0; k < face.mNumIndices; ++k)
                out.corners.push_back(base + face.mIndices[k]);
            out.corner_counts.push_back(face.mNumIndices);
        }
    }
    for (unsigned c = 0; c < node.mNumChildren; ++c)
        append_node(scene, *node.mChildren[c], world, out);
}

}  // namespace

Polygons read_scene_assimp(const std::string& path) {
    // Phase 1: import. Validation rejects out-of-range indices; polygons are left to the shared
    // triangulation, and identical vertices are joined later, for all formats at once.
    require_readable_nonempty(path);
    AssimpErrorLog errors;
    Assimp::Importer importer;
    const aiScene* scene = importer.ReadFile(path, aiProcess_ValidateDataStructure);
    if (!scene)
        fail(path, errors.first_error().empty() ? importer.GetErrorString() : errors.first_error());
    if (!errors.first_error().empty()) fail(path, errors.first_error());
    if (!scene->mRootNode) fail(path, "the file holds no scene");

    // Phase 2: all meshes of the scene graph, in scene coordinates.
    Polygons out;
    append_node(*scene, *scene->mRootNode, kIdentity, out);
    return out;
}

}  // namespace oclvox::mesh_reading
