// Structs and math shared, token for token, by the OpenCL kernels and the C++ host reference.
//
// Determinism contract: everything here is plain IEEE single-precision +, -, *, comparisons,
// floor, min and max, evaluated in the order written. Kernels are built without fast-math and
// with FP_CONTRACT OFF; the host is built with -ffp-contract=off. So a kernel and the host
// reference compute bit-identical results on every conforming device.
//
// Coordinates: a triangle arrives as an integer anchor (a voxel corner near it) plus its three
// vertices relative to that anchor, in voxel units, computed in double on the host and rounded
// once to float. All tests work in anchor-relative coordinates, so precision does not fall off
// with the distance from the grid origin, and voxel (i,j,k) is the box [q, q+1] with
// q = (i,j,k) - anchor, which is exact in float.
#ifndef OCLVOX_VOXEL_MATH_H
#define OCLVOX_VOXEL_MATH_H

#ifdef __OPENCL_VERSION__
#pragma OPENCL FP_CONTRACT OFF
#define OV_FN static inline
typedef ulong ov_ulong;
#else
#include <cmath>
#include <cstdint>
#define OV_FN static inline
using std::fabs;
using std::nextafter;
namespace oclvox::detail {
typedef uint64_t ov_ulong;
// fmin and fmax as OpenCL and C define them (a NaN argument yields the other), inline: on
// baseline x86-64 std::fmin is an out-of-line libm call, and the host's distance-field
// reference (sdf_math.h) makes millions of them (the overlap math here uses ov_min and ov_max).
// The comparison is written apart from the NaN test so that it compiles to minss/maxss rather
// than to a branch on unpredictable data. They may differ from libm only in the sign of a zero
// result, which both standards leave unspecified and no comparison can see.
inline float fmin(float a, float b) {
    const float smaller = b < a ? b : a;
    return a != a ? b : smaller;
}
inline float fmax(float a, float b) {
    const float larger = b > a ? b : a;
    return a != a ? b : larger;
}
inline double fmin(double a, double b) {
    return std::fmin(a, b);
}
inline double fmax(double a, double b) {
    return std::fmax(a, b);
}
#endif

// A triangle as uploaded: anchor voxel corner and anchor-relative vertices (x0 y0 z0 x1 ...).
typedef struct {
    int anchor[3];
    float u[9];
} OvTriangle;

// Voxel index range [lo, hi] (inclusive, global voxel indices, not clipped to the grid) of the
// voxels whose boxes meet the triangle's bounding box. A closed voxel i spans [i, i+1], so it
// meets [a, b] iff i <= b and i + 1 >= a, i.e. i in [ceil(a) - 1, floor(b)]: touching counts. A
// half-open voxel [i, i+1) meets [a, b] iff i <= b and i + 1 > a, i.e. i in [floor(a), floor(b)].
typedef struct {
    int lo[3];
    int hi[3];
} OvRange;

// SAT with per-triangle constants. Box-normal axes are covered by the voxel range. For each of
// the nine axes e_k x f_j the two non-zero components (on axes k+1, k+2) and the interval
// [lo, hi]: the voxel at q is separated on that axis iff dot(axis, q) < lo or > hi. Same for the
// triangle normal.
typedef struct {
    int anchor[3];
    float normal[3];
    float normal_lo, normal_hi;
    float block_lo, block_hi;
    float axis[9][2];
    float axis_lo[9], axis_hi[9];
} OvSatTriangle;

// PEF (Schwarz & Seidel 2010, 26-separating): plane test with the critical-corner offsets d1, d2
// and, for each projection k (dropping axis k, keeping axes k+1, k+2), three edge functions
// n . q' + d >= 0.
typedef struct {
    int anchor[3];
    float normal[3];
    float d1, d2;
    float block_lo, block_hi;
    float edge_normal[3][3][2];
    float edge_offset[3][3];
    // Half-open boxes: bit 3k+j set means edge function (k, j) must be > 0 rather than >= 0 (its
    // critical corner lies on an open face); bits 9 and 10 do the same for the plane test's
    // n.q + d2 < 0 and n.q + d1 > 0.
    int strict;
} OvPefTriangle;

// The smaller and the larger of two floats that are not NaN: a compare and a select, where fmin
// and fmax must also handle NaN, a few more instructions each on x86. Everything here is
// computed from prepared triangles, whose coordinates are finite and bounded by the clip (below
// 2^21), so no NaN arises; with none, the two agree but for the sign of a zero, which no test
// below can see (zeros compare equal, and a zero is only compared or added).
OV_FN float ov_min(float a, float b) {
    return b < a ? b : a;
}
OV_FN float ov_max(float a, float b) {
    return b > a ? b : a;
}
OV_FN float ov_min3(float a, float b, float c) {
    return ov_min(ov_min(a, b), c);
}
OV_FN float ov_max3(float a, float b, float c) {
    return ov_max(ov_max(a, b), c);
}

// The range along one axis, from the anchor and the three vertices' coordinates on that axis,
// relative to it. The anchor is the floor of the smallest coordinate (prepare_triangles), so that
// coordinate less the anchor lies in [0, 1), and rounding it (to double, then to float) keeps it
// in [0, 1]; rounding is monotonic, so it is still the smallest, `low`, and the largest, `high`, is
// at least 0. Then ceil(low) - 1 is -1 where low is 0 and 0 elsewhere, floor(low) is 1 where low
// is 1 and 0 elsewhere, and floor(high) is its truncation: a comparison each instead of a floor
// or ceiling (most of preparing's arithmetic on the host, which computes millions).
OV_FN void ov_axis_range(int anchor, float a, float b, float c, int half_open, int* lo, int* hi) {
    float low = ov_min3(a, b, c);
    float high = ov_max3(a, b, c);
    *lo = anchor + (half_open ? (low == 1.0f ? 1 : 0) : (low == 0.0f ? -1 : 0));
    *hi = anchor + (int)high;
}

OV_FN OvRange ov_triangle_range(OvTriangle t, int half_open) {
    OvRange r;
    for (int k = 0; k < 3; ++k)
        ov_axis_range(t.anchor[k], t.u[k], t.u[3 + k], t.u[6 + k], half_open, &r.lo[k], &r.hi[k]);
    return r;
}

// Whether the range is a row of voxels: one voxel along at least two axes (a single voxel is a
// row of one). Then every voxel of it meets the triangle, exactly, whatever the rounding of the
// per-voxel test. Along an axis where the range is one voxel i, the triangle's coordinates lie in
// i's box (closed: strictly between its faces, as the range would otherwise reach the neighbour;
// half-open: within [i, i+1)). Along the row's own axis the triangle's coordinates fill the
// interval between its smallest and largest vertex coordinate (it is connected), and each voxel
// of the range meets that interval: so each holds a point of the triangle. A conservative test
// (SAT, PEF) therefore sets the row's voxels without its setup or tests (on a device, through
// set_direct_bits in voxelize.cl). Rows are most triangles of a finely tessellated mesh at a
// coarse grid: buildings, 98% at 256^3 and 90% at 1024^3; motorBike, 13% at 256^3. Thin voxels
// must still be tested.
OV_FN int ov_range_is_row(OvRange r) {
    return (r.lo[0] != r.hi[0]) + (r.lo[1] != r.hi[1]) + (r.lo[2] != r.hi[2]) <= 1;
}

// A row of a direct pair as one 64-bit entry for set_direct_bits: the bit of its first (lowest)
// voxel among a batch's brick bits (below 2^48), the axis it runs along (0-2; any for one voxel)
// and its length (1 to 2^14). A row lies in one brick (its pair's), so it never leaves the
// brick's blocks.
#define OV_ROW_FIRST_BITS 48
OV_FN ov_ulong ov_direct_row(ov_ulong first_bit, int axis, int length) {
    return first_bit | (ov_ulong)axis << OV_ROW_FIRST_BITS |
           (ov_ulong)(length - 1) << (OV_ROW_FIRST_BITS + 2);
}

// Edge j of the triangle: f_j = u_{j+1} - u_j.
OV_FN float ov_edge(OvTriangle t, int j, int k) {
    int next = j == 2 ? 0 : j + 1;
    return t.u[3 * next + k] - t.u[3 * j + k];
}

// Triangle normal f_0 x f_1 (zero for a degenerate triangle).
OV_FN void ov_normal(OvTriangle t, float n[3]) {
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        n[k] = ov_edge(t, 0, a1) * ov_edge(t, 1, a2) - ov_edge(t, 0, a2) * ov_edge(t, 1, a1);
    }
}

