// Solid voxelization: choosing the inside test, crossing parity in brick columns, and the
// generalized winding number, each on the device and as a host reference.
//
// Parity phases: snap every vertex to fixed point (solid_math.h); bin triangles into the brick
// columns (brick_size^2 footprints over the whole grid height) their xy boxes reach; then per
// batch of brick columns that fits the device budget: flip one bit per (triangle, covered voxel
// column), prefix-XOR every voxel column, pack the bits into bricks and merge the non-empty ones.
// A voxel column never crosses a batch, so the result cannot depend on the brick size.
//
// Winding phases: a bounding-ball tree over the triangles (Barill et al. 2018, first order: far
// subtrees as dipoles); then per batch of bricks inside the mesh's bounding box, one work item per
// voxel walks it. The host reference sums every triangle exactly, in double.
#include "solid.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "opencl_runtime.hpp"
#include "solid_math.h"

namespace oclvox::detail {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr uint64_t kMaxItemsPerBatch = uint64_t(1) << 31;
constexpr uint64_t kItemsPerLaunch = uint64_t(1) << 22;
// A winding item walks the whole tree, so its launches are kept short.
constexpr uint64_t kWindingItemsPerLaunch = uint64_t(1) << 14;
// The host reference winding number refuses more triangle evaluations than this.
constexpr uint64_t kMaxReferenceWindingTerms = uint64_t(1) << 34;

std::string mib(uint64_t bytes) {
    return std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB";
}

// ---- choosing the inside test ----

// Vertices snapped to fixed-point grid units, or false if a vertex lies too far outside the grid
// for the exact integer arithmetic of solid_math.h.
bool parity_triangles(const Mesh& mesh, const Grid& grid, std::vector<OvParityTriangle>& out) {
    const double limit = double(OVS_MAX_UNITS) / OVS_UNITS;
    const double inv = 1.0 / grid.voxel_size;
    out.resize(mesh.triangles.size());
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
        for (int v = 0; v < 3; ++v)
            for (int k = 0; k < 3; ++k) {
                const double g = (mesh.positions[mesh.triangles[t][v]][k] - grid.origin[k]) * inv;
                if (!(std::fabs(g) < limit)) return false;
                out[t].v[3 * v + k] = std::llround(g * OVS_UNITS);
            }
    return true;
}

struct Choice {
    InsideTest test;
    std::string reason;
};

Choice choose_inside_test(const Mesh& mesh, InsideTest requested, bool parity_fits) {
    const std::string too_far = "the mesh reaches more than " +
                                std::to_string(OVS_MAX_UNITS / OVS_UNITS) +
                                " voxels from the grid origin, beyond exact parity arithmetic";
    if (requested == InsideTest::Parity) {
        if (!parity_fits) throw GridError("parity inside test impossible: " + too_far);
        return {InsideTest::Parity, "forced by options"};
    }
    if (requested == InsideTest::Winding) return {InsideTest::Winding, "forced by options"};
    const MeshEdgeReport edges = mesh_edge_report(mesh);
    if (edges.boundary)
        return {InsideTest::Winding,
                "mesh has " + std::to_string(edges.boundary) + " boundary edges"};
    if (edges.non_manifold)
        return {InsideTest::Winding,
                "mesh has " + std::to_string(edges.non_manifold) + " non-manifold edges"};
    if (edges.misoriented)
        return {InsideTest::Winding, "mesh has " + std::to_string(edges.misoriented) +
                                         " edges between inconsistently oriented triangles"};
    if (!parity_fits) return {InsideTest::Winding, too_far};
    return {InsideTest::Parity, "mesh is closed"};
}

// ---- parity: binning and batches ----

struct Layout {
    int brick;              // brick edge in voxels
    int nx, ny, nz;         // grid
    int64_t nbx, nby, nbz;  // bricks per axis
    uint32_t words;         // 32-bit words per voxel column
    size_t blocks_per_brick;
    uint64_t slot_bytes() const {
        return uint64_t(brick) * brick * words * 4 + uint64_t(nbz) * blocks_per_brick * 8;
    }
};

Layout make_layout(const SparseVoxels& result) {
    const Grid& g = result.grid();
    const auto nb = result.brick_dims();
    return {result.brick_size(),
            int(g.dims[0]),
            int(g.dims[1]),
            int(g.dims[2]),
            nb[0],
            nb[1],
            nb[2],
            uint32_t((g.dims[2] + 31) / 32),
            result.blocks_per_brick()};
}

// Triangles by brick column (index bx + nbx * by), only those that can flip a grid voxel.
struct ColumnBins {
    std::vector<uint64_t> columns;     // brick columns with at least one triangle, ascending
    std::vector<uint64_t> first_pair;  // per column, into pair_triangle; one extra at the end
    std::vector<uint32_t> pair_triangle;
};

ColumnBins bin_columns(const std::vector<OvParityTriangle>& triangles, const Layout& l) {
    // A crossing at or above the centre of the top voxel flips nothing in the grid.
    const int64_t top_centre = int64_t(l.nz - 1) * OVS_UNITS + OVS_UNITS / 2;
    std::vector<std::pair<uint64_t, uint32_t>> pairs;
    for (size_t t = 0; t < triangles.size(); ++t) {
        const OvParityTriangle& tri = triangles[t];
        if (std::min({tri.v[2], tri.v[5], tri.v[8]}) >= top_centre) continue;
        OvColumnRange r;
        if (!ovs_column_range(&tri, 0, 0, std::max(l.nx, l.ny), l.nx, l.ny, &r)) continue;
        for (int by = r.lo[1] / l.brick; by <= r.hi[1] / l.brick; ++by)
            for (int bx = r.lo[0] / l.brick; bx <= r.hi[0] / l.brick; ++bx)
                pairs.push_back({uint64_t(bx) + uint64_t(l.nbx) * uint64_t(by), uint32_t(t)});
    }
    std::sort(pairs.begin(), pairs.end());
    ColumnBins bins;
    for (size_t p = 0; p < pairs.size(); ++p) {
        if (p == 0 || pairs[p].first != pairs[p - 1].first) {
            bins.columns.push_back(pairs[p].first);
            bins.first_pair.push_back(p);
        }
        bins.pair_triangle.push_back(pairs[p].second);
    }
    bins.first_pair.push_back(pairs.size());
    return bins;
}

struct Batch {
    size_t first_column = 0, column_count = 0;
    std::vector<cl_uint> pair_triangle, pair_slot, pair_first_item;
    std::vector<cl_int> slot_column;
    uint64_t items = 0;
};

// Brick columns [first, ...) into one batch, limited by slots and work items.
Batch make_batch(const ColumnBins& bins, const std::vector<OvParityTriangle>& triangles,
                 const Layout& l, size_t first, size_t max_slots) {
    Batch batch;
    batch.first_column = first;
    std::vector<cl_uint> counts;
    for (size_t c = first; c < bins.columns.size() && batch.column_count < max_slots; ++c) {
        const int bx = int(bins.columns[c] % uint64_t(l.nbx));
        const int by = int(bins.columns[c] / uint64_t(l.nbx));
        uint64_t column_items = 0;
        counts.clear();
        for (uint64_t p = bins.first_pair[c]; p < bins.first_pair[c + 1]; ++p) {
            OvColumnRange r;
            counts.push_back(cl_uint(ovs_column_range(&triangles[bins.pair_triangle[p]], bx, by,
                                                      l.brick, l.nx, l.ny, &r)));
            column_items += counts.back();
        }
        if (batch.items + column_items > kMaxItemsPerBatch) {
            if (batch.column_count == 0)
                throw GridError("brick column " + std::to_string(bins.columns[c]) + " needs " +
                                std::to_string(column_items) +
                                " work items, more than one batch can hold: use smaller bricks");
            break;
        }
        const cl_uint slot = cl_uint(batch.column_count++);
        batch.slot_column.push_back(bx);
        batch.slot_column.push_back(by);
        for (size_t i = 0; i < counts.size(); ++i) {
            batch.pair_triangle.push_back(bins.pair_triangle[bins.first_pair[c] + i]);
            batch.pair_slot.push_back(slot);
            batch.pair_first_item.push_back(cl_uint(batch.items));
            batch.items += counts[i];
        }
    }
    return batch;
}

// Merges the bricks of one packed brick column (bricks bottom to top, blocks as 64-bit words).
void merge_column(SparseVoxels& result, const Layout& l, uint64_t column, const uint64_t* blocks) {
    for (int64_t row = 0; row < l.nbz; ++row)
        result.merge_brick(column + uint64_t(l.nbx) * uint64_t(l.nby) * uint64_t(row),
                           blocks + size_t(row) * l.blocks_per_brick);
}

// ---- device helpers ----

uint64_t device_budget(const Device::Impl& cl, const VoxelizeOptions& options) {
    return std::min<uint64_t>(
        {options.device_budget_bytes, cl.info.max_alloc, cl.info.global_memory / 2});
}

void report_progress(const VoxelizeOptions& options, uint64_t done, uint64_t total) {
    if (options.progress && !options.progress(done, total))
        throw Cancelled("solid voxelization cancelled after " + std::to_string(done) + " of " +
                        std::to_string(total) + " bricks");
}

// ---- parity ----

void parity_device(Device::Impl& cl, const std::vector<OvParityTriangle>& triangles,
                   SparseVoxels& result, const VoxelizeOptions& options, VoxelizeStats& stats) {
    auto t = Clock::now();
    const Layout l = make_layout(result);
    const ColumnBins bins = bin_columns(triangles, l);
    stats.brick_pairs = bins.pair_triangle.size();
    stats.bricks_active = bins.columns.size() * uint64_t(l.nbz);
    stats.seconds_binning += seconds_since(t);
    if (bins.columns.empty()) return;

    const uint64_t budget = device_budget(cl, options);
    if (l.slot_bytes() > budget)
        throw GridError("one brick column of " + std::to_string(l.brick) + "^2 x " +
                        std::to_string(l.nz) + " voxels needs " + mib(l.slot_bytes()) +
                        " for parity, over the device budget of " + mib(budget) +
                        ": use smaller bricks");
    const size_t max_slots =
        size_t(std::min<uint64_t>(budget / l.slot_bytes(), bins.columns.size()));
    const size_t column_words = size_t(l.brick) * l.brick * l.words;
    const size_t block_words = 2 * size_t(l.nbz) * l.blocks_per_brick;

    const cl::Program& program = cl.program(kKernel_solid);
    t = Clock::now();
    const cl::Buffer tri_buffer = upload(cl.context, cl.queue, triangles);
    cl::Buffer bits(cl.context, CL_MEM_READ_WRITE, max_slots * column_words * sizeof(cl_uint));
    cl::Buffer blocks(cl.context, CL_MEM_READ_WRITE, max_slots * block_words * sizeof(cl_uint));
    cl.queue.finish();
    stats.seconds_upload += seconds_since(t);

    cl::Kernel flip(program, "parity_flip"), prefix(program, "parity_prefix"),
        pack(program, "parity_pack");
    const size_t flip_group = work_group_size(flip, cl.device);
    const size_t prefix_group = work_group_size(prefix, cl.device);
    const size_t pack_group = work_group_size(pack, cl.device);
    std::vector<cl_uint> host_words;
    std::vector<uint64_t> host_blocks(block_words / 2);

    for (size_t done = 0; done < bins.columns.size();) {
        t = Clock::now();
        Batch batch = make_batch(bins, triangles, l, done, max_slots);
        const cl_uint pair_count = cl_uint(batch.pair_triangle.size());
        const cl::Buffer pair_triangle = upload(cl.context, cl.queue, batch.pair_triangle);
        const cl::Buffer pair_slot = upload(cl.context, cl.queue, batch.pair_slot);
        const cl::Buffer pair_first = upload(cl.context, cl.queue, batch.pair_first_item);
        const cl::Buffer slot_column = upload(cl.context, cl.queue, batch.slot_column);
        cl.queue.enqueueFillBuffer(bits, cl_uint(0), 0,
                                   batch.column_count * column_words * sizeof(cl_uint));
        cl.queue.finish();
        stats.seconds_upload += seconds_since(t);

        // Flips, then parity per voxel column, then the brick layout.
        t = Clock::now();
        flip.setArg(0, tri_buffer);
        flip.setArg(1, pair_triangle);
        flip.setArg(2, pair_slot);
        flip.setArg(3, pair_first);
        flip.setArg(4, pair_count);
        flip.setArg(5, slot_column);
        flip.setArg(7, cl_uint(batch.items));
        flip.setArg(8, cl_int(l.brick));
        flip.setArg(9, cl_int(l.nx));
        flip.setArg(10, cl_int(l.ny));
        flip.setArg(11, cl_int(l.nz));
        flip.setArg(12, cl_uint(l.words));
        flip.setArg(13, bits);
        for (uint64_t base = 0; base < batch.items; base += kItemsPerLaunch) {
            flip.setArg(6, cl_uint(base));
            launch(cl.queue, flip, std::min(kItemsPerLaunch, batch.items - base), flip_group);
        }
        const uint64_t columns = uint64_t(batch.column_count) * l.brick * l.brick;
        prefix.setArg(0, bits);
        prefix.setArg(1, cl_uint(columns));
        prefix.setArg(2, cl_uint(l.words));
        launch(cl.queue, prefix, columns, prefix_group);
        const uint64_t pack_items = uint64_t(batch.column_count) * l.nbz * l.blocks_per_brick;
        pack.setArg(0, bits);
        pack.setArg(1, cl_uint(batch.column_count));
        pack.setArg(2, cl_int(l.brick));
        pack.setArg(3, cl_int(l.nbz));
        pack.setArg(4, cl_int(l.nz));
        pack.setArg(5, cl_uint(l.words));
        pack.setArg(6, blocks);
        launch(cl.queue, pack, pack_items, pack_group);
        cl.queue.finish();
        stats.seconds_kernels += seconds_since(t);
        stats.work_items += batch.items + columns + pack_items;

        t = Clock::now();
        host_words.resize(batch.column_count * block_words);
        cl.queue.enqueueReadBuffer(blocks, CL_TRUE, 0, host_words.size() * sizeof(cl_uint),
                                   host_words.data());
        for (size_t slot = 0; slot < batch.column_count; ++slot) {
            const cl_uint* w = host_words.data() + slot * block_words;
            for (size_t b = 0; b < host_blocks.size(); ++b)
                host_blocks[b] = uint64_t(w[2 * b]) | uint64_t(w[2 * b + 1]) << 32;
            merge_column(result, l, bins.columns[batch.first_column + slot], host_blocks.data());
        }
        stats.seconds_download += seconds_since(t);
        ++stats.batches;
        done += batch.column_count;
        report_progress(options, done * uint64_t(l.nbz), bins.columns.size() * uint64_t(l.nbz));
    }
}

// The same flips, prefix and packing on the host, one brick column at a time.
void parity_reference(const std::vector<OvParityTriangle>& triangles, SparseVoxels& result,
                      VoxelizeStats& stats) {
    const Layout l = make_layout(result);
    const ColumnBins bins = bin_columns(triangles, l);
    stats.brick_pairs = bins.pair_triangle.size();
    stats.bricks_active = bins.columns.size() * uint64_t(l.nbz);
    std::vector<uint32_t> bits(size_t(l.brick) * l.brick * l.words);
    std::vector<uint64_t> blocks(size_t(l.nbz) * l.blocks_per_brick);
    const int nb = l.brick / 4;
    for (size_t c = 0; c < bins.columns.size(); ++c) {
        const int bx = int(bins.columns[c] % uint64_t(l.nbx));
        const int by = int(bins.columns[c] / uint64_t(l.nbx));
        std::fill(bits.begin(), bits.end(), 0u);
        for (uint64_t p = bins.first_pair[c]; p < bins.first_pair[c + 1]; ++p) {
            const OvParityTriangle& tri = triangles[bins.pair_triangle[p]];
            OvColumnRange r;
            if (!ovs_column_range(&tri, bx, by, l.brick, l.nx, l.ny, &r)) continue;
            for (int j = r.lo[1]; j <= r.hi[1]; ++j)
                for (int i = r.lo[0]; i <= r.hi[0]; ++i) {
                    const int k = ovs_parity_flip(&tri, i, j, l.nz);
                    if (k < 0 || k >= l.nz) continue;
                    const size_t column =
                        size_t(j - by * l.brick) * l.brick + size_t(i - bx * l.brick);
                    bits[column * l.words + size_t(k >> 5)] ^= 1u << (k & 31);
                }
        }
        std::fill(blocks.begin(), blocks.end(), 0);
        for (size_t column = 0; column < size_t(l.brick) * l.brick; ++column) {
            uint32_t carry = 0;
            const int x = int(column % size_t(l.brick)), y = int(column / size_t(l.brick));
            for (uint32_t w = 0; w < l.words; ++w) {
                const uint32_t v = ovs_prefix_xor(bits[column * l.words + w], carry);
                carry = v >> 31;
                for (int b = 0; b < 32; ++b) {
                    const int k = int(w) * 32 + b;
                    if (k >= l.nz || !(v >> b & 1u)) continue;
                    const int lz = k % l.brick;
                    const size_t block = size_t(k / l.brick) * l.blocks_per_brick +
                                         size_t(x / 4 + nb * (y / 4 + nb * (lz / 4)));
                    blocks[block] |= uint64_t(1) << ((x & 3) + 4 * ((y & 3) + 4 * (lz & 3)));
                }
            }
        }
        merge_column(result, l, bins.columns[c], blocks.data());
    }
}

// ---- winding number ----

// Voxels whose centres lie in the mesh's bounding box, per axis (empty if lo > hi). Outside it
// the winding number of a closed mesh is 0; for open meshes oclvox defines the solid to stay
// within the bounding box.
struct VoxelBox {
    int64_t lo[3], hi[3];
    bool empty() const { return lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]; }
};

