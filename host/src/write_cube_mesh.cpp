// Voxel cubes as a surface mesh (.obj, binary little-endian .ply, or binary .stl with each quad
// split into two triangles).
//
// Only exposed faces are emitted: a face between two set voxels is inside the solid. Each face is
// one quad in world coordinates (origin + lattice index * voxel_size), wound counter-clockwise
// seen from outside so the right-hand normal points out of the set voxel. In OBJ and PLY corners
// are lattice points shared by all the quads that touch them, so the mesh is indexed, not a quad
// soup.
//
// Streaming: the faces come one voxel layer at a time, a brick layer's bricks at a time, in
// (z, y, x, direction) order straight from the voxels' rows: a brick's rows of a layer are its
// bits along x (brick-local y), so a row's exposed faces in one direction are the row less its
// neighbour row (y +- 1, z +- 1) or its own bits shifted by one (x +- 1), a few word operations a
// row. Vertices are numbered in order of first use; a vertex is a lattice point of the layer's
// bottom or top plane, found in that plane's table (the top plane's becomes the next layer's
// bottom), so the largest buffers are one brick layer's rows of three planes and one layer's
// faces. OBJ takes each voxel layer's new vertices and quads in turn; PLY, which needs all
// vertices before any face, walks the layers twice (vertices, faces), each walk numbering the
// vertices identically, and writes its header's counts, known only then, at the end; STL walks
// them once, its count too written at the end. The file does not depend on the brick size or
// hash order.
#include <algorithm>
#include <charconv>
#include <functional>
#include <limits>
#include <vector>

#include "atomic_file.hpp"
#include "block_writer.hpp"
#include "brick_layout.hpp"
#include "oclvox/field.hpp"
#include "stl_format.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// One voxel layer's share of the mesh: the lattice points it uses first (vertex positions in
// voxel units, numbered on from the previous layers' vertices) and its quads (global vertex
// indices, outward winding).
struct LayerMesh {
    std::vector<std::array<int64_t, 3>> new_points;
    std::vector<std::array<uint32_t, 4>> quads;
};

// The vertex numbers of one lattice plane's points (key x + (nx + 1) * y): open addressing,
// cleared in time proportional to what it holds, so a plane costs its own points only.
class PlaneVertices {
  public:
    // The vertex of `key`, or `fresh` (then recorded as its vertex) if it has none; `inserted`
    // says which.
    uint32_t find_or_add(uint64_t key, uint32_t fresh, bool& inserted) {
        if (2 * (used_.size() + 1) > keys_.size()) grow();
        for (size_t slot = hash(key);; slot = (slot + 1) & (keys_.size() - 1)) {
            if (keys_[slot] == key) {
                inserted = false;
                return vertices_[slot];
            }
            if (keys_[slot] == kEmpty) {
                keys_[slot] = key;
                vertices_[slot] = fresh;
                used_.push_back(slot);
                inserted = true;
                return fresh;
            }
        }
    }
    void clear() {
        for (const size_t slot : used_) keys_[slot] = kEmpty;
        used_.clear();
    }

  private:
    static constexpr uint64_t kEmpty = ~uint64_t(0);
    size_t hash(uint64_t key) const { return size_t((key * 0x9E3779B97F4A7C15ull) >> shift_); }
    void grow() {
        const std::vector<uint64_t> keys = std::move(keys_);
        const std::vector<uint32_t> vertices = std::move(vertices_);
        const std::vector<size_t> used = std::move(used_);
        const size_t size = std::max<size_t>(1024, 2 * keys.size());
        keys_.assign(size, kEmpty);
        vertices_.resize(size);
        used_.clear();
        shift_ = 64 - __builtin_ctzll(size);
        bool inserted;
        for (const size_t slot : used) find_or_add(keys[slot], vertices[slot], inserted);
    }
    std::vector<uint64_t> keys_;
    std::vector<uint32_t> vertices_;
    std::vector<size_t> used_;
    int shift_ = 64;
};

