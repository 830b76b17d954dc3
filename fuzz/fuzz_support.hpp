// Shared by the fuzz targets: the library reads files, so each input is written to a file first.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace oclvox_fuzz {

// A file in the temporary folder, named after this process, rewritten for every input and removed
// when the fuzzer exits. A failure to write it is the machine's fault, not the library's: abort.
class ScratchFile {
  public:
    explicit ScratchFile(const std::string& suffix) {
        const char* folder = std::getenv("TMPDIR");
        path_ = std::string(folder && *folder ? folder : "/tmp") + "/oclvox-fuzz-" +
                std::to_string(getpid()) + suffix;
    }
    ~ScratchFile() { std::remove(path_.c_str()); }

    const std::string& write(const uint8_t* data, size_t size) const {
        std::FILE* file = std::fopen(path_.c_str(), "wb");
        if (!file || std::fwrite(data, 1, size, file) != size || std::fclose(file) != 0) {
            std::perror(path_.c_str());
            std::abort();
        }
        return path_;
    }
    const std::string& path() const { return path_; }

  private:
    std::string path_;
};

}  // namespace oclvox_fuzz
