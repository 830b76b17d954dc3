// The stats' phase timings: seconds on the steady clock since a phase's start.
#pragma once

#include <chrono>

namespace oclvox::detail {

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace oclvox::detail
