// Voxel cubes as a surface mesh (.obj, binary little-endian .ply, or binary .stl through
// write_mesh with each quad split into two triangles).
//
// Only exposed faces are emitted: a face between two set voxels is inside the solid. Each face is
// one quad in world coordinates (origin + lattice index * voxel_size), wound counter-clockwise
// seen from outside so the right-hand normal points out of the set voxel. Corners are lattice
// points shared by all the quads that touch them, so the mesh is indexed, not a quad soup.
//
// Streaming: the mesh is built one z-layer of bricks at a time. A layer's exposed faces are
// found from its blocks (neighbours inside a block from the block's bits, others by lookup) and
// sorted by (z, y, x, direction); vertices are numbered in order of first use. Only the lattice
// points on the layer's top plane carry over to the next layer, so the largest buffer is one
// layer's faces. OBJ takes each voxel layer's new vertices and quads in turn; PLY, which needs the
// counts first and all vertices before any face, walks the layers three times (count, vertices,
// faces), each walk numbering the vertices identically. The file does not depend on the brick
// size or hash order.
#include <algorithm>
#include <functional>
#include <limits>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "atomic_file.hpp"
#include "brick_layout.hpp"
#include "little_endian.hpp"
#include "number_text.hpp"
#include "oclvox/field.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// Face `direction` of voxel (i,j,k): axis direction / 2, towards +axis when direction is even.
struct ExposedFace {
    int64_t k, j, i;
    uint8_t direction;
    bool operator<(const ExposedFace& o) const {
        return std::tie(k, j, i, direction) < std::tie(o.k, o.j, o.i, o.direction);
    }
};

// One voxel layer's share of the mesh: the lattice points it uses first (vertex positions in
// voxel units, numbered on from the previous layers' vertices) and its quads (global vertex
// indices, outward winding).
struct LayerMesh {
    std::vector<std::array<int64_t, 3>> new_points;
    std::vector<std::array<uint32_t, 4>> quads;
};

// The exposed faces of the voxels in one brick layer, sorted.
std::vector<ExposedFace> exposed_faces(const SparseVoxels& voxels, const BrickLayout& layout,
                                       const uint64_t* bricks, size_t count) {
    std::vector<ExposedFace> faces;
    for (size_t b = 0; b < count; ++b) {
        const uint64_t* blocks = voxels.brick_blocks(bricks[b]);
        for (size_t w = 0; w < layout.blocks_per_brick(); ++w) {
            const uint64_t word = blocks[w];
            if (!word) continue;
            const auto o = layout.block_origin(bricks[b], w);
            for (uint64_t mask = word; mask; mask &= mask - 1) {
                const int bit = __builtin_ctzll(mask);
                const auto local = voxel_in_block(bit);
                for (uint8_t direction = 0; direction < 6; ++direction) {
                    const int axis = direction / 2;
                    const bool positive = direction % 2 == 0;
                    const int step = positive ? 1 : -1, bit_step = axis == 0   ? 1
                                                                   : axis == 1 ? 4
                                                                               : 16;
                    bool neighbour_set;
                    if (positive ? local[axis] < 3 : local[axis] > 0) {
                        neighbour_set = (word >> (bit + step * bit_step)) & 1u;
                    } else {
                        // get() is false outside the grid, so boundary faces count as exposed.
                        std::array<int64_t, 3> n{o[0] + local[0], o[1] + local[1], o[2] + local[2]};
                        n[axis] += step;
                        neighbour_set = voxels.get(n[0], n[1], n[2]);
                    }
                    if (!neighbour_set)
                        faces.push_back(
                            {o[2] + local[2], o[1] + local[1], o[0] + local[0], direction});
                }
            }
        }
    }
    std::sort(faces.begin(), faces.end());
    return faces;
}

