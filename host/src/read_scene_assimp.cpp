// glTF 2.0 (.gltf, .glb) and 3MF through assimp: every mesh of the scene graph, placed by the
// world matrix of each node that uses it (composed in double), merged into one polygon set.
// Assimp stores vertices and matrices in float, so these formats are exact only to float.
//
// Assimp is not ours and not hardened: fuzzing found malformed files on which it aborts the
// process (an ai_assert in its zip reader, from a 1.4 KB .3mf), allocates 3.7 GB (a 616-byte
// .glb) or leaks. So it runs in a child process under a memory limit, and hands the
// polygons back through a pipe: whatever it does to itself, the caller gets an InputError naming
// the file, and its own memory is untouched.
#include <assimp/DefaultIOSystem.h>
#include <assimp/MemoryIOWrapper.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <assimp/LogStream.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <new>
#include <nlohmann/json.hpp>

#include "file_names.hpp"
#include "host_memory.hpp"
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

// Assimp's file access with the mesh file itself served from `bytes` (read once by the caller, so
// that a named pipe gives all its bytes to one reader) and every file it names (a .gltf's
// buffers) from disk, found as assimp finds them beside the mesh file's path.
class InputInMemory : public Assimp::DefaultIOSystem {
  public:
    InputInMemory(const std::string& path, std::string_view bytes) : path_(path), bytes_(bytes) {}
    bool Exists(const char* file) const override {
        return file == path_ || Assimp::DefaultIOSystem::Exists(file);
    }
    Assimp::IOStream* Open(const char* file, const char* mode) override {
        if (file != path_) return Assimp::DefaultIOSystem::Open(file, mode);
        return new Assimp::MemoryIOStream(reinterpret_cast<const uint8_t*>(bytes_.data()),
                                          bytes_.size());
    }

  private:
    const std::string& path_;
    std::string_view bytes_;
};

Polygons import_scene(const std::string& path, std::string_view bytes) {
    // Phase 1: import. Validation rejects out-of-range indices; polygons are left to the shared
    // triangulation, and identical vertices are joined later, for all formats at once.
    AssimpErrorLog errors;
    Assimp::Importer importer;
    importer.SetIOHandler(new InputInMemory(path, bytes));  // the importer owns it
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

// ---- the child process and what it sends back ----

// The child's address-space budget: room for the importer's work, plus far more than
// the mesh data the input files can hold (assimp keeps a few copies of it), capped by the host
// budget.
uint64_t import_memory_limit(const std::string& path, std::string_view bytes) {
    std::error_code error;
    uint64_t input = bytes.size();
    // A .gltf names its binary buffers; they are input too. (Its JSON is parsed here only to
    // size the limit: anything unexpected is left for assimp to report.)
    if (detail::lowercase_extension(path) == ".gltf") {
        const nlohmann::json j = nlohmann::json::parse(bytes, nullptr, false);
        const std::filesystem::path folder = std::filesystem::path(path).parent_path();
        if (j.is_object() && j.contains("buffers") && j["buffers"].is_array())
            for (const nlohmann::json& buffer : j["buffers"])
                if (buffer.is_object() && buffer.contains("uri") && buffer["uri"].is_string()) {
                    const uint64_t size = std::filesystem::file_size(
                        folder / buffer["uri"].get<std::string>(), error);
                    if (!error) input += size;
                }
    }
    const uint64_t limit = (uint64_t(1) << 30) + 64 * input;
    return std::min(limit, std::max<uint64_t>(detail::physical_memory() / 2, uint64_t(1) << 30));
}

#ifdef __has_feature
#if __has_feature(address_sanitizer)
#define OCLVOX_SANITIZED_ADDRESSES 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(OCLVOX_SANITIZED_ADDRESSES)
// Sanitizers reserve terabytes of address space before main, so those builds limit the data
// segment instead (which the sanitizer's allocator also grows), and send the sanitizer's report
// of a refused allocation where assimp's own messages go: it is the limit working, not a bug.
#include <sanitizer/common_interface_defs.h>
constexpr bool kSanitizedAddresses = true;
#else
constexpr bool kSanitizedAddresses = false;
#endif

// Field `index` of /proc/self/statm (0: all mapped memory, 5: data and stack) in bytes, or 0 if
// unknown.
uint64_t mapped_bytes(int index) {
    FILE* statm = std::fopen("/proc/self/statm", "r");
    if (!statm) return 0;
    unsigned long long pages = 0;
    bool read = true;
    for (int i = 0; i <= index && read; ++i) read = std::fscanf(statm, "%llu", &pages) == 1;
    std::fclose(statm);
    return read ? uint64_t(pages) * uint64_t(sysconf(_SC_PAGESIZE)) : 0;
}

void write_all(int fd, const void* data, size_t bytes) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::write(fd, p, bytes);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) _exit(3);
        p += n;
        bytes -= size_t(n);
    }
}

template <class T, class Allocator>
void write_vector(int fd, const std::vector<T, Allocator>& v) {
    const uint64_t n = v.size();
    write_all(fd, &n, sizeof n);
    write_all(fd, v.data(), n * sizeof(T));
}