// A brick layer's stored bricks (ascending, so by brick y, then x), each with the positions in
// that list of its neighbours across its -x, +x, -y and +y faces (-1: none stored).
struct BrickLayer {
    std::vector<uint64_t> bricks;
    std::vector<std::array<int64_t, 4>> neighbours;
};

BrickLayer brick_layer(const std::vector<uint64_t>& sorted, size_t first, size_t end, uint64_t nbx,
                       uint64_t nby) {
    BrickLayer layer;
    layer.bricks.assign(sorted.begin() + ptrdiff_t(first), sorted.begin() + ptrdiff_t(end));
    auto position = [&](uint64_t brick) {
        const auto it = std::lower_bound(layer.bricks.begin(), layer.bricks.end(), brick);
        return it != layer.bricks.end() && *it == brick ? int64_t(it - layer.bricks.begin())
                                                        : int64_t(-1);
    };
    for (const uint64_t brick : layer.bricks) {
        const uint64_t bx = brick % nbx, by = brick / nbx % nby;
        layer.neighbours.push_back(
            {bx > 0 ? position(brick - 1) : -1, bx + 1 < nbx ? position(brick + 1) : -1,
             by > 0 ? position(brick - nbx) : -1, by + 1 < nby ? position(brick + nbx) : -1});
    }
    return layer;
}

// Reads one voxel layer of a brick layer's bricks (the bricks at the same x and y, in the brick
// layer holding that voxel layer) as rows along x: row y (brick-local) of brick b is words
// [(b * brick + y) * words, ... + words), bit x % 64 of word x / 64 being brick-local voxel x.
// Bricks not stored there, and layers outside the grid, are zero rows.
class LayerReader {
  public:
    LayerReader(const SparseVoxels& voxels, const BrickLayout& layout)
        : voxels_(voxels),
          layout_(layout),
          brick_(voxels.brick_size()),
          blocks_(voxels.blocks_per_brick_axis()),
          words_((brick_ + 63) / 64) {}

    void read(const BrickLayer& layer, int64_t z, std::vector<uint64_t>& rows) const {
        rows.assign(layer.bricks.size() * size_t(brick_ * words_), 0);
        if (z < 0 || z >= voxels_.grid().dims[2]) return;
        const uint64_t layer_bricks = layout_.layer_bricks();
        const uint64_t brick_z = uint64_t(z / brick_);
        const int64_t zb = z % brick_ / 4, shift = 16 * (z % 4);
        for (size_t b = 0; b < layer.bricks.size(); ++b) {
            const uint64_t* blocks =
                voxels_.brick_blocks(layer.bricks[b] % layer_bricks + brick_z * layer_bricks);
            if (!blocks) continue;
            uint64_t* brick_rows = &rows[b * size_t(brick_ * words_)];
            for (int64_t yb = 0; yb < blocks_; ++yb)
                for (int64_t xb = 0; xb < blocks_; ++xb) {
                    const uint64_t block = blocks[size_t(xb + blocks_ * (yb + blocks_ * zb))];
                    if (!block) continue;
                    for (int64_t y = 0; y < 4; ++y)
                        brick_rows[(4 * yb + y) * words_ + xb / 16] |=
                            (block >> (shift + 4 * y) & 0xF) << (4 * xb % 64);
                }
        }
    }
    const uint64_t* row(const std::vector<uint64_t>& rows, int64_t b, int64_t y) const {
        return &rows[size_t((b * brick_ + y) * words_)];
    }

  private:
    const SparseVoxels& voxels_;
    const BrickLayout& layout_;
    int64_t brick_, blocks_, words_;
};

