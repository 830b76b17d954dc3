// Drawing the progress bar: '\r' back to the line start, then the whole line again.
#include "progress_bar.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <utility>

#include "interrupt.hpp"

namespace oclvox_cli {

namespace {
constexpr int kBarWidth = 30;
}

ProgressBar::ProgressBar(std::string label, std::string unit, const ReportingArgs& reporting)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      enabled_(!reporting.quiet && isatty(STDERR_FILENO)) {}

ProgressBar::~ProgressBar() {
    // "\033[K" clears to the end of the line; every terminal this bar is drawn on understands it.
    if (drawn_) std::fputs("\r\033[K", stderr);
}

oclvox::ProgressCallback ProgressBar::callback() {
    return [this](uint64_t done, uint64_t total) {
        update(done, total);
        return !interrupted();
    };
}

void ProgressBar::update(uint64_t done, uint64_t total) {
    if (!enabled_ || total == 0) return;
    done = std::min(done, total);

    // Redraw only when the shown value changes: the library may report thousands of batches, and
    // writing each one to a terminal would cost more than the work it reports.
    const int permille = int(done * 1000 / total);
    if (permille == last_permille_) return;
    last_permille_ = permille;

    const int filled = permille * kBarWidth / 1000;
    char bar[kBarWidth + 1];
    std::fill(bar, bar + filled, '#');
    std::fill(bar + filled, bar + kBarWidth, '.');
    bar[kBarWidth] = '\0';
    std::fprintf(stderr, "\r%s [%s] %5.1f%%", label_.c_str(), bar, permille / 10.0);
    if (!unit_.empty())
        std::fprintf(stderr, "  %llu/%llu %s", (unsigned long long)done, (unsigned long long)total,
                     unit_.c_str());
    std::fputs("\033[K", stderr);
    std::fflush(stderr);
    drawn_ = true;
}

}  // namespace oclvox_cli
