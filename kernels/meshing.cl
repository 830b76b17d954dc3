// Surface Nets and Marching Cubes on the device: a count kernel and an emit kernel per method,
// one work item per sample of the active bricks (item first + global id is sample l of brick
// item / brick_size^3, l in x-fastest order). Counts and offsets live in the active bricks' slots
// (OmTiling, brick_base). The per-sample work is shared with the host reference through
// meshing_math.h; the prefix sums between the two passes run on the host (see
// meshing_device.cpp).
#include "meshing_math.h"

static OmTiling om_tiling(int size, int nx, int ny, int nz) {
    OmTiling t;
    t.size = size;
    t.count[0] = (nx + size - 1) / size;
    t.count[1] = (ny + size - 1) / size;
    t.count[2] = (nz + size - 1) / size;
    return t;
}

static OmField om_field(int nx, int ny, int nz, float iso) {
    OmField f;
    f.n[0] = nx;
    f.n[1] = ny;
    f.n[2] = nz;
    f.iso = iso;
    return f;
}

// The sample of this work item; 0 for the padding of the last work group and for the parts of
// border bricks beyond the grid.
static int om_item(__global const int* bricks, int brick_size, uint first, uint count, OmField f,
                   int* x, int* y, int* z) {
    uint gid = (uint)get_global_id(0);
    if (gid >= count) return 0;
    uint item = first + gid, size = (uint)brick_size, volume = size * size * size;
    uint brick = item / volume, within = item % volume;
    *x = bricks[3 * brick + 0] + (int)(within % size);
    *y = bricks[3 * brick + 1] + (int)(within / size % size);
    *z = bricks[3 * brick + 2] + (int)(within / (size * size));
    return *x < f.n[0] && *y < f.n[1] && *z < f.n[2];
}

__kernel void sn_count(__global const float* values, int nx, int ny, int nz, float iso,
                       __global const int* bricks, int brick_size, uint first, uint count,
                       __global const uint* brick_base, __global uint* vertex_count,
                       __global uint* triangle_count) {
    OmField f = om_field(nx, ny, nz, iso);
    int x, y, z;
    if (!om_item(bricks, brick_size, first, count, f, &x, &y, &z)) return;
    uint v, t;
    om_sn_count(values, f, x, y, z, &v, &t);
    uint s = om_slot(f, om_tiling(brick_size, nx, ny, nz), brick_base, x, y, z);
    vertex_count[s] = v;
    triangle_count[s] = t;
}

__kernel void sn_emit(__global const float* values, int nx, int ny, int nz, float iso,
                      __global const int* bricks, int brick_size, uint first, uint count,
                      __global const uint* brick_base, __global const uint* vertex_offset,
                      __global const uint* triangle_offset, __global uint* vertex_sample,
                      __global float* vertex_local, __global uint* triangles) {
    OmField f = om_field(nx, ny, nz, iso);
    int x, y, z;
    if (!om_item(bricks, brick_size, first, count, f, &x, &y, &z)) return;
    om_sn_emit(values, f, x, y, z, om_tiling(brick_size, nx, ny, nz), brick_base, vertex_offset,
               triangle_offset, 0u, 0u, vertex_sample, vertex_local, triangles);
}

__kernel void mc_count(__global const float* values, __global const uchar* table, int nx, int ny,
                       int nz, float iso, __global const int* bricks, int brick_size, uint first,
                       uint count, __global const uint* brick_base, __global uint* vertex_count,
                       __global uint* triangle_count) {
    OmField f = om_field(nx, ny, nz, iso);
    int x, y, z;
    if (!om_item(bricks, brick_size, first, count, f, &x, &y, &z)) return;
    uint v, t;
    om_mc_count(values, table, f, x, y, z, &v, &t);
    uint s = om_slot(f, om_tiling(brick_size, nx, ny, nz), brick_base, x, y, z);
    vertex_count[s] = v;
    triangle_count[s] = t;
}

__kernel void mc_emit(__global const float* values, __global const uchar* table, int nx, int ny,
                      int nz, float iso, __global const int* bricks, int brick_size, uint first,
                      uint count, __global const uint* brick_base,
                      __global const uint* vertex_offset, __global const uint* triangle_offset,
                      __global uint* vertex_sample, __global float* vertex_local,
                      __global uint* triangles) {
    OmField f = om_field(nx, ny, nz, iso);
    int x, y, z;
    if (!om_item(bricks, brick_size, first, count, f, &x, &y, &z)) return;
    om_mc_emit(values, table, f, x, y, z, om_tiling(brick_size, nx, ny, nz), brick_base,
               vertex_offset, triangle_offset, 0u, 0u, vertex_sample, vertex_local, triangles);
}