// Calls face(x, y, z, direction) for every exposed face, in (z, y, x, direction) order, and
// layer_done() after each voxel layer that has any, working a brick layer at a time; reports
// each brick layer done as phase `phase` of `progress`. Face `direction` of a voxel: axis
// direction / 2, towards +axis when direction is even.
template <class Face, class LayerDone>
void for_each_exposed_face(const SparseVoxels& voxels, ProgressPhases& progress, size_t phase,
                           Face&& face, LayerDone&& layer_done) {
    const auto& dims = voxels.grid().dims;
    const BrickLayout layout(voxels);
    const int64_t brick = voxels.brick_size(), words = (brick + 63) / 64;
    const uint64_t nbx = uint64_t(voxels.brick_dims()[0]), nby = uint64_t(voxels.brick_dims()[1]);
    const std::vector<uint64_t> bricks = voxels.brick_indices();  // sorted: layers in z order
    const LayerReader reader(voxels, layout);
    std::vector<uint64_t> below, here, above;
    std::vector<uint64_t> exposed(size_t(6 * words));  // per direction, a row's exposed voxels
    const int last_bit = int((brick - 1) % 64);        // of the row's last word
    for (size_t first = 0; first < bricks.size();) {
        const uint64_t brick_z = bricks[first] / layout.layer_bricks();
        size_t end = first;
        while (end < bricks.size() && bricks[end] / layout.layer_bricks() == brick_z) ++end;
        const BrickLayer layer = brick_layer(bricks, first, end, nbx, nby);
        const int64_t z_first = int64_t(brick_z) * brick;
        reader.read(layer, z_first - 1, below);
        reader.read(layer, z_first, here);
        for (int64_t z = z_first; z < std::min(z_first + brick, dims[2]); ++z) {
            reader.read(layer, z + 1, above);
            bool any_face = false;
            // Rows in (y, x) order: a run of bricks with the same brick y, each voxel row across
            // them.
            for (size_t run = 0; run < layer.bricks.size();) {
                size_t run_end = run;
                while (run_end < layer.bricks.size() &&
                       layer.bricks[run_end] / nbx == layer.bricks[run] / nbx)
                    ++run_end;
                const int64_t y_first = int64_t(layer.bricks[run] / nbx % nby) * brick;
                for (int64_t ly = 0; ly < brick && y_first + ly < dims[1]; ++ly)
                    for (size_t b = run; b < run_end; ++b) {
                        const uint64_t* set = reader.row(here, int64_t(b), ly);
                        bool any = false;
                        for (int64_t w = 0; w < words; ++w) any = any || set[w] != 0;
                        if (!any) continue;
                        const auto& n = layer.neighbours[b];
                        const uint64_t* beside[4] = {
                            ly + 1 < brick ? reader.row(here, int64_t(b), ly + 1)
                            : n[3] >= 0    ? reader.row(here, n[3], 0)
                                           : nullptr,
                            ly > 0      ? reader.row(here, int64_t(b), ly - 1)
                            : n[2] >= 0 ? reader.row(here, n[2], brick - 1)
                                        : nullptr,
                            reader.row(above, int64_t(b), ly), reader.row(below, int64_t(b), ly)};
                        // The voxels just past the row's ends, in its x neighbours' rows.
                        const bool after = n[1] >= 0 && (reader.row(here, n[1], ly)[0] & 1);
                        const bool before =
                            n[0] >= 0 && (reader.row(here, n[0], ly)[words - 1] >> last_bit & 1);
                        for (int64_t w = 0; w < words; ++w) {
                            // Whether voxel x + 1 (x - 1) is set, at bit x.
                            uint64_t plus_x = set[w] >> 1 | (w + 1 < words ? set[w + 1] << 63 : 0);
                            if (w + 1 == words && after) plus_x |= uint64_t(1) << last_bit;
                            const uint64_t minus_x = set[w] << 1 | (w > 0    ? set[w - 1] >> 63
                                                                    : before ? 1
                                                                             : 0);
                            uint64_t* e = &exposed[size_t(6 * w)];
                            e[0] = set[w] & ~plus_x;
                            e[1] = set[w] & ~minus_x;
                            for (int d = 2; d < 6; ++d)
                                e[d] = set[w] & ~(beside[d - 2] ? beside[d - 2][w] : 0);
                        }
                        const int64_t x_first = int64_t(layer.bricks[b] % nbx) * brick;
                        for (int64_t w = 0; w < words; ++w) {
                            const uint64_t* e = &exposed[size_t(6 * w)];
                            for (uint64_t faces = e[0] | e[1] | e[2] | e[3] | e[4] | e[5]; faces;
                                 faces &= faces - 1) {
                                const int bit = __builtin_ctzll(faces);
                                for (int d = 0; d < 6; ++d)
                                    if (e[d] >> bit & 1)
                                        face(x_first + 64 * w + bit, y_first + ly, z, d);
                                any_face = true;
                            }
                        }
                    }
                run = run_end;
            }
            if (any_face) layer_done();
            std::swap(below, here);
            std::swap(here, above);
        }
        first = end;
        progress.report(phase, first, bricks.size());
    }
}

