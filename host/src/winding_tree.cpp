#include "winding_tree.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "device_batches.hpp"
#include "timing.hpp"

namespace oclvox::detail {

namespace {

// A winding item walks the whole tree, so its launches are kept short.
constexpr uint64_t kWindingItemsPerLaunch = uint64_t(1) << 14;

// Leaves small enough that a near leaf costs little to sum exactly.
constexpr size_t kLeafTriangles = 8;

// A subtree of this many triangles or more builds its two halves in parallel.
constexpr size_t kParallelSubtree = 4096;

struct TreeBuilder {
    const std::vector<std::array<double, 9>>& tri;  // grid coordinates in voxel units
    const std::vector<double>& weight;              // empty: every triangle counts once
    const size_t leaf_triangles;
    // Per triangle, worked out once (every level of the tree reads them).
    std::vector<std::array<double, 3>> centroid, area_normal;
    std::vector<double> area;
    std::vector<uint32_t> order;
    std::vector<WindingNode> nodes;
    // The node count of a subtree of n triangles, for every n the build meets: median splits make
    // a subtree's shape depend on n alone, so each node's index is known before its subtrees are
    // built, and they can be built at once.
    std::map<size_t, size_t> subtree_nodes;

    TreeBuilder(const std::vector<std::array<double, 9>>& triangles,
                const std::vector<double>& weights, size_t leaf_size)
        : tri(triangles),
          weight(weights),
          leaf_triangles(leaf_size),
          centroid(tri.size()),
          area_normal(tri.size()),
          area(tri.size()),
          order(tri.size()) {
        tbb::parallel_for(size_t(0), tri.size(), [&](size_t t) {
            const auto& v = tri[t];
            const double e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
            const double e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
            const std::array<double, 3> n{(e1[1] * e2[2] - e1[2] * e2[1]) / 2,
                                          (e1[2] * e2[0] - e1[0] * e2[2]) / 2,
                                          (e1[0] * e2[1] - e1[1] * e2[0]) / 2};
            area_normal[t] = n;
            area[t] = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            centroid[t] = {(v[0] + v[3] + v[6]) / 3, (v[1] + v[4] + v[7]) / 3,
                           (v[2] + v[5] + v[8]) / 3};
            order[t] = uint32_t(t);
        });
        count_nodes(tri.size());
        nodes.resize(subtree_nodes.at(tri.size()));
    }

    size_t count_nodes(size_t n) {
        if (const auto known = subtree_nodes.find(n); known != subtree_nodes.end())
            return known->second;
        const size_t count =
            n <= leaf_triangles ? 1 : 1 + count_nodes(n / 2) + count_nodes(n - n / 2);
        subtree_nodes[n] = count;
        return count;
    }

    // Builds the subtree of order[lo, hi) into nodes[index, index + its node count).
    void build(size_t index, size_t lo, size_t hi) {
        // Expansion centre: area-weighted, falling back to the plain centroid mean for zero-area
        // subtrees.
        double normal[3] = {0, 0, 0}, weighted[3] = {0, 0, 0}, plain[3] = {0, 0, 0}, total = 0;
        double box_lo[3] = {INFINITY, INFINITY, INFINITY},
               box_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t i = lo; i < hi; ++i) {
            const uint32_t t = order[i];
            const double w = weight.empty() ? 1 : weight[t];
            const auto& n = area_normal[t];
            const auto& c = centroid[t];
            for (int k = 0; k < 3; ++k) {
                normal[k] += w * n[k];
                weighted[k] += w * area[t] * c[k];
                plain[k] += c[k];
                box_lo[k] = std::min(box_lo[k], c[k]);
                box_hi[k] = std::max(box_hi[k], c[k]);
            }
            total += w * area[t];
        }
        WindingNode node{};
        for (int k = 0; k < 3; ++k) {
            node.centre[k] = total > 0 ? weighted[k] / total : plain[k] / double(hi - lo);
            node.area_normal[k] = normal[k];
        }
        node.area = total;
        // The radius is the root of the largest squared distance: the square root is correctly
        // rounded, so monotonic, and the root of the largest is the largest root.
        double radius2 = 0;
        for (size_t i = lo; i < hi; ++i) {
            const uint32_t t = order[i];
            const double w = weight.empty() ? 1 : weight[t];
            const auto& p = tri[t];
            for (int v = 0; v < 3; ++v) {
                const double dx = p[3 * v] - node.centre[0], dy = p[3 * v + 1] - node.centre[1],
                             dz = p[3 * v + 2] - node.centre[2];
                radius2 = std::max(radius2, dx * dx + dy * dy + dz * dz);
            }
            const auto& n = area_normal[t];
            const auto& c = centroid[t];
            for (int r = 0; r < 3; ++r)
                for (int k = 0; k < 3; ++k)
                    node.moment[3 * r + k] += w * n[r] * (c[k] - node.centre[k]);
        }
        node.radius = std::sqrt(radius2);
        node.first = lo;
        node.count = hi - lo;
        node.skip = index + subtree_nodes.at(hi - lo);
        node.leaf = hi - lo <= leaf_triangles;

