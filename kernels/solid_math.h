// Solid voxelization math shared, token for token, by kernels/solid.cl and the C++ host reference.
//
// Parity (Schwarz & Seidel 2010): a voxel is inside iff an odd number of surface crossings lie
// below its centre on the vertical line through it. Each triangle flips, in every voxel column
// whose centre (i + 0.5, j + 0.5) its xy projection covers, the first voxel whose centre lies
// above the crossing; a prefix XOR up the column then gives every voxel its parity.
//
// Both decisions are exact for the vertices as rounded, once, to a fixed-point grid of 2^-40
// voxel (so a vertex has one value in every triangle that uses it; it moves by at most 2^-41
// voxel, and not at all at 2^12 voxels or more from the grid origin, where doubles are no finer).
// The 2D edge functions are exact 128-bit integers and a voxel centre is compared with the
// crossing height by an exact 192-bit integer expression, so a closed mesh never double counts
// or drops a crossing at a shared edge or vertex, and a centre is on the side of the surface it
// truly lies on, however close. A centre exactly on a projected edge or vertex is decided by
// simulation of simplicity: the column is moved to (x + e, y + e^2) for an infinitesimal e > 0,
// which no edge or vertex can contain. Vertical triangles cover no column for the same reason. A
// centre exactly on the surface counts the crossing as not below it.
//
// A float filter with rigorous error bounds decides the clear cases and defers the others to the
// integer test, so the answer never depends on float rounding: device and host agree bit for bit.
#ifndef OCLVOX_SOLID_MATH_H
#define OCLVOX_SOLID_MATH_H

