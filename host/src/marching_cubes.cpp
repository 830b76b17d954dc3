// Marching Cubes with asymptotic-decider face resolution, host reference.
//
// The case table is derived in marching_cubes_tables.cpp, the per-sample work lives in
// kernels/meshing_math.h (om_mc_count, om_mc_emit) and the brick tiling in
// meshing_reference.cpp; this file fixes the method's entry point and brick size.
#include "meshing.hpp"

namespace oclvox {

namespace {
// Same tiling as Surface Nets (see surface_nets.cpp).
constexpr int kBrickSize = 32;
}  // namespace

Mesh marching_cubes(const ScalarField& field, float iso, const ProgressCallback& progress) {
    return detail::mesh_field_reference(field, iso, detail::MeshingMethod::MarchingCubes,
                                        kBrickSize, progress);
}

}  // namespace oclvox
