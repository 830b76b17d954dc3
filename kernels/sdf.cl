// Narrow-band distance field and its full-grid extension, OpenCL C 1.2.
//
// Distances are squared, in voxel units, kept as the bits of non-negative floats in uint buffers.
//
// band_leaf_samples: the samples of a batch of 8x8x8 leaves, each leaf from the triangles the
//                host binned to it (a gather, one work group per leaf): the band of sparse fields
//                and of dense ones.
// far_distances: for full-grid fields, every voxel beyond the band takes its least squared
//                distance to all the triangles, from the tree over them (ov_tree_distance2).
#include "sdf_math.h"

// One work group of 64 per leaf of slots [slot_first + group_base, ...): item (y, z) computes the
// leaf's row of 8 samples along x (ov_row_distance2) against every triangle of the leaf's list
// (pair_triangle[slot_first_pair[slot] .. slot_first_pair[slot + 1])) and writes it once, at
// (slot - slot_first) * 512, x fastest in a leaf. A gather: no atomics. A sample takes a triangle
// only inside the triangle's voxel range, and a row only where the row cull keeps it; the culls
// are conservative, so the minimum is that of every triangle's band samples. pair_rows[p]: the
// rows (bits 0-7, by y) and layers (bits 8-15, by z) of the leaf that pair p's triangle's voxel
// range reaches.
// The list is taken a tile of 64 triangles at a time, each item copying one into local memory,
// because every row reads every triangle it reaches: read from the triangles themselves, on a
// mesh of many small triangles (buildings: 713 a leaf, 134 KB) each row streamed the whole list
// from the second-level cache, and those reads were half the kernel's time; a tile stays in the
// first. Most of a tile's triangles miss most rows (three quarters of the pairs), and a row
// tests its bit of pair_rows before it copies the triangle.
__kernel __attribute__((reqd_work_group_size(64, 1, 1))) void band_leaf_samples(
    __global const OvSdfTriangle* triangles, __global const uint* slot_first_pair,
    __global const uint* pair_triangle, __global const ushort* pair_rows,
    __global const ulong* slot_leaf, uint slot_first, uint group_base, uint slot_end, int leaves_x,
    int leaves_y, float band, float band2, __global uint* distance2) {
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
    __local OvSdfTriangle tile[64];
    __local ushort tile_rows[64];
    uint list_end = slot_first_pair[slot + 1];
    for (uint base = slot_first_pair[slot]; base < list_end; base += 64) {
        uint n = min(64u, list_end - base);
        barrier(CLK_LOCAL_MEM_FENCE);  // the last tile's reads are done
        uint l = (uint)get_local_id(0);
        if (l < n) {
            tile[l] = triangles[pair_triangle[base + l]];
            tile_rows[l] = pair_rows[base + l];
        }
        barrier(CLK_LOCAL_MEM_FENCE);  // the tile is whole
        for (uint q = 0; q < n; ++q) {
            uint rows = tile_rows[q];
            if (!((rows >> y) & (rows >> (8 + z)) & 1u)) continue;
            OvSdfTriangle t = tile[q];
            if (!ov_row_near(&t, i0, j, k, band)) continue;
            float8 d2 = ov_row_distance2(&t, i0, j, k);
            best = select(best, fmin(best, d2), (i >= t.lo[0]) & (i <= t.hi[0]));
        }
    }
    vstore8(as_uint8(best), 0, distance2 + (size_t)batch_slot * 512 + 8 * (y + 8 * z));
}

// One work item per OV_SDF_FAR_ROWS rows of 8 voxels along x (rows (i0, j0..j0+7, k)), items
// [item_base, item_end) of the grid's (ceil(nx / 8) per line of x, ceil(ny / 8) per layer): the
// rows' voxels that the band left at band2 take the tree's distance (one walk per row, each from
// the leaf that last brought the row before it nearer); the band's voxels keep theirs, the same
// minimum over the triangles near them, and start the walk with it.
__kernel void far_distances(__global const OvSdfNode* nodes,
                            __global const OvSdfTriangle* tree_triangles, ulong item_base,
                            ulong item_end, int nx, int ny, float band2, __global uint* distance2) {
    ulong item = item_base + get_global_id(0);
    if (item >= item_end) return;
    ulong items_x = (ulong)((nx + 7) / 8),
          items_y = (ulong)((ny + OV_SDF_FAR_ROWS - 1) / OV_SDF_FAR_ROWS);
    int i0 = (int)(item % items_x) * 8, j0 = (int)(item / items_x % items_y) * OV_SDF_FAR_ROWS,
        k = (int)(item / (items_x * items_y));
    int width = min(8, nx - i0);
    uint hint = OV_SDF_NO_HINT;
    for (int j = j0; j < min(j0 + OV_SDF_FAR_ROWS, ny); ++j) {
        size_t first = (size_t)i0 + (size_t)nx * ((size_t)j + (size_t)ny * k);
        float start[8];
        int far = 0;
        for (int l = 0; l < 8; ++l) {
            float d2 = l < width ? as_float(distance2[first + l]) : 0.0f;
            int beyond = l < width && !(d2 < band2);
            start[l] = beyond ? INFINITY : d2;
            far |= beyond;
        }
        if (!far) continue;
        float result[8];
        vstore8(ov_tree_row_distance2(nodes, tree_triangles, i0, j, k, vload8(0, start), &hint), 0,
                result);
        for (int l = 0; l < width; ++l)
            if (start[l] == INFINITY) distance2[first + l] = as_uint(result[l]);
    }
}
