// Conservative (26-separating) and thin surface voxelization, OpenCL C 1.2.
//
// Two phases. setup_*: one work item per triangle computes the per-triangle constants of the
// overlap test once. voxelize_*: one work item per (triangle, column of 4x4x4 blocks along x)
// finds, for each of the column's 4x4 voxel rows, the exact run of voxels the triangle overlaps
// (a row meets it in one interval; see the row spans in voxel_math.h), turns the runs into each
// block's 64-bit mask with shifts and ORs it into the brick's bits with at most two 32-bit atomics.
// Work items are numbered pair by pair; an item finds its (triangle, brick) pair by binary search
// in the pairs' first-item offsets, so a huge triangle spreads over many items instead of
// serialising on one.
#include "voxel_math.h"
#include "work_items.h"

__kernel void setup_sat(__global const OvTriangle* triangles, uint count, int half_open,
                        __global OvSatTriangle* out) {
    uint i = get_global_id(0);
    if (i < count) out[i] = ov_setup_sat(triangles[i], half_open);
}

__kernel void setup_pef(__global const OvTriangle* triangles, uint count, int half_open,
                        __global OvPefTriangle* out) {
    uint i = get_global_id(0);
    if (i < count) out[i] = ov_setup_pef(triangles[i], half_open);
}

__kernel void setup_thin(__global const OvTriangle* triangles, uint count, int half_open,
                         __global OvThinTriangle* out) {
    uint i = get_global_id(0);
    if (i < count) out[i] = ov_setup_thin(triangles[i], half_open);
}

typedef struct {
    uint triangle, slot;
    int brick[3];
    int block_y, block_z;  // global block coordinates of the column
    OvPairWork work;
} Item;

// Returns 0 for the padding items past the end of the launch.
static int decode_item(__global const uint* pair_triangle, __global const uint* pair_slot,
                       __global const uint* pair_first_item, uint pair_count,
                       __global const int* slot_brick, __global const OvRange* ranges,
                       uint item_base, uint item_end, int brick_size, int nx, int ny, int nz,
                       Item* it) {
    uint item = item_base + (uint)get_global_id(0);
    if (item >= item_end) return 0;
    uint p = find_pair(pair_first_item, pair_count, item);
    it->triangle = pair_triangle[p];
    it->slot = pair_slot[p];
    for (int k = 0; k < 3; ++k) it->brick[k] = slot_brick[3 * it->slot + k];
    OvRange r = ranges[it->triangle];
    ov_pair_work(r, it->brick[0], it->brick[1], it->brick[2], brick_size, nx, ny, nz, &it->work);
    uint index_in_pair = item - pair_first_item[p];
    uint cy = (uint)it->work.block_count[1];
    it->block_y = it->work.block_lo[1] + (int)(index_in_pair % cy);
    it->block_z = it->work.block_lo[2] + (int)(index_in_pair / cy);
    return 1;
}

static void store_block(__global uint* bits, const Item* it, int block_x, int brick_size,
                        uint mask_lo, uint mask_hi) {
    int nb = brick_size / 4;
    int bx = block_x - it->brick[0] * nb;
    int by = it->block_y - it->brick[1] * nb;
    int bz = it->block_z - it->brick[2] * nb;
    size_t words_per_brick = 2 * (size_t)nb * nb * nb;
    size_t word = it->slot * words_per_brick + 2 * (size_t)(bx + nb * (by + nb * bz));
    if (mask_lo) atomic_or(&bits[word], mask_lo);
    if (mask_hi) atomic_or(&bits[word + 1], mask_hi);
}

// The four x bits of row r (bit r * 4 of a block mask: ov_block_bit(x, y, z) = x + 4 * (y + 4z))
// for the voxels first..last clipped to the block starting at x0.
static uint row_bits(int first, int last, int x0) {
    int a = max(first, x0) - x0, b = min(last, x0 + 3) - x0;
    return a <= b ? (0xFu << a) & (0xFu >> (3 - b)) : 0u;
}

// Rows of more than this many voxels are bounded before the walks. (Bounding shorter rows, even by
// the plane test alone, cost more instructions than it saved: callgrind, bunny 512^3, PoCL.)
#define OV_SPAN_MIN_ROW 8