VoxelBox centre_box(const Mesh& mesh, const Grid& grid) {
    VoxelBox box;
    for (int k = 0; k < 3; ++k) {
        double mn = INFINITY, mx = -INFINITY;
        for (const auto& tri : mesh.triangles)
            for (uint32_t v : tri) {
                const double g = (mesh.positions[v][k] - grid.origin[k]) / grid.voxel_size;
                mn = std::min(mn, g);
                mx = std::max(mx, g);
            }
        box.lo[k] = std::max<int64_t>(0, int64_t(std::ceil(std::max(mn - 0.5, -1.0))));
        box.hi[k] = std::min<int64_t>(
            grid.dims[k] - 1, int64_t(std::floor(std::min(mx - 0.5, double(grid.dims[k])))));
    }
    return box;
}

// The winding tree: triangles in leaf order (float voxel units) and the nodes over them.
struct WindingTree {
    std::vector<float> vertices;  // 9 per triangle
    std::vector<OvWindingNode> nodes;
};

// Leaves small enough that a near leaf costs little to sum exactly.
constexpr size_t kLeafTriangles = 8;

struct TreeBuilder {
    const std::vector<std::array<double, 9>>& tri;  // grid coordinates in voxel units
    std::vector<uint32_t> order;
    std::vector<OvWindingNode> nodes;

