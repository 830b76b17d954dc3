// Conservative (26-separating) surface voxelization, OpenCL C 1.2.
//
// One work item per (triangle, run of up to OV_BLOCKS_PER_ITEM 4x4x4 blocks): it computes its
// triangle's overlap-test constants and voxel range, tests each block's voxels (its three
// projections a face at a time, then the plane a row of 4 at a time), gathers a 64-bit mask
// privately and ORs it into the brick's bits with at most two 32-bit atomics. The constants are
// computed by every item rather than once per triangle in a setup pass: most triangles have one
// or two items, and a setup pass's buffer (up to 184 bytes a triangle, written once and read
// once) cost more than the arithmetic, in fresh memory on CPU devices above all. Each item is
// given its (triangle, brick) pair's index, so a huge triangle spreads over many items instead of
// serialising on one.
//
// For SAT and PEF a triangle whose range is one voxel sets that voxel untested
// (ov_range_is_one_voxel): the host sends those voxels to set_direct_bits instead, a work item
// each that decodes no pair and reads no triangle.
#include "voxel_math.h"

typedef struct {
    uint triangle, slot;
    int brick[3];
    OvPairWork work;
    int block_first, block_end;  // this item's blocks, numbered within the pair x fastest
} Item;

// Returns 0 for the padding items past the end of the launch.
static int decode_item(__global const OvTriangle* triangles, int half_open,
                       __global const uint* pair_triangle, __global const uint* pair_slot,
                       __global const uint* pair_first_item, __global const uint* item_pair,
                       __global const int* slot_brick, uint item_base, uint item_end,
                       int brick_size, int nx, int ny, int nz, Item* it, OvTriangle* t) {
    uint item = item_base + (uint)get_global_id(0);
    if (item >= item_end) return 0;
    uint p = item_pair[item];
    it->triangle = pair_triangle[p];
    it->slot = pair_slot[p];
    for (int k = 0; k < 3; ++k) it->brick[k] = slot_brick[3 * it->slot + k];
    *t = triangles[it->triangle];
    OvRange r = ov_triangle_range(*t, half_open);
    int blocks = ov_pair_work(r, it->brick[0], it->brick[1], it->brick[2], brick_size, nx, ny, nz,
                              &it->work);
    it->block_first = (int)(item - pair_first_item[p]) * OV_BLOCKS_PER_ITEM;
    it->block_end = min(it->block_first + OV_BLOCKS_PER_ITEM, blocks);
    return 1;
}

// The global coordinates of block b of the item's pair (x fastest), found once per item, and the
// step to the next block (an increment, not three divisions per block).
static void item_block(const Item* it, int b, int block[3]) {
    int cx = it->work.block_count[0], cy = it->work.block_count[1];
    block[0] = it->work.block_lo[0] + b % cx;
    block[1] = it->work.block_lo[1] + b / cx % cy;
    block[2] = it->work.block_lo[2] + b / (cx * cy);
}

static void next_block(const Item* it, int block[3]) {
    if (++block[0] < it->work.block_lo[0] + it->work.block_count[0]) return;
    block[0] = it->work.block_lo[0];
    if (++block[1] < it->work.block_lo[1] + it->work.block_count[1]) return;
    block[1] = it->work.block_lo[1];
    ++block[2];
}

static void store_block(__global uint* bits, const Item* it, const int block[3], int brick_size,
                        uint mask_lo, uint mask_hi) {
    int nb = brick_size / 4;
    size_t words_per_brick = 2 * (size_t)nb * nb * nb;
    size_t word = it->slot * words_per_brick +
                  2 * (size_t)ov_brick_block(block[0], block[1], block[2], it->brick[0],
                                             it->brick[1], it->brick[2], brick_size);
    if (mask_lo) atomic_or(&bits[word], mask_lo);
    if (mask_hi) atomic_or(&bits[word + 1], mask_hi);
}

