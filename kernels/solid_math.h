// Solid voxelization math shared, token for token, by kernels/solid.cl and the C++ host reference.
//
// Parity (Schwarz & Seidel 2010): a voxel is inside iff an odd number of surface crossings lie
// below its centre on the vertical line through it. Each triangle flips, in every voxel column
// whose centre (i + 0.5, j + 0.5) its xy projection covers, the first voxel whose centre lies
// above the crossing; a prefix XOR up the column then gives every voxel its parity.
//
// Which triangle covers a column is decided exactly, so a closed mesh never double counts or
// drops a crossing at a shared edge or vertex: vertices are snapped once to a fixed-point grid of
// 1/256 voxel (so a vertex has one value in every triangle that uses it), and the 2D edge
// functions are exact 64-bit integer expressions. A centre exactly on a projected edge or vertex
// is decided by simulation of simplicity: the column is moved to (x + e, y + e^2) for an
// infinitesimal e > 0, which no edge or vertex can contain. Vertical triangles cover no column
// for the same reason. Only the crossing height is computed in float; rounding there can only
// move a crossing past a voxel centre that lies within rounding of the surface.
#ifndef OCLVOX_SOLID_MATH_H
#define OCLVOX_SOLID_MATH_H

#ifdef __OPENCL_VERSION__
#pragma OPENCL FP_CONTRACT OFF
#define OVS_FN static inline
typedef long ovs_long;
#else
#include <cstdint>
#define OVS_FN static inline
namespace oclvox::detail {
typedef int64_t ovs_long;
#endif

// Fixed-point units per voxel. Voxel centres, i * 256 + 128, are exact.
#define OVS_UNITS 256
// Snapped coordinates must stay within +-2^29 units (2^21 voxels): with grid axes up to 2^20
// voxels, edge-function products then stay below 2^60 and their sums below 2^63.
#define OVS_MAX_UNITS ((ovs_long)1 << 29)

// A triangle for the parity test: vertices in fixed-point grid units (x0 y0 z0 x1 ...).
typedef struct {
    ovs_long v[9];
} OvParityTriangle;

// Voxel columns (i, j) of a triangle's xy bounding box whose centres it may cover, clipped to one
// brick column (bx, by) of brick_size voxels and to the grid; returns how many (0 if none).
typedef struct {
    int lo[2], hi[2];
} OvColumnRange;

// floor(a / b) for b > 0.
OVS_FN ovs_long ovs_floor_div(ovs_long a, ovs_long b) {
    ovs_long q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

OVS_FN ovs_long ovs_column_range(const OvParityTriangle* t, int bx, int by, int brick_size, int nx,
                                 int ny, OvColumnRange* r) {
    int brick[2] = {bx, by};
    int dims[2] = {nx, ny};
    ovs_long count = 1;
    for (int k = 0; k < 2; ++k) {
        ovs_long lo = t->v[k], hi = t->v[k];
        for (int i = 1; i < 3; ++i) {
            lo = t->v[3 * i + k] < lo ? t->v[3 * i + k] : lo;
            hi = t->v[3 * i + k] > hi ? t->v[3 * i + k] : hi;
        }
        // Centres c = i * 256 + 128 with lo <= c <= hi; the exact test decides the boundary ones.
        ovs_long first = ovs_floor_div(lo - OVS_UNITS / 2 + OVS_UNITS - 1, OVS_UNITS);
        ovs_long last = ovs_floor_div(hi - OVS_UNITS / 2, OVS_UNITS);
        ovs_long brick_lo = (ovs_long)brick[k] * brick_size;
        ovs_long brick_hi = brick_lo + brick_size - 1;
        if (brick_hi > dims[k] - 1) brick_hi = dims[k] - 1;
        if (first < brick_lo) first = brick_lo;
        if (last > brick_hi) last = brick_hi;
        if (last < first) return 0;
        r->lo[k] = (int)first;
        r->hi[k] = (int)last;
        count *= last - first + 1;
    }
    return count;
}

// Side of the column centre p relative to the projected edge a -> b, with a and b given relative
// to p: +1 left, -1 right, 0 only if a and b project to the same point. Exact, and antisymmetric
// (swapping a and b negates it), so two triangles sharing an edge always see opposite sides.
OVS_FN int ovs_edge_side(ovs_long ax, ovs_long ay, ovs_long bx, ovs_long by) {
    ovs_long e = ax * by - ay * bx;
    if (e != 0) return e > 0 ? 1 : -1;
    // Centre on the edge's line: the sign at (x + e, y + e^2) is that of e * (ay - by) +
    // e^2 * (bx - ax).
    if (ay != by) return ay > by ? 1 : -1;
    if (bx != ax) return bx > ax ? 1 : -1;
    return 0;
}

// The parity flip of triangle t in column (i, j): -1 if t does not cover the column's centre,
// else the first voxel k in [0, nz] whose centre lies above the crossing (nz: none in the grid).
OVS_FN int ovs_parity_flip(const OvParityTriangle* t, int i, int j, int nz) {
    ovs_long px = (ovs_long)i * OVS_UNITS + OVS_UNITS / 2;
    ovs_long py = (ovs_long)j * OVS_UNITS + OVS_UNITS / 2;
    ovs_long ax = t->v[0] - px, ay = t->v[1] - py;
    ovs_long bx = t->v[3] - px, by = t->v[4] - py;
    ovs_long cx = t->v[6] - px, cy = t->v[7] - py;

    // Covered iff the perturbed centre is strictly on the same side of all three edges, whichever
    // way the triangle winds: parity must not depend on orientation.
    int s_ab = ovs_edge_side(ax, ay, bx, by);
    int s_bc = ovs_edge_side(bx, by, cx, cy);
    int s_ca = ovs_edge_side(cx, cy, ax, ay);
    if (s_ab == 0 || s_ab != s_bc || s_bc != s_ca) return -1;

    // Barycentric weights (twice the sub-triangle areas, exact), made non-negative.
    ovs_long w_c = ax * by - ay * bx;
    ovs_long w_a = bx * cy - by * cx;
    ovs_long w_b = cx * ay - cy * ax;
    if (s_ab < 0) {
        w_a = -w_a;
        w_b = -w_b;
        w_c = -w_c;
    }
    ovs_long area = w_a + w_b + w_c;  // > 0: not all weights can vanish on a covering triangle

    // Crossing height relative to vertex a: z - za = num / area. Voxel k's centre is above it iff
    // g(k) = (centre_k - za) * area - num > 0. g is evaluated in float, and float rounding is
    // monotone, so g is non-decreasing in k and the first k with g(k) > 0 is well defined; a
    // float estimate of it is only a starting point for the search, which makes the result
    // independent of how the estimate was rounded.
    float f_area = (float)area;
    float num = (float)w_b * (float)(t->v[5] - t->v[2]) + (float)w_c * (float)(t->v[8] - t->v[2]);
    float estimate = ((float)t->v[2] + num / f_area - (float)(OVS_UNITS / 2)) / (float)OVS_UNITS;
    int k = 0;
    if (estimate >= (float)nz)
        k = nz;
    else if (estimate > 0.0f)
        k = (int)estimate + 1;
    while (k > 0 &&
           (float)((ovs_long)(k - 1) * OVS_UNITS + OVS_UNITS / 2 - t->v[2]) * f_area - num > 0.0f)
        --k;
    while (k < nz &&
           !((float)((ovs_long)k * OVS_UNITS + OVS_UNITS / 2 - t->v[2]) * f_area - num > 0.0f))
        ++k;
    return k;
}

// Inclusive prefix XOR of the 32 bits of `word` (bit 0 first), continuing the parity `carry`
// (0 or 1) of the bits below it.
OVS_FN unsigned int ovs_prefix_xor(unsigned int word, unsigned int carry) {
    word ^= word << 1;
    word ^= word << 2;
    word ^= word << 4;
    word ^= word << 8;
    word ^= word << 16;
    return carry ? ~word : word;
}

// A node of the winding-number tree (after Barill et al. 2018). Nodes are in depth-first order:
// an inner node's first child follows it and `skip` is the index just past its subtree, so the
// kernel walks the tree without a stack. Seen from further than OVS_WINDING_FAR radii, a subtree's
// solid angle is taken as that of a dipole: area_normal . (centre - p) / |centre - p|^3.
typedef struct {
    float centre[3];       // area-weighted centroid of the subtree's triangles (voxel units)
    float radius;          // of the ball around centre holding every vertex of the subtree
    float area_normal[3];  // sum of (b - a) x (c - a) / 2 over the subtree
    unsigned int skip;
    unsigned int first, count;  // a leaf's triangles [first, first + count); count 0 inside
} OvWindingNode;

#define OVS_WINDING_FAR 3.0f

#ifndef __OPENCL_VERSION__
}  // namespace oclvox::detail
#endif

#endif