// Calls `visit(layer)` for each voxel layer with an exposed face, in z order, numbering the
// vertices in order of first use, and reports as for_each_exposed_face does.
void for_each_layer_mesh(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, size_t phase,
                         const std::function<void(const LayerMesh&)>& visit) {
    const uint64_t points_x = uint64_t(voxels.grid().dims[0]) + 1;
    uint64_t vertices = 0;
    LayerMesh mesh;
    // The vertices of the lattice planes under and over the current voxel layer z (of the last
    // face seen), and the layer before it that had faces.
    PlaneVertices bottom, top;
    int64_t z = -1, last_z = -2;
    auto vertex_at = [&](const std::array<int64_t, 3>& p) {
        bool inserted;
        const uint32_t vertex = (p[2] == z ? bottom : top)
                                    .find_or_add(uint64_t(p[0]) + points_x * uint64_t(p[1]),
                                                 uint32_t(vertices), inserted);
        if (inserted) {
            // PLY indices are signed 32-bit; OBJ shares the limit to keep one code path.
            if (vertices >= uint64_t(std::numeric_limits<int32_t>::max()))
                throw OutputError("cannot write " + path +
                                  ": the surface has more than 2^31 vertices");
            ++vertices;
            mesh.new_points.push_back(p);
        }
        return vertex;
    };
    // The vertices of the current voxel's 8 corners (bit 0: +x, 1: +y, 2: +z), each looked up when
    // first needed (kNone until then), so a vertex is still numbered at its first use; the
    // corners a voxel shares with the previous voxel of its row carry over.
    constexpr uint32_t kNone = ~uint32_t(0);
    std::array<uint32_t, 8> corner;
    std::array<int64_t, 3> corner_voxel{-2, -1, -1};  // the voxel `corner` is for
    for_each_exposed_face(
        voxels, progress, phase,
        [&](int64_t x, int64_t y, int64_t face_z, int direction) {
            if (face_z != z) {
                // The points of plane z are the last layer's top ones if it was layer z - 1.
                z = face_z;
                std::swap(bottom, top);
                if (last_z != z - 1) bottom.clear();
                top.clear();
                last_z = z;
            }
            if (x != corner_voxel[0] || y != corner_voxel[1] || z != corner_voxel[2]) {
                const bool next_in_row =
                    x == corner_voxel[0] + 1 && y == corner_voxel[1] && z == corner_voxel[2];
                for (int c = 0; c < 8; c += 2)
                    corner[size_t(c)] = next_in_row ? corner[size_t(c + 1)] : kNone;
                for (int c = 1; c < 8; c += 2) corner[size_t(c)] = kNone;
                corner_voxel = {x, y, z};
            }
            // The face lies in the plane axis = index (+1 for the positive side); u, v follow
            // axis cyclically so that u x v = +axis and the corner order p, p+u, p+u+v, p+v
            // faces +axis.
            const int axis = direction / 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
            const bool positive = direction % 2 == 0;
            auto vertex = [&](int c) {
                if (corner[size_t(c)] == kNone)
                    corner[size_t(c)] = vertex_at({x + (c & 1), y + (c >> 1 & 1), z + (c >> 2)});
                return corner[size_t(c)];
            };
            const int p = positive ? 1 << axis : 0;
            const uint32_t a = vertex(p), b = vertex(p | 1 << u), c = vertex(p | 1 << u | 1 << v),
                           d = vertex(p | 1 << v);
            mesh.quads.push_back(positive ? std::array<uint32_t, 4>{a, b, c, d}
                                          : std::array<uint32_t, 4>{a, d, c, b});
        },
        [&] {
            visit(mesh);
            mesh.new_points.clear();
            mesh.quads.clear();
        });
}