// The child: imports and writes either 'P' and the polygons, or 'E' and a message; never returns.
[[noreturn]] void run_import_child(const std::string& path, std::string_view bytes,
                                   uint64_t memory_limit, int fd) {
    // Die with the parent; take Ctrl-C and SIGTERM as a plain process would (the CLI blocks them
    // in every thread for its watcher, and the mask is inherited).
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    sigset_t all;
    sigfillset(&all);
    sigprocmask(SIG_UNBLOCK, &all, nullptr);
    for (int sig : {SIGINT, SIGTERM, SIGPIPE}) signal(sig, SIG_DFL);
    // The library never prints; what assimp would print (assertion failures) goes nowhere.
    const int null = open("/dev/null", O_WRONLY);
    if (null >= 0) {
        dup2(null, STDOUT_FILENO);
        dup2(null, STDERR_FILENO);
        close(null);
    }
    // On top of what the process has mapped already (libraries, a device runtime's threads).
    const int resource = kSanitizedAddresses ? RLIMIT_DATA : RLIMIT_AS;
    const uint64_t mapped = mapped_bytes(kSanitizedAddresses ? 5 : 0);
    const rlimit limit{mapped + memory_limit, mapped + memory_limit};
    setrlimit(resource, &limit);
#if defined(__SANITIZE_ADDRESS__) || defined(OCLVOX_SANITIZED_ADDRESSES)
    __sanitizer_set_report_path("stderr");
#endif
    // The message sent back is the whole InputError message.
    std::string message;
    try {
        const Polygons polygons = import_scene(path, bytes);
        write_all(fd, "P", 1);
        write_vector(fd, polygons.positions);
        write_vector(fd, polygons.corners);
        write_vector(fd, polygons.corner_counts);
        _exit(0);
    } catch (const InputError& e) {
        message = e.what();
    } catch (const std::bad_alloc&) {
        message = "mesh file '" + path +
                  "': the importer (assimp) ran out of its memory limit of " +
                  std::to_string(memory_limit >> 20) + " MiB";
    } catch (const std::exception& e) {
        message = "mesh file '" + path + "': the importer (assimp) failed: " + e.what();
    } catch (...) {
        message = "mesh file '" + path + "': the importer (assimp) failed";
    }
    write_all(fd, "E", 1);
    const uint64_t n = message.size();
    write_all(fd, &n, sizeof n);
    write_all(fd, message.data(), message.size());
    _exit(0);
}

// Reads the child's answer from `bytes`, checking every count against what is there.
class Answer {
  public:
    explicit Answer(const std::string& bytes) : bytes_(bytes) {}
    bool take(void* out, size_t n) {
        if (bytes_.size() - at_ < n) return false;
        if (n > 0)
            std::memcpy(out, bytes_.data() + at_, n);  // an empty vector's data() may be null
        at_ += n;
        return true;
    }
    template <class T, class Allocator>
    bool take_vector(std::vector<T, Allocator>& v) {
        uint64_t n = 0;
        if (!take(&n, sizeof n) || n > (bytes_.size() - at_) / sizeof(T)) return false;
        v.resize(size_t(n));
        return take(v.data(), size_t(n) * sizeof(T));
    }
    bool done() const { return at_ == bytes_.size(); }

  private:
    const std::string& bytes_;
    size_t at_ = 0;
};

std::string how_it_ended(int status) {
    if (WIFSIGNALED(status))
        return "was killed by signal " + std::to_string(WTERMSIG(status)) + " (" +
               strsignal(WTERMSIG(status)) + ")";
    return "exited with status " + std::to_string(WEXITSTATUS(status));
}

}  // namespace

Polygons read_scene_assimp(const std::string& path) {
    // The file is read here, once (the child inherits the bytes).
    const FileBytes mesh_file = read_whole_file(path);
    const std::string_view file = mesh_file.view();
    const uint64_t memory_limit = import_memory_limit(path, file);

    // Phase 1: the import, in a child process.
    int fds[2];
    if (pipe(fds) != 0) fail(path, std::string("cannot create a pipe: ") + std::strerror(errno));
    const pid_t child = fork();
    if (child < 0) {
        close(fds[0]);
        close(fds[1]);
        fail(path, std::string("cannot start the importer process: ") + std::strerror(errno));
    }
    if (child == 0) {
        close(fds[0]);
        run_import_child(path, file, memory_limit, fds[1]);
    }
    close(fds[1]);

    // Phase 2: everything it sends, then how it ended.
    std::string bytes;
    char buffer[1 << 16];
    for (;;) {
        const ssize_t n = ::read(fds[0], buffer, sizeof buffer);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        bytes.append(buffer, size_t(n));
    }
    close(fds[0]);
    int status = 0;
    while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
    }

    // Phase 3: the polygons, or the reason there are none.
    Answer answer(bytes);
    char kind = 0;
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0 && answer.take(&kind, 1)) {
        Polygons polygons;
        if (kind == 'P' && answer.take_vector(polygons.positions) &&
            answer.take_vector(polygons.corners) && answer.take_vector(polygons.corner_counts) &&
            answer.done())
            return polygons;
        std::string message;
        uint64_t n = 0;
        if (kind == 'E' && answer.take(&n, sizeof n) && n <= bytes.size()) {
            message.resize(size_t(n));
            if (answer.take(message.data(), message.size()) && answer.done())
                throw InputError(message);
        }
    }
    fail(path, "the importer (assimp) " + how_it_ended(status) +
                   " on this file, which it cannot read (the address-space limit was " +
                   std::to_string(memory_limit >> 20) + " MiB)");
}

}  // namespace oclvox::mesh_reading
