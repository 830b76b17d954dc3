// The winding-number tree (after Barill et al. 2018) over a set of triangles, and w with its
// expansions' error bound at points: on an OpenCL device (the `winding_points` kernel) and on
// the host, both through ovs_winding_at (kernels/solid_math.h), so with the same bits. Used by
// the winding-number solid (solid_winding.cpp) for the mesh and for the fans over its holes.
#pragma once

#include <array>
#include <vector>

#include "host_memory.hpp"
#include "opencl_runtime.hpp"
#include "solid_math.h"

namespace oclvox::detail {

// Signed solid angle of triangle (a, b, c) seen from p, in double (Van Oosterom & Strackee, as
// ovs_solid_angle): positive when p lies behind the triangle.
double solid_angle_double(const double* a, const double* b, const double* c, const double* p);

// Triangles in grid coordinates (voxel units), double.
std::vector<std::array<double, 9>> grid_triangles(const Mesh& mesh, const Grid& grid);

// The winding tree: triangles in leaf order (float voxel units) and the nodes over them.
struct WindingTree {
    std::vector<float> vertices;  // 9 per triangle
    std::vector<OvWindingNode> nodes;
};

// The tree over `triangles` (grid coordinates): leaves of at most 8 triangles near each other,
// split at the median centroid; the same tree for any number of threads.
WindingTree build_winding_tree(const std::vector<std::array<double, 9>>& triangles);

// Evaluates the winding number at points on the device, in launches short enough for a GPU's
// watchdog.
class WindingEvaluator {
  public:
    WindingEvaluator(Device::Impl& cl, const WindingTree& tree, VoxelizeStats& stats);

    // w and its expansions' error bound at each point (x y z triples): ovs_winding_at with
    // far_ratio and node_tolerance.
    void evaluate(const FilledLaterVector<float>& points, float far_ratio, float node_tolerance,
                  std::vector<float>& w, std::vector<float>& error);

  private:
    Device::Impl& cl_;
    VoxelizeStats& stats_;
    cl::Kernel kernel_;
    cl::Buffer vertices_, nodes_;
    cl_uint node_count_ = 0;
    size_t group_ = 1;
    size_t points_per_batch_ = size_t(1) << 20;  // the most; less after allocation failures
};

// w and its expansions' error bound at each point (x y z triples) on the host: the kernel's
// float arithmetic, for checking that a device gives the same bits.
void winding_points_reference(const WindingTree& tree, const FilledLaterVector<float>& points,
                              float far_ratio, float node_tolerance, std::vector<float>& w,
                              std::vector<float>& error);

}  // namespace oclvox::detail
