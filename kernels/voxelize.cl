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
// For SAT and PEF a triangle whose range is a row of voxels sets them untested
// (ov_range_is_row): the host sends those rows to set_direct_bits instead, a work item each that
// decodes no pair and reads no triangle.
#include "voxel_math.h"

// CPU devices whose compiler is clang (PoCL, Intel's) prefetch triangles (decode_item) with
// clang's builtin: their OpenCL prefetch() does nothing.
#if defined(OV_WIDE_BLOCKS) && defined(__has_builtin)
#if __has_builtin(__builtin_prefetch)
#define OV_PREFETCH_TRIANGLES
#endif
#endif

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
#ifdef OV_PREFETCH_TRIANGLES
    // A brick's triangles lie scattered through the triangle array, so on a CPU each item's first
    // read of its triangle waited for memory (a fifth of the kernel's time through PoCL). The
    // triangle of the item 8 places on (both cache lines it may span) is asked for now, to be in
    // the cache when that item starts.
    if (item + 8 < item_end) {
        __global const char* ahead =
            (__global const char*)(triangles + pair_triangle[item_pair[item + 8]]);
        __builtin_prefetch(ahead);
        __builtin_prefetch(ahead + sizeof(OvTriangle) - 1);
    }
#endif
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

// Bits 4y .. 4y + 3 set for each bit y of a 4-bit mask: a column's 4 lanes to its row of a 4x4
// face (bit x + 4y).
static uint ov_spread_nibbles(uint b) {
    return (b & 1u) * 0xFu | (b & 2u) * 0x78u | (b & 4u) * 0x3C0u | (b & 8u) * 0x1E00u;
}