    std::array<double, 3> centroid(uint32_t t) const {
        return {(tri[t][0] + tri[t][3] + tri[t][6]) / 3, (tri[t][1] + tri[t][4] + tri[t][7]) / 3,
                (tri[t][2] + tri[t][5] + tri[t][8]) / 3};
    }

    // Builds the subtree of order[lo, hi) at the end of `nodes`.
    void build(size_t lo, size_t hi) {
        const size_t index = nodes.size();
        nodes.emplace_back();
        // Dipole moment and its centre (area-weighted, falling back to the plain centroid mean
        // for zero-area subtrees).
        double normal[3] = {0, 0, 0}, weighted[3] = {0, 0, 0}, plain[3] = {0, 0, 0}, area = 0;
        double box_lo[3] = {INFINITY, INFINITY, INFINITY},
               box_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t i = lo; i < hi; ++i) {
            const auto& v = tri[order[i]];
            const double e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
            const double e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
            const double n[3] = {(e1[1] * e2[2] - e1[2] * e2[1]) / 2,
                                 (e1[2] * e2[0] - e1[0] * e2[2]) / 2,
                                 (e1[0] * e2[1] - e1[1] * e2[0]) / 2};
            const double a = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            const auto c = centroid(order[i]);
            for (int k = 0; k < 3; ++k) {
                normal[k] += n[k];
                weighted[k] += a * c[k];
                plain[k] += c[k];
                box_lo[k] = std::min(box_lo[k], c[k]);
                box_hi[k] = std::max(box_hi[k], c[k]);
            }
            area += a;
        }
        double centre[3], radius = 0;
        for (int k = 0; k < 3; ++k)
            centre[k] = area > 0 ? weighted[k] / area : plain[k] / double(hi - lo);
        for (size_t i = lo; i < hi; ++i)
            for (int v = 0; v < 3; ++v) {
                const auto& p = tri[order[i]];
                const double dx = p[3 * v] - centre[0], dy = p[3 * v + 1] - centre[1],
                             dz = p[3 * v + 2] - centre[2];
                radius = std::max(radius, std::sqrt(dx * dx + dy * dy + dz * dz));
            }
        OvWindingNode node{};
        for (int k = 0; k < 3; ++k) {
            node.centre[k] = float(centre[k]);
            node.area_normal[k] = float(normal[k]);
        }
        // Rounded up a little, so the float ball still holds every vertex.
        node.radius = float(radius * (1 + 1e-6) + 1e-6);

