#include "stdio_files.hpp"

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <iterator>
#include <sstream>

#include "file_names.hpp"
#include "interrupt.hpp"
#include "options.hpp"
#include "progress_bar.hpp"

namespace oclvox_cli {

namespace {

bool starts_with(const std::string& text, const char* prefix) {
    return text.compare(0, std::strlen(prefix), prefix) == 0;
}

// Replaces every occurrence of `from` in `text`.
std::string replace_all(std::string text, const std::string& from, const std::string& to) {
    for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
        text.replace(at, from.size(), to);
    return text;
}

}  // namespace

std::string sniff_mesh_format(const std::string& bytes) {
    if (starts_with(bytes, "glTF")) return ".glb";
    if (starts_with(bytes, "PK\x03\x04")) return ".3mf";  // a zip archive: 3MF is one
    if (starts_with(bytes, "ply\n") || starts_with(bytes, "ply\r\n")) return ".ply";
    // Binary STL: an 80-byte header, a triangle count, 50 bytes per triangle. Checked before the
    // ASCII signature because binary headers often begin with "solid" too.
    if (bytes.size() >= 84) {
        uint32_t count = 0;
        for (int b = 3; b >= 0; --b) count = (count << 8) | uint8_t(bytes[80 + size_t(b)]);
        if (84 + 50 * uint64_t(count) == bytes.size()) return ".stl";
    }
    const size_t first = bytes.find_first_not_of(" \t\r\n");
    if (first == std::string::npos) return "";
    const std::string text = bytes.substr(first, 4096);
    if (starts_with(text, "solid") && text.find("facet") != std::string::npos) return ".stl";
    if (starts_with(text, "OFF") || starts_with(text, "COFF") || starts_with(text, "NOFF"))
        return ".off";
    if (text[0] == '{') return ".gltf";
    // OBJ has no signature: a vertex or face statement at the start of a line.
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);)
        if (starts_with(line, "v ") || starts_with(line, "f ") || starts_with(line, "o ") ||
            starts_with(line, "g "))
            return ".obj";
    return "";
}

StagedFile::StagedFile(const std::string& extension) {
    const char* folder = std::getenv("TMPDIR");
    std::string pattern =
        std::string(folder && *folder ? folder : "/tmp") + "/oclvox-XXXXXX" + extension;
    const int fd = mkstemps(pattern.data(), int(extension.size()));
    if (fd < 0)
        throw oclvox::Error("cannot create a temporary file in " +
                            pattern.substr(0, pattern.rfind('/')) + ": " + std::strerror(errno));
    ::close(fd);
    path_ = pattern;
    remove_on_stop(path_);
}

StagedFile::~StagedFile() {
    if (path_.empty()) return;
    std::remove(path_.c_str());
    forget_on_stop(path_);
}

MeshInput::MeshInput(const std::string& given, const std::string& input_format) : given_(given) {
    if (given != "-") {
        if (!input_format.empty())
            throw UsageError("--input-format applies to stdin (-) only; '" + given +
                             "' has its format in its name");
        return;
    }
    const std::string bytes((std::istreambuf_iterator<char>(std::cin)),
                            std::istreambuf_iterator<char>());
    if (bytes.empty()) throw oclvox::InputError("stdin: no data (an empty input)");
    const std::string extension = input_format.empty()
                                      ? sniff_mesh_format(bytes)
                                      : "." + oclvox::detail::lowercase(input_format);
    if (extension.empty())
        throw oclvox::InputError(
            "stdin: cannot tell the mesh format from the content; give --input-format (obj, stl, "
            "ply, off, gltf, glb or 3mf)");
    staged_.emplace(extension);
    std::ofstream out(staged_->path(), std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
    out.close();
    if (!out) throw oclvox::Error("cannot stage stdin in " + staged_->path());
}

oclvox::Mesh load_mesh_input(const MeshInput& input, const ReportingArgs& reporting) {
    ProgressBar bar("loading", "", reporting);
    if (input.path() == input.name()) return oclvox::load_mesh(input.path(), bar.callback());
    try {
        return oclvox::load_mesh(input.path(), bar.callback());
    } catch (const oclvox::InputError& e) {
        throw oclvox::InputError(replace_all(e.what(), input.path(), "stdin"));
    }
}

OutputTarget::OutputTarget(const std::string& given, const std::string& extension) : given_(given) {
    if (is_stdout()) staged_.emplace(extension);
}

void OutputTarget::finish() const {
    if (!is_stdout()) return;
    // A reader that stops early (`| head`) must not kill the run by SIGPIPE before the staged
    // file is removed: the write fails with EPIPE instead and is reported.
    std::signal(SIGPIPE, SIG_IGN);
    std::ifstream in(staged_->path(), std::ios::binary);
    std::cout.flush();
    char buffer[1 << 16];
    while (in.read(buffer, sizeof buffer) || in.gcount() > 0) {
        if (std::fwrite(buffer, 1, size_t(in.gcount()), stdout) != size_t(in.gcount()))
            throw oclvox::OutputError("cannot write to stdout: " +
                                      std::string(std::strerror(errno)));
    }
    if (std::fflush(stdout) != 0)
        throw oclvox::OutputError("cannot write to stdout: " + std::string(std::strerror(errno)));
}

}  // namespace oclvox_cli