// One voxelize kernel per predicate, written once: SETUP is the per-triangle struct made by
// SETUP_FN, PLANE4 its plane test of a row of 4 voxels along x and PROJECTION4 the tests of one
// of its three projections (voxel_math.h). A block's projection tests are taken first, a 4x4
// face each: the (y, z) face as 4 layers of y lanes, (z, x) as 4 layers of x lanes, (x, y) as 4
// rows of x lanes; then each row whose (y, z) test holds takes the plane test and the other two
// faces' lanes. Lanes outside the pair's voxel range are dropped.
#define OV_VOXELIZE_KERNEL(NAME, SETUP, SETUP_FN, PLANE4, PROJECTION4)                            \
    __kernel void NAME(__global const OvTriangle* triangles, int half_open,                       \
                       __global const uint* pair_triangle, __global const uint* pair_slot,        \
                       __global const uint* pair_first_item, __global const uint* item_pair,      \
                       __global const int* slot_brick, uint item_base, uint item_end,             \
                       int brick_size, int nx, int ny, int nz, __global uint* bits) {             \
        Item it;                                                                                  \
        OvTriangle t;                                                                             \
        if (!decode_item(triangles, half_open, pair_triangle, pair_slot, pair_first_item,         \
                         item_pair, slot_brick, item_base, item_end, brick_size, nx, ny, nz, &it, \
                         &t))                                                                     \
            return;                                                                               \
        SETUP s = SETUP_FN(t, half_open);                                                         \
        int block[3];                                                                             \
        item_block(&it, it.block_first, block);                                                   \
        for (int b = it.block_first; b < it.block_end; ++b, next_block(&it, block)) {             \
            /* Skip the block if it lies entirely on one side of the triangle's plane. */         \
            float block_dn = s.normal[0] * (float)(block[0] * 4 - s.anchor[0]) +                  \
                             s.normal[1] * (float)(block[1] * 4 - s.anchor[1]) +                  \
                             s.normal[2] * (float)(block[2] * 4 - s.anchor[2]);                   \
            if (block_dn < s.block_lo || block_dn > s.block_hi) continue;                         \
            int lo[3], hi[3];                                                                     \
            for (int k = 0; k < 3; ++k) {                                                         \
                lo[k] = max(it.work.voxel_lo[k], block[k] * 4);                                   \
                hi[k] = min(it.work.voxel_hi[k], block[k] * 4 + 3);                               \
            }                                                                                     \
            /* The three faces' tests of the rows in range, as 16-bit masks of 4 rows of 4        \
               lanes: yz bit y + 4z, zx bit x + 4z, xy bit x + 4y (block-local). */               \
            float4 qx = ov_row4(block[0] * 4 - s.anchor[0]);                                      \
            float4 qy = ov_row4(block[1] * 4 - s.anchor[1]);                                      \
            uint yz = 0, zx = 0, xy = 0;                                                          \
            for (int z = lo[2]; z <= hi[2]; ++z) {                                                \
                float qz = (float)(z - s.anchor[2]);                                              \
                yz |= ov_lane_bits(PROJECTION4(&s, 0, qy, (float4)(qz))) << 4 * (z & 3);          \
                zx |= ov_lane_bits(PROJECTION4(&s, 1, (float4)(qz), qx)) << 4 * (z & 3);          \
            }                                                                                     \
            for (int y = lo[1]; y <= hi[1]; ++y)                                                  \
                xy |= ov_lane_bits(PROJECTION4(&s, 2, qx, (float4)((float)(y - s.anchor[1]))))    \
                      << 4 * (y & 3);                                                             \
            int4 x = (int4)(block[0] * 4) + (int4)(0, 1, 2, 3);                                   \
            uint xs = ov_lane_bits((x >= lo[0]) & (x <= hi[0]));                                  \
            ulong mask = 0;                                                                       \
            for (int z = lo[2]; z <= hi[2]; ++z)                                                  \
                for (int y = lo[1]; y <= hi[1]; ++y) {                                            \
                    if (!((yz >> ((y & 3) + 4 * (z & 3))) & 1)) continue;                         \
                    uint lanes = (zx >> 4 * (z & 3)) & (xy >> 4 * (y & 3)) & xs & 0xFu;           \
                    if (!lanes) continue;                                                         \
                    lanes &= ov_lane_bits(                                                        \
                        PLANE4(&s, qx, (float)(y - s.anchor[1]), (float)(z - s.anchor[2])));      \
                    mask |= (ulong)lanes << ov_block_bit(0, y & 3, z & 3);                        \
                }                                                                                 \
            uint mask_lo = (uint)mask, mask_hi = (uint)(mask >> 32);                              \
            store_block(bits, &it, block, brick_size, mask_lo, mask_hi);                          \
        }                                                                                         \
    }

OV_VOXELIZE_KERNEL(voxelize_sat, OvSatTriangle, ov_setup_sat, ov_sat_plane4, ov_sat_projection4)
OV_VOXELIZE_KERNEL(voxelize_pef, OvPefTriangle, ov_setup_pef, ov_pef_plane4, ov_pef_projection4)
OV_VOXELIZE_KERNEL(voxelize_thin, OvThinTriangle, ov_setup_thin, ov_thin_plane4,
                   ov_thin_projection4)

// Sets bits [first, end) of the list: each is a bit's index among the batch's brick bits (the
// voxel of a one-voxel (triangle, brick) pair, for SAT and PEF: see ov_range_is_one_voxel).
__kernel void set_direct_bits(__global const ulong* bit_index, uint first, uint end,
                              __global uint* bits) {
    uint i = first + (uint)get_global_id(0);
    if (i >= end) return;
    ulong bit = bit_index[i];
    atomic_or(&bits[bit >> 5], 1u << (uint)(bit & 31));
}
