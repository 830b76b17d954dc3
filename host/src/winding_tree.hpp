// The winding-number tree (after Barill et al. 2018) over a set of triangles, and w with its
// expansions' error bound at points: on an OpenCL device (the `winding_points` kernel) and on
// the host, both through ovs_winding_at (kernels/solid_math.h), so with the same bits. Used by
// the winding-number solid (solid_winding.cpp) for the mesh and for the fans over its holes.
#pragma once

#include <array>
#include <vector>

#include "host_memory.hpp"
#include "opencl_runtime.hpp"
#include "overlap_double.hpp"
#include "solid_math.h"

namespace oclvox::detail {

// Signed solid angle of triangle (a, b, c) seen from p, in double (Van Oosterom & Strackee, as
// ovs_solid_angle): positive when p lies behind the triangle.
double solid_angle_double(const double* a, const double* b, const double* c, const double* p);

// Triangles in grid coordinates (voxel units), double.
std::vector<std::array<double, 9>> grid_triangles(const Mesh& mesh, const Grid& grid);

// A winding tree in double (after Barill et al. 2018), depth first: a node over triangles
// [first, first + count) of `order`, then, unless it is a leaf, the trees over the halves of a
// median split of their centroids along the widest axis; `skip` is the node just past its
// subtree. A node holds the area-weighted centroid of its triangles (the expansion centre), the
// ball around it holding their vertices, and, each triangle times its weight, their area, area
// vectors' sum and moment: sum of area vector i times centroid offset j (moment[3 * i + j]).
struct WindingNode {
    Vec3d centre;
    double radius, area;
    size_t first, count;
    Vec3d area_normal;
    std::array<double, 9> moment;
    size_t skip;
    bool leaf;
};
struct WindingNodes {
    std::vector<WindingNode> nodes;
    std::vector<uint32_t> order;  // the triangles in the tree's order
};

// The tree over `triangles` (grid coordinates), each counting weights[t] times (every one once
// where `weights` is empty), with leaves of at most leaf_triangles; none for no triangles. The
// same tree for any number of threads.
WindingNodes build_winding_nodes(const std::vector<std::array<double, 9>>& triangles,
                                 const std::vector<double>& weights, size_t leaf_triangles);

// The winding tree for the kernel: triangles in leaf order (float voxel units) and the nodes over
// them.
struct WindingTree {
    std::vector<float> vertices;  // 9 per triangle
    std::vector<OvWindingNode> nodes;
};

// The kernel's tree over `triangles` (grid coordinates): build_winding_nodes with leaves of at
// most 8 triangles, in float, its balls and areas rounded up.
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
