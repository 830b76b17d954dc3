// Per-sample meshing work shared, token for token, by kernels/meshing.cl and the host reference
// (Surface Nets and Marching Cubes). Same determinism contract as voxel_math.h: plain
// single-precision + - * and comparisons in the order written, FP_CONTRACT OFF; the only
// divisions (vertex positions) go through om_divide, which is correctly rounded on any device
// whatever its own division does. So device == host bit for bit.
//
// Ownership: every vertex and triangle belongs to exactly one sample s = (x, y, z), which is what
// lets any tiling (bricks on the host, launch slices on the device) produce the same mesh:
//  - the cell "at" s is the cube with s as its lowest corner (it exists if s + (1,1,1) is in the
//    grid); the grid edge "(s, a)" joins s and s + e_a;
//  - Surface Nets: s owns the vertex of its cell and the quads of its edges (s, 0..2);
//  - Marching Cubes: s owns the vertices on its edges (s, 0..2), in axis order, then the centre
//    vertices its cell needs (rare ambiguous cases), and the triangles of its cell.
// A count pass gives each sample its numbers of vertices and triangles; exclusive prefix sums
// over samples in index order give every sample its first vertex and triangle; an emit pass
// writes them. So vertices come out ordered by owner, and a triangle finds the index of a vertex
// owned by a neighbour from that neighbour's offset. The emit functions write vertex v and
// triangle t at v - vertex_base and t - triangle_base of their output arrays (the kernels and
// the dense reference pass 0), so a caller can emit a part of the mesh into buffers of its own
// while triangles keep the global vertex indices.
//
// Counts and offsets are stored only for the samples of the active bricks (those that can hold
// surface, see OmTiling): the storage follows the surface, not the grid, while the prefix sums
// still run in global sample order, so the mesh does not depend on the tiling.
//
// Vertices are written as their owner sample plus a float position relative to it in voxel units
// (a cell-local position in [0,1]^3), so precision does not depend on the grid size; the host
// converts them to world coordinates in double.
//
// Cube conventions: corner c of a cell is at offset (c & 1, c >> 1 & 1, c >> 2 & 1). Edge e runs
// along axis a = e >> 2 from the corner with offsets (e & 1) on axis a+1 and (e >> 1 & 1) on axis
// a+2 (axes mod 3). Face f = 2d + side is the face at offset `side` along axis d; its corners in
// cyclic order are base, base + e_u, base + e_u + e_v, base + e_v with u = d+1, v = d+2.
#ifndef OCLVOX_MESHING_MATH_H
#define OCLVOX_MESHING_MATH_H

