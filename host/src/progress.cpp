#include "progress.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace oclvox::detail {

ProgressPhases::ProgressPhases(ProgressCallback callback, std::string what)
    : callback_(std::move(callback)), what_(std::move(what)) {}

size_t ProgressPhases::add(double weight) {
    start_.push_back(total_weight_);
    weight_.push_back(std::max(0.0, weight));
    total_weight_ += weight_.back();
    return start_.size() - 1;
}

bool ProgressPhases::pass_on(size_t phase, uint64_t done, uint64_t total, bool last) {
    if (!callback_) return true;
    // A phase with nothing to do (total 0) is complete.
    const double fraction = total ? double(std::min(done, total)) / double(total) : 1.0;
    uint64_t count = kPhasedProgressTotal;
    if (!last && total_weight_ > 0)
        count = uint64_t(std::floor(double(kPhasedProgressTotal) *
                                    (start_[phase] + weight_[phase] * fraction) / total_weight_));
    count = std::clamp(count, reported_, kPhasedProgressTotal);

    const auto now = std::chrono::steady_clock::now();
    if (any_reported_ && !last && now - last_report_ < kInterval) return true;
    any_reported_ = true;
    last_report_ = now;
    reported_ = count;
    return callback_(count, kPhasedProgressTotal);
}

void ProgressPhases::report(size_t phase, uint64_t done, uint64_t total) {
    if (!pass_on(phase, done, total, false))
        throw Cancelled(what_ + " cancelled by the progress callback at " +
                        std::to_string(reported_ / (kPhasedProgressTotal / 100)) + "%");
}

std::function<void(uint64_t, uint64_t)> ProgressPhases::reporter(size_t phase) {
    if (!callback_) return {};
    return [this, phase](uint64_t done, uint64_t total) { report(phase, done, total); };
}

ProgressCallback ProgressPhases::forward(size_t phase) {
    if (!callback_) return {};
    return
        [this, phase](uint64_t done, uint64_t total) { return pass_on(phase, done, total, false); };
}

void ProgressPhases::finish() {
    if (!pass_on(0, 0, 0, true))
        throw Cancelled(what_ + " cancelled by the progress callback at its end");
}

}  // namespace oclvox::detail