double world_coordinate(const Grid& grid, int axis, int64_t lattice) {
    return grid.origin[axis] + double(lattice) * grid.voxel_size;
}

// The OBJ text of lattice coordinates (shortest round-trip decimals of world_coordinate), kept
// in a direct-mapped cache per axis: a layer's vertices share their z and mostly nearby x and y,
// and formatting a double costs several times copying its text.
class CoordinateText {
  public:
    explicit CoordinateText(const Grid& grid) : grid_(grid) {}
    void write(BlockWriter& w, int axis, int64_t lattice) {
        Entry& e = cache_[size_t(axis)][size_t(lattice) % kEntries];
        if (e.lattice != lattice) {
            const auto end = std::to_chars(e.text, e.text + sizeof e.text,
                                           world_coordinate(grid_, axis, lattice))
                                 .ptr;
            e.length = uint8_t(end - e.text);
            e.lattice = lattice;
        }
        w.bytes(e.text, e.length);
    }

  private:
    static constexpr size_t kEntries = 4096;
    struct Entry {
        int64_t lattice = -1;
        uint8_t length = 0;
        char text[32];
    };
    const Grid& grid_;
    std::array<std::vector<Entry>, 3> cache_{
        std::vector<Entry>(kEntries), std::vector<Entry>(kEntries), std::vector<Entry>(kEntries)};
};

}  // namespace

void write_cube_mesh_obj(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress) {
    const Grid& grid = voxels.grid();
    const size_t pass = progress.add(1);
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter w(out);
        CoordinateText coordinates(grid);
        w.text("# oclvox: exposed faces of " + std::to_string(voxels.count()) + " voxels\n");
        for_each_layer_mesh(path, voxels, progress, pass, [&](const LayerMesh& layer) {
            for (const auto& p : layer.new_points) {
                w.character('v');
                for (int axis = 0; axis < 3; ++axis) {
                    w.character(' ');
                    coordinates.write(w, axis, p[size_t(axis)]);
                }
                w.character('\n');
            }
            for (const auto& quad : layer.quads) {  // OBJ indices start at 1
                w.character('f');
                for (const uint32_t index : quad) {
                    w.character(' ');
                    w.number(uint64_t(index) + 1);
                }
                w.character('\n');
            }
        });
        w.flush();
        progress.finish();
    });
}

// The PLY header of a mesh of `vertices` and `quads`, its comment line padded with spaces to the
// length of the header of the largest counts, so that the header of the counts found by the walks
// replaces the one written before them byte for byte.
std::string cube_mesh_ply_header(uint64_t voxels, uint64_t vertices, uint64_t quads) {
    auto header = [&](const std::string& comment, uint64_t v, uint64_t q) {
        return "ply\nformat binary_little_endian 1.0\n" + comment + "\nelement vertex " +
               std::to_string(v) +
               "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
               std::to_string(q) + "\nproperty list uchar int vertex_indices\nend_header\n";
    };
    const std::string comment =
        "comment oclvox: exposed faces of " + std::to_string(voxels) + " voxels";
    const size_t longest =
        header(comment, uint64_t(std::numeric_limits<int32_t>::max()), ~uint64_t(0)).size();
    const size_t length = header(comment, vertices, quads).size();
    return header(comment + std::string(longest - length, ' '), vertices, quads);
}