        // Leaf, or split at the median centroid along the longest axis of the centroids' box.
        if (hi - lo <= kLeafTriangles) {
            node.first = uint32_t(lo);
            node.count = uint32_t(hi - lo);
        } else {
            int axis = 0;
            for (int k = 1; k < 3; ++k)
                if (box_hi[k] - box_lo[k] > box_hi[axis] - box_lo[axis]) axis = k;
            const size_t mid = lo + (hi - lo) / 2;
            std::nth_element(
                order.begin() + lo, order.begin() + mid, order.begin() + hi,
                [&](uint32_t a, uint32_t b) { return centroid(a)[axis] < centroid(b)[axis]; });
            build(lo, mid);
            build(mid, hi);
        }
        node.skip = uint32_t(nodes.size());
        nodes[index] = node;
    }
};

WindingTree build_winding_tree(const Mesh& mesh, const Grid& grid) {
    std::vector<std::array<double, 9>> tri(mesh.triangles.size());
    for (size_t t = 0; t < tri.size(); ++t)
        for (int v = 0; v < 3; ++v)
            for (int k = 0; k < 3; ++k)
                tri[t][3 * v + k] =
                    (mesh.positions[mesh.triangles[t][v]][k] - grid.origin[k]) / grid.voxel_size;
    TreeBuilder builder{tri, std::vector<uint32_t>(tri.size()), {}};
    for (size_t t = 0; t < tri.size(); ++t) builder.order[t] = uint32_t(t);
    builder.build(0, tri.size());
    WindingTree tree;
    tree.nodes = std::move(builder.nodes);
    tree.vertices.reserve(tri.size() * 9);
    for (uint32_t t : builder.order)
        for (double x : tri[t]) tree.vertices.push_back(float(x));
    return tree;
}

