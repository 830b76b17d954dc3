// The tree over a distance field's prepared triangles that full-grid fields search beyond the
// band (ov_tree_distance2 in kernels/sdf_math.h): boxes split at the median centroid of their
// longest axis down to a few triangles, stored depth first: a node's first child follows it, and
// the first child's skip link is the second.
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "sdf_internal.hpp"

namespace oclvox::detail {

namespace {

// Triangles per leaf: the device walks a row of 8 voxels at once, and evaluating a leaf's
// triangles for the row is cheap beside a step of the walk; 8 was fastest through PoCL on
// bunny00 at 64 and 128 (1, 2, 4, 16 measured too).
constexpr size_t kLeafTriangles = 8;

// A box in global voxel coordinates, in double (a float vertex plus its integer anchor is exact).
struct Box {
    double lo[3] = {INFINITY, INFINITY, INFINITY};
    double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    void add(const Box& b) {
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], b.lo[a]);
            hi[a] = std::max(hi[a], b.hi[a]);
        }
    }
};

Box triangle_box(const OvSdfTriangle& t) {
    Box box;
    for (int v = 0; v < 3; ++v)
        for (int a = 0; a < 3; ++a) {
            const double x = double(t.anchor[a]) + double(t.vertex[v][a]);
            box.lo[a] = std::min(box.lo[a], x);
            box.hi[a] = std::max(box.hi[a], x);
        }
    return box;
}

// x - margin rounded down to float, or x + margin rounded up. The margin covers the float
// evaluation of distances to the box's triangles: their errors grow with the coordinates'
// magnitudes (about 2^-23 of them), so it does too, with a factor of a hundred to spare.
float widened(double x, double margin, bool up) {
    const double target = up ? x + margin : x - margin;
    float f = float(target);
    if (up && double(f) < target) f = std::nextafter(f, INFINITY);
    if (!up && double(f) > target) f = std::nextafter(f, -INFINITY);
    return f;
}

// Subtrees over more triangles than this build their two halves in parallel.
constexpr size_t kParallelTriangles = 16384;

struct Builder {
    const std::vector<Box>& boxes;
    SdfTree& tree;
    // The nodes of a subtree over n > kLeafTriangles triangles. The tree splits at the middle,
    // so this depends on n alone: every subtree's place in the depth-first order is known before
    // it is built, and subtrees build in parallel into the nodes laid out for them.
    std::map<size_t, size_t> subtree_nodes;

    size_t nodes_of(size_t n) const { return n <= kLeafTriangles ? 1 : subtree_nodes.at(n); }
    // Fills subtree_nodes for every size the tree over n triangles holds (a few per level: the
    // halves of n at depth d are the floor and ceiling of n / 2^d), and returns nodes_of(n).
    size_t count_nodes(size_t n) {
        if (n <= kLeafTriangles) return 1;
        if (const auto known = subtree_nodes.find(n); known != subtree_nodes.end())
            return known->second;
        const size_t nodes = 1 + count_nodes(n / 2) + count_nodes(n - n / 2);
        subtree_nodes[n] = nodes;
        return nodes;
    }

    // Builds the subtree of order[begin, end) depth first from node `node` on.
    void build(size_t begin, size_t end, size_t node) {
        Box box, centres;
        for (size_t p = begin; p < end; ++p) {
            const Box& b = boxes[tree.order[p]];
            box.add(b);
            Box centre;
            for (int a = 0; a < 3; ++a) centre.lo[a] = centre.hi[a] = (b.lo[a] + b.hi[a]) / 2;
            centres.add(centre);
        }
        OvSdfNode& out = tree.nodes[node];
        for (int a = 0; a < 3; ++a) {
            const double margin = 1e-2 + 1e-5 * std::max(std::abs(box.lo[a]), std::abs(box.hi[a]));
            out.lo[a] = widened(box.lo[a], margin, false);
            out.hi[a] = widened(box.hi[a], margin, true);
        }
        out.skip = unsigned(node + nodes_of(end - begin));
        if (end - begin <= kLeafTriangles) {
            out.first = unsigned(begin);
            out.count = unsigned(end - begin);
            return;
        }
        // The median by centroid along the longest axis of the centroids (ties by index, so the
        // tree depends neither on the sort nor on the threads).
        int axis = 0;
        for (int a = 1; a < 3; ++a)
            if (centres.hi[a] - centres.lo[a] > centres.hi[axis] - centres.lo[axis]) axis = a;
        const size_t middle = begin + (end - begin) / 2;
        auto centre = [&](uint32_t t) { return boxes[t].lo[axis] + boxes[t].hi[axis]; };
        std::nth_element(tree.order.begin() + ptrdiff_t(begin),
                         tree.order.begin() + ptrdiff_t(middle),
                         tree.order.begin() + ptrdiff_t(end), [&](uint32_t a, uint32_t b) {
                             return centre(a) < centre(b) || (centre(a) == centre(b) && a < b);
                         });
        auto first_half = [&] { build(begin, middle, node + 1); };
        auto second_half = [&] { build(middle, end, node + 1 + nodes_of(middle - begin)); };
        if (end - begin > kParallelTriangles) {
            tbb::parallel_invoke(first_half, second_half);
        } else {
            first_half();
            second_half();
        }
    }
};

}  // namespace

SdfTree build_sdf_tree(const std::vector<OvSdfTriangle>& triangles) {
    SdfTree tree;
    if (triangles.empty()) return tree;
    std::vector<Box> boxes(triangles.size());
    for (size_t t = 0; t < triangles.size(); ++t) boxes[t] = triangle_box(triangles[t]);
    tree.order.resize(triangles.size());
    for (size_t t = 0; t < triangles.size(); ++t) tree.order[t] = uint32_t(t);
    Builder builder{boxes, tree, {}};
    tree.nodes.resize(builder.count_nodes(triangles.size()));
    builder.build(0, triangles.size(), 0);
    return tree;
}

}  // namespace oclvox::detail