// One voxelize kernel per predicate P (sat, pef, thin), written once: SETUP is the per-triangle
// struct made by ov_setup_P, and ov_P_plane4 / ov_P_projection4 (and their 16-lane forms) its
// plane test and the tests of one of its three projections (voxel_math.h). A block's mask comes
// from ov_P_block4 or, on devices built with OV_WIDE_BLOCKS (CPUs), ov_P_block16: the same tests
// of the same voxels, so the same bits either way.
//
// ov_P_block4 takes a block's projection tests first, a 4x4 face each: the (y, z) face as 4
// layers of y lanes, (z, x) as 4 layers of x lanes, (x, y) as 4 rows of x lanes; then each row
// whose (y, z) test holds takes the plane test and the other two faces' lanes. Lanes outside the
// pair's voxel range are dropped.
//
// ov_P_block16 takes each face's 16 lanes at once and the plane test a layer of 16 lanes at a
// time, the voxel range applied to the lane masks: a CPU's vector unit does 16 lanes about as
// fast as 4, and the block's work no longer branches row by row.
#define OV_BLOCK_MASKS(P, SETUP)                                                                   \
    static ulong ov_##P##_block4(const SETUP* s, const int block[3], const int lo[3],              \
                                 const int hi[3]) {                                                \
        /* The three faces' tests of the rows in range, as 16-bit masks of 4 rows of 4 lanes:      \
           yz bit y + 4z, zx bit x + 4z, xy bit x + 4y (block-local). */                           \
        float4 qx = ov_row4(block[0] * 4 - s->anchor[0]);                                          \
        float4 qy = ov_row4(block[1] * 4 - s->anchor[1]);                                          \
        uint yz = 0, zx = 0, xy = 0;                                                               \
        for (int z = lo[2]; z <= hi[2]; ++z) {                                                     \
            float qz = (float)(z - s->anchor[2]);                                                  \
            yz |= ov_lane_bits(ov_##P##_projection4(s, 0, qy, (float4)(qz))) << 4 * (z & 3);       \
            zx |= ov_lane_bits(ov_##P##_projection4(s, 1, (float4)(qz), qx)) << 4 * (z & 3);       \
        }                                                                                          \
        for (int y = lo[1]; y <= hi[1]; ++y)                                                       \
            xy |=                                                                                  \
                ov_lane_bits(ov_##P##_projection4(s, 2, qx, (float4)((float)(y - s->anchor[1]))))  \
                << 4 * (y & 3);                                                                    \
        int4 x = (int4)(block[0] * 4) + (int4)(0, 1, 2, 3);                                        \
        uint xs = ov_lane_bits((x >= lo[0]) & (x <= hi[0]));                                       \
        ulong mask = 0;                                                                            \
        for (int z = lo[2]; z <= hi[2]; ++z)                                                       \
            for (int y = lo[1]; y <= hi[1]; ++y) {                                                 \
                if (!((yz >> ((y & 3) + 4 * (z & 3))) & 1)) continue;                              \
                uint lanes = (zx >> 4 * (z & 3)) & (xy >> 4 * (y & 3)) & xs & 0xFu;                \
                if (!lanes) continue;                                                              \
                lanes &= ov_lane_bits(                                                             \
                    ov_##P##_plane4(s, qx, (float)(y - s->anchor[1]), (float)(z - s->anchor[2]))); \
                mask |= (ulong)lanes << ov_block_bit(0, y & 3, z & 3);                             \
            }                                                                                      \
        return mask;                                                                               \
    }                                                                                              \
    static ulong ov_##P##_block16(const SETUP* s, const int block[3], const int lo[3],             \
                                  const int hi[3]) {                                               \
        /* Lane i of a face or layer is (i % 4, i / 4) in its two axes. */                         \
        const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);          \
        const int16 low = lane & 3, high = lane >> 2;                                              \
        const float16 x_low = convert_float16((int16)(block[0] * 4 - s->anchor[0]) + low);         \
        const float16 y_low = convert_float16((int16)(block[1] * 4 - s->anchor[1]) + low);         \
        const float16 y_high = convert_float16((int16)(block[1] * 4 - s->anchor[1]) + high);       \
        const float16 z_high = convert_float16((int16)(block[2] * 4 - s->anchor[2]) + high);       \
        uint yz = ov_lane_bits16(ov_##P##_projection16(s, 0, y_low, z_high)); /* y + 4z */         \
        uint zx = ov_lane_bits16(ov_##P##_projection16(s, 1, z_high, x_low)); /* x + 4z */         \
        uint xy = ov_lane_bits16(ov_##P##_projection16(s, 2, x_low, y_high)); /* x + 4y */         \
        int4 x = (int4)(block[0] * 4) + (int4)(0, 1, 2, 3);                                        \
        int4 y = (int4)(block[1] * 4) + (int4)(0, 1, 2, 3);                                        \
        uint in_range = xy & ov_lane_bits((x >= lo[0]) & (x <= hi[0])) * 0x1111u &                 \
                        ov_spread_nibbles(ov_lane_bits((y >= lo[1]) & (y <= hi[1])));              \
        ulong mask = 0;                                                                            \
        for (int z = lo[2]; z <= hi[2]; ++z) {                                                     \
            uint layer = in_range & ov_spread_nibbles(yz >> 4 * (z & 3) & 0xFu) &                  \
                         (zx >> 4 * (z & 3) & 0xFu) * 0x1111u;                                     \
            if (!layer) continue;                                                                  \
            layer &=                                                                               \
                ov_lane_bits16(ov_##P##_plane16(s, x_low, y_high, (float)(z - s->anchor[2])));     \
            mask |= (ulong)layer << 16 * (z & 3);                                                  \
        }                                                                                          \
        return mask;                                                                               \
    }

#ifdef OV_WIDE_BLOCKS
#define OV_BLOCK_MASK(P) ov_##P##_block16
#else
#define OV_BLOCK_MASK(P) ov_##P##_block4
#endif

#define OV_VOXELIZE_KERNEL(NAME, P, SETUP)                                                        \
    OV_BLOCK_MASKS(P, SETUP)                                                                      \
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
        SETUP s = ov_setup_##P(t, half_open);                                                     \
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
            ulong mask = OV_BLOCK_MASK(P)(&s, block, lo, hi);                                     \
            store_block(bits, &it, block, brick_size, (uint)mask, (uint)(mask >> 32));            \
        }                                                                                         \
    }

OV_VOXELIZE_KERNEL(voxelize_sat, sat, OvSatTriangle)
OV_VOXELIZE_KERNEL(voxelize_pef, pef, OvPefTriangle)
OV_VOXELIZE_KERNEL(voxelize_thin, thin, OvThinTriangle)

// Sets the voxels of entries [first, end) of the list: each a row of a direct pair (the voxels
// of a (triangle, brick) pair whose range is a row, for SAT and PEF: see ov_range_is_row), as
// ov_direct_row encodes it. Along the row a voxel's bit moves on by 1, 4 or 16 (x, y, z) within
// its 4x4x4 block, and to the next block's (1, nb or nb^2 blocks on: x fastest in the brick) at
// the block's face.
__kernel void set_direct_bits(__global const ulong* rows, uint first, uint end, int brick_size,
                              __global uint* bits) {
    uint i = first + (uint)get_global_id(0);
    if (i >= end) return;
    ulong row = rows[i];
    ulong bit = row & (((ulong)1 << OV_ROW_FIRST_BITS) - 1);
    int axis = (int)(row >> OV_ROW_FIRST_BITS) & 3;
    int length = (int)(row >> (OV_ROW_FIRST_BITS + 2)) + 1;
    int nb = brick_size / 4;
    ulong step = axis == 0 ? 1 : axis == 1 ? 4 : 16;
    ulong block_step = 64 * (ulong)(axis == 0 ? 1 : axis == 1 ? nb : nb * nb);
    int in_block = (int)(bit >> (2 * axis)) & 3;  // the voxel's coordinate in its block
    for (int v = 0; v < length; ++v) {
        atomic_or(&bits[bit >> 5], 1u << (uint)(bit & 31));
        if (in_block == 3) {
            bit += block_step - 3 * step;
            in_block = 0;
        } else {
            bit += step;
            ++in_block;
        }
    }
}