// Block cull: a 4x4x4 block whose minimum corner is q0 is skipped iff dot(n, q0) < *lo or > *hi,
// i.e. the whole block [q0, q0 + 4] lies on one side of the triangle's plane. The cull only saves
// work: it is widened by a margin far above float rounding so it never drops a voxel the per-voxel
// test would set (device == reference tests hold it to that).
OV_FN void ov_block_cull(OvTriangle t, const float n[3], float* lo, float* hi) {
    float p0 = n[0] * t.u[0] + n[1] * t.u[1] + n[2] * t.u[2];
    float p1 = n[0] * t.u[3] + n[1] * t.u[4] + n[2] * t.u[5];
    float p2 = n[0] * t.u[6] + n[1] * t.u[7] + n[2] * t.u[8];
    float box_lo = 4.0f * (ov_min(n[0], 0.0f) + ov_min(n[1], 0.0f) + ov_min(n[2], 0.0f));
    float box_hi = 4.0f * (ov_max(n[0], 0.0f) + ov_max(n[1], 0.0f) + ov_max(n[2], 0.0f));
    float reach = 8.0f;
    for (int i = 0; i < 9; ++i) reach = ov_max(reach, fabs(t.u[i]) + 8.0f);
    float tmin = ov_min3(p0, p1, p2), tmax = ov_max3(p0, p1, p2);
    float margin = 1e-5f * ((box_hi - box_lo) * reach + fabs(tmin) + fabs(tmax));
    *lo = tmin - box_hi - margin;
    *hi = tmax - box_lo + margin;
}