        // Unless a leaf, split at the median centroid along the longest axis of the centroids'
        // box.
        if (!node.leaf) {
            int axis = 0;
            for (int k = 1; k < 3; ++k)
                if (box_hi[k] - box_lo[k] > box_hi[axis] - box_lo[axis]) axis = k;
            const size_t mid = lo + (hi - lo) / 2;
            std::nth_element(
                order.begin() + lo, order.begin() + mid, order.begin() + hi,
                [&](uint32_t a, uint32_t b) { return centroid[a][axis] < centroid[b][axis]; });
            // The halves touch disjoint parts of `order` and `nodes`: the same tree for any
            // number of threads.
            const size_t left = index + 1, right = left + subtree_nodes.at(mid - lo);
            if (hi - lo >= kParallelSubtree)
                tbb::parallel_invoke([&] { build(left, lo, mid); }, [&] { build(right, mid, hi); });
            else {
                build(left, lo, mid);
                build(right, mid, hi);
            }
        }
        nodes[index] = node;
    }
};

}  // namespace

double solid_angle_double(const double* a_, const double* b_, const double* c_, const double* p) {
    double a[3], b[3], c[3];
    for (int k = 0; k < 3; ++k) {
        a[k] = a_[k] - p[k];
        b[k] = b_[k] - p[k];
        c[k] = c_[k] - p[k];
    }
    const double det = a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) +
                       a[2] * (b[0] * c[1] - b[1] * c[0]);
    const double la = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    const double lb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    const double lc = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    const double den = la * lb * lc + (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * lc +
                       (b[0] * c[0] + b[1] * c[1] + b[2] * c[2]) * la +
                       (c[0] * a[0] + c[1] * a[1] + c[2] * a[2]) * lb;
    return 2 * std::atan2(det, den);
}

// Triangles in grid coordinates (voxel units), double.
std::vector<std::array<double, 9>> grid_triangles(const Mesh& mesh, const Grid& grid) {
    std::vector<std::array<double, 9>> tri(mesh.triangles.size());
    for (size_t t = 0; t < tri.size(); ++t)
        for (int v = 0; v < 3; ++v)
            for (int k = 0; k < 3; ++k)
                tri[t][3 * v + k] =
                    (mesh.positions[mesh.triangles[t][v]][k] - grid.origin[k]) / grid.voxel_size;
    return tri;
}

WindingNodes build_winding_nodes(const std::vector<std::array<double, 9>>& triangles,
                                 const std::vector<double>& weights, size_t leaf_triangles) {
    if (triangles.empty()) return {};
    TreeBuilder builder(triangles, weights, leaf_triangles);
    builder.build(0, 0, triangles.size());
    return {std::move(builder.nodes), std::move(builder.order)};
}

WindingTree build_winding_tree(const std::vector<std::array<double, 9>>& tri) {
    const WindingNodes built = build_winding_nodes(tri, {}, kLeafTriangles);
    WindingTree tree;
    tree.nodes.resize(built.nodes.size());
    tbb::parallel_for(size_t(0), built.nodes.size(), [&](size_t i) {
        const WindingNode& from = built.nodes[i];
        OvWindingNode& node = tree.nodes[i];
        for (int k = 0; k < 3; ++k) {
            node.centre[k] = float(from.centre[k]);
            node.area_normal[k] = float(from.area_normal[k]);
        }
        for (int k = 0; k < 9; ++k) node.moment[k] = float(from.moment[k]);
        // Rounded up a little, so the float ball still holds every vertex and the error bound
        // stays an upper bound.
        node.radius = float(from.radius * (1 + 1e-6) + 1e-6);
        node.abs_area = float(from.area * (1 + 1e-6));
        node.skip = uint32_t(from.skip);
        node.first = from.leaf ? uint32_t(from.first) : 0;
        node.count = from.leaf ? uint32_t(from.count) : 0;
    });
    tree.vertices.resize(tri.size() * 9);
    tbb::parallel_for(size_t(0), tri.size(), [&](size_t i) {
        for (int k = 0; k < 9; ++k)
            tree.vertices[9 * i + size_t(k)] = float(tri[built.order[i]][k]);
    });
    return tree;
}

