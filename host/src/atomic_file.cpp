// Write-then-rename: readers of `path` see either the old file or the complete new one.
//
// The temporary file lives in the target's folder (same file system, so std::rename is atomic)
// and is named after the target plus the process id and a per-process counter, so concurrent
// writers in one process or across processes never share a temporary file. There is no fsync:
// this protects against interrupted runs, not against power loss.
#include "atomic_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

namespace {

std::string temporary_name_for(const std::string& path) {
    static std::atomic<unsigned> counter{0};
    return path + ".tmp-" + std::to_string(getpid()) + "-" + std::to_string(counter++);
}

// errno is not guaranteed to be set by iostreams; fall back to a generic reason.
std::string last_system_error() {
    return errno != 0 ? std::strerror(errno) : "unknown I/O error";
}

// Removes the temporary file unless the rename into place succeeded.
struct TemporaryFile {
    std::string name;
    bool renamed = false;
    ~TemporaryFile() {
        if (!renamed) std::remove(name.c_str());
    }
};

}  // namespace

void write_file_atomically(const std::string& path,
                           const std::function<void(std::ostream&)>& write) {
    TemporaryFile temporary{temporary_name_for(path)};

    // Phase 1: create the temporary file. A missing or read-only folder fails here.
    errno = 0;
    std::ofstream stream(temporary.name, std::ios::binary | std::ios::trunc);
    if (!stream.is_open())
        throw OutputError("cannot write " + path + ": cannot create " + temporary.name + ": " +
                          last_system_error());

    // Phase 2: let the format write its bytes. Failures other than OutputError are reported as
    // OutputError too, so callers of write_voxels only need to handle one type.
    try {
        write(stream);
    } catch (const OutputError&) {
        throw;
    } catch (const std::exception& e) {
        throw OutputError("cannot write " + path + ": " + e.what());
    }

    // Phase 3: the stream buffers, so a full disk may only show up on flush or close.
    errno = 0;
    stream.flush();
    const bool written = stream.good();
    stream.close();
    if (!written || stream.fail())
        throw OutputError("cannot write " + path + ": " + last_system_error());

    // Phase 4: replace the target in one step.
    if (std::rename(temporary.name.c_str(), path.c_str()) != 0)
        throw OutputError("cannot write " + path + ": cannot rename " + temporary.name +
                          " into place: " + std::strerror(errno));
    temporary.renamed = true;
}

}  // namespace oclvox::detail