// Half-open boxes [q, q+1): on an axis a the box projects to an interval whose upper end is open
// if a has a positive component and whose lower end is open if it has a negative one. "d < lo"
// (box entirely below the triangle) must then become "d <= lo", which for floats is exactly
// "d < nextafter(lo, +inf)"; likewise for hi. So the per-voxel test stays the same.
OV_FN void ov_half_open_axis(float c_neg, float c_pos, float* lo, float* hi) {
    if (c_pos > 0.0f) *lo = nextafter(*lo, INFINITY);
    if (c_neg < 0.0f) *hi = nextafter(*hi, -INFINITY);
}

OV_FN OvSatTriangle ov_setup_sat(OvTriangle t, int half_open) {
    OvSatTriangle s;
    for (int k = 0; k < 3; ++k) s.anchor[k] = t.anchor[k];

    // Nine edge-cross axes e_k x f_j: component on axis k+1 is -f[k+2], on axis k+2 it is f[k+1].
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        for (int j = 0; j < 3; ++j) {
            float c0 = -ov_edge(t, j, a2);
            float c1 = ov_edge(t, j, a1);
            float p0 = c0 * t.u[a1] + c1 * t.u[a2];
            float p1 = c0 * t.u[3 + a1] + c1 * t.u[3 + a2];
            float p2 = c0 * t.u[6 + a1] + c1 * t.u[6 + a2];
            // Unit box [q, q+1] projects to dot(axis, q) + [sum of negative parts, sum of
            // positive].
            float box_lo = ov_min(c0, 0.0f) + ov_min(c1, 0.0f);
            float box_hi = ov_max(c0, 0.0f) + ov_max(c1, 0.0f);
            int i = 3 * k + j;
            s.axis[i][0] = c0;
            s.axis[i][1] = c1;
            s.axis_lo[i] = ov_min3(p0, p1, p2) - box_hi;
            s.axis_hi[i] = ov_max3(p0, p1, p2) - box_lo;
            if (half_open) ov_half_open_axis(box_lo, box_hi, &s.axis_lo[i], &s.axis_hi[i]);
        }
    }

    // Triangle normal. For a degenerate triangle it is zero and the test passes, which leaves the
    // segment (or point) to the edge axes and the range, as a segment/box SAT needs.
    float n[3];
    ov_normal(t, n);
    ov_block_cull(t, n, &s.block_lo, &s.block_hi);
    float p0 = n[0] * t.u[0] + n[1] * t.u[1] + n[2] * t.u[2];
    float p1 = n[0] * t.u[3] + n[1] * t.u[4] + n[2] * t.u[5];
    float p2 = n[0] * t.u[6] + n[1] * t.u[7] + n[2] * t.u[8];
    float box_lo = ov_min(n[0], 0.0f) + ov_min(n[1], 0.0f) + ov_min(n[2], 0.0f);
    float box_hi = ov_max(n[0], 0.0f) + ov_max(n[1], 0.0f) + ov_max(n[2], 0.0f);
    for (int k = 0; k < 3; ++k) s.normal[k] = n[k];
    s.normal_lo = ov_min3(p0, p1, p2) - box_hi;
    s.normal_hi = ov_max3(p0, p1, p2) - box_lo;
    if (half_open) ov_half_open_axis(box_lo, box_hi, &s.normal_lo, &s.normal_hi);
    return s;
}