void winding_device(Device::Impl& cl, const Mesh& mesh, SparseVoxels& result,
                    const VoxelizeOptions& options, VoxelizeStats& stats) {
    auto t = Clock::now();
    const Grid& grid = result.grid();
    const VoxelBox box = centre_box(mesh, grid);
    if (box.empty()) return;
    const int b = result.brick_size();
    const auto nb = result.brick_dims();
    std::vector<cl_int> bricks;  // (bx, by, bz) of every brick meeting the box
    for (int64_t bz = box.lo[2] / b; bz <= box.hi[2] / b; ++bz)
        for (int64_t by = box.lo[1] / b; by <= box.hi[1] / b; ++by)
            for (int64_t bx = box.lo[0] / b; bx <= box.hi[0] / b; ++bx)
                bricks.insert(bricks.end(), {cl_int(bx), cl_int(by), cl_int(bz)});
    const size_t brick_count = bricks.size() / 3;
    stats.bricks_active = brick_count;
    const WindingTree tree = build_winding_tree(mesh, grid);
    stats.seconds_binning += seconds_since(t);

    const uint64_t brick_bytes = result.blocks_per_brick() * sizeof(uint64_t);
    const uint64_t budget = device_budget(cl, options);
    if (brick_bytes > budget)
        throw GridError("one brick of " + std::to_string(b) + "^3 voxels needs " +
                        mib(brick_bytes) + ", over the device budget of " + mib(budget) +
                        ": use smaller bricks");
    const uint64_t voxels_per_brick = uint64_t(b) * b * b;
    const size_t max_slots = size_t(std::min<uint64_t>(
        {budget / brick_bytes, kMaxItemsPerBatch / voxels_per_brick, uint64_t(brick_count)}));

    const cl::Program& program = cl.program(kKernel_solid);
    t = Clock::now();
    const cl::Buffer vertex_buffer = upload(cl.context, cl.queue, tree.vertices);
    const cl::Buffer node_buffer = upload(cl.context, cl.queue, tree.nodes);
    cl::Buffer blocks(cl.context, CL_MEM_READ_WRITE, max_slots * brick_bytes);
    cl.queue.finish();
    stats.seconds_upload += seconds_since(t);

    cl::Kernel winding(program, "winding");
    const size_t group = work_group_size(winding, cl.device);
    std::vector<cl_uint> words(max_slots * result.blocks_per_brick() * 2);
    std::vector<uint64_t> brick_blocks(result.blocks_per_brick());
    for (size_t done = 0; done < brick_count;) {
        const size_t slots = std::min(max_slots, brick_count - done);
        const uint64_t items = slots * voxels_per_brick;
        t = Clock::now();
        cl.queue.enqueueFillBuffer(blocks, cl_uint(0), 0, slots * brick_bytes);
        winding.setArg(0, vertex_buffer);
        winding.setArg(1, node_buffer);
        winding.setArg(2, cl_uint(tree.nodes.size()));
        // The batch's bricks; the upload is asynchronous, so the host copy outlives the batch.
        const std::vector<cl_int> batch_bricks(bricks.begin() + 3 * done,
                                               bricks.begin() + 3 * (done + slots));
        const cl::Buffer window = upload(cl.context, cl.queue, batch_bricks);
        winding.setArg(3, window);
        winding.setArg(5, cl_uint(items));
        winding.setArg(6, cl_int(b));
        for (int k = 0; k < 3; ++k) {
            winding.setArg(7 + k, cl_int(box.lo[k]));
            winding.setArg(10 + k, cl_int(box.hi[k]));
        }
        winding.setArg(13, blocks);
        for (uint64_t base = 0; base < items; base += kWindingItemsPerLaunch) {
            winding.setArg(4, cl_uint(base));
            launch(cl.queue, winding, std::min(kWindingItemsPerLaunch, items - base), group);
        }
        cl.queue.finish();
        stats.seconds_kernels += seconds_since(t);
        stats.work_items += items;

        t = Clock::now();
        cl.queue.enqueueReadBuffer(blocks, CL_TRUE, 0, slots * brick_bytes, words.data());
        for (size_t slot = 0; slot < slots; ++slot) {
            const cl_uint* w = words.data() + slot * brick_blocks.size() * 2;
            for (size_t i = 0; i < brick_blocks.size(); ++i)
                brick_blocks[i] = uint64_t(w[2 * i]) | uint64_t(w[2 * i + 1]) << 32;
            const cl_int* brick = bricks.data() + 3 * (done + slot);
            result.merge_brick(
                uint64_t(brick[0]) +
                    uint64_t(nb[0]) * (uint64_t(brick[1]) + uint64_t(nb[1]) * uint64_t(brick[2])),
                brick_blocks.data());
        }
        stats.seconds_download += seconds_since(t);
        ++stats.batches;
        done += slots;
        report_progress(options, done, brick_count);
    }
}

