// Solid voxelization, OpenCL C 1.2: crossing parity along voxel columns, and the generalized
// winding number.
//
// Parity works on a batch of brick columns (a brick_size^2 footprint and the whole grid height),
// each held as one bit column of `words` 32-bit words per voxel column (bit k of the column is
// voxel k). parity_flip: one work item per (triangle, voxel column) toggles the bit just above
// the crossing. parity_prefix: one work item per voxel column turns flips into parity. parity_pack:
// one work item per 4x4 voxel columns and 32 layers copies the bits into the bricks' block layout.
#include "solid_math.h"
#include "work_items.h"

__kernel void parity_flip(__global const OvParityTriangle* triangles,
                          __global const uint* pair_triangle, __global const uint* pair_slot,
                          __global const uint* pair_first_item, uint pair_count,
                          __global const int* slot_column, uint item_base, uint item_end,
                          int brick_size, int nx, int ny, int nz, uint words, __global uint* bits) {
    uint item = item_base + (uint)get_global_id(0);
    if (item >= item_end) return;
    uint p = find_pair(pair_first_item, pair_count, item);
    uint slot = pair_slot[p];
    OvParityTriangle t = triangles[pair_triangle[p]];
    int bx = slot_column[2 * slot], by = slot_column[2 * slot + 1];
    OvColumnRange r;
    ovs_column_range(&t, bx, by, brick_size, nx, ny, &r);
    uint index = item - pair_first_item[p];
    uint width = (uint)(r.hi[0] - r.lo[0] + 1);
    int i = r.lo[0] + (int)(index % width);
    int j = r.lo[1] + (int)(index / width);
    int k = ovs_parity_flip(&t, i, j, nz);
    if (k < 0 || k >= nz) return;
    size_t column = ((size_t)slot * brick_size + (size_t)(j - by * brick_size)) * brick_size +
                    (size_t)(i - bx * brick_size);
    atomic_xor(&bits[column * words + (size_t)(k >> 5)], 1u << (k & 31));
}

__kernel void parity_prefix(__global uint* bits, uint columns, uint words) {
    uint column = (uint)get_global_id(0);
    if (column >= columns) return;
    __global uint* w = bits + (size_t)column * words;
    uint carry = 0;
    for (uint i = 0; i < words; ++i) {
        uint v = ovs_prefix_xor(w[i], carry);
        w[i] = v;
        carry = v >> 31;
    }
}

// blocks: per slot, the bricks of the column bottom to top, each in the SparseVoxels block layout
// as two 32-bit words per block (low word first). Voxels at or above nz are left clear: the grid
// ends there even when the parity does not. One work item per 4x4 columns and 8 block rows: the
// rows' 32 layers are one word of each of its 16 voxel columns, read once.
__kernel void parity_pack(__global const uint* bits, uint slots, int brick_size, int brick_rows,
                          int nz, uint words, __global uint* blocks) {
    uint item = (uint)get_global_id(0);
    int nb = brick_size / 4;
    int rows = nb * brick_rows;  // block rows over the whole column height
    uint per_slot = (uint)(nb * nb * ((rows + 7) / 8));
    if (item >= slots * per_slot) return;
    uint slot = item / per_slot;
    uint in_slot = item % per_slot;
    int gx = (int)(in_slot % (uint)nb);
    int gy = (int)(in_slot / (uint)nb % (uint)nb);
    int word = (int)(in_slot / (uint)(nb * nb));
    // Layer 32 * word + 4 * r + z of column (x, y) is bit 4 * r + z of that column's word; above
    // nz it is cut (and the column has no word there).
    int k0 = 32 * word;
    uint valid = k0 + 32 <= nz ? 0xffffffffu : k0 >= nz ? 0u : (1u << (nz - k0)) - 1u;
    uint column_bits[16];
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) {
            size_t column = ((size_t)slot * brick_size + (size_t)(gy * 4 + y)) * brick_size +
                            (size_t)(gx * 4 + x);
            column_bits[x + 4 * y] = valid ? bits[column * words + (size_t)word] & valid : 0u;
        }
    for (int r = 0; r < 8 && 8 * word + r < rows; ++r) {
        // Bit z of each column's nibble goes to bit x + 4y + 16z of the block.
        ulong mask = 0;
        for (int c = 0; c < 16; ++c) {
            uint nibble = column_bits[c] >> (4 * r) & 15u;
            ulong spread = (ulong)(nibble & 1u) | (ulong)(nibble >> 1 & 1u) << 16 |
                           (ulong)(nibble >> 2 & 1u) << 32 | (ulong)(nibble >> 3 & 1u) << 48;
            mask |= spread << c;
        }
        // Block (gx, gy, gz) is block (gx, gy, gz % nb) of brick gz / nb in the column.
        int gz = 8 * word + r;
        size_t brick = (size_t)slot * brick_rows + (size_t)(gz / nb);
        size_t block = (size_t)(gx + nb * (gy + nb * (gz % nb)));
        blocks[2 * (brick * nb * nb * nb + block)] = (uint)mask;
        blocks[2 * (brick * nb * nb * nb + block) + 1] = (uint)(mask >> 32);
    }
}