// q: voxel index minus anchor, as float (exact). Closed boxes: equality means touching, which
// overlaps.
OV_FN int ov_sat_overlaps(const OvSatTriangle* s, float qx, float qy, float qz) {
    float q[3] = {qx, qy, qz};
    float dn = s->normal[0] * qx + s->normal[1] * qy + s->normal[2] * qz;
    if (dn < s->normal_lo || dn > s->normal_hi) return 0;
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        for (int j = 0; j < 3; ++j) {
            int i = 3 * k + j;
            float d = s->axis[i][0] * q[a1] + s->axis[i][1] * q[a2];
            if (d < s->axis_lo[i] || d > s->axis_hi[i]) return 0;
        }
    }
    return 1;
}

// Exact orientation of a projected triangle. Where a projection is nearly degenerate (a sliver, a
// face almost perpendicular to the projection plane), the float n[k] = f0 x f1 can cancel to 0
// or take the wrong sign; edge functions turned by that sign point outwards, and a conservative
// test then drops voxels far along the sliver that the triangle clearly crosses. So the sign is
// computed exactly, from error-free transformations that need only +, - and * (FP_CONTRACT is off
// and there is no FMA, so they are exact on every conforming device, as long as no product
// underflows: all nonzero coordinates at least 2^-50 in magnitude).

// a + b = *sum + *err exactly (Knuth's TwoSum, any magnitudes).
OV_FN void ov_two_sum(float a, float b, float* sum, float* err) {
    float s = a + b;
    float b_virtual = s - a;
    float a_virtual = s - b_virtual;
    *sum = s;
    *err = (a - a_virtual) + (b - b_virtual);
}

// a = *hi + *lo with both halves of at most 12 significant bits (Veltkamp's split, 2^12 + 1).
OV_FN void ov_split(float a, float* hi, float* lo) {
    float c = 4097.0f * a;
    float h = c - (c - a);
    *hi = h;
    *lo = a - h;
}

// a * b = *product + *err exactly (Dekker's TwoProduct without FMA).
OV_FN void ov_two_product(float a, float b, float* product, float* err) {
    float a_hi, a_lo, b_hi, b_lo;
    ov_split(a, &a_hi, &a_lo);
    ov_split(b, &b_hi, &b_lo);
    float p = a * b;
    *product = p;
    *err = a_lo * b_lo - (((p - a_hi * b_hi) - a_lo * b_hi) - a_hi * b_lo);
}

// Exact sign (-1, 0 or 1) of twice the signed area of the triangle projected onto axes (a1, a2):
// the sum over edges of u_j x u_{j+1}, six exact products, twelve terms, summed exactly into a
// nonoverlapping expansion (Shewchuk's Grow-Expansion) whose largest nonzero part has the sign.
OV_FN float ov_exact_orientation(OvTriangle t, int a1, int a2) {
    float expansion[12];
    int length = 0;
    for (int j = 0; j < 3; ++j) {
        int next = j == 2 ? 0 : j + 1;
        float terms[4];
        ov_two_product(t.u[3 * j + a1], t.u[3 * next + a2], &terms[0], &terms[1]);
        ov_two_product(-t.u[3 * j + a2], t.u[3 * next + a1], &terms[2], &terms[3]);
        for (int i = 0; i < 4; ++i) {
            float carry = terms[i];
            for (int e = 0; e < length; ++e) ov_two_sum(carry, expansion[e], &carry, &expansion[e]);
            expansion[length++] = carry;
        }
    }
    for (int e = 11; e >= 0; --e)
        if (expansion[e] != 0.0f) return expansion[e] > 0.0f ? 1.0f : -1.0f;
    return 0.0f;
}

