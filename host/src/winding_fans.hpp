// The fans that close an open mesh's holes for the generalized winding number solid
// (solid_winding.cpp): their triangles, their winding number in double, and bounds on it and on
// its gradient over a ball, which let whole tiles of voxels near a hole be decided at once.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <vector>

#include "oclvox/oclvox.hpp"
#include "overlap_double.hpp"
#include "winding_tree.hpp"

namespace oclvox::detail {

// Fans that close the mesh's holes. The boundary of the mesh (after welding: each edge carrying
// the number of triangles running it one way minus the other) splits into connected cycles; a
// fan of triangles (apex, a, b) from the mean vertex of each cycle has exactly that boundary. So
// the mesh minus the fans is a closed cycle, and w = n + w_fans where n, the winding number of
// that cycle, is an integer that changes only across the mesh or a fan. A closed, consistently
// oriented mesh (or a union of such, duplicated shells included) has no fans.
struct BoundaryFans {
    std::vector<std::array<double, 9>> triangles;  // grid coordinates (voxel units)
    std::vector<double> weight;                    // how many times each counts
    double total_weight = 0;
    // The tree over the triangles (build_winding_nodes, their weights counted), leaves of 16
    // triangles at most; the triangles are stored in its order.
    std::vector<WindingNode> nodes;

    // w of the fans at p, in double: every fan triangle's solid angle.
    double winding(const Vec3d& p) const;

    // w of the fans at p within `error` of winding(p), its rounding included, at a fraction of
    // the cost where fans have many triangles: a node of the tree farther off than kFarRadii of
    // its radii counts as the second-order expansion of its triangles' solid angles about its
    // centre (as the kernel's tree, after Barill et al. 2018), with a remainder of at most
    // 3 area radius^2 / gap^4 (the third derivatives of 1/|x| have norm at most 6/|x|^4); the
    // others count triangle by triangle. A decision that the error leaves open can still ask
    // winding(p).
    struct Estimate {
        double value, error;
    };
    static constexpr double kFarRadii = 4;
    Estimate winding_estimate(const Vec3d& p) const;

    // An upper bound on |w of the fans| over the ball of radius `reach` around p: a triangle's
    // solid angle is at most its area over its least distance squared, and at most 2 pi.
    double bound(const Vec3d& p, double reach) const;

    // An upper bound on |grad w of the fans| over the ball of radius `reach` around p (infinite
    // if a fan triangle comes that close). The solid angle's kernel n.r/|r|^3 has a gradient of
    // at most 2/|r|^3, so a triangle at least d away contributes at most 2 area / d^3, and also
    // at most 4 pi / d (the integral of 2/|r|^3 over the whole of its plane beyond distance d):
    // the second is what keeps the long triangles of a fan over a large hole from making every
    // voxel near it undecided. A near triangle's d is its least distance, not its ball's.
    double gradient_bound(const Vec3d& p, double reach) const;

    // Whether |w of the fans| at p is certainly below 1/2 by a sum like bound(p, 0)'s, taken
    // over the tree: a node farther off than its radius counts as its weighted area over its gap
    // squared (none of its triangles is nearer), so it can say "not below" where bound would
    // not, never "below" where bound would not. Stops once the sum passes 1/2: cheap where fans
    // are many and near.
    bool below_half_at(const Vec3d& p) const;

    // The least distance from p to fan triangle t, in double.
    double least_distance(size_t t, const Vec3d& p) const;

    // Area of fan triangle t; the distance between two points.
    double area_of(size_t t) const;
    static double distance(const Vec3d& p, const Vec3d& q);

  private:
    // Fan triangle t's solid angle seen from p, times its weight.
    double weighted_solid_angle(size_t t, const Vec3d& p) const;

    // The sum over the fans of a term of area and distance from the ball of radius `reach`
    // around p, over 4 pi, leaf by leaf: a leaf whose ball is farther off than its radius as one
    // term, far(its weighted area, the gap between the balls), which must bound the sum of its
    // triangles' terms; every other triangle as near(its area, d) times its weight, d its least
    // distance less `reach` (shrunk a little so that rounding cannot make it larger than the
    // true distance; 0 or less when the triangle comes within the ball).
    template <class Far, class Near>
    double sum_over_ball(const Vec3d& p, double reach, Far far, Near near) const {
        double sum = 0;
        for (const WindingNode& c : nodes) {
            if (!c.leaf) continue;
            const double gap = distance(p, c.centre) - c.radius - reach;
            if (gap > c.radius) {
                sum += far(c.area, gap);
                continue;
            }
            for (size_t t = c.first; t < c.first + c.count; ++t)
                sum += weight[t] * near(area_of(t), least_distance(t, p) * (1 - 1e-9) - reach);
        }
        return sum / (4 * M_PI);
    }
};

// The fans of the mesh's holes, in grid coordinates (voxel units): none for a closed,
// consistently oriented mesh.
BoundaryFans boundary_fans(const Mesh& mesh, const Grid& grid);

}  // namespace oclvox::detail
