// OpenCL programs embedded at build time (cmake/embed_kernel.cmake), includes inlined.
#pragma once

namespace oclvox::detail {

struct KernelSource {
    const char* name;
    const char* text;
    const char* sha256;  // of `text`: part of the on-disk program cache key
};

extern const KernelSource kKernel_voxelize;
extern const KernelSource kKernel_solid;
extern const KernelSource kKernel_sdf;
extern const KernelSource kKernel_meshing;
extern const KernelSource kKernel_blocks;

}  // namespace oclvox::detail