// The same sign, usually from the plain float determinant: Shewchuk's orient2d filter, whose
// bound (3 + 16 eps) eps |terms| (eps = 2^-24) covers every rounding of that evaluation; the
// absolute 1e-30 covers products that underflow. Only near-degenerate projections pay for the
// exact sum.
OV_FN float ov_projected_orientation(OvTriangle t, int a1, int a2) {
    float left = (t.u[a1] - t.u[6 + a1]) * (t.u[3 + a2] - t.u[6 + a2]);
    float right = (t.u[a2] - t.u[6 + a2]) * (t.u[3 + a1] - t.u[6 + a1]);
    float det = left - right;
    float eps = 5.9604645e-08f;  // 2^-24
    float bound = (3.0f + 16.0f * eps) * eps * (fabs(left) + fabs(right)) + 1e-30f;
    if (det > bound) return 1.0f;
    if (det < -bound) return -1.0f;
    return ov_exact_orientation(t, a1, a2);
}

OV_FN OvPefTriangle ov_setup_pef(OvTriangle t, int half_open) {
    OvPefTriangle s;
    s.strict = 0;
    for (int k = 0; k < 3; ++k) s.anchor[k] = t.anchor[k];

    float n[3];
    ov_normal(t, n);
    for (int k = 0; k < 3; ++k) s.normal[k] = n[k];
    ov_block_cull(t, n, &s.block_lo, &s.block_hi);
    // Critical corner c of the unit box: the corner furthest along n. The box meets the plane iff
    // n.q + d1 and n.q + d2 do not have the same strict sign.
    float c[3];
    for (int k = 0; k < 3; ++k) c[k] = n[k] > 0.0f ? 1.0f : 0.0f;
    s.d1 = n[0] * (c[0] - t.u[0]) + n[1] * (c[1] - t.u[1]) + n[2] * (c[2] - t.u[2]);
    s.d2 = n[0] * ((1.0f - c[0]) - t.u[0]) + n[1] * ((1.0f - c[1]) - t.u[1]) +
           n[2] * ((1.0f - c[2]) - t.u[2]);
    // The corner furthest along n (d1) is on an open face if n has a positive component; the
    // nearest one (d2) if n has a negative component.
    if (half_open && (n[0] < 0.0f || n[1] < 0.0f || n[2] < 0.0f)) s.strict |= 1 << 9;
    if (half_open && (n[0] > 0.0f || n[1] > 0.0f || n[2] > 0.0f)) s.strict |= 1 << 10;

    // Projection k keeps axes (a1, a2). Edge normals are turned to point inwards by the exact
    // orientation of the projected triangle. Each edge line passes through its first vertex with
    // the rounded edge as direction (off the true edge by rounding only: anchor-relative
    // coordinates are >= 0, so each difference is exact or within 2^-24 of itself), so with the
    // true orientation the test is exact up to rounding. A projection of exactly zero area (a
    // segment) may take either orientation: opposite edges then demand both sides of the segment.
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        float sign = ov_projected_orientation(t, a1, a2) >= 0.0f ? 1.0f : -1.0f;
        for (int j = 0; j < 3; ++j) {
            float ex = ov_edge(t, j, a1);
            float ey = ov_edge(t, j, a2);
            float nx = -ey * sign;
            float ny = ex * sign;
            s.edge_normal[k][j][0] = nx;
            s.edge_normal[k][j][1] = ny;
            s.edge_offset[k][j] = -(nx * t.u[3 * j + a1] + ny * t.u[3 * j + a2]) +
                                  ov_max(0.0f, nx) + ov_max(0.0f, ny);
            if (half_open && (nx > 0.0f || ny > 0.0f)) s.strict |= 1 << (3 * k + j);
        }
    }
    return s;
}

OV_FN int ov_pef_overlaps(const OvPefTriangle* s, float qx, float qy, float qz) {
    float q[3] = {qx, qy, qz};
    float dn = s->normal[0] * qx + s->normal[1] * qy + s->normal[2] * qz;
    float e1 = dn + s->d1;
    float e2 = dn + s->d2;
    // The box meets the plane iff e2 <= 0 <= e1 (strict where the corner is on an open face).
    // Compared one by one: the product e1 * e2 could underflow to 0 or overflow to NaN.
    if (e2 > 0.0f || (e2 == 0.0f && (s->strict >> 9 & 1))) return 0;
    if (e1 < 0.0f || (e1 == 0.0f && (s->strict >> 10 & 1))) return 0;
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        for (int j = 0; j < 3; ++j) {
            float e = s->edge_normal[k][j][0] * q[a1] + s->edge_normal[k][j][1] * q[a2] +
                      s->edge_offset[k][j];
            if (e < 0.0f || (e == 0.0f && (s->strict >> (3 * k + j) & 1))) return 0;
        }
    }
    return 1;
}

