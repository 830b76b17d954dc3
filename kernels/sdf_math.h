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
#else
#include <cmath>
#define OV_SDF_FN static inline
namespace oclvox::detail {
#endif

// A triangle with its distance constants (built by the host, see sdf_prepare.cpp).
//   vertex[j]    anchor-relative vertex j
//   edge[j]      vertex[j+1] - vertex[j]
//   inv_len2[j]  1 / |edge[j]|^2, or 0 for a zero-length edge (the segment is then a point)
//   normal       unit normal; has_face is 0 when the triangle is too thin to have one, and then
//                only its edges count, which is the right distance for a segment or a point
//   side[j]      edge[j] x normal: points away from the triangle across edge j
//   lo, hi       voxels (global indices, clipped to the grid) whose centres can be in the band
typedef struct {
    int anchor[3];
    float vertex[3][3];
    float edge[3][3];
    float inv_len2[3];
    float normal[3];
    float side[3][3];
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

// Whether the 4x4x4 block with minimum voxel (i,j,k) may hold a centre within `band` of the
// triangle: false only when every centre is farther than band from the triangle's plane. It
// only saves work, so its margin is generous: it must never skip a centre the exact test keeps.
OV_SDF_FN int ov_block_near(const OvSdfTriangle* t, int i, int j, int k, float band) {
    if (!t->has_face) return 1;
    float c[3];
    c[0] = (float)(i - t->anchor[0]) + 2.0f - t->vertex[0][0];
    c[1] = (float)(j - t->anchor[1]) + 2.0f - t->vertex[0][1];
    c[2] = (float)(k - t->anchor[2]) + 2.0f - t->vertex[0][2];
    float h = fabs(ov_dot3(c, t->normal));
    float reach = fabs(c[0]) + fabs(c[1]) + fabs(c[2]);
    // Centres are at most 1.5 * sqrt(3) < 2.6 from the block centre.
    return h <= band + 2.6f + 0.01f + 1e-5f * reach;
}

#ifndef __OPENCL_VERSION__
}  // namespace oclvox::detail
#endif

#endif  // OCLVOX_SDF_MATH_H