void write_cube_mesh_ply(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress) {
    const Grid& grid = voxels.grid();
    const uint64_t voxel_count = voxels.count();
    // Two walks over the layers (vertices, faces) after a header with room for any counts, which
    // are written into it at the end. A grid whose vertices could pass PLY's signed 32-bit
    // indices (over 2^31 / 8 voxels) is walked once more first, so that one over the limit is
    // refused (by for_each_layer_mesh) before its file is written.
    const bool may_pass_limit = 8 * voxel_count >= uint64_t(std::numeric_limits<int32_t>::max());
    const size_t checking = may_pass_limit ? progress.add(1) : 0, vertex_pass = progress.add(1),
                 face_pass = progress.add(1);
    if (may_pass_limit)
        for_each_layer_mesh(path, voxels, progress, checking, [](const LayerMesh&) {});
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter w(out);
        w.text(cube_mesh_ply_header(voxel_count, 0, 0));
        uint64_t vertices = 0, quads = 0;
        for_each_layer_mesh(path, voxels, progress, vertex_pass, [&](const LayerMesh& layer) {
            vertices += layer.new_points.size();
            quads += layer.quads.size();
            for (const auto& p : layer.new_points)
                for (int axis = 0; axis < 3; ++axis)
                    w.little_endian(world_coordinate(grid, axis, p[size_t(axis)]));
        });
        for_each_layer_mesh(path, voxels, progress, face_pass, [&](const LayerMesh& layer) {
            for (const auto& quad : layer.quads) {
                w.character(char(4));
                for (const uint32_t index : quad) w.little_endian(int32_t(index));
            }
        });
        w.flush();
        out.seekp(0);
        out << cube_mesh_ply_header(voxel_count, vertices, quads);
        progress.finish();
    });
}

// STL has no shared vertices: each exposed face is two triangles written as it comes, and the
// count, known at the end, is written into the header then. A grid whose faces could pass STL's
// 32-bit count (more than 2^32 / 12 voxels: 6 faces each, 2 triangles a face) is counted in a
// walk of its own first, so that one over the limit is refused before its file is written.
void write_cube_mesh_stl(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress) {
    const Grid& grid = voxels.grid();
    const uint64_t voxel_count = voxels.count();
    const bool may_pass_limit = 12 * voxel_count > std::numeric_limits<uint32_t>::max();
    const size_t counting = may_pass_limit ? progress.add(1) : 0, face_pass = progress.add(1);
    if (may_pass_limit) {
        uint64_t faces = 0;
        for_each_exposed_face(
            voxels, progress, counting, [&](int64_t, int64_t, int64_t, int) { ++faces; }, [] {});
        if (2 * faces > std::numeric_limits<uint32_t>::max())
            throw OutputError("cannot write " + path +
                              ": the surface has more than 2^32 triangles");
    }
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter w(out);
        write_stl_header(w, "oclvox: exposed faces of " + std::to_string(voxel_count) + " voxels",
                         0);
        uint64_t faces = 0;
        for_each_exposed_face(
            voxels, progress, face_pass,
            [&](int64_t x, int64_t y, int64_t z, int direction) {
                // The quad of for_each_layer_mesh, split along its first diagonal.
                const int axis = direction / 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
                const bool positive = direction % 2 == 0;
                std::array<int64_t, 3> p{x, y, z};
                if (positive) p[size_t(axis)] += 1;
                auto corner = [&](int du, int dv) {
                    std::array<double, 3> world;
                    for (int k = 0; k < 3; ++k)
                        world[size_t(k)] = world_coordinate(
                            grid, k, p[size_t(k)] + (k == u ? du : 0) + (k == v ? dv : 0));
                    return world;
                };
                const auto a = corner(0, 0), b = corner(1, 0), c = corner(1, 1), d = corner(0, 1);
                ++faces;
                // The face's normal, +-axis: what the corners give, exactly (their differences
                // are +0 or positive, so the products are, and the length is the one component).
                std::array<double, 3> n{};
                n[size_t(axis)] = positive ? 1.0 : -1.0;
                if (positive) {
                    write_stl_facet(w, n, a, b, c);
                    write_stl_facet(w, n, a, c, d);
                } else {
                    write_stl_facet(w, n, a, d, c);
                    write_stl_facet(w, n, a, c, b);
                }
            },
            [] {});
        w.flush();
        out.seekp(kStlCountOffset);
        write_le(out, uint32_t(2 * faces));
        progress.finish();
    });
}

}  // namespace oclvox::detail
