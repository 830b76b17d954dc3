// Naive Surface Nets (Gibson's 1998 surface nets without the relaxation step), host reference.
//
// The per-sample work lives in kernels/meshing_math.h (om_sn_count, om_sn_emit) and the brick
// tiling in meshing_reference.cpp; this file fixes the method's entry point and brick size.
#include "meshing.hpp"

namespace oclvox {

namespace {
// Bricks of 32^3 samples: small enough to skip empty space finely, large enough that the
// one-sample halo re-read by the emptiness check stays cheap.
constexpr int kBrickSize = 32;
}  // namespace

Mesh surface_nets(const ScalarField& field, float iso, const ProgressCallback& progress) {
    return detail::mesh_field_reference(field, iso, detail::MeshingMethod::SurfaceNets, kBrickSize,
                                        progress);
}

}  // namespace oclvox
