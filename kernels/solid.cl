// Solid voxelization, OpenCL C 1.2: crossing parity along voxel columns, and the generalized
// winding number.
//
// Parity works on a batch of brick columns (a brick_size^2 footprint and the whole grid height),
// each held as `words` layers of 32 voxels: word w of voxel column (x, y) of slot s is
// bits[((s * words + w) * brick_size + y) * brick_size + x], and its bit b is voxel 32 w + b of the
// column. Neighbouring columns' words are neighbours, so neighbouring work items of parity_blocks
// read neighbouring words. parity_flip: one work item per (triangle, voxel row
// of its footprint in the brick column) toggles, in each voxel column of the row it covers, the bit
// just above the crossing. parity_blocks: one work item per 4x4 voxel columns turns their flips
// into parity, word by word up the columns, and copies the bits into the bricks' block layout.
#include "solid_math.h"

__kernel void parity_flip(__global const OvParityTriangle* triangles,
                          __global const uint* pair_triangle, __global const uint* pair_slot,
                          __global const uint* pair_first_item, __global const uint* item_pair,
                          __global const int* slot_column, uint item_base, uint item_end,
                          int brick_size, int nx, int ny, int nz, uint words, __global uint* bits) {
    uint item = item_base + (uint)get_global_id(0);
    if (item >= item_end) return;
    uint p = item_pair[item];
    uint slot = pair_slot[p];
    OvParityTriangle t = triangles[pair_triangle[p]];
    int bx = slot_column[2 * slot], by = slot_column[2 * slot + 1];
    OvColumnRange r;
    ovs_column_range(&t, bx, by, brick_size, nx, ny, &r);
    int j = r.lo[1] + (int)(item - pair_first_item[p]);
    size_t layer = (size_t)brick_size * brick_size;
    size_t row = (size_t)slot * words * layer + (size_t)(j - by * brick_size) * brick_size;
    for (int i = r.lo[0]; i <= r.hi[0]; ++i) {
        int k = ovs_parity_flip(&t, i, j, nz);
        if (k < 0 || k >= nz) continue;
        size_t column = row + (size_t)(i - bx * brick_size);
        atomic_xor(&bits[column + (size_t)(k >> 5) * layer], 1u << (k & 31));
    }
}