// Calls `visit(layer)` for each voxel layer with an exposed face, in z order, working a brick
// layer at a time, and reports each brick layer done as phase `phase` of `progress`.
void for_each_layer_mesh(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, size_t phase,
                         const std::function<void(const LayerMesh&)>& visit) {
    const auto& dims = voxels.grid().dims;
    const uint64_t points_x = uint64_t(dims[0]) + 1, points_y = uint64_t(dims[1]) + 1;
    const BrickLayout layout(voxels);
    const std::vector<uint64_t> bricks = voxels.brick_indices();  // sorted: layers in z order
    uint64_t vertices = 0;
    std::unordered_map<uint64_t, uint32_t> carried;  // lattice point -> vertex, previous top plane
    for (size_t first = 0; first < bricks.size();) {
        const uint64_t layer = bricks[first] / layout.layer_bricks();
        size_t end = first;
        while (end < bricks.size() && bricks[end] / layout.layer_bricks() == layer) ++end;

        LayerMesh mesh;
        std::unordered_map<uint64_t, uint32_t> vertex_of_point = std::move(carried);
        auto vertex_at = [&](const std::array<int64_t, 3>& p) {
            const uint64_t key =
                uint64_t(p[0]) + points_x * (uint64_t(p[1]) + points_y * uint64_t(p[2]));
            auto [it, inserted] = vertex_of_point.try_emplace(key, uint32_t(vertices));
            if (inserted) {
                // PLY indices are signed 32-bit; OBJ shares the limit to keep one code path.
                if (vertices >= uint64_t(std::numeric_limits<int32_t>::max()))
                    throw OutputError("cannot write " + path +
                                      ": the surface has more than 2^31 vertices");
                ++vertices;
                mesh.new_points.push_back(p);
            }
            return it->second;
        };
        int64_t top = 0;  // the lattice plane shared with the next layer
        const std::vector<ExposedFace> faces =
            exposed_faces(voxels, layout, &bricks[first], end - first);
        for (size_t f = 0; f < faces.size(); ++f) {
            const ExposedFace& face = faces[f];
            // The face lies in the plane axis = index (+1 for the positive side); u, v follow
            // axis cyclically so that u x v = +axis and the corner order p, p+u, p+u+v, p+v
            // faces +axis.
            const int axis = face.direction / 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
            const bool positive = face.direction % 2 == 0;
            std::array<int64_t, 3> p{face.i, face.j, face.k};
            if (positive) p[axis] += 1;
            std::array<int64_t, 3> pu = p, puv = p, pv = p;
            pu[u] += 1;
            puv[u] += 1;
            puv[v] += 1;
            pv[v] += 1;
            const uint32_t a = vertex_at(p), b = vertex_at(pu), c = vertex_at(puv),
                           d = vertex_at(pv);
            mesh.quads.push_back(positive ? std::array<uint32_t, 4>{a, b, c, d}
                                          : std::array<uint32_t, 4>{a, d, c, b});
            top = face.k + 1;
            if (f + 1 == faces.size() || faces[f + 1].k != face.k) {  // a voxel layer is done
                visit(mesh);
                mesh.new_points.clear();
                mesh.quads.clear();
            }
        }
        for (const auto& [key, vertex] : vertex_of_point)
            if (int64_t(key / (points_x * points_y)) == top) carried.emplace(key, vertex);
        first = end;
        progress.report(phase, first, bricks.size());
    }
}

double world_coordinate(const Grid& grid, int axis, int64_t lattice) {
    return grid.origin[axis] + double(lattice) * grid.voxel_size;
}

}  // namespace

void write_cube_mesh_obj(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress) {
    const Grid& grid = voxels.grid();
    const size_t pass = progress.add(1);
    write_file_atomically(path, [&](std::ostream& out) {
        out << "# oclvox: exposed faces of " << voxels.count() << " voxels\n";
        for_each_layer_mesh(path, voxels, progress, pass, [&](const LayerMesh& layer) {
            for (const auto& p : layer.new_points) {
                out << 'v';
                for (int axis = 0; axis < 3; ++axis) {
                    out << ' ';
                    write_shortest_number(out, world_coordinate(grid, axis, p[axis]));
                }
                out << '\n';
            }
            for (const auto& quad : layer.quads)  // OBJ indices start at 1
                out << "f " << quad[0] + 1 << ' ' << quad[1] + 1 << ' ' << quad[2] + 1 << ' '
                    << quad[3] + 1 << '\n';
        });
        progress.finish();
    });
}

void write_cube_mesh_ply(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress) {
    const Grid& grid = voxels.grid();
    // Three passes over the layers: counting (the header comes first), vertices, faces.
    const size_t counting = progress.add(1), vertex_pass = progress.add(1),
                 face_pass = progress.add(1);
    uint64_t vertices = 0, quads = 0;
    for_each_layer_mesh(path, voxels, progress, counting, [&](const LayerMesh& layer) {
        vertices += layer.new_points.size();
        quads += layer.quads.size();
    });
    write_file_atomically(path, [&](std::ostream& out) {
        out << "ply\n"
            << "format binary_little_endian 1.0\n"
            << "comment oclvox: exposed faces of " << voxels.count() << " voxels\n"
            << "element vertex " << vertices << '\n'
            << "property double x\nproperty double y\nproperty double z\n"
            << "element face " << quads << '\n'
            << "property list uchar int vertex_indices\n"
            << "end_header\n";
        for_each_layer_mesh(path, voxels, progress, vertex_pass, [&](const LayerMesh& layer) {
            for (const auto& p : layer.new_points)
                for (int axis = 0; axis < 3; ++axis)
                    write_le(out, world_coordinate(grid, axis, p[axis]));
        });
        for_each_layer_mesh(path, voxels, progress, face_pass, [&](const LayerMesh& layer) {
            for (const auto& quad : layer.quads) {
                out.put(char(4));
                for (uint32_t index : quad) write_le(out, int32_t(index));
            }
        });
        progress.finish();
    });
}

// STL goes through the shared mesh writer, so unlike OBJ and PLY it holds the whole mesh; the
// progress covers building it, and ends before the (shorter) write.
void write_cube_mesh_stl(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress) {
    const Grid& grid = voxels.grid();
    const size_t pass = progress.add(1);
    Mesh mesh;
    for_each_layer_mesh(path, voxels, progress, pass, [&](const LayerMesh& layer) {
        for (const auto& p : layer.new_points)
            mesh.positions.push_back({world_coordinate(grid, 0, p[0]),
                                      world_coordinate(grid, 1, p[1]),
                                      world_coordinate(grid, 2, p[2])});
        for (const auto& q : layer.quads) {  // the quad's winding carries over to both halves
            mesh.triangles.push_back({q[0], q[1], q[2]});
            mesh.triangles.push_back({q[0], q[2], q[3]});
        }
    });
    progress.finish();
    write_mesh(path, mesh);
}

}  // namespace oclvox::detail