// Double-precision winding number at every voxel centre of the box, summing every triangle.
void winding_reference(const Mesh& mesh, SparseVoxels& result) {
    const Grid& grid = result.grid();
    const VoxelBox box = centre_box(mesh, grid);
    if (box.empty()) return;
    uint64_t voxels = 1;
    for (int k = 0; k < 3; ++k) voxels *= uint64_t(box.hi[k] - box.lo[k] + 1);
    if (voxels > kMaxReferenceWindingTerms / std::max<uint64_t>(1, mesh.triangles.size()))
        throw GridError("the CPU reference winding number would sum more than " +
                        std::to_string(kMaxReferenceWindingTerms) +
                        " solid angles: lower the resolution");
    std::vector<std::array<double, 3>> g(mesh.positions.size());
    for (size_t v = 0; v < g.size(); ++v)
        for (int k = 0; k < 3; ++k)
            g[v][k] = (mesh.positions[v][k] - grid.origin[k]) / grid.voxel_size;
    for (int64_t z = box.lo[2]; z <= box.hi[2]; ++z)
        for (int64_t y = box.lo[1]; y <= box.hi[1]; ++y)
            for (int64_t x = box.lo[0]; x <= box.hi[0]; ++x) {
                const double p[3] = {double(x) + 0.5, double(y) + 0.5, double(z) + 0.5};
                double sum = 0;
                for (const auto& tri : mesh.triangles) {
                    double a[3], b[3], c[3];
                    for (int k = 0; k < 3; ++k) {
                        a[k] = g[tri[0]][k] - p[k];
                        b[k] = g[tri[1]][k] - p[k];
                        c[k] = g[tri[2]][k] - p[k];
                    }
                    // Van Oosterom & Strackee, as in the kernel.
                    const double det = a[0] * (b[1] * c[2] - b[2] * c[1]) +
                                       a[1] * (b[2] * c[0] - b[0] * c[2]) +
                                       a[2] * (b[0] * c[1] - b[1] * c[0]);
                    const double la = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
                    const double lb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
                    const double lc = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
                    const double den = la * lb * lc +
                                       (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * lc +
                                       (b[0] * c[0] + b[1] * c[1] + b[2] * c[2]) * la +
                                       (c[0] * a[0] + c[1] * a[1] + c[2] * a[2]) * lb;
                    sum += 2 * std::atan2(det, den);
                }
                // |w| > 1/2: an inward-facing closed mesh has w = -1 inside.
                if (std::fabs(sum) > 2 * M_PI) result.set(x, y, z);
            }
}

// Shared by both entry points: choose the test, and record the choice.
template <typename Parity, typename Winding>
SparseVoxels run_solid(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                       VoxelizeStats& stats, Parity parity, Winding winding) {
    validate_mesh(mesh);
    validate_grid(grid);
    SparseVoxels result(grid, options.brick_size);
    const auto nb = result.brick_dims();
    stats.triangles_in = mesh.triangles.size();
    stats.bricks_total = uint64_t(nb[0]) * uint64_t(nb[1]) * uint64_t(nb[2]);

    std::vector<OvParityTriangle> triangles;
    const bool fits = parity_triangles(mesh, grid, triangles);
    const Choice choice = choose_inside_test(mesh, options.inside, fits);
    stats.inside_test = to_string(choice.test);
    stats.inside_test_reason = choice.reason;
    stats.triangles_used = mesh.triangles.size();
    if (choice.test == InsideTest::Parity)
        parity(triangles, result);
    else
        winding(result);
    stats.voxels_set = result.count();
    return result;
}

}  // namespace