// One voxelize kernel per predicate, written once: SETUP is the per-triangle struct, OVERLAPS its
// per-voxel test, ROW_POSSIBLE its exact whole-row rejection, SPAN its row bound and MODERATE the
// bound's precondition.
#define OV_VOXELIZE_KERNEL(NAME, SETUP, OVERLAPS, ROW_POSSIBLE, SPAN, MODERATE)                   \
    __kernel void NAME(__global const SETUP* setups, __global const OvRange* ranges,              \
                       __global const uint* pair_triangle, __global const uint* pair_slot,        \
                       __global const uint* pair_first_item, uint pair_count,                     \
                       __global const int* slot_brick, uint item_base, uint item_end,             \
                       int brick_size, int nx, int ny, int nz, __global uint* bits) {             \
        Item it;                                                                                  \
        if (!decode_item(pair_triangle, pair_slot, pair_first_item, pair_count, slot_brick,       \
                         ranges, item_base, item_end, brick_size, nx, ny, nz, &it))               \
            return;                                                                               \
        SETUP s = setups[it.triangle];                                                            \
        /* Rows of the column, anchor-relative: qx over the pair's range, qy and qz in the */     \
        /* column's blocks. Row r = (y & 3) + 4 * (z & 3) keeps its run in first[r]..last[r] */   \
        /* (global x; empty if first > last). */                                                  \
        int x_lo = it.work.voxel_lo[0] - s.anchor[0], x_hi = it.work.voxel_hi[0] - s.anchor[0];   \
        int y_lo = max(it.work.voxel_lo[1], it.block_y * 4);                                      \
        int y_hi = min(it.work.voxel_hi[1], it.block_y * 4 + 3);                                  \
        int z_lo = max(it.work.voxel_lo[2], it.block_z * 4);                                      \
        int z_hi = min(it.work.voxel_hi[2], it.block_z * 4 + 3);                                  \
        int first[16], last[16];                                                                  \
        /* Beyond the span preconditions the runs may have gaps: test every voxel. */             \
        int reach = max(max(abs(x_lo), abs(x_hi)),                                                \
                        max(max(abs(y_lo - s.anchor[1]), abs(y_hi - s.anchor[1])),                \
                            max(abs(z_lo - s.anchor[2]), abs(z_hi - s.anchor[2]))));              \
        int unsafe = reach > (1 << 20) || !MODERATE(&s);                                          \
        for (int r = 0; r < 16; ++r) {                                                            \
            first[r] = 1;                                                                         \
            last[r] = 0;                                                                          \
        }                                                                                         \
        for (int z = z_lo; z <= z_hi && !unsafe; ++z)                                             \
            for (int y = y_lo; y <= y_hi; ++y) {                                                  \
                float qy = (float)(y - s.anchor[1]), qz = (float)(z - s.anchor[2]);               \
                if (!ROW_POSSIBLE(&s, qy, qz)) continue;                                          \
                int lo = x_lo, hi = x_hi;                                                         \
                /* Short rows: the walks below cost less than the bound. */                       \
                if (x_hi - x_lo >= OV_SPAN_MIN_ROW) {                                             \
                    OvSpan span = ov_span_start(x_lo, x_hi);                                      \
                    SPAN(&s, qy, qz, &span);                                                      \
                    ov_span_range(span, x_lo, x_hi, &lo, &hi);                                    \
                }                                                                                 \
                /* The accepted qx form one interval inside [lo, hi]: its ends are the first */   \
                /* voxel that passes from either side. */                                         \
                while (lo <= hi && !OVERLAPS(&s, (float)lo, qy, qz)) ++lo;                        \
                while (hi > lo && !OVERLAPS(&s, (float)hi, qy, qz)) --hi;                         \
                int r = (y & 3) + 4 * (z & 3);                                                    \
                first[r] = lo + s.anchor[0];                                                      \
                last[r] = hi + s.anchor[0];                                                       \
            }                                                                                     \
        for (int bx = it.work.block_lo[0]; bx < it.work.block_lo[0] + it.work.block_count[0];     \
             ++bx) {                                                                              \
            uint mask_lo = 0, mask_hi = 0;                                                        \
            if (!unsafe) {                                                                        \
                for (int r = 0; r < 8; ++r) {                                                     \
                    mask_lo |= row_bits(first[r], last[r], bx * 4) << (4 * r);                    \
                    mask_hi |= row_bits(first[r + 8], last[r + 8], bx * 4) << (4 * r);            \
                }                                                                                 \
            } else {                                                                              \
                /* Non-finite magnitudes: the runs may have gaps, test every voxel. */            \
                int xb_lo = max(it.work.voxel_lo[0], bx * 4);                                     \
                int xb_hi = min(it.work.voxel_hi[0], bx * 4 + 3);                                 \
                for (int z = z_lo; z <= z_hi; ++z)                                                \
                    for (int y = y_lo; y <= y_hi; ++y)                                            \
                        for (int x = xb_lo; x <= xb_hi; ++x) {                                    \
                            if (!OVERLAPS(&s, (float)(x - s.anchor[0]), (float)(y - s.anchor[1]), \
                                          (float)(z - s.anchor[2])))                              \
                                continue;                                                         \
                            int bit = ov_block_bit(x & 3, y & 3, z & 3);                          \
                            if (bit < 32)                                                         \
                                mask_lo |= 1u << bit;                                             \
                            else                                                                  \
                                mask_hi |= 1u << (bit - 32);                                      \
                        }                                                                         \
            }                                                                                     \
            store_block(bits, &it, bx, brick_size, mask_lo, mask_hi);                             \
        }                                                                                         \
    }

OV_VOXELIZE_KERNEL(voxelize_sat, OvSatTriangle, ov_sat_overlaps, ov_sat_row_possible, ov_sat_span,
                   ov_sat_moderate)
OV_VOXELIZE_KERNEL(voxelize_pef, OvPefTriangle, ov_pef_overlaps, ov_pef_row_possible, ov_pef_span,
                   ov_pef_moderate)
OV_VOXELIZE_KERNEL(voxelize_thin, OvThinTriangle, ov_thin_overlaps, ov_thin_row_possible,
                   ov_thin_span, ov_thin_moderate)
