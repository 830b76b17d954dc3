// The three surface predicates (conservative SAT, conservative PEF, thin) as one description
// each: the kernel name on the device, and the same setup/test functions on the host.
#pragma once

#include "oclvox/oclvox.hpp"
#include "voxel_math.h"

namespace oclvox::detail {

enum class SurfaceTest { SAT, PEF, Thin };

// Thin voxelization has one predicate; the conservative one is SAT or PEF.
inline SurfaceTest surface_test_for(const VoxelizeOptions& options) {
    if (options.mode == VoxelizeMode::Thin) return SurfaceTest::Thin;
    return options.test == OverlapTest::SAT ? SurfaceTest::SAT : SurfaceTest::PEF;
}

// The kernel of kernels/voxelize.cl that tests with `test`.
inline const char* surface_kernel(SurfaceTest test) {
    switch (test) {
        case SurfaceTest::SAT:
            return "voxelize_sat";
        case SurfaceTest::PEF:
            return "voxelize_pef";
        case SurfaceTest::Thin:
            break;
    }
    return "voxelize_thin";
}

// Calls f(setup_function, overlap_function) with the host versions of `test`, the setup bound to
// the boundary rule.
template <typename F>
void with_host_surface_test(SurfaceTest test, Boundary boundary, F f) {
    const int half_open = boundary == Boundary::HalfOpen;
    switch (test) {
        case SurfaceTest::SAT:
            f([half_open](const OvTriangle& t) { return ov_setup_sat(t, half_open); },
              ov_sat_overlaps);
            return;
        case SurfaceTest::PEF:
            f([half_open](const OvTriangle& t) { return ov_setup_pef(t, half_open); },
              ov_pef_overlaps);
            return;
        case SurfaceTest::Thin:
            f([half_open](const OvTriangle& t) { return ov_setup_thin(t, half_open); },
              ov_thin_overlaps);
            return;
    }
}

}  // namespace oclvox::detail
