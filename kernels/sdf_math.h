// Point-to-triangle distance, shared token for token by kernels/sdf.cl and the C++ reference.
//
// Determinism contract (as kernels/voxel_math.h): only IEEE single-precision +, -, *,
// comparisons, min and max, evaluated in the order written, FP_CONTRACT OFF on both sides. There
// is no division and no square root here: OpenCL 1.2 allows both to be off by ulps, so the
// reciprocals and the unit normal are computed once per triangle on the host (in double, rounded
// once) and uploaded, and distances stay squared until the host takes the root. A kernel and the
// reference therefore produce the same bits.
//
// Coordinates: voxel units relative to the triangle's integer anchor, so voxel (i,j,k)'s centre is
// (i,j,k) - anchor + 0.5, exact in float, and precision does not fall off away from the origin.
#ifndef OCLVOX_SDF_MATH_H
#define OCLVOX_SDF_MATH_H

#ifdef __OPENCL_VERSION__
#pragma OPENCL FP_CONTRACT OFF
#define OV_SDF_FN static inline
#define OV_SDF_GLOBAL __global
#else
#include <cmath>
#define OV_SDF_FN static inline
#define OV_SDF_GLOBAL
namespace oclvox::detail {
#endif

// A triangle with its distance constants (built by the host, see sdf_prepare.cpp).
//   vertex[j]    anchor-relative vertex j
//   edge[j]      vertex[j+1] - vertex[j]
//   inv_len2[j]  1 / |edge[j]|^2, or 0 for a zero-length edge (the segment is then a point)
//   normal       unit normal; has_face is 0 when the triangle is too thin to have one, and then
//                only its edges count, which is the right distance for a segment or a point
//   side[j]      edge[j] x normal: points away from the triangle across edge j
//   centre       anchor-relative centre of a sphere holding the triangle, radius its radius
//                (rounded up): cheap lower bounds on the distance, for culling only
//   lo, hi       voxels (global indices, clipped to the grid) whose centres can be in the band
typedef struct {
    int anchor[3];
    float vertex[3][3];
    float edge[3][3];
    float inv_len2[3];
    float normal[3];
    float side[3][3];
    float centre[3];
    float radius;
    int has_face;
    int lo[3], hi[3];
} OvSdfTriangle;

OV_SDF_FN float ov_dot3(const float a[3], const float b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// Squared distance from p to the segment vertex[j] .. vertex[j] + edge[j].
OV_SDF_FN float ov_segment_distance2(const OvSdfTriangle* t, int j, const float p[3]) {
    float w[3];
    for (int k = 0; k < 3; ++k) w[k] = p[k] - t->vertex[j][k];
    float s = ov_dot3(w, t->edge[j]) * t->inv_len2[j];
    s = fmin(fmax(s, 0.0f), 1.0f);
    float r[3];
    for (int k = 0; k < 3; ++k) r[k] = w[k] - s * t->edge[j][k];
    return ov_dot3(r, r);
}

// Squared distance from p (anchor-relative) to the closed triangle. If p projects inside the
// triangle the closest point is that projection; otherwise it lies on the boundary, so it is the
// nearest of the three edges' closest points.
OV_SDF_FN float ov_triangle_distance2(const OvSdfTriangle* t, const float p[3]) {
    if (t->has_face) {
        int inside = 1;
        for (int j = 0; j < 3; ++j) {
            float w[3];
            for (int k = 0; k < 3; ++k) w[k] = p[k] - t->vertex[j][k];
            if (ov_dot3(w, t->side[j]) > 0.0f) inside = 0;
        }
        if (inside) {
            float w[3];
            for (int k = 0; k < 3; ++k) w[k] = p[k] - t->vertex[0][k];
            float h = ov_dot3(w, t->normal);
            return h * h;
        }
    }
    float d0 = ov_segment_distance2(t, 0, p);
    float d1 = ov_segment_distance2(t, 1, p);
    float d2 = ov_segment_distance2(t, 2, p);
    return fmin(fmin(d0, d1), d2);
}

// Squared distance from voxel (i,j,k)'s centre to the triangle.
OV_SDF_FN float ov_voxel_distance2(const OvSdfTriangle* t, int i, int j, int k) {
    float p[3];
    p[0] = (float)(i - t->anchor[0]) + 0.5f;
    p[1] = (float)(j - t->anchor[1]) + 0.5f;
    p[2] = (float)(k - t->anchor[2]) + 0.5f;
    return ov_triangle_distance2(t, p);
}

// Whether the anchor-relative point c may lie within `reach_limit` of the triangle: false only
// when it is farther than that from the triangle's plane or from its bounding sphere. Culling only
// saves work, so the margin is generous: it must never reject a point whose exactly evaluated
// distance is below the limit.
OV_SDF_FN int ov_may_reach(const OvSdfTriangle* t, float cx, float cy, float cz,
                           float reach_limit) {
    float from_vertex[3] = {cx - t->vertex[0][0], cy - t->vertex[0][1], cz - t->vertex[0][2]};
    float from_centre[3] = {cx - t->centre[0], cy - t->centre[1], cz - t->centre[2]};
    float size = fabs(from_vertex[0]) + fabs(from_vertex[1]) + fabs(from_vertex[2]);
    float limit = reach_limit + 0.01f + 1e-5f * size;
    if (t->has_face && fabs(ov_dot3(from_vertex, t->normal)) > limit) return 0;
    float sphere = t->radius + limit;
    return ov_dot3(from_centre, from_centre) <= sphere * sphere;
}

// Whether voxel (i,j,k)'s centre may be within `band` of the triangle (the band pass evaluates
// the exact distance only where this holds; the rest would fail d2 < band2 anyway).
OV_SDF_FN int ov_voxel_near(const OvSdfTriangle* t, int i, int j, int k, float band) {
    return ov_may_reach(t, (float)(i - t->anchor[0]) + 0.5f, (float)(j - t->anchor[1]) + 0.5f,
                        (float)(k - t->anchor[2]) + 0.5f, band);
}

// Whether the 4x4x4 block with minimum voxel (i,j,k) may hold a centre within `band` of the
// triangle. Centres are at most 1.5 * sqrt(3) < 2.6 from the block centre.
OV_SDF_FN int ov_block_near(const OvSdfTriangle* t, int i, int j, int k, float band) {
    return ov_may_reach(t, (float)(i - t->anchor[0]) + 2.0f, (float)(j - t->anchor[1]) + 2.0f,
                        (float)(k - t->anchor[2]) + 2.0f, band + 2.6f);
}

// Whether the row of 8 voxels (i0..i0+7, j, k) may hold a centre within `band` of the triangle.
// Its centres are at most 3.5 from the row's middle, which lies on no voxel centre.
OV_SDF_FN int ov_row_near(const OvSdfTriangle* t, int i0, int j, int k, float band) {
    return ov_may_reach(t, (float)(i0 - t->anchor[0]) + 4.0f, (float)(j - t->anchor[1]) + 0.5f,
                        (float)(k - t->anchor[2]) + 0.5f, band + 3.5f);
}

// A node of the tree over the prepared triangles that full-grid fields search beyond the band
// (sdf_tree.cpp builds it). Nodes are stored depth first; `skip` is the node after this one's
// subtree. A leaf (count > 0) holds triangles order[first .. first + count); an inner node's
// first child follows it. lo, hi: a box in global voxel coordinates holding the node's triangles
// with a margin for rounding, so that no triangle in it is nearer to a point than the box's gap
// (ov_box_gap2) says.
typedef struct {
    float lo[3], hi[3];
    unsigned int first, count, skip, unused;
} OvSdfNode;

// A lower bound on the squared distance from voxel (i,j,k)'s centre to anything in the box
// [lo, hi], shrunk by a part in 10^4 to stay below every distance computed to the box's triangles
// in float.
OV_SDF_FN float ov_box_gap2(OV_SDF_GLOBAL const OvSdfNode* node, int i, int j, int k) {
    float c[3] = {(float)i + 0.5f, (float)j + 0.5f, (float)k + 0.5f};
    float gap2 = 0.0f;
    for (int a = 0; a < 3; ++a) {
        float g = fmax(fmax(node->lo[a] - c[a], c[a] - node->hi[a]), 0.0f);
        gap2 += g * g;
    }
    return gap2 * 0.9999f;
}

// Orders an inner node's two children (and their gaps) so that the walk enters the closer first.
OV_SDF_FN void ov_closer_first(unsigned int* closer, unsigned int* farther, float* closer_gap,
                               float* farther_gap) {
    if (*farther_gap < *closer_gap) {
        unsigned int node = *closer;
        *closer = *farther;
        *farther = node;
        float gap = *closer_gap;
        *closer_gap = *farther_gap;
        *farther_gap = gap;
    }
}

// Deepest tree ov_tree_distance2 can walk: its stack holds one node per level. The tree is split
// at medians, so 2^32 triangles make fewer than 33 levels.
#define OV_SDF_TREE_DEPTH 64

// Rows of 8 voxels along x that one work item of the far_distances kernel walks, one after
// another along y, each from the leaf that last brought the row before it nearer (bunny00's full
// grid at 128 through PoCL on 2 cores: 2.52 s with no such leaf, 1.95 s with 4 rows an item, 1.79
// s with 8, 1.72 s with 16; 8 keeps GPUs supplied with items at small grids).
#define OV_SDF_FAR_ROWS 8

// The least squared distance from voxel (i,j,k)'s centre to the tree's triangles: a walk that
// enters the nearer child first and passes over any subtree whose box is farther than the nearest
// triangle found so far. Every triangle it passes over is at least that far, so the result is the
// minimum over all the triangles, whatever the order of the walk.
OV_SDF_FN float ov_tree_distance2(OV_SDF_GLOBAL const OvSdfNode* nodes,
                                  OV_SDF_GLOBAL const unsigned int* order,
                                  OV_SDF_GLOBAL const OvSdfTriangle* triangles, int i, int j,
                                  int k) {
    float best = INFINITY;
    unsigned int stack[OV_SDF_TREE_DEPTH];
    int top = 0;
    unsigned int n = 0;
    for (;;) {
        OV_SDF_GLOBAL const OvSdfNode* node = nodes + n;
        int descend = 0;
        if (node->count == 0) {
            // An inner node: its first child follows it, the second follows the first's subtree.
            unsigned int closer = n + 1, farther = nodes[n + 1].skip;
            float closer_gap = ov_box_gap2(nodes + closer, i, j, k);
            float farther_gap = ov_box_gap2(nodes + farther, i, j, k);
            ov_closer_first(&closer, &farther, &closer_gap, &farther_gap);
            if (closer_gap <= best) {
                if (farther_gap <= best) stack[top++] = farther;
                n = closer;
                descend = 1;
            }
        } else {
            for (unsigned int t = node->first; t < node->first + node->count; ++t) {
                OvSdfTriangle triangle = triangles[order[t]];
                best = fmin(best, ov_voxel_distance2(&triangle, i, j, k));
            }
        }
        if (descend) continue;
        // The next stacked subtree that may still hold a nearer triangle.
        while (top > 0 && ov_box_gap2(nodes + stack[top - 1], i, j, k) > best) --top;
        if (top == 0) return best;
        n = stack[--top];
    }
}

#ifdef __OPENCL_VERSION__
// ov_voxel_distance2 of the 8 voxel centres (i0..i0+7, j, k) in the lanes of a float8: lane by
// lane the same operations in the same order as ov_triangle_distance2, both of its cases computed
// and one selected, so every lane has the scalar function's bits (the kernels are tested against
// the reference bit for bit). Along a row only x changes, so the y and z terms are scalars, and a
// CPU device runs the row in one vector register whatever it makes of the work items.
OV_SDF_FN float8 ov_row_segment_distance2(const OvSdfTriangle* t, int v, float8 wx, float wy,
                                          float wz) {
    float8 s = (wx * t->edge[v][0] + wy * t->edge[v][1] + wz * t->edge[v][2]) * t->inv_len2[v];
    s = fmin(fmax(s, 0.0f), 1.0f);
    float8 rx = wx - s * t->edge[v][0];
    float8 ry = wy - s * t->edge[v][1];
    float8 rz = wz - s * t->edge[v][2];
    return rx * rx + ry * ry + rz * rz;
}

OV_SDF_FN float8 ov_row_distance2(const OvSdfTriangle* t, int i0, int j, int k) {
    float8 px = convert_float8((int8)(i0 - t->anchor[0]) + (int8)(0, 1, 2, 3, 4, 5, 6, 7)) + 0.5f;
    float py = (float)(j - t->anchor[1]) + 0.5f;
    float pz = (float)(k - t->anchor[2]) + 0.5f;
    float8 wx[3];
    float wy[3], wz[3];
    for (int v = 0; v < 3; ++v) {
        wx[v] = px - t->vertex[v][0];
        wy[v] = py - t->vertex[v][1];
        wz[v] = pz - t->vertex[v][2];
    }
    float8 d0 = ov_row_segment_distance2(t, 0, wx[0], wy[0], wz[0]);
    float8 d1 = ov_row_segment_distance2(t, 1, wx[1], wy[1], wz[1]);
    float8 d2 = ov_row_segment_distance2(t, 2, wx[2], wy[2], wz[2]);
    float8 edges = fmin(fmin(d0, d1), d2);
    if (!t->has_face) return edges;
    int8 inside = (int8)(-1);
    for (int v = 0; v < 3; ++v)
        inside &= ~(wx[v] * t->side[v][0] + wy[v] * t->side[v][1] + wz[v] * t->side[v][2] > 0.0f);
    float8 h = wx[0] * t->normal[0] + wy[0] * t->normal[1] + wz[0] * t->normal[2];
    return select(edges, h * h, inside);
}

// How much nearer than `best` the row of 8 voxel centres (i0..i0+7, j, k) may find a triangle in
// node's box: the least over the lanes of ov_box_gap2 (in float8, rounded in another order, which
// the 0.9999 shrink covers) minus the lane's best. At or above 0 no lane can get nearer there;
// below 0 the more negative, the more promising the box.
OV_SDF_FN float ov_row_box_margin(__global const OvSdfNode* node, int i0, int j, int k,
                                  float8 best) {
    float8 x = convert_float8((int8)(i0) + (int8)(0, 1, 2, 3, 4, 5, 6, 7)) + 0.5f;
    float y = (float)j + 0.5f, z = (float)k + 0.5f;
    float8 gx = fmax(fmax(node->lo[0] - x, x - node->hi[0]), 0.0f);
    float gy = fmax(fmax(node->lo[1] - y, y - node->hi[1]), 0.0f);
    float gz = fmax(fmax(node->lo[2] - z, z - node->hi[2]), 0.0f);
    float8 margin = (gx * gx + (gy * gy + gz * gz)) * 0.9999f - best;
    float4 m = fmin(margin.lo, margin.hi);
    return fmin(fmin(m.x, m.y), fmin(m.z, m.w));
}

// The row's distances to the triangles of leaf node n, folded into best (lanes take the least);
// whether any lane got nearer. tree_triangles: the triangles in the tree's order
// (triangles[order[t]] at t), so that a leaf's are read side by side.
OV_SDF_FN int ov_row_leaf_distance2(__global const OvSdfNode* node,
                                    __global const OvSdfTriangle* tree_triangles, int i0, int j,
                                    int k, float8* best) {
    float8 before = *best;
    for (unsigned int t = node->first; t < node->first + node->count; ++t) {
        OvSdfTriangle triangle = tree_triangles[t];
        *best = fmin(*best, ov_row_distance2(&triangle, i0, j, k));
    }
    return any(*best < before);
}

// No leaf to start from (ov_tree_row_distance2's hint).
#define OV_SDF_NO_HINT 0xffffffffu

// ov_tree_distance2 of the row of 8 voxel centres (i0..i0+7, j, k) in the lanes of a float8, from
// `best` (lanes already known, or 0 for lanes to leave out): one walk for the row, evaluating its
// triangles with ov_row_distance2 (each lane the scalar function's bits). It passes over a
// subtree only when every lane's gap to it is at least the lane's best (a triangle there could not
// lower that lane's minimum), so each lane ends at its own minimum over all the triangles, as
// ov_tree_distance2 finds it.
// *hint: a leaf node whose triangles are taken first (the last leaf that brought a neighbouring
// row nearer: usually near this row too, so the walk passes over far subtrees from its start), or
// OV_SDF_NO_HINT; on return, the last leaf that brought this row nearer. A leaf taken twice changes
// nothing, and every bound is some triangle's distance, so the result does not depend on it.
OV_SDF_FN float8 ov_tree_row_distance2(__global const OvSdfNode* nodes,
                                       __global const OvSdfTriangle* tree_triangles, int i0, int j,
                                       int k, float8 best, unsigned int* hint) {
    if (*hint != OV_SDF_NO_HINT)
        ov_row_leaf_distance2(nodes + *hint, tree_triangles, i0, j, k, &best);
    unsigned int stack[OV_SDF_TREE_DEPTH];
    int top = 0;
    unsigned int n = 0;
    if (ov_row_box_margin(nodes, i0, j, k, best) >= 0.0f) return best;
    for (;;) {
        __global const OvSdfNode* node = nodes + n;
        int descend = 0;
        if (node->count == 0) {
            unsigned int closer = n + 1, farther = nodes[n + 1].skip;
            float closer_margin = ov_row_box_margin(nodes + closer, i0, j, k, best);
            float farther_margin = ov_row_box_margin(nodes + farther, i0, j, k, best);
            ov_closer_first(&closer, &farther, &closer_margin, &farther_margin);
            if (closer_margin < 0.0f) {
                if (farther_margin < 0.0f) stack[top++] = farther;
                n = closer;
                descend = 1;
            }
        } else if (ov_row_leaf_distance2(node, tree_triangles, i0, j, k, &best)) {
            *hint = n;
        }
        if (descend) continue;
        while (top > 0 && ov_row_box_margin(nodes + stack[top - 1], i0, j, k, best) >= 0.0f) --top;
        if (top == 0) return best;
        n = stack[--top];
    }
}
#endif

#ifndef __OPENCL_VERSION__
}  // namespace oclvox::detail
#endif

#endif  // OCLVOX_SDF_MATH_H
