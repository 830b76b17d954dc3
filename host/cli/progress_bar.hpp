// A one-line progress bar on stderr, redrawn in place. Debian packages no C++ progress-bar
// library, and this tool needs only "n of total" with a percentage.
#pragma once

#include <cstdint>
#include <string>

namespace oclvox_cli {

class ProgressBar {
  public:
    // A disabled bar draws nothing, so callers can update it unconditionally; enable it only when
    // stderr is a terminal, since carriage-return redraws garble logs and pipes.
    ProgressBar(std::string label, std::string unit, bool enabled);
    // Erases the bar, so whatever is printed next starts on a clean line.
    ~ProgressBar();
    ProgressBar(const ProgressBar&) = delete;
    ProgressBar& operator=(const ProgressBar&) = delete;

    void update(uint64_t done, uint64_t total);

  private:
    std::string label_, unit_;
    bool enabled_;
    bool drawn_ = false;
    int last_permille_ = -1;
};

}  // namespace oclvox_cli