// Thin (6-separating) surface voxelization, Schwarz & Seidel 2010: the plane must cross the
// voxel's centre segment along the normal's dominant axis, |n.(c - u0)| <= max|n_k| / 2, and in
// each of the three projections the triangle must meet the voxel's inscribed diamond (support
// max(|m_x|, |m_y|) / 2 around the centre) instead of the whole square. A subset of the
// conservative voxels that still leaves no 6-connected gap.
typedef struct {
    int anchor[3];
    float normal[3];
    float plane_offset, plane_half;  // n.q + plane_offset is the plane function at the centre
    float block_lo, block_hi;
    float edge_normal[3][3][2];
    float edge_offset[3][3];
    // Half-open voxels: bit 3k+j makes edge function (k, j) strict (> 0); bits 9 and 10 make the
    // plane test's lower and upper bound strict.
    int strict;
} OvThinTriangle;

// Half-open thin voxels: the centre segment along the dominant axis is [c - 1/2, c + 1/2) and each
// diamond loses its +x and +y corners, so neighbouring voxels no longer share the points where
// they touch. A support value is then strict when it is attained only at an excluded corner.
OV_FN OvThinTriangle ov_setup_thin(OvTriangle t, int half_open) {
    OvThinTriangle s;
    s.strict = 0;
    for (int k = 0; k < 3; ++k) s.anchor[k] = t.anchor[k];
    float n[3];
    ov_normal(t, n);
    for (int k = 0; k < 3; ++k) s.normal[k] = n[k];
    ov_block_cull(t, n, &s.block_lo, &s.block_hi);
    s.plane_offset = n[0] * (0.5f - t.u[0]) + n[1] * (0.5f - t.u[1]) + n[2] * (0.5f - t.u[2]);
    s.plane_half = 0.5f * ov_max3(fabs(n[0]), fabs(n[1]), fabs(n[2]));
    int dominant = fabs(n[0]) >= fabs(n[1]) && fabs(n[0]) >= fabs(n[2]) ? 0
                   : fabs(n[1]) >= fabs(n[2])                           ? 1
                                                                        : 2;
    // The plane crosses the segment at t = -value / n[dominant], which must lie in [-1/2, 1/2).
    if (half_open && n[dominant] > 0.0f) s.strict |= 1 << 9;
    if (half_open && n[dominant] < 0.0f) s.strict |= 1 << 10;
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        float sign = ov_projected_orientation(t, a1, a2) >= 0.0f ? 1.0f : -1.0f;  // as in PEF
        for (int j = 0; j < 3; ++j) {
            float nx = -ov_edge(t, j, a2) * sign;
            float ny = ov_edge(t, j, a1) * sign;
            s.edge_normal[k][j][0] = nx;
            s.edge_normal[k][j][1] = ny;
            s.edge_offset[k][j] = nx * (0.5f - t.u[3 * j + a1]) + ny * (0.5f - t.u[3 * j + a2]) +
                                  0.5f * ov_max(fabs(nx), fabs(ny));
            if (half_open &&
                ((fabs(nx) > fabs(ny) && nx > 0.0f) || (fabs(ny) > fabs(nx) && ny > 0.0f)))
                s.strict |= 1 << (3 * k + j);
        }
    }
    return s;
}

OV_FN int ov_thin_overlaps(const OvThinTriangle* s, float qx, float qy, float qz) {
    float q[3] = {qx, qy, qz};
    float dn = s->normal[0] * qx + s->normal[1] * qy + s->normal[2] * qz + s->plane_offset;
    if (dn > s->plane_half || dn < -s->plane_half) return 0;
    if ((dn == -s->plane_half && (s->strict >> 9 & 1)) ||
        (dn == s->plane_half && (s->strict >> 10 & 1)))
        return 0;
    for (int k = 0; k < 3; ++k) {
        int a1 = k == 2 ? 0 : k + 1;
        int a2 = a1 == 2 ? 0 : a1 + 1;
        for (int j = 0; j < 3; ++j) {
            float e = s->edge_normal[k][j][0] * q[a1] + s->edge_normal[k][j][1] * q[a2] +
                      s->edge_offset[k][j];
            if (e < 0.0f || (e == 0.0f && (s->strict >> (3 * k + j) & 1))) return 0;
        }
    }
    return 1;
}

