// Narrow-band distance field and its jump-flooding extension, OpenCL C 1.2.
//
// Distances are squared, in voxel units, kept as the bits of non-negative floats in uint buffers.
//
// band_leaf_samples: the samples of a batch of 8x8x8 leaves, each leaf from the triangles the
//                host binned to it (a gather, one work group per leaf): the band of sparse fields
//                and of dense ones.
// band_nearest:  one work item per (triangle, 4x4x4 block) of the voxels near that triangle,
//                recording the lowest triangle index that attains each voxel's minimum (the seeds
//                of the jump flood; only for full-grid fields).
// jump:          one jump-flooding pass: each voxel takes the nearest of the triangles its 26
//                neighbours at distance `step` (and itself) know about.
#include "sdf_math.h"

#define OV_NONE 0xffffffffu

// Largest t with first_item[t] <= item (first_item is non-decreasing, first_item[0] == 0).
static uint find_triangle(__global const ulong* first_item, uint count, ulong item) {
    uint lo = 0, hi = count - 1;
    while (lo < hi) {
        uint mid = lo + (hi - lo + 1) / 2;
        if (first_item[mid] <= item)
            lo = mid;
        else
            hi = mid - 1;
    }
    return lo;
}

// Decodes this work item into its triangle and the block's minimum voxel; 0 for padding items
// and for blocks the plane cull rejects.
static int decode_item(__global const OvSdfTriangle* triangles, __global const ulong* first_item,
                       uint count, ulong item_base, ulong item_end, float band, OvSdfTriangle* t,
                       uint* index, int block[3]) {
    ulong item = item_base + get_global_id(0);
    if (item >= item_end) return 0;
    *index = find_triangle(first_item, count, item);
    *t = triangles[*index];
    ulong offset = item - first_item[*index];
    int bx = t->hi[0] / 4 - t->lo[0] / 4 + 1;
    int by = t->hi[1] / 4 - t->lo[1] / 4 + 1;
    block[0] = (t->lo[0] / 4 + (int)(offset % (ulong)bx)) * 4;
    block[1] = (t->lo[1] / 4 + (int)(offset / (ulong)bx % (ulong)by)) * 4;
    block[2] = (t->lo[2] / 4 + (int)(offset / ((ulong)bx * (ulong)by))) * 4;
    return ov_block_near(t, block[0], block[1], block[2], band);
}

// One work group of 64 per leaf of slots [slot_first + group_base, ...): item (y, z) computes the
// leaf's row of 8 samples along x (ov_row_distance2) against every triangle of the leaf's list
// (pair_triangle[slot_first_pair[slot] .. slot_first_pair[slot + 1])) and writes it once, at
// (slot - slot_first) * 512, x fastest in a leaf. A gather: no atomics. A sample takes a triangle
// only inside the triangle's voxel range, and a row only where the row cull keeps it; the culls
// are conservative, so the minimum is that of every triangle's band samples.
__kernel __attribute__((reqd_work_group_size(64, 1, 1))) void band_leaf_samples(
    __global const OvSdfTriangle* triangles, __global const uint* slot_first_pair,
    __global const uint* pair_triangle, __global const ulong* slot_leaf, uint slot_first,
    uint group_base, uint slot_end, int leaves_x, int leaves_y, float band, float band2,
    __global uint* distance2) {
    uint batch_slot = group_base + (uint)get_group_id(0);
    uint slot = slot_first + batch_slot;
    if (slot >= slot_end) return;
    ulong leaf = slot_leaf[slot];
    int y = (int)get_local_id(0) & 7, z = (int)get_local_id(0) >> 3;
    int i0 = (int)(leaf % (ulong)leaves_x) * 8;
    int j = (int)(leaf / (ulong)leaves_x % (ulong)leaves_y) * 8 + y;
    int k = (int)(leaf / ((ulong)leaves_x * (ulong)leaves_y)) * 8 + z;
    int8 i = (int8)(i0) + (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    float8 best = (float8)(band2);
    for (uint p = slot_first_pair[slot]; p < slot_first_pair[slot + 1]; ++p) {
        OvSdfTriangle t = triangles[pair_triangle[p]];
        if (j < t.lo[1] || j > t.hi[1] || k < t.lo[2] || k > t.hi[2]) continue;
        if (!ov_row_near(&t, i0, j, k, band)) continue;
        float8 d2 = ov_row_distance2(&t, i0, j, k);
        best = select(best, fmin(best, d2), (i >= t.lo[0]) & (i <= t.hi[0]));
    }
    vstore8(as_uint8(best), 0, distance2 + (size_t)batch_slot * 512 + 8 * (y + 8 * z));
}

__kernel void band_nearest(__global const OvSdfTriangle* triangles,
                           __global const ulong* first_item, uint count, ulong item_base,
                           ulong item_end, float band, float band2, int nx, int ny,
                           __global const uint* distance2, __global uint* nearest) {
    OvSdfTriangle t;
    uint index;
    int block[3];
    if (!decode_item(triangles, first_item, count, item_base, item_end, band, &t, &index, block))
        return;
    for (int k = max(block[2], t.lo[2]); k <= min(block[2] + 3, t.hi[2]); ++k)
        for (int j = max(block[1], t.lo[1]); j <= min(block[1] + 3, t.hi[1]); ++j)
            for (int i = max(block[0], t.lo[0]); i <= min(block[0] + 3, t.hi[0]); ++i) {
                if (!ov_voxel_near(&t, i, j, k, band)) continue;
                float d2 = ov_voxel_distance2(&t, i, j, k);
                size_t v = (size_t)i + (size_t)nx * ((size_t)j + (size_t)ny * k);
                if (d2 < band2 && as_uint(d2) == distance2[v]) atomic_min(&nearest[v], index);
            }
}

__kernel void jump(__global const OvSdfTriangle* triangles, __global const uint* nearest_in,
                   ulong voxel_base, ulong voxel_end, int step, int nx, int ny, int nz,
                   __global uint* nearest_out, __global uint* distance2_out) {
    ulong v = voxel_base + get_global_id(0);
    if (v >= voxel_end) return;
    int i = (int)(v % (ulong)nx), j = (int)(v / (ulong)nx % (ulong)ny),
        k = (int)(v / ((ulong)nx * (ulong)ny));
    uint best = nearest_in[v];
    float best_d2 = INFINITY;
    if (best != OV_NONE) {
        OvSdfTriangle t = triangles[best];
        best_d2 = ov_voxel_distance2(&t, i, j, k);
    }
    // Neighbours mostly share a few nearest triangles: each distinct one is evaluated once (the
    // choice below does not depend on how often a candidate is offered).
    uint seen[26];
    int seen_count = 0;
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                int a = i + dx * step, b = j + dy * step, c = k + dz * step;
                if (a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz) continue;
                uint candidate = nearest_in[(size_t)a + (size_t)nx * ((size_t)b + (size_t)ny * c)];
                if (candidate == OV_NONE || candidate == best) continue;
                int repeated = 0;
                for (int s = 0; s < seen_count; ++s) repeated |= seen[s] == candidate;
                if (repeated) continue;
                if (seen_count < 26) seen[seen_count++] = candidate;
                OvSdfTriangle t = triangles[candidate];
                float d2 = ov_voxel_distance2(&t, i, j, k);
                if (d2 < best_d2 || (d2 == best_d2 && candidate < best)) {
                    best = candidate;
                    best_d2 = d2;
                }
            }
    nearest_out[v] = best;
    if (best != OV_NONE) distance2_out[v] = as_uint(best_d2);
}