MeshEdgeReport mesh_edge_report(const Mesh& mesh) {
    // Weld bit-identical positions.
    std::map<std::array<double, 3>, uint32_t> ids;
    std::vector<uint32_t> welded(mesh.positions.size());
    for (size_t v = 0; v < mesh.positions.size(); ++v)
        welded[v] = ids.emplace(mesh.positions[v], uint32_t(ids.size())).first->second;

    // Per undirected edge: how many triangles run it low -> high, and high -> low.
    std::map<std::pair<uint32_t, uint32_t>, std::array<uint32_t, 2>> uses;
    for (const auto& tri : mesh.triangles) {
        const uint32_t v[3] = {welded[tri[0]], welded[tri[1]], welded[tri[2]]};
        if (v[0] == v[1] || v[1] == v[2] || v[2] == v[0]) continue;
        for (int e = 0; e < 3; ++e) {
            const uint32_t a = v[e], b = v[(e + 1) % 3];
            ++uses[{std::min(a, b), std::max(a, b)}][a < b ? 0 : 1];
        }
    }
    MeshEdgeReport report;
    report.edges = uses.size();
    for (const auto& [edge, n] : uses) {
        const uint32_t total = n[0] + n[1];
        if (total == 1)
            ++report.boundary;
        else if (total > 2)
            ++report.non_manifold;
        else if (n[0] != 1)
            ++report.misoriented;
    }
    return report;
}

SparseVoxels solid_device(Device::Impl& cl, const Mesh& mesh, const Grid& grid,
                          const VoxelizeOptions& options, VoxelizeStats& stats) {
    try {
        return run_solid(
            mesh, grid, options, stats,
            [&](const std::vector<OvParityTriangle>& triangles, SparseVoxels& result) {
                parity_device(cl, triangles, result, options, stats);
            },
            [&](SparseVoxels& result) { winding_device(cl, mesh, result, options, stats); });
    } catch (const cl::Error& e) {
        throw_device_error(e, "solid voxelization on " + cl.info.name);
    }
}

SparseVoxels solid_reference(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                             VoxelizeStats& stats) {
    const auto start = Clock::now();
    SparseVoxels result = run_solid(
        mesh, grid, options, stats,
        [&](const std::vector<OvParityTriangle>& triangles, SparseVoxels& out) {
            parity_reference(triangles, out, stats);
        },
        [&](SparseVoxels& out) { winding_reference(mesh, out); });
    stats.seconds_kernels = seconds_since(start);
    return result;
}

}  // namespace oclvox::detail