#ifdef __OPENCL_VERSION__
// The three predicates for a 4x4x4 block, factored. Each predicate is an AND of tests: a plane
// test, which reads all three coordinates of a voxel, and nine tests of the three axis-aligned
// projections, each of which reads only the two coordinates its projection keeps (SAT's nine
// edge axes, PEF's and thin's nine edge functions). So a block's projection tests are taken once
// per 4x4 face (4 rows of 4 lanes a projection) instead of once per voxel, and only the plane
// test once per row. Every test is the same float expression, in the same order, as in the scalar
// functions above, and an AND does not depend on the order of its terms: every voxel is the
// scalar result (the kernels are tested against the reference bit for bit). The lanes are int4
// masks (-1 where the test holds); a strict bit of the setup becomes a lane mask.
// The anchor-relative coordinates q0 .. q0 + 3 of a block's 4 voxels along one axis.
OV_FN float4 ov_row4(int q0) {
    return convert_float4((int4)(q0) + (int4)(0, 1, 2, 3));
}

// The lane tests, written once for N lanes (4: a row of a block; 16: a 4x4 face or layer of it).
// Projection k's tests (k = 0: the (y, z) plane, 1: (z, x), 2: (x, y); a1 and a2 as in the
// setups) at coordinates c1 along a1 and c2 along a2; the plane test at (qx, qy, qz).
#define OV_LANE_TESTS(N)                                                                           \
    OV_FN int##N ov_strict##N(int strict, int bit) {                                               \
        return (int##N)(-((strict >> bit) & 1));                                                   \
    }                                                                                              \
    OV_FN int##N ov_sat_projection##N(const OvSatTriangle* s, int k, float##N c1, float##N c2) {   \
        int##N m = (int##N)(-1);                                                                   \
        for (int j = 0; j < 3; ++j) {                                                              \
            int i = 3 * k + j;                                                                     \
            float##N d = s->axis[i][0] * c1 + s->axis[i][1] * c2;                                  \
            m &= ~(d < s->axis_lo[i]) & ~(d > s->axis_hi[i]);                                      \
        }                                                                                          \
        return m;                                                                                  \
    }                                                                                              \
    OV_FN int##N ov_edge_projection##N(const float edge_normal[3][3][2],                           \
                                       const float edge_offset[3][3], int strict, int k,           \
                                       float##N c1, float##N c2) {                                 \
        int##N m = (int##N)(-1);                                                                   \
        for (int j = 0; j < 3; ++j) {                                                              \
            float##N e =                                                                           \
                edge_normal[k][j][0] * c1 + edge_normal[k][j][1] * c2 + edge_offset[k][j];         \
            m &= ~((e < 0.0f) | ((e == 0.0f) & ov_strict##N(strict, 3 * k + j)));                  \
        }                                                                                          \
        return m;                                                                                  \
    }                                                                                              \
    OV_FN int##N ov_pef_projection##N(const OvPefTriangle* s, int k, float##N c1, float##N c2) {   \
        return ov_edge_projection##N(s->edge_normal, s->edge_offset, s->strict, k, c1, c2);        \
    }                                                                                              \
    OV_FN int##N ov_thin_projection##N(const OvThinTriangle* s, int k, float##N c1, float##N c2) { \
        return ov_edge_projection##N(s->edge_normal, s->edge_offset, s->strict, k, c1, c2);        \
    }                                                                                              \
    OV_FN int##N ov_sat_plane##N(const OvSatTriangle* s, float##N qx, float##N qy, float qz) {     \
        float##N dn = s->normal[0] * qx + s->normal[1] * qy + s->normal[2] * qz;                   \
        return ~(dn < s->normal_lo) & ~(dn > s->normal_hi);                                        \
    }                                                                                              \
    OV_FN int##N ov_pef_plane##N(const OvPefTriangle* s, float##N qx, float##N qy, float qz) {     \
        float##N dn = s->normal[0] * qx + s->normal[1] * qy + s->normal[2] * qz;                   \
        float##N e1 = dn + s->d1;                                                                  \
        float##N e2 = dn + s->d2;                                                                  \
        int##N m = ~((e2 > 0.0f) | ((e2 == 0.0f) & ov_strict##N(s->strict, 9)));                   \
        return m & ~((e1 < 0.0f) | ((e1 == 0.0f) & ov_strict##N(s->strict, 10)));                  \
    }                                                                                              \
    OV_FN int##N ov_thin_plane##N(const OvThinTriangle* s, float##N qx, float##N qy, float qz) {   \
        float##N dn = s->normal[0] * qx + s->normal[1] * qy + s->normal[2] * qz + s->plane_offset; \
        int##N m = ~(dn > s->plane_half) & ~(dn < -s->plane_half);                                 \
        return m & ~(((dn == -s->plane_half) & ov_strict##N(s->strict, 9)) |                       \
                     ((dn == s->plane_half) & ov_strict##N(s->strict, 10)));                       \
    }
OV_LANE_TESTS(4)
OV_LANE_TESTS(16)

// The 16 lanes of a mask as the low 16 bits of an int (lane i at bit i): each lane's bit, then
// the halves ORed together.
OV_FN uint ov_lane_bits16(int16 m) {
    int16 b =
        m & (int16)(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384, 32768);
    int8 b8 = b.lo | b.hi;
    int4 b4 = b8.lo | b8.hi;
    int2 b2 = b4.lo | b4.hi;
    return (uint)(b2.s0 | b2.s1);
}

// The 4 lanes of a mask as the low 4 bits of an int (lane i at bit i).
OV_FN uint ov_lane_bits(int4 m) {
    return (uint)((m.s0 & 1) | (m.s1 & 2) | (m.s2 & 4) | (m.s3 & 8));
}
#endif

// Bit of voxel (x, y, z) (local to its 4x4x4 block) in the block's 64-bit mask.
OV_FN int ov_block_bit(int x, int y, int z) {
    return x + 4 * (y + 4 * z);
}

// Index of block (x, y, z) (global block coordinates) among the blocks of brick (bx, by, bz)
// (x fastest): a brick's result is its blocks' 64-bit masks in this order, each as two 32-bit
// words (bits 0-31, then 32-63), so the block's bits are bits 64 * index ... 64 * index + 63 of
// it. Scalar arguments: through PoCL, pointers to the item's private arrays cost the voxelize
// kernels 9% on motorBike.
OV_FN int ov_brick_block(int x, int y, int z, int bx, int by, int bz, int brick_size) {
    int nb = brick_size / 4;
    return (x - bx * nb) + nb * ((y - by * nb) + nb * (z - bz * nb));
}

// The work of one (triangle, brick) pair: the voxels of the triangle's range inside both the
// brick and the grid, covered by 4x4x4 blocks (aligned to the global grid) that become one work
// item each. Returns the number of blocks (0 if the range misses the brick or the grid); sets the
// clipped voxel range and the first block. Host and kernel count work items with this function.
typedef struct {
    int voxel_lo[3], voxel_hi[3];
    int block_lo[3], block_count[3];
} OvPairWork;

OV_FN int ov_pair_work(OvRange r, int bx, int by, int bz, int brick_size, int nx, int ny, int nz,
                       OvPairWork* w) {
    int brick[3] = {bx, by, bz};
    int dims[3] = {nx, ny, nz};
    int total = 1;
    for (int k = 0; k < 3; ++k) {
        int lo = r.lo[k] > brick[k] * brick_size ? r.lo[k] : brick[k] * brick_size;
        int hi = r.hi[k] < brick[k] * brick_size + brick_size - 1
                     ? r.hi[k]
                     : brick[k] * brick_size + brick_size - 1;
        if (lo < 0) lo = 0;
        if (hi > dims[k] - 1) hi = dims[k] - 1;
        if (lo > hi) return 0;
        w->voxel_lo[k] = lo;
        w->voxel_hi[k] = hi;
        w->block_lo[k] = lo / 4;
        w->block_count[k] = hi / 4 - lo / 4 + 1;
        total *= w->block_count[k];
    }
    return total;
}

// A (triangle, brick) pair's blocks are split into work items of up to this many consecutive
// blocks: enough to share an item's decoding and its triangle's constants among several blocks,
// few enough that a huge triangle still spreads over many items (a 64^3 brick has 4096 blocks).
// Through PoCL on 2 cores 32 took 5-15% less kernel time than 8 at 1024^3 and 2048^3, once the
// blocks' tests had become cheaper than an item's set-up; the same at 256^3.
#define OV_BLOCKS_PER_ITEM 32

// The work items of a pair of `blocks` blocks (ov_pair_work); host and kernel count with this.
OV_FN int ov_pair_items(int blocks) {
    return (blocks + OV_BLOCKS_PER_ITEM - 1) / OV_BLOCKS_PER_ITEM;
}

#ifndef __OPENCL_VERSION__
}  // namespace oclvox::detail
#endif

#endif  // OCLVOX_VOXEL_MATH_H
