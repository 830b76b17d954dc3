// "-" as an input (stdin) or an output (stdout). The library reads and writes files by name, so
// stdin is first copied to a private temporary file named with the format's extension, and an
// output for stdout is written to one and copied to stdout after the run. Both temporary files
// are removed when the run ends, including by SIGINT/SIGTERM.
#pragma once

#include <optional>
#include <string>

#include "oclvox/oclvox.hpp"
#include "report.hpp"

namespace oclvox_cli {

// The format of a mesh read from stdin, from its first bytes: ".glb", ".3mf", ".ply", ".off",
// ".stl" (binary by its size rule, or ASCII "solid ... facet"), ".gltf" (JSON) or ".obj";
// "" if none fits.
std::string sniff_mesh_format(const std::string& bytes);

class StagedFile {
  public:
    // A temporary file ending in `extension` (".obj"), created empty.
    explicit StagedFile(const std::string& extension);
    ~StagedFile();
    StagedFile(const StagedFile&) = delete;
    StagedFile& operator=(const StagedFile&) = delete;

    const std::string& path() const { return path_; }

  private:
    std::string path_;
};

// An input as given: a file name, or "-" for stdin, staged with --input-format's extension or the
// sniffed one. path() is what the library reads; name() is what messages call it.
class MeshInput {
  public:
    MeshInput(const std::string& given, const std::string& input_format);
    const std::string& path() const { return staged_ ? staged_->path() : given_; }
    const std::string& name() const { return given_; }

  private:
    std::string given_;
    std::optional<StagedFile> staged_;
};

// load_mesh for an input as given, with a "loading" progress bar (and Ctrl-C checked through it);
// errors about a staged stdin copy name stdin.
oclvox::Mesh load_mesh_input(const MeshInput& input, const ReportingArgs& reporting);

// An output as given: a file name, or "-" for stdout (written to a staged file with `extension`,
// copied to stdout by finish()).
class OutputTarget {
  public:
    OutputTarget(const std::string& given, const std::string& extension);
    const std::string& path() const { return staged_ ? staged_->path() : given_; }
    bool is_stdout() const { return given_ == "-"; }
    // Copies a staged output to stdout; nothing for a file.
    void finish() const;

  private:
    std::string given_;
    std::optional<StagedFile> staged_;
};

}  // namespace oclvox_cli