WindingEvaluator::WindingEvaluator(Device::Impl& cl, const WindingTree& tree, VoxelizeStats& stats)
    : cl_(cl), stats_(stats), kernel_(cl.program(kKernel_solid), "winding_points") {
    auto t = Clock::now();
    vertices_ = upload(cl.context, cl.queue, tree.vertices);
    nodes_ = upload(cl.context, cl.queue, tree.nodes);
    node_count_ = cl_uint(tree.nodes.size());
    cl.queue.finish();
    stats.seconds_upload += seconds_since(t);
    group_ = work_group_size(kernel_, cl.device);
}

void WindingEvaluator::evaluate(const FilledLaterVector<float>& points, float far_ratio,
                                float node_tolerance, std::vector<float>& w,
                                std::vector<float>& error) {
    const size_t count = points.size() / 3;
    w.resize(count);
    error.resize(count);
    // Batches of points, smaller after a device allocation failure (a failed batch's results
    // are written again by its retry).
    auto run_batch = [&](size_t done, size_t max_points) {
        const size_t n = std::min(max_points, count - done);
        auto t = Clock::now();
        const cl::Buffer point_buffer =
            batch_buffer(cl_.context, CL_MEM_READ_ONLY, 3 * n * sizeof(float));
        cl::Buffer w_buffer = batch_buffer(cl_.context, CL_MEM_WRITE_ONLY, n * sizeof(float));
        cl::Buffer error_buffer = batch_buffer(cl_.context, CL_MEM_WRITE_ONLY, n * sizeof(float));
        cl_.queue.enqueueWriteBuffer(point_buffer, CL_FALSE, 0, 3 * n * sizeof(float),
                                     &points[3 * done]);
        cl_.queue.finish();
        stats_.seconds_upload += seconds_since(t);

        t = Clock::now();
        set_args(kernel_, 0, vertices_, nodes_, node_count_, point_buffer, cl_uint(0), cl_uint(n),
                 far_ratio, node_tolerance, w_buffer, error_buffer);
        run_sliced(
            cl_.queue, n, group_,
            [&](uint64_t first, uint64_t slice) {
                kernel_.setArg(4, cl_uint(first));
                launch(cl_.queue, kernel_, slice, group_);
            },
            {}, kWindingItemsPerLaunch);
        cl_.queue.finish();
        stats_.seconds_kernels += seconds_since(t);
        stats_.work_items += n;
        ++stats_.batches;

        t = Clock::now();
        cl_.queue.enqueueReadBuffer(w_buffer, CL_FALSE, 0, n * sizeof(float), &w[done]);
        cl_.queue.enqueueReadBuffer(error_buffer, CL_TRUE, 0, n * sizeof(float), &error[done]);
        stats_.seconds_download += seconds_since(t);
        return n;
    };
    run_batches(cl_.queue, count, points_per_batch_, stats_,
                "evaluating winding numbers on " + cl_.info.name, "point", run_batch);
}

void winding_points_reference(const WindingTree& tree, const FilledLaterVector<float>& points,
                              float far_ratio, float node_tolerance, std::vector<float>& w,
                              std::vector<float>& error) {
    const size_t count = points.size() / 3;
    w.resize(count);
    error.resize(count);
    tbb::parallel_for(size_t(0), count, [&](size_t i) {
        w[i] = ovs_winding_at(tree.vertices.data(), tree.nodes.data(), unsigned(tree.nodes.size()),
                              OvFloat3{points[3 * i], points[3 * i + 1], points[3 * i + 2]},
                              far_ratio, node_tolerance, &error[i]);
    });
}

}  // namespace oclvox::detail
