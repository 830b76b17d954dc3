// Compact downloads of brick bits, OpenCL C 1.2: a batch's bricks are arrays of 4x4x4 blocks, each
// two 32-bit words (low word first), and most blocks of a surface's bricks are empty. So a device
// with its own memory sends back only the non-empty ones: block_counts counts them per group of 64
// blocks, the host turns the counts into offsets, and compact_blocks writes each group's non-empty
// blocks, in block order, from its offset: the block's index in the batch and its two words.
//
// One work group of 64 items per group of 64 blocks, an item per block (first_block + its global
// id; slices start at multiples of 64): neighbouring items read neighbouring words.
#define OV_GROUP_BLOCKS 64

static int block_set(__global const uint* bits, uint block, uint block_count) {
    return block < block_count && (bits[2 * (size_t)block] | bits[2 * (size_t)block + 1]) != 0u;
}

__kernel __attribute__((reqd_work_group_size(OV_GROUP_BLOCKS, 1, 1))) void block_counts(
    __global const uint* bits, uint block_count, uint first_block, __global uint* counts) {
    __local uint count;
    uint block = first_block + (uint)get_global_id(0);
    if (get_local_id(0) == 0) count = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (block_set(bits, block, block_count)) atomic_inc(&count);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0) counts[block / OV_GROUP_BLOCKS] = count;
}

__kernel __attribute__((reqd_work_group_size(OV_GROUP_BLOCKS, 1, 1))) void compact_blocks(
    __global const uint* bits, uint block_count, uint first_block, __global const uint* offsets,
    __global uint* indices, __global uint* words) {
    // Each item's place among its group's non-empty blocks: an exclusive prefix sum of the set
    // flags in local memory (Hillis-Steele, log2(64) steps).
    __local uint flags[OV_GROUP_BLOCKS];
    uint block = first_block + (uint)get_global_id(0);
    uint lid = (uint)get_local_id(0);
    int set = block_set(bits, block, block_count);
    flags[lid] = set ? 1u : 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint step = 1; step < OV_GROUP_BLOCKS; step <<= 1) {
        uint add = lid >= step ? flags[lid - step] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        flags[lid] += add;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (!set) return;
    uint at = offsets[block / OV_GROUP_BLOCKS] + flags[lid] - 1u;  // inclusive sum, less this block
    indices[at] = block;
    words[2 * (size_t)at] = bits[2 * (size_t)block];
    words[2 * (size_t)at + 1] = bits[2 * (size_t)block + 1];
}