// blocks: per slot, the bricks of the column bottom to top, each in the SparseVoxels block layout
// as two 32-bit words per block (low word first). One work item per 4x4 voxel columns walks their
// words bottom to top: each word of flips becomes parity (a prefix XOR continuing its column's
// carry), and its 32 layers, 8 block rows, are copied into the blocks. Taking the prefix on the
// way spares a pass that wrote every parity word back and one that read it again. Voxels at or
// above nz are left clear: the grid ends there even when the parity does not. Only blocks that
// hold a voxel are written (the blocks arrive zero): in the host's memory the pages of a brick
// outside the solid are then never touched, and the host knows that brick empty unread.
__kernel void parity_blocks(__global const uint* bits, uint slots, int brick_size, int brick_rows,
                            int nz, uint words, __global uint* blocks) {
    uint item = (uint)get_global_id(0);
    int nb = brick_size / 4;
    if (item >= slots * (uint)(nb * nb)) return;
    uint slot = item / (uint)(nb * nb);
    int gx = (int)(item % (uint)nb);
    int gy = (int)(item / (uint)nb % (uint)nb);
    int rows = nb * brick_rows;  // block rows over the whole column height
    size_t layer = (size_t)brick_size * brick_size;
    __global const uint* columns =
        bits + (size_t)slot * words * layer + (size_t)gy * 4 * brick_size + (size_t)gx * 4;
    // Row y's 4 columns as the lanes of carry[y]: each one's parity below the current word (0 or
    // 1). A row's 4 words are neighbours, read as one vector.
    uint4 carry[4] = {(uint4)(0u), (uint4)(0u), (uint4)(0u), (uint4)(0u)};
    // The column's bricks may reach above its last word: those block rows stay clear.
    for (int word = 0; 8 * word < rows; ++word) {
        // Layer 32 * word + 4 * r + z of column (x, y) is bit 4 * r + z of that column's word.
        int k0 = 32 * word;
        uint valid = k0 + 32 <= nz ? 0xffffffffu : k0 >= nz ? 0u : (1u << (nz - k0)) - 1u;
        uint4 flips[4];
        uint crossed = 0;
        for (int y = 0; y < 4; ++y) {
            flips[y] = valid ? vload4(0, columns + (size_t)word * layer + (size_t)y * brick_size)
                             : (uint4)(0u);
            crossed |= flips[y].s0 | flips[y].s1 | flips[y].s2 | flips[y].s3;
        }
        uint column_bits[16];
        if (!crossed) {
            // No crossing in these 32 layers (most words of a solid: outside it or inside it): each
            // column's parity is its carry throughout, so layer k of the transpose below is the
            // 16 columns' carries wherever k is in the grid, and nothing needs transposing.
            uint carries = 0;  // bit x + 4y: column (x, y)'s
            for (int y = 0; y < 4; ++y)
                carries |= (carry[y].s0 | carry[y].s1 << 1 | carry[y].s2 << 2 | carry[y].s3 << 3)
                           << 4 * y;
            if (!carries) continue;  // no voxel: the blocks stay clear
            for (int k = 0; k < 16; ++k)
                column_bits[k] = (valid >> k & 1u ? carries : 0u) |
                                 (valid >> (16 + k) & 1u ? carries << 16 : 0u);
        } else {
            for (int y = 0; y < 4; ++y) {
                uint4 parity = ovs_prefix_xor4(flips[y], carry[y]);
                carry[y] = parity >> 31;
                parity &= (uint4)(valid);
                column_bits[4 * y] = parity.s0;
                column_bits[4 * y + 1] = parity.s1;
                column_bits[4 * y + 2] = parity.s2;
                column_bits[4 * y + 3] = parity.s3;
            }
            // Transpose the 16 x 32 bit matrix (column c, layer k) in place, as two 16 x 16
            // halves side by side in each word: afterwards bits 0-15 of column_bits[k] are layer
            // k's 16 columns and bits 16-31 are layer 16 + k's. Each step swaps the off-diagonal
            // j x j blocks of every 2j x 2j block (Hacker's Delight, "transposing a bit matrix"),
            // the masks repeated in both halves.
            const uint masks[4] = {0x00ff00ffu, 0x0f0f0f0fu, 0x33333333u, 0x55555555u};
#pragma unroll
            for (int s = 0; s < 4; ++s) {
                int j = 8 >> s;
#pragma unroll
                for (int i = 0; i < 8; ++i) {
                    int a = (i & ~(j - 1)) << 1 | (i & (j - 1));  // the i-th row with bit j clear
                    uint t = (column_bits[a] >> j ^ column_bits[a + j]) & masks[s];
                    column_bits[a + j] ^= t;
                    column_bits[a] ^= t << j;
                }
            }
        }
        for (int r = 0; r < 8 && 8 * word + r < rows; ++r) {
            // Layers 4r .. 4r + 3 are bits z = 0 .. 3 of the block's rows: bit x + 4y + 16z.
            int shift = r < 4 ? 0 : 16;
            int k = 4 * r - shift;
            uint low = (column_bits[k] >> shift & 0xffffu) | (column_bits[k + 1] >> shift) << 16;
            uint high = (column_bits[k + 2] >> shift & 0xffffu) | (column_bits[k + 3] >> shift)
                                                                      << 16;
            // Block (gx, gy, gz) is block (gx, gy, gz % nb) of brick gz / nb in the column.
            int gz = 8 * word + r;
            size_t brick = (size_t)slot * brick_rows + (size_t)(gz / nb);
            size_t block = (size_t)(gx + nb * (gy + nb * (gz % nb)));
            if (low | high) {
                blocks[2 * (brick * nb * nb * nb + block)] = low;
                blocks[2 * (brick * nb * nb * nb + block) + 1] = high;
            }
        }
    }
}

// Generalized winding number w at points (x, y, z in voxel units relative to the grid origin),
// and the bound on its expansions' error: ovs_winding_at (solid_math.h) at each.
__kernel void winding_points(__global const float* vertices, __global const OvWindingNode* nodes,
                             uint node_count, __global const float* points, uint item_base,
                             uint item_end, float far_ratio, float node_tolerance,
                             __global float* w, __global float* error) {
    uint item = item_base + (uint)get_global_id(0);
    if (item >= item_end) return;
    float item_error;
    w[item] = ovs_winding_at(vertices, nodes, node_count, vload3(item, points), far_ratio,
                             node_tolerance, &item_error);
    error[item] = item_error;
}
