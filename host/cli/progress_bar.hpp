// A one-line progress bar on stderr, redrawn in place, that is also how a command's long phase
// learns of Ctrl-C. Debian packages no C++ progress-bar library, and this tool needs only "n of
// total" with a percentage.
#pragma once

#include <cstdint>
#include <string>

#include "oclvox/oclvox.hpp"
#include "report.hpp"

namespace oclvox_cli {

class ProgressBar {
  public:
    // `unit`: what the library's counts are ("bricks"), shown after them; empty for runs whose
    // counts are fractions of their estimated work (distance fields, meshing): percentage only.
    // The bar is drawn only when stderr is a terminal, since carriage-return redraws garble logs
    // and pipes, and never with --quiet.
    ProgressBar(std::string label, std::string unit, const ReportingArgs& reporting);
    // Erases the bar, so whatever is printed next starts on a clean line.
    ~ProgressBar();
    ProgressBar(const ProgressBar&) = delete;
    ProgressBar& operator=(const ProgressBar&) = delete;

    // For the library's progress option: draws the bar, and cancels the run once SIGINT or
    // SIGTERM arrived. It refers to this bar, which must outlive the run.
    oclvox::ProgressCallback callback();

  private:
    void update(uint64_t done, uint64_t total);

    std::string label_, unit_;
    bool enabled_;
    bool drawn_ = false;
    int last_permille_ = -1;
};

}  // namespace oclvox_cli
