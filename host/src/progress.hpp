// Progress of a run made of several phases of different kinds (a distance field's band pass,
// full-grid search and sign; a mesher's passes), reported through one ProgressCallback.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// The callback sees done out of kPhasedProgressTotal: the fraction of the run's estimated work.
// Phases count in their own units (work items, voxels, bricks), so no count of one unit would
// describe the whole run; a fixed total also cannot grow while the run goes on.
constexpr uint64_t kPhasedProgressTotal = 1000000;

class ProgressPhases {
  public:
    // `what` names the run in the message of the Cancelled it throws ("signed distance field").
    ProgressPhases(ProgressCallback callback, std::string what);

    // Adds a phase whose estimated cost is `weight`, in any unit shared by the run's phases, and
    // returns its number. Every phase is added before the first report.
    size_t add(double weight);

    // Phase `phase` has done `done` of its `total` units: the run's count becomes the weights of
    // the phases before it plus this phase's weight times done / total. Reports reach the callback
    // at most every kInterval (the loops of a phase may report after every small unit of work),
    // and the count never goes back. Throws Cancelled when the callback returns false.
    void report(size_t phase, uint64_t done, uint64_t total);

    // report(phase, ...) as a function, for loops that take one (detail::run_sliced); empty
    // without a callback.
    std::function<void(uint64_t done, uint64_t total)> reporter(size_t phase);

    // The callback of a nested run that takes its own progress option (the solid voxelization
    // that gives a distance field its sign): its reports count as phase `phase`'s, and a false
    // answer is returned to it, so it cancels itself as it always does.
    ProgressCallback forward(size_t phase);

    // The last report, done == total, passed on whatever the interval. Throws Cancelled like
    // report.
    void finish();

  private:
    static constexpr std::chrono::milliseconds kInterval{50};

    bool pass_on(size_t phase, uint64_t done, uint64_t total, bool last);

    ProgressCallback callback_;
    std::string what_;
    std::vector<double> start_, weight_;  // per phase
    double total_weight_ = 0;
    uint64_t reported_ = 0;
    bool any_reported_ = false;
    std::chrono::steady_clock::time_point last_report_;
};

}  // namespace oclvox::detail
