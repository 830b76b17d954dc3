// Narrow-band distance field and its jump-flooding extension, OpenCL C 1.2.
//
// Distances are squared, in voxel units, kept as the bits of non-negative floats in uint buffers:
// for those, unsigned integer order is float order, so atomic_min on the bits is a float min
// that is exact and independent of the order work items run in.
//
// band_distance: one work item per (triangle, 4x4x4 block) of the voxels near that triangle.
// band_nearest:  the same items again, recording the lowest triangle index that attains each
//                voxel's minimum (the seeds of the jump flood; only for full-grid fields).
// band_leaves:   the same items, marking the 8x8x8 leaf of every block the cull keeps in a bit set
//                of leaves (a sparse field's leaves).
// band_distance_leaves: band_distance into the samples of a batch of those leaves only, found
//                through the bit set and the rank of its words.
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

__kernel void band_distance(__global const OvSdfTriangle* triangles,
                            __global const ulong* first_item, uint count, ulong item_base,
                            ulong item_end, float band, float band2, int nx, int ny,
                            __global uint* distance2) {
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
                if (d2 < band2)
                    atomic_min(&distance2[(size_t)i + (size_t)nx * ((size_t)j + (size_t)ny * k)],
                               as_uint(d2));
            }
}

// decode_item, and the linear index of the 8x8x8 leaf holding the block's minimum voxel.
static int decode_leaf_item(__global const OvSdfTriangle* triangles,
                            __global const ulong* first_item, uint count, ulong item_base,
                            ulong item_end, float band, int leaves_x, int leaves_y,
                            OvSdfTriangle* t, int block[3], ulong* leaf) {
    uint index;
    if (!decode_item(triangles, first_item, count, item_base, item_end, band, t, &index, block))
        return 0;
    *leaf = (ulong)(block[0] >> 3) +
            (ulong)leaves_x * ((ulong)(block[1] >> 3) + (ulong)leaves_y * (ulong)(block[2] >> 3));
    return 1;
}

__kernel void band_leaves(__global const OvSdfTriangle* triangles, __global const ulong* first_item,
                          uint count, ulong item_base, ulong item_end, float band, int leaves_x,
                          int leaves_y, __global uint* leaf_bits) {
    OvSdfTriangle t;
    int block[3];
    ulong leaf;
    if (!decode_leaf_item(triangles, first_item, count, item_base, item_end, band, leaves_x,
                          leaves_y, &t, block, &leaf))
        return;
    uint bit = 1u << (uint)(leaf & 31);
    // Most blocks find their leaf marked already; reading first spares the atomic.
    if (!(leaf_bits[leaf >> 5] & bit)) atomic_or(&leaf_bits[leaf >> 5], bit);
}

// Samples of leaf slots [slot_first, slot_end) at (slot - slot_first) * 512, x fastest in a leaf;
// a leaf's slot is the number of marked leaves before it (leaf_rank holds that count before each
// word of leaf_bits).
__kernel void band_distance_leaves(__global const OvSdfTriangle* triangles,
                                   __global const ulong* first_item, uint count, ulong item_base,
                                   ulong item_end, float band, float band2, int leaves_x,
                                   int leaves_y, __global const uint* leaf_bits,
                                   __global const uint* leaf_rank, uint slot_first, uint slot_end,
                                   __global uint* distance2) {
    OvSdfTriangle t;
    int block[3];
    ulong leaf;
    if (!decode_leaf_item(triangles, first_item, count, item_base, item_end, band, leaves_x,
                          leaves_y, &t, block, &leaf))
        return;
    uint word = (uint)(leaf >> 5);
    uint slot = leaf_rank[word] + popcount(leaf_bits[word] & ((1u << (uint)(leaf & 31)) - 1u));
    if (slot < slot_first || slot >= slot_end) return;
    __global uint* samples = distance2 + (size_t)(slot - slot_first) * 512;
    for (int k = max(block[2], t.lo[2]); k <= min(block[2] + 3, t.hi[2]); ++k)
        for (int j = max(block[1], t.lo[1]); j <= min(block[1] + 3, t.hi[1]); ++j)
            for (int i = max(block[0], t.lo[0]); i <= min(block[0] + 3, t.hi[0]); ++i) {
                if (!ov_voxel_near(&t, i, j, k, band)) continue;
                float d2 = ov_voxel_distance2(&t, i, j, k);
                if (d2 < band2)
                    atomic_min(&samples[(i & 7) + 8 * ((j & 7) + 8 * (k & 7))], as_uint(d2));
            }
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
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                int a = i + dx * step, b = j + dy * step, c = k + dz * step;
                if (a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz) continue;
                uint candidate = nearest_in[(size_t)a + (size_t)nx * ((size_t)b + (size_t)ny * c)];
                if (candidate == OV_NONE || candidate == best) continue;
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