#ifdef __OPENCL_VERSION__
#pragma OPENCL FP_CONTRACT OFF
#define OM_FN static inline
#define OM_GLOBAL __global
#define OM_UINT uint
#define OM_UCHAR uchar
#define OM_LONG long
#else
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#define OM_FN static inline
#define OM_GLOBAL
#define OM_UINT uint32_t
#define OM_UCHAR uint8_t
#define OM_LONG int64_t
namespace oclvox::detail {
using std::fabs;
using std::frexp;
using std::min;
using std::nextafter;
#endif

// Marching Cubes case table (derived on the host, see marching_cubes_tables.cpp), indexed by
// mask | faces << 8 for the 8-bit inside-corner mask and the 6 asymptotic-decider bits. Entry
// bytes: [0] triangle count, [1] centre-vertex count, [2 + 2j, 3 + 2j] the 12-bit mask (low byte
// first) of the edges whose crossings centre j averages, then 3 vertex codes per triangle: an
// edge 0..11, or OM_MC_CENTRE_BASE + j for centre j.
#define OM_MC_ENTRY_BYTES 48
#define OM_MC_MAX_TRIANGLES 12
#define OM_MC_MAX_CENTRES 2
#define OM_MC_TRIANGLES_AT 6
#define OM_MC_CENTRE_BASE 12
#define OM_MC_ENTRIES (256 * 64)

typedef struct {
    int n[3];   // samples along each axis
    float iso;  // inside: value < iso
} OmField;

// The tiling of the grid into cubic bricks of `size` samples (count[k] of them along axis k,
// the last ones clipped by the grid). A brick is active when it may own surface. Each active
// brick's samples have consecutive slots in the count and offset arrays, x fastest over the
// brick's clipped extent, from the brick's base slot; brick_base[brick] is OM_NO_BRICK for an
// inactive brick. Every sample that owns a vertex or triangle lies in an active brick (its
// brick's samples with their one-sample halo change sign), so lookups never meet OM_NO_BRICK.
#define OM_NO_BRICK 0xffffffffu
typedef struct {
    int size;
    int count[3];
} OmTiling;

OM_FN int om_next_axis(int a) {
    return a == 2 ? 0 : a + 1;
}

OM_FN OM_UINT om_index(OmField f, int x, int y, int z) {
    return (OM_UINT)x + (OM_UINT)f.n[0] * ((OM_UINT)y + (OM_UINT)f.n[1] * (OM_UINT)z);
}

// The slot of sample (x, y, z), which must lie in an active brick.
OM_FN OM_UINT om_slot(OmField f, OmTiling t, OM_GLOBAL const OM_UINT* brick_base, int x, int y,
                      int z) {
    // One brick (the host's sparse mesher tiles each box so): no divisions, the same slot.
    if (t.count[0] == 1 && t.count[1] == 1 && t.count[2] == 1)
        return brick_base[0] + (OM_UINT)x +
               (OM_UINT)min(t.size, f.n[0]) *
                   ((OM_UINT)y + (OM_UINT)min(t.size, f.n[1]) * (OM_UINT)z);
    int b[3] = {x / t.size, y / t.size, z / t.size};
    OM_UINT base =
        brick_base[(OM_UINT)b[0] +
                   (OM_UINT)t.count[0] * ((OM_UINT)b[1] + (OM_UINT)t.count[1] * (OM_UINT)b[2])];
    int ex = min(t.size, f.n[0] - b[0] * t.size), ey = min(t.size, f.n[1] - b[1] * t.size);
    return base + (OM_UINT)(x - b[0] * t.size) +
           (OM_UINT)ex *
               ((OM_UINT)(y - b[1] * t.size) + (OM_UINT)ey * (OM_UINT)(z - b[2] * t.size));
}

OM_FN int om_inside(float value, float iso) {
    return value < iso;
}

// Corner offsets along the axes.
OM_FN int om_corner_bit(int corner, int axis) {
    return (corner >> axis) & 1;
}

// Lower and upper corner of edge e.
OM_FN int om_edge_corner(int e, int upper) {
    int a = e >> 2, b = om_next_axis(a), c = om_next_axis(b);
    return ((e & 1) << b) | (((e >> 1) & 1) << c) | (upper << a);
}

// Corner i (0..3, cyclic) of face f.
OM_FN int om_face_corner(int f, int i) {
    int d = f >> 1, u = om_next_axis(d), v = om_next_axis(u);
    int cu = i == 1 || i == 2, cv = i >= 2;
    return ((f & 1) << d) | (cu << u) | (cv << v);
}

// ---- Correctly rounded division ----------------------------------------------------------------
// OpenCL C 1.2 lets a single-precision x / y be off by 2.5 ulp unless the program is built with
// -cl-fp32-correctly-rounded-divide-sqrt, which a device need not support. So the quotients that
// place vertices are computed here from an approximate quotient and an exact test: the result is
// the IEEE round-to-nearest-even quotient wherever the approximation starts, hence the same bits on
// every device and on the host. The test uses only operations that OpenCL defines exactly (frexp,
// nextafter, float <-> integer conversions of exact values, 64-bit integer arithmetic). Like all
// of oclvox's bit-for-bit results it assumes a device that keeps single-precision denormals
// (CL_FP_DENORM), which every desktop GPU and CPU driver does.

// The integer mantissa and exponent of a finite x >= 0, normalised: x = m * 2^e with m in
// [2^23, 2^24), or m = 0 and e = -149 for x = 0.
OM_FN OM_LONG om_mantissa(float x, int* e) {
    int exponent;
    float fraction = frexp(x, &exponent);  // x = fraction * 2^exponent, fraction in [0.5, 1)
    *e = x == 0.0f ? -149 : exponent - 24;
    return (OM_LONG)(fraction * 16777216.0f);  // exact: an integer below 2^24
}

// The same in units of x's ulp: x = m * 2^e with 2^e the spacing of floats at x (e >= -149), so
// m < 2^24 and the parity of m says whether x is "even" for rounding ties.
OM_FN OM_LONG om_ulp_mantissa(float x, int* e) {
    OM_LONG m = om_mantissa(x, e);
    if (*e < -149) {  // subnormal: the bits shifted out are zero
        m >>= -149 - *e;
        *e = -149;
    }
    return m;
}

// Sign (-1, 0, +1) of n / d minus the midpoint between q and the next float above it, computed
// exactly, for finite n >= 0, d > 0 and q >= 0.
OM_FN int om_above_midpoint(float n, float d, float q) {
    int en, ed, eq;
    OM_LONG N = om_mantissa(n, &en), D = om_mantissa(d, &ed), Q = om_ulp_mantissa(q, &eq);
    // The midpoint is (2Q + 1) * 2^(eq - 1): compare N * 2^en with (2Q + 1) * D * 2^(eq - 1 + ed),
    // i.e. N * 2^k with M. M is in [2^23, 2^49) and N, unless 0, in [2^23, 2^24).
    OM_LONG M = (2 * Q + 1) * D;
    int k = en - ed - eq + 1;
    if (N == 0 || k < 0) return -1;  // N * 2^k < 2^23 <= M
    if (k > 26) return 1;            // N * 2^k >= 2^50 > M
    OM_LONG lhs = N << k;
    return lhs > M ? 1 : (lhs < M ? -1 : 0);
}

// The correctly rounded (to nearest, ties to even) quotient n / d, for finite n >= 0 and d > 0
// with a finite quotient, walked to from the estimate q one ulp per step. Each step moves towards
// the answer only when the exact test proves it lies that way, so the result does not depend on
// q; the time does, and OpenCL's bound of 2.5 ulp on x / y keeps it to a few steps. (Ties cannot
// occur between normal floats, but can for subnormal quotients such as 2^-149 / 2.)
OM_FN float om_divide_from(float n, float d, float q) {
    if (!(q > 0.0f)) q = 0.0f;  // -0 (or, off any conformant device, negative or NaN): +0
    if (q > FLT_MAX) q = FLT_MAX;
    for (;;) {
        int e;
        int odd = (int)(om_ulp_mantissa(q, &e) & 1);
        int above = om_above_midpoint(n, d, q);
        if (above > 0 || (above == 0 && odd)) {
            q = nextafter(q, INFINITY);
            continue;
        }
        if (q > 0.0f) {
            float below = nextafter(q, 0.0f);
            int above_below = om_above_midpoint(n, d, below);
            if (above_below < 0 || (above_below == 0 && odd)) {
                q = below;
                continue;
            }
        }
        return q;
    }
}

// n / d, correctly rounded, on any device (domain as om_divide_from). The host's division is
// IEEE's, correctly rounded already, so there the walk would only confirm it (at a cost that
// showed in the host meshers' profiles).
OM_FN float om_divide(float n, float d) {
#ifdef __OPENCL_VERSION__
    return om_divide_from(n, d, n / d);
#else
    return n / d;
#endif
}

// Where along an edge from value a to value b the linear interpolant reaches iso. Called only
// when exactly one end is inside, so b != a; the result is in [0, 1] because float subtraction is
// monotonic (|iso - a| <= |b - a|) and the division is correctly rounded.
OM_FN float om_crossing(float a, float b, float iso) {
    float n = iso - a, d = b - a;
    if (!(fabs(d) <= FLT_MAX)) {  // b - a overflowed: the same on halved values
        n = iso * 0.5f - a * 0.5f;
        d = b * 0.5f - a * 0.5f;
    }
    if (d < 0.0f) {
        n = -n;
        d = -d;
    }
    return om_divide(n, d);
}

OM_FN void om_cell_values(OM_GLOBAL const float* values, OmField f, int x, int y, int z,
                          float v[8]) {
    for (int c = 0; c < 8; ++c)
        v[c] = values[om_index(f, x + om_corner_bit(c, 0), y + om_corner_bit(c, 1),
                               z + om_corner_bit(c, 2))];
}

OM_FN int om_cell_exists(OmField f, int x, int y, int z) {
    return x + 1 < f.n[0] && y + 1 < f.n[1] && z + 1 < f.n[2];
}

// Does grid edge (s, a) exist and change sign?
OM_FN int om_edge_changes(OM_GLOBAL const float* values, OmField f, int x, int y, int z, int a) {
    int s[3] = {x, y, z};
    if (s[a] + 1 >= f.n[a]) return 0;
    s[a] += 1;
    return om_inside(values[om_index(f, x, y, z)], f.iso) !=
           om_inside(values[om_index(f, s[0], s[1], s[2])], f.iso);
}

OM_FN int om_inside_mask(const float v[8], float iso) {
    int mask = 0;
    for (int c = 0; c < 8; ++c) mask |= om_inside(v[c], iso) << c;
    return mask;
}

// Cell-local mean of the crossings on the edges in the 12-bit mask `edges`, summed in edge
// order: the Surface Nets vertex (all sign-changing edges) and the Marching Cubes centre vertex
// (the edges of one contour loop).
OM_FN void om_mean_crossing(const float v[8], float iso, int edges, float p[3]) {
    float sum[3] = {0.0f, 0.0f, 0.0f};
    int count = 0;
    for (int e = 0; e < 12; ++e) {
        if (!((edges >> e) & 1)) continue;
        int lo = om_edge_corner(e, 0), hi = om_edge_corner(e, 1);
        float t = om_crossing(v[lo], v[hi], iso);
        for (int k = 0; k < 3; ++k)
            sum[k] = sum[k] + (k == (e >> 2) ? t : (float)om_corner_bit(lo, k));
        ++count;
    }
    for (int k = 0; k < 3; ++k) p[k] = om_divide(sum[k], (float)count);
}

// The cell's sign-changing edges as a 12-bit mask.
OM_FN int om_changing_edges(const float v[8], float iso) {
    int edges = 0;
    for (int e = 0; e < 12; ++e)
        edges |=
            (om_inside(v[om_edge_corner(e, 0)], iso) != om_inside(v[om_edge_corner(e, 1)], iso))
            << e;
    return edges;
}

// ---- Surface Nets ------------------------------------------------------------------------------

// Does edge (s, a) get a quad: it changes sign and all four cells around it exist?
OM_FN int om_sn_has_quad(OM_GLOBAL const float* values, OmField f, int x, int y, int z, int a) {
    int s[3] = {x, y, z};
    int b = om_next_axis(a), c = om_next_axis(b);
    if (s[b] < 1 || s[c] < 1 || s[b] + 1 >= f.n[b] || s[c] + 1 >= f.n[c]) return 0;
    return om_edge_changes(values, f, x, y, z, a);
}

OM_FN void om_sn_count(OM_GLOBAL const float* values, OmField f, int x, int y, int z,
                       OM_UINT* vertices, OM_UINT* triangles) {
    *vertices = 0;
    *triangles = 0;
    if (om_cell_exists(f, x, y, z)) {
        float v[8];
        om_cell_values(values, f, x, y, z, v);
        int mask = om_inside_mask(v, f.iso);
        *vertices = mask != 0 && mask != 255;
    }
    for (int a = 0; a < 3; ++a) *triangles += 2 * om_sn_has_quad(values, f, x, y, z, a);
}

OM_FN void om_sn_emit(OM_GLOBAL const float* values, OmField f, int x, int y, int z,
                      OmTiling tiling, OM_GLOBAL const OM_UINT* brick_base,
                      OM_GLOBAL const OM_UINT* vertex_offset,
                      OM_GLOBAL const OM_UINT* triangle_offset, OM_UINT vertex_base,
                      OM_UINT triangle_base, OM_GLOBAL OM_UINT* vertex_sample,
                      OM_GLOBAL float* vertex_local, OM_GLOBAL OM_UINT* triangles) {
    OM_UINT s = om_index(f, x, y, z), slot = om_slot(f, tiling, brick_base, x, y, z);
    if (om_cell_exists(f, x, y, z)) {
        float v[8];
        om_cell_values(values, f, x, y, z, v);
        int mask = om_inside_mask(v, f.iso);
        if (mask != 0 && mask != 255) {
            float p[3];
            om_mean_crossing(v, f.iso, om_changing_edges(v, f.iso), p);
            OM_UINT o = vertex_offset[slot] - vertex_base;
            vertex_sample[o] = s;
            for (int k = 0; k < 3; ++k) vertex_local[3 * o + k] = p[k];
        }
    }
    OM_UINT t = triangle_offset[slot] - triangle_base;
    for (int a = 0; a < 3; ++a) {
        if (!om_sn_has_quad(values, f, x, y, z, a)) continue;
        // The four cells around the edge, counter-clockwise in the (b, c) plane, so the quad
        // faces +e_a (b x c = a); flipped when the edge runs from outside to inside.
        int b = om_next_axis(a), c = om_next_axis(b);
        int cell[4][3];
        for (int i = 0; i < 4; ++i) {
            cell[i][0] = x;
            cell[i][1] = y;
            cell[i][2] = z;
            cell[i][b] -= i == 0 || i == 3;
            cell[i][c] -= i <= 1;
        }
        OM_UINT q[4];
        for (int i = 0; i < 4; ++i)
            q[i] =
                vertex_offset[om_slot(f, tiling, brick_base, cell[i][0], cell[i][1], cell[i][2])];
        if (!om_inside(values[s], f.iso)) {
            OM_UINT swap = q[1];
            q[1] = q[3];
            q[3] = swap;
        }
        triangles[3 * t + 0] = q[0];
        triangles[3 * t + 1] = q[1];
        triangles[3 * t + 2] = q[2];
        triangles[3 * t + 3] = q[0];
        triangles[3 * t + 4] = q[2];
        triangles[3 * t + 5] = q[3];
        t += 2;
    }
}

// ---- Marching Cubes ----------------------------------------------------------------------------

// Asymptotic decider bits: for each face whose inside corners sit on one diagonal and outside
// corners on the other, bit f is set when the bilinear saddle is inside, i.e. the inside corners
// connect across the face. With values relative to iso, the saddle value is
// (A C - B D) / (A + C - B - D) for diagonal pairs (A, C) inside and (B, D) outside; the
// denominator is negative, so the saddle is inside iff A C > B D. Both cells sharing the face
// compute the same two products (float multiplication is commutative) and compare them the same
// way, so they always agree; a tie counts as not connected.
// `inside` is om_inside_mask(v, iso): the sides it gives pass over the faces that are not
// ambiguous (most of them) before any product is formed.
OM_FN int om_mc_face_bits(const float v[8], float iso, int inside) {
    if (inside == 0 || inside == 0xff) return 0;
    int bits = 0;
    for (int f = 0; f < 6; ++f) {
        int in[4];
        for (int i = 0; i < 4; ++i) in[i] = (inside >> om_face_corner(f, i)) & 1;
        if (in[0] != in[2] || in[1] != in[3] || in[0] == in[1]) continue;
        float w[4];
        for (int i = 0; i < 4; ++i) w[i] = v[om_face_corner(f, i)] - iso;
        float inside_pair = in[0] ? w[0] * w[2] : w[1] * w[3];
        float outside_pair = in[0] ? w[1] * w[3] : w[0] * w[2];
        bits |= (inside_pair > outside_pair) << f;
    }
    return bits;
}

OM_FN int om_mc_case(const float v[8], float iso) {
    int inside = om_inside_mask(v, iso);
    return inside | om_mc_face_bits(v, iso, inside) << 8;
}

// Index among the sample's own vertices of the one on edge (s, a): its sign-changing edges with
// a smaller axis come first.
OM_FN OM_UINT om_mc_rank(OM_GLOBAL const float* values, OmField f, int x, int y, int z, int a) {
    OM_UINT rank = 0;
    for (int b = 0; b < a; ++b) rank += om_edge_changes(values, f, x, y, z, b);
    return rank;
}

OM_FN void om_mc_count(OM_GLOBAL const float* values, OM_GLOBAL const OM_UCHAR* table, OmField f,
                       int x, int y, int z, OM_UINT* vertices, OM_UINT* triangles) {
    *vertices = 0;
    *triangles = 0;
    for (int a = 0; a < 3; ++a) *vertices += om_edge_changes(values, f, x, y, z, a);
    if (om_cell_exists(f, x, y, z)) {
        float v[8];
        om_cell_values(values, f, x, y, z, v);
        OM_GLOBAL const OM_UCHAR* entry = table + om_mc_case(v, f.iso) * OM_MC_ENTRY_BYTES;
        *triangles = entry[0];
        *vertices += entry[1];
    }
}

// Vertices of sample s: crossings on its edges (s, 0..2) in axis order, then the centres of its
// cell; then the cell's triangles.
OM_FN void om_mc_emit(OM_GLOBAL const float* values, OM_GLOBAL const OM_UCHAR* table, OmField f,
                      int x, int y, int z, OmTiling tiling, OM_GLOBAL const OM_UINT* brick_base,
                      OM_GLOBAL const OM_UINT* vertex_offset,
                      OM_GLOBAL const OM_UINT* triangle_offset, OM_UINT vertex_base,
                      OM_UINT triangle_base, OM_GLOBAL OM_UINT* vertex_sample,
                      OM_GLOBAL float* vertex_local, OM_GLOBAL OM_UINT* triangles) {
    OM_UINT s = om_index(f, x, y, z), slot = om_slot(f, tiling, brick_base, x, y, z);
    OM_UINT o = vertex_offset[slot] - vertex_base;
    for (int a = 0; a < 3; ++a) {
        if (!om_edge_changes(values, f, x, y, z, a)) continue;
        int u[3] = {x, y, z};
        u[a] += 1;
        float t = om_crossing(values[s], values[om_index(f, u[0], u[1], u[2])], f.iso);
        vertex_sample[o] = s;
        for (int k = 0; k < 3; ++k) vertex_local[3 * o + k] = k == a ? t : 0.0f;
        ++o;
    }
    if (!om_cell_exists(f, x, y, z)) return;
    float v[8];
    om_cell_values(values, f, x, y, z, v);
    OM_GLOBAL const OM_UCHAR* entry = table + om_mc_case(v, f.iso) * OM_MC_ENTRY_BYTES;
    OM_UINT first_centre = o + vertex_base;  // the global index, for the triangles
    for (int j = 0; j < (int)entry[1]; ++j) {
        float p[3];
        om_mean_crossing(v, f.iso, entry[2 + 2 * j] | entry[3 + 2 * j] << 8, p);
        vertex_sample[o] = s;
        for (int k = 0; k < 3; ++k) vertex_local[3 * o + k] = p[k];
        ++o;
    }
    OM_UINT t = triangle_offset[slot] - triangle_base;
    for (int i = 0; i < 3 * (int)entry[0]; ++i) {
        int code = entry[OM_MC_TRIANGLES_AT + i];
        if (code >= OM_MC_CENTRE_BASE) {
            triangles[3 * t + i] = first_centre + (OM_UINT)(code - OM_MC_CENTRE_BASE);
            continue;
        }
        int lo = om_edge_corner(code, 0);
        int ox = x + om_corner_bit(lo, 0), oy = y + om_corner_bit(lo, 1),
            oz = z + om_corner_bit(lo, 2);
        triangles[3 * t + i] = vertex_offset[om_slot(f, tiling, brick_base, ox, oy, oz)] +
                               om_mc_rank(values, f, ox, oy, oz, code >> 2);
    }
}

#ifndef __OPENCL_VERSION__
}  // namespace oclvox::detail
#endif

#endif  // OCLVOX_MESHING_MATH_H