// Signed solid angle of triangle (a, b, c) seen from the origin (Van Oosterom & Strackee 1983):
// tan(omega / 2) = det[a b c] / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|). Positive when the
// origin lies behind the triangle (opposite its normal (b - a) x (c - a)), so a closed,
// outward-facing mesh sums to 4 pi inside.
static float solid_angle(float3 a, float3 b, float3 c) {
    float det = dot(a, cross(b, c));
    float la = length(a), lb = length(b), lc = length(c);
    float den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    return 2.0f * ovs_atan2(det, den);
}

// Generalized winding number w at points (x, y, z in voxel units relative to the grid origin),
// walking the winding tree: subtrees farther than far_ratio radii count as their second-order
// expansion (solid_math.h), near leaves triangle by triangle (vertices in leaf order). Writes w
// and a bound on the error of the expansions (not counting float rounding); far_ratio = INFINITY
// sums every triangle exactly.
__kernel void winding_points(__global const float* vertices, __global const OvWindingNode* nodes,
                             uint node_count, __global const float* points, uint item_base,
                             uint item_end, float far_ratio, float node_tolerance,
                             __global float* w, __global float* error) {
    uint item = item_base + (uint)get_global_id(0);
    if (item >= item_end) return;
    float3 p = vload3(item, points);
    float sum = 0.0f, bound = 0.0f;
    for (uint i = 0; i < node_count;) {
        __global const OvWindingNode* n = nodes + i;
        float3 d = (float3)(n->centre[0], n->centre[1], n->centre[2]) - p;
        float dist2 = dot(d, d);
        float reach = far_ratio * n->radius;
        float gap = sqrt(dist2) - n->radius;
        float node_bound = 3.0f * n->abs_area * n->radius * n->radius / (gap * gap * gap * gap);
        if (dist2 > reach * reach && gap > 0.0f && node_bound <= node_tolerance) {
            float3 an = (float3)(n->area_normal[0], n->area_normal[1], n->area_normal[2]);
            float3 md = (float3)(n->moment[0] * d.x + n->moment[1] * d.y + n->moment[2] * d.z,
                                 n->moment[3] * d.x + n->moment[4] * d.y + n->moment[5] * d.z,
                                 n->moment[6] * d.x + n->moment[7] * d.y + n->moment[8] * d.z);
            float trace = n->moment[0] + n->moment[4] + n->moment[8];
            float dist = sqrt(dist2);
            float inv3 = 1.0f / (dist2 * dist);
            sum += (dot(an, d) + trace) * inv3 - 3.0f * dot(d, md) * inv3 / dist2;
            bound += node_bound;
            i = n->skip;
        } else if (n->count) {
            for (uint t = n->first; t < n->first + n->count; ++t) {
                __global const float* v = vertices + 9 * (size_t)t;
                float3 a = (float3)(v[0], v[1], v[2]) - p;
                float3 b = (float3)(v[3], v[4], v[5]) - p;
                float3 c = (float3)(v[6], v[7], v[8]) - p;
                sum += solid_angle(a, b, c);
            }
            i = n->skip;
        } else {
            ++i;
        }
    }
    w[item] = sum / (4.0f * M_PI_F);
    error[item] = bound / (4.0f * M_PI_F);
}
