// Write-then-rename: readers of `path` see either the old file or the complete new one.
//
// The temporary file lives in the target's folder (same file system, so std::rename is atomic)
// and is named after the target plus the process id and a per-process counter, so concurrent
// writers in one process or across processes never share a temporary file. There is no fsync:
// this protects against interrupted runs, not against power loss. Errors name the user's path;
// the temporary file is an implementation detail they never see.
//
// A program that must stop at once (the CLI on SIGINT or SIGTERM) calls abandon_pending_writes
// from another thread: the temporary files of writes in progress are registered, so it can
// remove them, and from then on no temporary file is created or renamed into place.
#include "atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <locale>
#include <memory>
#include <mutex>
#include <set>

#include "file_names.hpp"
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

// The temporary files of this process's writes in progress, and whether writing was abandoned.
// The lock is held while a temporary file is created and while it is renamed, so an abandoning
// thread removes every file that exists and no file appears afterwards.
struct PendingWrites {
    std::mutex lock;
    std::set<std::string> names;
    bool abandoned = false;
};
// Never destroyed: a signal may arrive while static objects are being destroyed at exit.
PendingWrites& pending_writes() {
    static PendingWrites* const pending = new PendingWrites;
    return *pending;
}

[[noreturn]] void throw_abandoned(const std::string& path) {
    throw Cancelled("cannot write " + path + ": writing was abandoned (the run is stopping)");
}

// Creates the temporary file on construction and removes it unless the rename into place
// succeeded.
struct TemporaryFile {
    std::string name;
    bool renamed = false;

    TemporaryFile(const std::string& path, std::ofstream& stream) : name(temporary_name_for(path)) {
        PendingWrites& pending = pending_writes();
        const std::lock_guard<std::mutex> hold(pending.lock);
        if (pending.abandoned) throw_abandoned(path);
        pending.names.insert(name);
        stream.open(name, std::ios::binary | std::ios::trunc);
    }
    void rename_to(const std::string& path) {
        PendingWrites& pending = pending_writes();
        const std::lock_guard<std::mutex> hold(pending.lock);
        if (pending.abandoned) throw_abandoned(path);
        if (std::rename(name.c_str(), path.c_str()) != 0)
            throw OutputError("cannot write " + path + ": " + std::strerror(errno));
        renamed = true;
    }
    ~TemporaryFile() {
        PendingWrites& pending = pending_writes();
        const std::lock_guard<std::mutex> hold(pending.lock);
        pending.names.erase(name);
        if (!renamed) std::remove(name.c_str());
    }
};

// The output stream's buffer (see write_file_atomically).
constexpr size_t kStreamBufferBytes = size_t(1) << 20;

}  // namespace

void write_file_atomically(const std::string& path,
                           const std::function<void(std::ostream&)>& write) {
    // Phase 1: create the temporary file. A missing or read-only folder fails here. Its buffer
    // is 1 MiB, set before the file opens (libstdc++ ignores it after): a format written in many
    // small pieces (OpenVDB's stream writes a leaf in four of 12-64 bytes) otherwise made a system
    // call every 8 KiB, a fifth of writing bunny00's 187 MB surface .vdb at 4096^3.
    errno = 0;
    const std::unique_ptr<char[]> buffer(new char[kStreamBufferBytes]);  // pages touched as filled
    std::ofstream stream;
    stream.rdbuf()->pubsetbuf(buffer.get(), std::streamsize(kStreamBufferBytes));
    TemporaryFile temporary(path, stream);
    if (!stream.is_open())
        throw OutputError("cannot write " + path + ": cannot create a file in folder '" +
                          folder_of(path) + "': " + last_system_error());

    // Phase 2: let the format write its bytes, numbers in the classic locale whatever the
    // program's global one (an application's std::locale::global with a decimal comma or
    // thousands separators made "translate 0,5" and "element vertex 1,794,572"). Failures other
    // than OutputError are reported as OutputError too, so callers of write_voxels only need to
    // handle one type.
    stream.imbue(std::locale::classic());
    try {
        write(stream);
    } catch (const OutputError&) {
        throw;
    } catch (const Cancelled&) {  // a progress callback said stop: not a failure to write
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

    // Phase 4: replace the target in one step (a directory of that name makes this fail).
    temporary.rename_to(path);
}

}  // namespace oclvox::detail

namespace oclvox {

void check_output_path(const std::string& path, const std::vector<std::string>& inputs) {
    auto refuse = [&](const std::string& why) {
        throw OutputError("cannot write '" + path + "': " + why);
    };
    if (path.empty()) refuse("the output path is empty");

    // Phase 1: the target itself is a file or nothing; never a directory, never an input. Identity
    // is the file system's (device and inode), so "./a.obj", "a.obj" and links all compare equal.
    struct stat target {};
    if (::stat(path.c_str(), &target) == 0) {
        if (S_ISDIR(target.st_mode)) refuse("it is a directory");
        for (const std::string& input : inputs) {
            struct stat source {};
            if (::stat(input.c_str(), &source) == 0 && source.st_dev == target.st_dev &&
                source.st_ino == target.st_ino)
                refuse("it is the input file '" + input + "'");
        }
    }

    // Phase 2: the folder exists and a file can be created in it (what write_file_atomically
    // does first), so a run never computes for minutes and then fails to save.
    const std::string folder = detail::folder_of(path);
    struct stat folder_stat {};
    if (::stat(folder.c_str(), &folder_stat) != 0 || !S_ISDIR(folder_stat.st_mode))
        refuse("folder '" + folder + "' does not exist");
    const std::string probe = detail::temporary_name_for(path);
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
    if (fd < 0) refuse("folder '" + folder + "' cannot be written: " + std::strerror(errno));
    ::close(fd);
    ::unlink(probe.c_str());
}

void write_text_file(const std::string& path, const std::string& text) {
    detail::write_file_atomically(path, [&](std::ostream& out) { out << text; });
}

void abandon_pending_writes() {
    detail::PendingWrites& pending = detail::pending_writes();
    const std::lock_guard<std::mutex> hold(pending.lock);
    pending.abandoned = true;
    for (const std::string& name : pending.names) std::remove(name.c_str());
}

}  // namespace oclvox