#ifdef __OPENCL_VERSION__
#pragma OPENCL FP_CONTRACT OFF
#define OVS_FN static inline
typedef long ovs_long;
typedef ulong ovs_ulong;
#define ovs_mul_hi(a, b) mul_hi(a, b)
#define OVS_FABS fabs
#define OVS_FMAX fmax
#define OVS_FMIN fmin
#define OVS_SIGNBIT signbit
#define OVS_COPYSIGN copysign
#define OVS_SQRT sqrt
#define OVS_GLOBAL __global
#else
#include <cmath>
#include <cstdint>
#define OVS_FN static inline
#define OVS_FABS std::fabs
#define OVS_FMAX std::fmax
#define OVS_FMIN std::fmin
#define OVS_SIGNBIT std::signbit
#define OVS_COPYSIGN std::copysign
#define OVS_SQRT std::sqrt
#define OVS_GLOBAL
namespace oclvox::detail {
typedef int64_t ovs_long;
typedef uint64_t ovs_ulong;
// OpenCL's mul_hi for ulong: the high 64 bits of the 128-bit product a * b.
OVS_FN ovs_ulong ovs_mul_hi(ovs_ulong a, ovs_ulong b) {
    const ovs_ulong a_lo = a & 0xffffffffu, a_hi = a >> 32;
    const ovs_ulong b_lo = b & 0xffffffffu, b_hi = b >> 32;
    const ovs_ulong lo_hi = a_lo * b_hi, hi_lo = a_hi * b_lo;
    const ovs_ulong middle = ((a_lo * b_lo) >> 32) + (lo_hi & 0xffffffffu) + (hi_lo & 0xffffffffu);
    return a_hi * b_hi + (lo_hi >> 32) + (hi_lo >> 32) + (middle >> 32);
}
#endif

// Fixed-point units per voxel (2^40). Voxel centres, i * OVS_UNITS + OVS_UNITS / 2, are exact.
#define OVS_UNITS ((ovs_long)1 << 40)
// Snapped coordinates stay within +-2^61 units (2^21 voxels), and grid axes hold at most 2^20
// voxels, so coordinates relative to a column centre or to another vertex stay below 2^62; 2D
// edge functions below 2^125; twice a triangle's projected area below 2^124 (its xy box's area);
// the crossing numerator and the centre test below 2^188: all within the 192-bit OvWide.
#define OVS_MAX_UNITS ((ovs_long)1 << 61)

// A triangle for the parity test: vertices in fixed-point grid units (x0 y0 z0 x1 ...).
typedef struct {
    ovs_long v[9];
} OvParityTriangle;

// A signed 192-bit integer in two's complement, least significant word first.
typedef struct {
    ovs_ulong w[3];
} OvWide;

OVS_FN OvWide ovs_wide(ovs_long a) {
    OvWide r;
    r.w[0] = (ovs_ulong)a;
    r.w[1] = r.w[2] = a < 0 ? ~(ovs_ulong)0 : 0;
    return r;
}

OVS_FN OvWide ovs_add(OvWide a, OvWide b) {
    OvWide r;
    r.w[0] = a.w[0] + b.w[0];
    ovs_ulong carry = r.w[0] < a.w[0] ? 1 : 0;
    ovs_ulong sum = a.w[1] + b.w[1];
    ovs_ulong carry_out = sum < a.w[1] ? 1 : 0;
    r.w[1] = sum + carry;
    carry_out += r.w[1] < sum ? 1 : 0;
    r.w[2] = a.w[2] + b.w[2] + carry_out;
    return r;
}

OVS_FN OvWide ovs_negate(OvWide a) {
    OvWide r;
    r.w[0] = ~a.w[0] + 1;
    ovs_ulong carry = r.w[0] == 0 ? 1 : 0;
    r.w[1] = ~a.w[1] + carry;
    carry = (carry && r.w[1] == 0) ? 1 : 0;
    r.w[2] = ~a.w[2] + carry;
    return r;
}

OVS_FN int ovs_sign(OvWide a) {
    if ((ovs_long)a.w[2] < 0) return -1;
    return (a.w[0] | a.w[1] | a.w[2]) != 0 ? 1 : 0;
}

// a * b, for |a| < 2^128 (the product must fit, which the bounds above guarantee).
OVS_FN OvWide ovs_mul(OvWide a, ovs_long b) {
    int negative = (ovs_sign(a) < 0) != (b < 0);
    OvWide m = ovs_sign(a) < 0 ? ovs_negate(a) : a;
    ovs_ulong mb = b < 0 ? (ovs_ulong)0 - (ovs_ulong)b : (ovs_ulong)b;
    OvWide r;
    r.w[0] = m.w[0] * mb;
    ovs_ulong high = ovs_mul_hi(m.w[0], mb);
    r.w[1] = high + m.w[1] * mb;
    r.w[2] = ovs_mul_hi(m.w[1], mb) + (r.w[1] < high ? 1 : 0);
    return negative ? ovs_negate(r) : r;
}

// a / 2^64 as a float (within a few units of its last place), for a float estimate of a ratio of
// two OvWide values. Converted as a magnitude, so that no two large words cancel.
OVS_FN float ovs_wide_float(OvWide a) {
    OvWide m = ovs_sign(a) < 0 ? ovs_negate(a) : a;
    float f = (float)m.w[2] * 0x1p64f + (float)m.w[1] + (float)m.w[0] * 0x1p-64f;
    return ovs_sign(a) < 0 ? -f : f;
}

// ax * by - ay * bx, exactly.
OVS_FN OvWide ovs_cross(ovs_long ax, ovs_long ay, ovs_long bx, ovs_long by) {
    return ovs_add(ovs_mul(ovs_wide(ax), by), ovs_negate(ovs_mul(ovs_wide(ay), bx)));
}

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
        // Centres c = i * OVS_UNITS + OVS_UNITS / 2 with lo <= c <= hi; the exact test decides
        // the boundary ones.
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
// to p and e = ax * by - ay * bx: +1 left, -1 right, 0 only if a and b project to the same point.
// Exact, and antisymmetric (swapping a and b negates it), so two triangles sharing an edge always
// see opposite sides.
OVS_FN int ovs_edge_side(OvWide e, ovs_long ax, ovs_long ay, ovs_long bx, ovs_long by) {
    int s = ovs_sign(e);
    if (s != 0) return s;
    // Centre on the edge's line: the sign at (x + e, y + e^2) is that of e * (ay - by) +
    // e^2 * (bx - ax).
    if (ay != by) return ay > by ? 1 : -1;
    if (bx != ax) return bx > ax ? 1 : -1;
    return 0;
}

// Whether the centre of voxel k lies strictly above the crossing za + num / area (area > 0).
OVS_FN int ovs_centre_above(OvWide area, OvWide num, ovs_long za, int k) {
    ovs_long centre = (ovs_long)k * OVS_UNITS + OVS_UNITS / 2;
    return ovs_sign(ovs_add(ovs_mul(area, centre - za), ovs_negate(num))) > 0;
}

// The parity flip of triangle t in column (i, j), in exact integers: -1 if t does not cover the
// column's centre, else the first voxel k in [0, nz] whose centre lies above the crossing (nz:
// none in the grid).
OVS_FN int ovs_parity_flip_exact(const OvParityTriangle* t, int i, int j, int nz) {
    ovs_long px = (ovs_long)i * OVS_UNITS + OVS_UNITS / 2;
    ovs_long py = (ovs_long)j * OVS_UNITS + OVS_UNITS / 2;
    ovs_long ax = t->v[0] - px, ay = t->v[1] - py;
    ovs_long bx = t->v[3] - px, by = t->v[4] - py;
    ovs_long cx = t->v[6] - px, cy = t->v[7] - py;

    // Barycentric weights: twice the areas of the sub-triangles opposite each vertex.
    OvWide w_c = ovs_cross(ax, ay, bx, by);
    OvWide w_a = ovs_cross(bx, by, cx, cy);
    OvWide w_b = ovs_cross(cx, cy, ax, ay);

    // Covered iff the perturbed centre is strictly on the same side of all three edges, whichever
    // way the triangle winds: parity must not depend on orientation.
    int s_ab = ovs_edge_side(w_c, ax, ay, bx, by);
    int s_bc = ovs_edge_side(w_a, bx, by, cx, cy);
    int s_ca = ovs_edge_side(w_b, cx, cy, ax, ay);
    if (s_ab == 0 || s_ab != s_bc || s_bc != s_ca) return -1;
    if (s_ab < 0) {
        w_a = ovs_negate(w_a);
        w_b = ovs_negate(w_b);
        w_c = ovs_negate(w_c);
    }
    // Now every weight is >= 0, and their sum is > 0: not all can vanish on a covering triangle.
    OvWide area = ovs_add(ovs_add(w_a, w_b), w_c);

    // Crossing height relative to vertex a: num / area. The first voxel whose centre lies above
    // it is found by an exact search, which starts at a float estimate (close, as the weights
    // are exact and non-negative) and so does not depend on how the estimate was rounded.
    OvWide num = ovs_add(ovs_mul(w_b, t->v[5] - t->v[2]), ovs_mul(w_c, t->v[8] - t->v[2]));
    float ratio = ovs_wide_float(num) / ovs_wide_float(area);
    float estimate = ((float)t->v[2] + ratio - (float)(OVS_UNITS / 2)) / (float)OVS_UNITS;
    int k = 0;
    if (estimate >= (float)nz)
        k = nz;
    else if (estimate > 0.0f)
        k = (int)estimate + 1;
    while (k > 0 && ovs_centre_above(area, num, t->v[2], k - 1)) --k;
    while (k < nz && !ovs_centre_above(area, num, t->v[2], k)) ++k;
    return k;
}

// The float filter in front of the exact test. Every float below carries a rigorous bound on its
// distance from the exact value, so whatever it decides is what the exact test would decide
// (float + - * are correctly rounded in OpenCL C and on the host, and an overflow to inf or NaN
// decides nothing); only what it cannot decide, centres within about 2^-20 relative of an edge
// or of the crossing, goes to the exact test. Coordinates are scaled by 2^-20 so that no product
// underflows and none overflows below the OvWide bounds.
#define OVS_FILTER_SCALE 0x1p-20f
#define OVS_UNDECIDED (-2)

// |x|, the same function on device and host.
OVS_FN float ovs_abs(float x) {
    return x < 0.0f ? -x : x;
}

// G(k) = sum over vertices of w_v * (centre_k - z_v): > 0 iff voxel k's centre lies above the
// crossing (the weights w are >= 0). Returns +1 or -1 where the float evaluation decides the sign
// beyond its error bound, else 0. werr: bounds on |w - exact weight|.
OVS_FN int ovs_filtered_above(const OvParityTriangle* t, const float* w, const float* werr, int k) {
    ovs_long centre = (ovs_long)k * OVS_UNITS + OVS_UNITS / 2;
    float g = 0.0f, bound = 0.0f;
    for (int v = 0; v < 3; ++v) {
        float h = (float)(centre - t->v[3 * v + 2]) * OVS_FILTER_SCALE;
        g += w[v] * h;
        bound += (werr[v] + 0x1p-20f * w[v]) * ovs_abs(h);
    }
    // The products and sums above round at most a few times 2^-24 relative; twice the bound
    // covers them and the rounding of the bound itself.
    bound *= 2.0f;
    if (g > bound) return 1;
    if (g < -bound) return -1;
    return 0;
}

// The parity flip as ovs_parity_flip_exact, or OVS_UNDECIDED where the float filter cannot tell.
OVS_FN int ovs_parity_flip_filtered(const OvParityTriangle* t, int i, int j, int nz) {
    ovs_long px = (ovs_long)i * OVS_UNITS + OVS_UNITS / 2;
    ovs_long py = (ovs_long)j * OVS_UNITS + OVS_UNITS / 2;
    float x[3], y[3];
    for (int v = 0; v < 3; ++v) {
        x[v] = (float)(t->v[3 * v] - px) * OVS_FILTER_SCALE;
        y[v] = (float)(t->v[3 * v + 1] - py) * OVS_FILTER_SCALE;
    }
    // w[v]: the weight of vertex v, the edge function of the opposite edge. With p1 and p2 its
    // rounded products, |w - exact| <= 2^-21 (|p1| + |p2|): the two conversions, the product and
    // the difference each round by at most 2^-24 relative.
    float w[3], werr[3];
    int plus = 0, minus = 0;
    for (int v = 0; v < 3; ++v) {
        int a = (v + 1) % 3, b = (v + 2) % 3;
        float p1 = x[a] * y[b], p2 = y[a] * x[b];
        w[v] = p1 - p2;
        werr[v] = 0x1p-21f * (ovs_abs(p1) + ovs_abs(p2));
        plus += w[v] > werr[v] ? 1 : 0;
        minus += w[v] < -werr[v] ? 1 : 0;
    }
    if (plus > 0 && minus > 0) return -1;
    if (plus + minus < 3) return OVS_UNDECIDED;
    if (minus == 3)
        for (int v = 0; v < 3; ++v) w[v] = -w[v];

    // Start from the float crossing height and confirm it between two centres.
    float area = w[0] + w[1] + w[2];
    float za = (float)t->v[2] * OVS_FILTER_SCALE;
    float dzb = (float)(t->v[5] - t->v[2]) * OVS_FILTER_SCALE;
    float dzc = (float)(t->v[8] - t->v[2]) * OVS_FILTER_SCALE;
    float voxel = (float)OVS_UNITS * OVS_FILTER_SCALE;
    float estimate = (za + (w[1] * dzb + w[2] * dzc) / area - 0.5f * voxel) / voxel;
    int k = 0;
    if (estimate >= (float)nz)
        k = nz;
    else if (estimate > 0.0f)
        k = (int)estimate + 1;
    if (k > 0 && ovs_filtered_above(t, w, werr, k - 1) >= 0) return OVS_UNDECIDED;
    if (k < nz && ovs_filtered_above(t, w, werr, k) <= 0) return OVS_UNDECIDED;
    return k;
}

// The parity flip of triangle t in column (i, j): -1 if t does not cover the column's centre,
// else the first voxel k in [0, nz] whose centre lies above the crossing (nz: none in the grid).
OVS_FN int ovs_parity_flip(const OvParityTriangle* t, int i, int j, int nz) {
    int k = ovs_parity_flip_filtered(t, i, j, nz);
    return k != OVS_UNDECIDED ? k : ovs_parity_flip_exact(t, i, j, nz);
}

// Inclusive prefix XOR of the 32 bits of `word` (bit 0 first), continuing the parity `carry`
// (0 or 1) of the bits below it: complemented where that parity is odd. Written once for the
// reference's single words (ovs_prefix_xor) and the kernel's rows of four (ovs_prefix_xor4, lane
// by lane the same steps).
#define OVS_PREFIX_XOR(NAME, WORD)            \
    OVS_FN WORD NAME(WORD word, WORD carry) { \
        word ^= word << 1;                    \
        word ^= word << 2;                    \
        word ^= word << 4;                    \
        word ^= word << 8;                    \
        word ^= word << 16;                   \
        return word ^ ((WORD)(0u) - carry);   \
    }
OVS_PREFIX_XOR(ovs_prefix_xor, unsigned int)
#ifdef __OPENCL_VERSION__
OVS_PREFIX_XOR(ovs_prefix_xor4, uint4)
#endif

// A node of the winding-number tree (after Barill et al. 2018). Nodes are in depth-first order:
// an inner node's first child follows it and `skip` is the index just past its subtree, so the
// kernel walks the tree without a stack. Seen from a point p farther than OVS_WINDING_FAR radii
// from `centre`, a subtree's solid angle is taken from the second-order Taylor expansion of
// f(x) = (x - p) / |x - p|^3 about the centre, with d = centre - p, r = |d|:
//   area_normal . d / r^3 + trace(M) / r^3 - 3 d.M.d / r^5,
// where M = sum over the subtree's triangles of area_normal_t (centroid_t - centre)^T. The
// linear term is exact for flat triangles (the mean of x - centre over a triangle is its
// centroid's offset), so the remainder is the quadratic Taylor term, bounded by
//   3 * abs_area * radius^2 / (r - radius)^4
// (the third derivatives of 1/|x| have norm 6/|x|^4); the kernel sums this bound per point.
typedef struct {
    float centre[3];       // area-weighted centroid of the subtree's triangles (voxel units)
    float radius;          // of the ball around centre holding every vertex of the subtree
    float area_normal[3];  // sum of (b - a) x (c - a) / 2 over the subtree
    float abs_area;        // sum of the triangles' areas
    float moment[9];       // M above, row-major: moment[3 * i + j] = M_ij
    unsigned int skip;
    unsigned int first, count;  // a leaf's triangles [first, first + count); count 0 inside
} OvWindingNode;

// Far-field acceptance: a subtree counts as its expansion beyond this many radii (Barill et al.
// use 2 with their second-order term); the kernel adds the remainder bound of every subtree it
// accepts to the point's error bound.
#define OVS_WINDING_FAR 2.0f

// Winding number: atan2(y, x) to within 3e-7 radians (about an ulp of pi in float), for the solid
// angles of the winding kernel. atan on [0, 1] is a degree-7 polynomial in its square
// (least-squares weighted towards minimax, fitted for this function), folded to the octant and
// quadrant without branches so work-items vectorize: the library atan2 was half of the winding
// kernel's time on CPU devices. Each angle's error reaches w divided by 2 pi, far inside the
// evaluation's tolerance (kTileRounding in solid_winding.cpp). Signs follow atan2: copysign on y
// (so +-0 give +-pi when x is negative), pi when x is -0.
OVS_FN float ovs_atan2(float y, float x) {
    const float ax = OVS_FABS(x), ay = OVS_FABS(y);
    const float hi = OVS_FMAX(ax, ay), lo = OVS_FMIN(ax, ay);
    const float t = hi > 0.0f ? lo / hi : 0.0f;
    const float s = t * t;
    float r = -0.00405456498f;
    r = r * s + 0.0218629558f;
    r = r * s - 0.0559123345f;
    r = r * s + 0.0964219868f;
    r = r * s - 0.139086306f;
    r = r * s + 0.199465662f;
    r = r * s - 0.333298594f;
    r = r * s + 0.999999344f;
    r *= t;
    r = ay > ax ? 1.57079637f - r : r;         // pi / 2 in float
    r = OVS_SIGNBIT(x) ? 3.14159274f - r : r;  // pi in float
    return OVS_COPYSIGN(r, y);
}

// Winding number: three-component float vectors, OpenCL's float3 in a kernel (whose arithmetic
// a CPU device runs as vector instructions) and a struct on the host, with - and * component by
// component and dot and cross products written out, in the same order on both sides (OpenCL's
// own dot, cross and length may fuse or reorder).
#ifdef __OPENCL_VERSION__
typedef float3 OvFloat3;
#define OVS_FLOAT3(x, y, z) ((float3)((x), (y), (z)))
#else
struct OvFloat3 {
    float x, y, z;
};
OVS_FN OvFloat3 operator-(OvFloat3 a, OvFloat3 b) {
    return {a.x - b.x, a.y - b.y, a.z - b.z};
}
OVS_FN OvFloat3 operator*(OvFloat3 a, OvFloat3 b) {
    return {a.x * b.x, a.y * b.y, a.z * b.z};
}
#define OVS_FLOAT3(x, y, z) (OvFloat3{(x), (y), (z)})
#endif
OVS_FN float ovs_dot3(OvFloat3 a, OvFloat3 b) {
    const OvFloat3 t = a * b;
    return t.x + t.y + t.z;
}
OVS_FN OvFloat3 ovs_cross3(OvFloat3 a, OvFloat3 b) {
    return OVS_FLOAT3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

// Winding number: the signed solid angle of triangle (a, b, c) seen from the origin (Van
// Oosterom & Strackee 1983): tan(omega / 2) = det[a b c] / (|a||b||c| + (a.b)|c| + (b.c)|a| +
// (c.a)|b|). Positive when the origin lies behind the triangle (opposite its normal
// (b - a) x (c - a)), so a closed, outward-facing mesh sums to 4 pi inside.
OVS_FN float ovs_solid_angle(OvFloat3 a, OvFloat3 b, OvFloat3 c) {
    const float det = ovs_dot3(a, ovs_cross3(b, c));
    const float la = OVS_SQRT(ovs_dot3(a, a)), lb = OVS_SQRT(ovs_dot3(b, b)),
                lc = OVS_SQRT(ovs_dot3(c, c));
    const float den =
        la * lb * lc + ovs_dot3(a, b) * lc + ovs_dot3(b, c) * la + ovs_dot3(c, a) * lb;
    return 2.0f * ovs_atan2(det, den);
}

// Generalized winding number w at point p (voxel units relative to the grid origin), walking the
// winding tree: subtrees farther than far_ratio radii whose remainder bound is at most
// node_tolerance count as their second-order expansion, near leaves triangle by triangle
// (vertices in leaf order, 9 floats each). Sets *error to the sum of the accepted expansions'
// remainder bounds over 4 pi (float rounding not counted); far_ratio = INFINITY sums every
// triangle exactly.
//
// The same bits on the host and on every device whose division and sqrt are correctly rounded:
// single-precision + - * / and sqrt in the order written, FP_CONTRACT OFF (the host's division
// and sqrt are IEEE; a device is built with -cl-fp32-correctly-rounded-divide-sqrt where it
// reports support, as PoCL and NVIDIA's driver do). So the winding solid's voxels do not depend
// on such a device.
OVS_FN float ovs_winding_at(const OVS_GLOBAL float* vertices, const OVS_GLOBAL OvWindingNode* nodes,
                            unsigned int node_count, OvFloat3 p, float far_ratio,
                            float node_tolerance, float* error) {
    float sum = 0.0f, bound = 0.0f;
    for (unsigned int i = 0; i < node_count;) {
        const OVS_GLOBAL OvWindingNode* n = nodes + i;
        const OvFloat3 d = OVS_FLOAT3(n->centre[0], n->centre[1], n->centre[2]) - p;
        const float dist2 = ovs_dot3(d, d);
        const float reach = far_ratio * n->radius;
        const float dist = OVS_SQRT(dist2);
        const float gap = dist - n->radius;
        const float node_bound =
            3.0f * n->abs_area * n->radius * n->radius / (gap * gap * gap * gap);
        if (dist2 > reach * reach && gap > 0.0f && node_bound <= node_tolerance) {
            const OVS_GLOBAL float* m = n->moment;
            const OvFloat3 an = OVS_FLOAT3(n->area_normal[0], n->area_normal[1], n->area_normal[2]);
            const OvFloat3 md = OVS_FLOAT3(ovs_dot3(OVS_FLOAT3(m[0], m[1], m[2]), d),
                                           ovs_dot3(OVS_FLOAT3(m[3], m[4], m[5]), d),
                                           ovs_dot3(OVS_FLOAT3(m[6], m[7], m[8]), d));
            const float trace = m[0] + m[4] + m[8];
            const float inv3 = 1.0f / (dist2 * dist);
            sum += (ovs_dot3(an, d) + trace) * inv3 - 3.0f * ovs_dot3(d, md) * inv3 / dist2;
            bound += node_bound;
            i = n->skip;
        } else if (n->count) {
            for (unsigned int t = n->first; t < n->first + n->count; ++t) {
                const OVS_GLOBAL float* v = vertices + 9 * (size_t)t;
                sum += ovs_solid_angle(OVS_FLOAT3(v[0], v[1], v[2]) - p,
                                       OVS_FLOAT3(v[3], v[4], v[5]) - p,
                                       OVS_FLOAT3(v[6], v[7], v[8]) - p);
            }
            i = n->skip;
        } else {
            ++i;
        }
    }
    *error = bound / (4.0f * 3.14159274f);
    return sum / (4.0f * 3.14159274f);
}

#ifndef __OPENCL_VERSION__
}  // namespace oclvox::detail
#endif

#endif
