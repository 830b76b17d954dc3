// Voxel cubes as a surface mesh (.obj, or binary little-endian .ply).
//
// Only exposed faces are emitted: a face between two set voxels is inside the solid. Each face is
// one quad in world coordinates (origin + lattice index * voxel_size), wound counter-clockwise
// seen from outside so the right-hand normal points out of the set voxel. Corners are lattice
// points shared by all the quads that touch them, so the mesh is indexed, not a quad soup.
//
// The faces are found from the sparse set (for_each plus neighbour lookups) and sorted, so no
// dense copy is needed and the file does not depend on the brick size or hash order.
#include <algorithm>
#include <charconv>
#include <limits>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "atomic_file.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// Face `direction` of voxel (i,j,k): axis direction / 2, towards +axis when direction is even.
struct ExposedFace {
    int32_t k, j, i;
    uint8_t direction;
    bool operator<(const ExposedFace& o) const {
        return std::tie(k, j, i, direction) < std::tie(o.k, o.j, o.i, o.direction);
    }
};

struct QuadMesh {
    std::vector<std::array<int64_t, 3>> lattice_points;  // vertex positions in voxel units
    std::vector<std::array<uint32_t, 4>> quads;          // vertex indices, outward winding
};

std::vector<ExposedFace> exposed_faces(const SparseVoxels& voxels) {
    std::vector<ExposedFace> faces;
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
        for (uint8_t direction = 0; direction < 6; ++direction) {
            std::array<int64_t, 3> neighbour{i, j, k};
            neighbour[direction / 2] += direction % 2 == 0 ? 1 : -1;
            // get() is false outside the grid, so faces on the grid boundary count as exposed.
            if (!voxels.get(neighbour[0], neighbour[1], neighbour[2]))
                faces.push_back({int32_t(k), int32_t(j), int32_t(i), direction});
        }
    });
    std::sort(faces.begin(), faces.end());
    return faces;
}

QuadMesh build_quad_mesh(const std::string& path, const SparseVoxels& voxels) {
    const auto& dims = voxels.grid().dims;
    const uint64_t points_x = uint64_t(dims[0]) + 1, points_y = uint64_t(dims[1]) + 1;

    QuadMesh mesh;
    std::unordered_map<uint64_t, uint32_t> vertex_of_point;
    auto vertex_at = [&](const std::array<int64_t, 3>& p) {
        const uint64_t key =
            uint64_t(p[0]) + points_x * (uint64_t(p[1]) + points_y * uint64_t(p[2]));
        auto [it, inserted] =
            vertex_of_point.try_emplace(key, uint32_t(mesh.lattice_points.size()));
        if (inserted) {
            // PLY indices are signed 32-bit; OBJ shares the limit to keep one code path.
            if (mesh.lattice_points.size() >= size_t(std::numeric_limits<int32_t>::max()))
                throw OutputError("cannot write " + path +
                                  ": the surface has more than 2^31 vertices");
            mesh.lattice_points.push_back(p);
        }
        return it->second;
    };

    for (const ExposedFace& face : exposed_faces(voxels)) {
        // The face lies in the plane axis = index (+1 for the positive side); u, v follow axis
        // cyclically so that u x v = +axis and the corner order p, p+u, p+u+v, p+v faces +axis.
        const int axis = face.direction / 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
        const bool positive = face.direction % 2 == 0;
        std::array<int64_t, 3> p{face.i, face.j, face.k};
        if (positive) p[axis] += 1;
        std::array<int64_t, 3> pu = p, puv = p, pv = p;
        pu[u] += 1;
        puv[u] += 1;
        puv[v] += 1;
        pv[v] += 1;
        const uint32_t a = vertex_at(p), b = vertex_at(pu), c = vertex_at(puv), d = vertex_at(pv);
        mesh.quads.push_back(positive ? std::array<uint32_t, 4>{a, b, c, d}
                                      : std::array<uint32_t, 4>{a, d, c, b});
    }
    return mesh;
}

double world_coordinate(const Grid& grid, int axis, int64_t lattice) {
    return grid.origin[axis] + double(lattice) * grid.voxel_size;
}

// Shortest text that reads back as the same double.
void write_number(std::ostream& out, double value) {
    char text[32];
    const auto result = std::to_chars(text, text + sizeof text, value);
    out.write(text, result.ptr - text);
}

}  // namespace

void write_cube_mesh_obj(const std::string& path, const SparseVoxels& voxels) {
    const QuadMesh mesh = build_quad_mesh(path, voxels);
    const Grid& grid = voxels.grid();
    write_file_atomically(path, [&](std::ostream& out) {
        out << "# oclvox: exposed faces of " << voxels.count() << " voxels, "
            << mesh.lattice_points.size() << " vertices, " << mesh.quads.size() << " quads\n";
        for (const auto& p : mesh.lattice_points) {
            out << 'v';
            for (int axis = 0; axis < 3; ++axis) {
                out << ' ';
                write_number(out, world_coordinate(grid, axis, p[axis]));
            }
            out << '\n';
        }
        for (const auto& quad : mesh.quads)  // OBJ indices start at 1
            out << "f " << quad[0] + 1 << ' ' << quad[1] + 1 << ' ' << quad[2] + 1 << ' '
                << quad[3] + 1 << '\n';
    });
}

void write_cube_mesh_ply(const std::string& path, const SparseVoxels& voxels) {
    const QuadMesh mesh = build_quad_mesh(path, voxels);
    const Grid& grid = voxels.grid();
    write_file_atomically(path, [&](std::ostream& out) {
        out << "ply\n"
            << "format binary_little_endian 1.0\n"
            << "comment oclvox: exposed faces of " << voxels.count() << " voxels\n"
            << "element vertex " << mesh.lattice_points.size() << '\n'
            << "property double x\nproperty double y\nproperty double z\n"
            << "element face " << mesh.quads.size() << '\n'
            << "property list uchar int vertex_indices\n"
            << "end_header\n";
        for (const auto& p : mesh.lattice_points)
            for (int axis = 0; axis < 3; ++axis)
                write_le_f64(out, world_coordinate(grid, axis, p[axis]));
        for (const auto& quad : mesh.quads) {
            out.put(char(4));
            for (uint32_t index : quad) write_le_i32(out, int32_t(index));
        }
    });
}

}  // namespace oclvox::detail
