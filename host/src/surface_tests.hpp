// The three surface predicates (conservative SAT, conservative PEF, thin) as one description
// each: the kernel names on the device, and the same setup/test functions on the host.
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

struct SurfaceKernels {
    const char* setup;
    const char* voxelize;
    size_t setup_bytes;
};

inline SurfaceKernels surface_kernels(SurfaceTest test) {
    switch (test) {
        case SurfaceTest::SAT:
            return {"setup_sat", "voxelize_sat", sizeof(OvSatTriangle)};
        case SurfaceTest::PEF:
            return {"setup_pef", "voxelize_pef", sizeof(OvPefTriangle)};
        case SurfaceTest::Thin:
            break;
    }
    return {"setup_thin", "voxelize_thin", sizeof(OvThinTriangle)};
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
