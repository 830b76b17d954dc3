// Voxel cubes as a surface mesh (.obj, binary little-endian .ply, or binary .stl with each quad
// split into two triangles).
//
// Only exposed faces are emitted: a face between two set voxels is inside the solid. Each face is
// one quad in world coordinates (origin + lattice index * voxel_size), wound counter-clockwise
// seen from outside so the right-hand normal points out of the set voxel. In OBJ and PLY corners
// are lattice points shared by all the quads that touch them, so the mesh is indexed, not a quad
// soup, its vertices numbered in order of first use.
//
// Streaming, on every core: the voxel layers go through stream_parts a slab of layers at a time,
// and within a slab each layer is made on its own. A layer's faces come in (y, x, direction)
// order straight from the voxels' rows: a brick's rows of a layer are its bits along x
// (brick-local y), so a row's exposed faces in one direction are the row less its neighbour row
// (y +- 1, z +- 1) or its own bits shifted by one (x +- 1), a few word operations a row. Its
// corners, lattice points of the layer's bottom and top planes, are numbered in order of first use
// within the layer. Then, in layer order, a count: a bottom point that the layer below used keeps
// that layer's number, and the layer's other points take the next numbers in the layer's order,
// which is the order of first use over the whole mesh; so the file does not depend on the slab
// thickness, the brick size or the cores. Each layer's bytes are then formatted on any core, and a
// task writes the slab while the next one is made. OBJ takes each layer's new vertices and quads
// in turn; PLY, which needs all vertices before any face, streams the layers twice (vertices,
// faces) and writes its header's counts, known only then, at the end; STL, which has no shared
// vertices, streams them once, its count too written at the end.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <charconv>
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

// PLY indices are signed 32-bit; OBJ shares the limit to keep one code path.
constexpr uint64_t kMaxVertices = uint64_t(std::numeric_limits<int32_t>::max());

// A lattice point of a layer's bottom or top plane as one word: x in the low bits, y above them
// (an axis has at most kMaxGridAxis voxels, so kMaxGridAxis + 1 lattice points), and kTopPlane
// set for the top plane.
constexpr int kPointYShift = 21;
static_assert(kMaxGridAxis < int64_t(1) << kPointYShift);
constexpr uint64_t kPointX = (uint64_t(1) << kPointYShift) - 1;
constexpr uint64_t kTopPlane = uint64_t(1) << 63;
uint64_t plane_point(int64_t x, int64_t y) {
    return uint64_t(x) | uint64_t(y) << kPointYShift;
}

// The vertex numbers of one lattice plane's points (plane_point keys): open addressing, cleared in
// time proportional to what it holds, so a plane costs its own points only.
class PlaneVertices {
  public:
    static constexpr uint32_t kNone = ~uint32_t(0);

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
    // The vertex of `key`, or kNone.
    uint32_t find(uint64_t key) const {
        if (used_.empty()) return kNone;
        for (size_t slot = hash(key);; slot = (slot + 1) & (keys_.size() - 1)) {
            if (keys_[slot] == key) return vertices_[slot];
            if (keys_[slot] == kEmpty) return kNone;
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

// A voxel layer's rows and its two neighbours', as ExposedFaces reads them.
struct LayerRows {
    std::vector<uint64_t> below, here, above;
};

// The exposed faces of the voxels, a voxel layer at a time; any number of layers at once.
class ExposedFaces {
  public:
    explicit ExposedFaces(const SparseVoxels& voxels)
        : voxels_(voxels),
          layout_(voxels),
          bricks_(voxels.brick_indices()),  // sorted: brick layers in z order
          brick_(voxels.brick_size()),
          blocks_(voxels.blocks_per_brick_axis()),
          words_((brick_ + 63) / 64),
          nbx_(uint64_t(voxels.brick_dims()[0])),
          nby_(uint64_t(voxels.brick_dims()[1])),
          voxels_set_(voxels.count()) {}

    int64_t brick_size() const { return brick_; }
    // The set voxels, counted once (a pass over every brick's words).
    uint64_t voxels_set() const { return voxels_set_; }

    // The stored bricks of brick layer `brick_z`, with their neighbours.
    BrickLayer brick_layer(int64_t brick_z) const {
        const uint64_t per_layer = layout_.layer_bricks();
        BrickLayer layer;
        layer.bricks.assign(
            std::lower_bound(bricks_.begin(), bricks_.end(), uint64_t(brick_z) * per_layer),
            std::lower_bound(bricks_.begin(), bricks_.end(), uint64_t(brick_z + 1) * per_layer));
        auto position = [&](uint64_t brick) {
            const auto it = std::lower_bound(layer.bricks.begin(), layer.bricks.end(), brick);
            return it != layer.bricks.end() && *it == brick ? int64_t(it - layer.bricks.begin())
                                                            : int64_t(-1);
        };
        for (const uint64_t brick : layer.bricks) {
            const uint64_t bx = brick % nbx_, by = brick / nbx_ % nby_;
            layer.neighbours.push_back({bx > 0 ? position(brick - 1) : -1,
                                        bx + 1 < nbx_ ? position(brick + 1) : -1,
                                        by > 0 ? position(brick - nbx_) : -1,
                                        by + 1 < nby_ ? position(brick + nbx_) : -1});
        }
        return layer;
    }

    // Calls face(x, y, direction) for every exposed face of voxel layer z, whose brick layer is
    // `layer`, in (y, x, direction) order. Face `direction` of a voxel: axis direction / 2,
    // towards +axis when direction is even.
    template <class Face>
    void for_each(const BrickLayer& layer, int64_t z, LayerRows& rows, Face&& face) const {
        const auto& dims = voxels_.grid().dims;
        read(layer, z - 1, rows.below);
        read(layer, z, rows.here);
        read(layer, z + 1, rows.above);
        uint64_t exposed[6 * kMaxWords];              // per direction, a row's exposed voxels
        const int last_bit = int((brick_ - 1) % 64);  // of the row's last word
        // Rows in (y, x) order: a run of bricks with the same brick y, each voxel row across
        // them.
        for (size_t run = 0; run < layer.bricks.size();) {
            size_t run_end = run;
            while (run_end < layer.bricks.size() &&
                   layer.bricks[run_end] / nbx_ == layer.bricks[run] / nbx_)
                ++run_end;
            const int64_t y_first = int64_t(layer.bricks[run] / nbx_ % nby_) * brick_;
            for (int64_t ly = 0; ly < brick_ && y_first + ly < dims[1]; ++ly)
                for (size_t b = run; b < run_end; ++b) {
                    const uint64_t* set = row(rows.here, int64_t(b), ly);
                    bool any = false;
                    for (int64_t w = 0; w < words_; ++w) any = any || set[w] != 0;
                    if (!any) continue;
                    const auto& n = layer.neighbours[b];
                    const uint64_t* beside[4] = {
                        ly + 1 < brick_ ? row(rows.here, int64_t(b), ly + 1)
                        : n[3] >= 0     ? row(rows.here, n[3], 0)
                                        : nullptr,
                        ly > 0      ? row(rows.here, int64_t(b), ly - 1)
                        : n[2] >= 0 ? row(rows.here, n[2], brick_ - 1)
                                    : nullptr,
                        row(rows.above, int64_t(b), ly), row(rows.below, int64_t(b), ly)};
                    // The voxels just past the row's ends, in its x neighbours' rows.
                    const bool after = n[1] >= 0 && (row(rows.here, n[1], ly)[0] & 1);
                    const bool before =
                        n[0] >= 0 && (row(rows.here, n[0], ly)[words_ - 1] >> last_bit & 1);
                    for (int64_t w = 0; w < words_; ++w) {
                        // Whether voxel x + 1 (x - 1) is set, at bit x.
                        uint64_t plus_x = set[w] >> 1 | (w + 1 < words_ ? set[w + 1] << 63 : 0);
                        if (w + 1 == words_ && after) plus_x |= uint64_t(1) << last_bit;
                        const uint64_t minus_x = set[w] << 1 | (w > 0    ? set[w - 1] >> 63
                                                                : before ? 1
                                                                         : 0);
                        uint64_t* e = &exposed[size_t(6 * w)];
                        e[0] = set[w] & ~plus_x;
                        e[1] = set[w] & ~minus_x;
                        for (int d = 2; d < 6; ++d)
                            e[d] = set[w] & ~(beside[d - 2] ? beside[d - 2][w] : 0);
                    }
                    const int64_t x_first = int64_t(layer.bricks[b] % nbx_) * brick_;
                    for (int64_t w = 0; w < words_; ++w) {
                        const uint64_t* e = &exposed[size_t(6 * w)];
                        for (uint64_t faces = e[0] | e[1] | e[2] | e[3] | e[4] | e[5]; faces;
                             faces &= faces - 1) {
                            const int bit = __builtin_ctzll(faces);
                            for (int d = 0; d < 6; ++d)
                                if (e[d] >> bit & 1) face(x_first + 64 * w + bit, y_first + ly, d);
                        }
                    }
                }
            run = run_end;
        }
    }

  private:
    static constexpr int64_t kMaxWords = (1024 + 63) / 64;  // of a row of the largest bricks

    // Reads voxel layer z of the bricks at the same x and y as `layer`'s (in the brick layer
    // holding z) as rows along x: row y (brick-local) of brick b is words
    // [(b * brick + y) * words, ... + words), bit x % 64 of word x / 64 being brick-local voxel
    // x. Bricks not stored there, and layers outside the grid, are zero rows.
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

    const SparseVoxels& voxels_;
    const BrickLayout layout_;
    const std::vector<uint64_t> bricks_;
    const int64_t brick_, blocks_, words_;
    const uint64_t nbx_, nby_;
    const uint64_t voxels_set_;
};

// One voxel layer's share of the mesh, made on its own: its corners in order of first use
// (plane_point keys, kTopPlane on the top plane) and its quads as indices into them (outward
// winding); the indices of its top plane's corners, among which the layer above finds the
// corners it shares; and, once numbered (number_layers), which corners are new to the file.
struct LayerMesh {
    std::vector<uint64_t> points;
    std::vector<std::array<uint32_t, 4>> quads;
    PlaneVertices top;
    // Per corner: one new to the file, its rank among the layer's new corners; one the layer
    // below used, kFromBelow | its index there.
    std::vector<uint32_t> origin;
    uint64_t first_number = 0;  // the file's number (from 0) of the layer's first new corner
    uint64_t new_points = 0;
};
constexpr uint32_t kFromBelow = uint32_t(1) << 31;

OutputError too_many_vertices(const std::string& path) {
    return OutputError("cannot write " + path + ": the surface has more than 2^31 vertices");
}

// A layer's scratch: its rows, and its bottom plane's corners.
struct LayerScratch {
    LayerRows rows;
    PlaneVertices bottom;
};

// Layer z's quads and corners, in LayerMesh; returns how many quads.
uint64_t make_layer_mesh(const ExposedFaces& faces, const BrickLayer& bricks, int64_t z,
                         LayerScratch& scratch, const std::string& path, LayerMesh& mesh) {
    mesh.points.clear();
    mesh.quads.clear();
    mesh.top.clear();
    scratch.bottom.clear();
    auto vertex_at = [&](int64_t x, int64_t y, bool on_top) {
        bool inserted;
        const uint64_t key = plane_point(x, y);
        const uint32_t vertex = (on_top ? mesh.top : scratch.bottom)
                                    .find_or_add(key, uint32_t(mesh.points.size()), inserted);
        if (inserted) {
            if (mesh.points.size() >= kMaxVertices) throw too_many_vertices(path);
            mesh.points.push_back(on_top ? key | kTopPlane : key);
        }
        return vertex;
    };
    // The corners of the current voxel (bit 0: +x, 1: +y, 2: +z), each looked up when first
    // needed (kNone until then), so a corner is still numbered at its first use; the corners a
    // voxel shares with the previous voxel of its row carry over.
    constexpr uint32_t kNone = PlaneVertices::kNone;
    std::array<uint32_t, 8> corner;
    int64_t corner_x = -2, corner_y = -1;  // the voxel `corner` is for
    faces.for_each(bricks, z, scratch.rows, [&](int64_t x, int64_t y, int direction) {
        if (x != corner_x || y != corner_y) {
            const bool next_in_row = x == corner_x + 1 && y == corner_y;
            for (size_t c = 0; c < 8; c += 2) corner[c] = next_in_row ? corner[c + 1] : kNone;
            for (size_t c = 1; c < 8; c += 2) corner[c] = kNone;
            corner_x = x;
            corner_y = y;
        }
        // The face lies in the plane axis = index (+1 for the positive side); u, v follow axis
        // cyclically so that u x v = +axis and the corner order p, p+u, p+u+v, p+v faces +axis.
        const int axis = direction / 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
        const bool positive = direction % 2 == 0;
        auto vertex = [&](int c) {
            if (corner[size_t(c)] == kNone)
                corner[size_t(c)] = vertex_at(x + (c & 1), y + (c >> 1 & 1), c >> 2 & 1);
            return corner[size_t(c)];
        };
        const int p = positive ? 1 << axis : 0;
        const uint32_t a = vertex(p), b = vertex(p | 1 << u), c = vertex(p | 1 << u | 1 << v),
                       d = vertex(p | 1 << v);
        mesh.quads.push_back(positive ? std::array<uint32_t, 4>{a, b, c, d}
                                      : std::array<uint32_t, 4>{a, d, c, b});
    });
    return mesh.quads.size();
}

// Which of the layer's corners the layer below (`below`; empty under the first layer) used: the
// corners of its top plane, which is this layer's bottom one; the others ranked in the layer's
// order.
void find_new_points(const LayerMesh& below, LayerMesh& mesh) {
    mesh.origin.resize(mesh.points.size());
    uint32_t fresh = 0;
    for (size_t i = 0; i < mesh.points.size(); ++i) {
        const uint64_t p = mesh.points[i];
        const uint32_t there = p & kTopPlane ? PlaneVertices::kNone : below.top.find(p);
        mesh.origin[i] = there != PlaneVertices::kNone ? kFromBelow | there : fresh++;
    }
    mesh.new_points = fresh;
}

// The file's number (from 0) of the layer's corner i (the corners of the layer below's top
// plane are all new there).
uint64_t number_of(const LayerMesh& below, const LayerMesh& mesh, uint32_t i) {
    const uint32_t origin = mesh.origin[i];
    return origin & kFromBelow ? below.first_number + below.origin[origin & ~kFromBelow]
                               : mesh.first_number + origin;
}

// Layers per slab: four per core and at least 16, to share out layers of different sizes (a
// solid's 512^3 .obj: 16-layer slabs 0.074-0.077 s, 4-layer 0.092-0.094 s), but no more than
// keep a slab within about kMeshSlabBytes when each set voxel of an average layer has six faces
// of 48 bytes (an overestimate for all but the thinnest shells), and never fewer than two per
// core.
constexpr double kMeshSlabBytes = double(uint64_t(256) << 20);
int64_t slab_layers_for(const ExposedFaces& faces, const Grid& grid) {
    const int64_t cores = tbb::this_task_arena::max_concurrency();
    const double layer_bytes = 6.0 * 48.0 * double(faces.voxels_set()) / double(grid.dims[2]);
    const int64_t fit = int64_t(std::min(64.0, kMeshSlabBytes / std::max(layer_bytes, 1.0)));
    return std::max(std::min(std::max<int64_t>(4 * cores, 16), fit),
                    std::min<int64_t>(2 * cores, 64));
}

enum class Corners { Numbered, None };

struct MeshSlab {
    std::vector<BlockWriter> bytes;
    std::vector<LayerMesh> meshes;
    std::vector<uint64_t> faces;
};

struct MeshCounts {
    uint64_t vertices = 0, faces = 0;
};

// Streams the voxel layers as the parts of a file (stream_parts) in slabs of `slab_layers` (0:
// slab_layers_for), writing each layer's bytes to `out` in layer order (nothing without `out`: a
// walk that only counts), and reports the layers done as phase `phase`. For each slab, on any
// core: make(bricks, z, scratch, mesh, bytes) makes layer z (its brick layer `bricks`) and
// returns its faces (its bytes to `bytes`, null when counting, or its LayerMesh); then, with
// Corners::Numbered, the layers' corners are numbered in layer order, and format(below, mesh, z,
// bytes) makes the bytes of a numbered layer (`below` the layer under it). Returns the counts of
// the walk.
template <class Make, class Format>
MeshCounts stream_layers(const ExposedFaces& faces, const SparseVoxels& voxels,
                         const std::string& path, std::ostream* out, int64_t slab_layers,
                         Corners corners, ProgressPhases& progress, size_t phase, Make&& make,
                         Format&& format) {
    const int64_t nz = voxels.grid().dims[2], brick = faces.brick_size();
    tbb::enumerable_thread_specific<LayerScratch> scratch;
    LayerMesh carried;  // the layer below the slab being made (its last layer, once numbered)
    MeshCounts counts;
    stream_parts<MeshSlab>(
        out, nz, slab_layers > 0 ? slab_layers : slab_layers_for(faces, voxels.grid()),
        [&](MeshSlab& slab, int64_t first, int64_t end) {
            const size_t layers = size_t(end - first);
            slab.meshes.resize(layers);
            slab.faces.assign(layers, 0);
            std::vector<BrickLayer> bricks;  // of the brick layers the slab lies in
            for (int64_t bz = first / brick; bz <= (end - 1) / brick; ++bz)
                bricks.push_back(faces.brick_layer(bz));
            // Phase 1: each layer's faces, on any core.
            tbb::parallel_for(size_t(0), layers, [&](size_t i) {
                const int64_t z = first + int64_t(i);
                slab.faces[i] = make(bricks[size_t(z / brick - first / brick)], z, scratch.local(),
                                     slab.meshes[i], out ? &slab.bytes[i] : nullptr);
            });
            for (const uint64_t n : slab.faces) counts.faces += n;
            if (corners == Corners::None) return;
            // Phase 2: which corners are new to the file, each layer against the one below.
            auto below = [&](size_t i) -> const LayerMesh& {
                return i ? slab.meshes[i - 1] : carried;
            };
            tbb::parallel_for(size_t(0), layers,
                              [&](size_t i) { find_new_points(below(i), slab.meshes[i]); });
            // Phase 3: the file's numbers of the layers' new corners, in layer order.
            for (LayerMesh& mesh : slab.meshes) {
                mesh.first_number = counts.vertices;
                counts.vertices += mesh.new_points;
                if (counts.vertices > kMaxVertices) throw too_many_vertices(path);
            }
            // Phase 4: each layer's bytes, on any core.
            if (out)
                tbb::parallel_for(size_t(0), layers, [&](size_t i) {
                    format(below(i), slab.meshes[i], first + int64_t(i), slab.bytes[i]);
                });
            std::swap(carried, slab.meshes.back());
        },
        [&](int64_t first) { progress.report(phase, uint64_t(first), uint64_t(nz)); });
    return counts;
}

double world_coordinate(const Grid& grid, int axis, int64_t lattice) {
    return grid.origin[axis] + double(lattice) * grid.voxel_size;
}

// The OBJ text (shortest round-trip decimal) of every lattice coordinate of one axis, made once:
// formatting a double costs several times copying its text, and each is used many times.
class LatticeText {
  public:
    LatticeText(const Grid& grid, int axis) {
        const int64_t points = grid.dims[size_t(axis)] + 1;
        start_.reserve(size_t(points) + 1);
        start_.push_back(0);
        char text[32];
        for (int64_t i = 0; i < points; ++i) {
            char* const end =
                std::to_chars(text, text + sizeof text, world_coordinate(grid, axis, i)).ptr;
            chars_.insert(chars_.end(), text, end);
            start_.push_back(uint32_t(chars_.size()));
        }
    }
    void write(BlockWriter& w, int64_t lattice) const {
        w.bytes(&chars_[start_[size_t(lattice)]],
                start_[size_t(lattice) + 1] - start_[size_t(lattice)]);
    }

  private:
    std::vector<char> chars_;
    std::vector<uint32_t> start_;
};

// make for the indexed formats: the layer's LayerMesh.
auto mesh_maker(const ExposedFaces& faces, const std::string& path) {
    return [&faces, &path](const BrickLayer& bricks, int64_t z, LayerScratch& scratch,
                           LayerMesh& mesh, BlockWriter*) {
        return make_layer_mesh(faces, bricks, z, scratch, path, mesh);
    };
}

}  // namespace

void write_cube_mesh_obj(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, int64_t slab_layers) {
    const Grid& grid = voxels.grid();
    const size_t pass = progress.add(1);
    const ExposedFaces faces(voxels);
    const LatticeText x_text(grid, 0), y_text(grid, 1);
    // A layer's new vertices, then its quads (OBJ indices start at 1).
    auto layer_text = [&](const LayerMesh& below, const LayerMesh& mesh, int64_t z,
                          BlockWriter& w) {
        char z_text[2][32];
        size_t z_length[2];
        for (int plane = 0; plane < 2; ++plane)
            z_length[plane] = size_t(std::to_chars(z_text[plane], z_text[plane] + 32,
                                                   world_coordinate(grid, 2, z + plane))
                                         .ptr -
                                     z_text[plane]);
        for (size_t i = 0; i < mesh.points.size(); ++i) {
            if (mesh.origin[i] & kFromBelow) continue;
            const uint64_t p = mesh.points[i];
            const int plane = p & kTopPlane ? 1 : 0;
            w.bytes("v ", 2);
            x_text.write(w, int64_t(p & kPointX));
            w.character(' ');
            y_text.write(w, int64_t(p >> kPointYShift & kPointX));
            w.character(' ');
            w.bytes(z_text[plane], z_length[plane]);
            w.character('\n');
        }
        for (const auto& quad : mesh.quads) {
            w.character('f');
            for (const uint32_t corner : quad) {
                w.character(' ');
                w.number(number_of(below, mesh, corner) + 1);
            }
            w.character('\n');
        }
    };
    write_file_atomically(path, [&](std::ostream& out) {
        out << "# oclvox: exposed faces of " << faces.voxels_set() << " voxels\n";
        stream_layers(faces, voxels, path, &out, slab_layers, Corners::Numbered, progress, pass,
                      mesh_maker(faces, path), layer_text);
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
                         ProgressPhases& progress, int64_t slab_layers) {
    const Grid& grid = voxels.grid();
    const ExposedFaces faces(voxels);
    const uint64_t voxel_count = faces.voxels_set();
    // Two walks over the layers (vertices, faces) after a header with room for any counts, which
    // are written into it at the end. A grid whose vertices could pass PLY's signed 32-bit
    // indices (over 2^31 / 8 voxels) is walked once more first, so that one over the limit is
    // refused before its file is written.
    const bool may_pass_limit = 8 * voxel_count >= kMaxVertices;
    const size_t checking = may_pass_limit ? progress.add(1) : 0, vertex_pass = progress.add(1),
                 face_pass = progress.add(1);
    auto no_bytes = [](const LayerMesh&, const LayerMesh&, int64_t, BlockWriter&) {};
    if (may_pass_limit)
        stream_layers(faces, voxels, path, nullptr, slab_layers, Corners::Numbered, progress,
                      checking, mesh_maker(faces, path), no_bytes);
    write_file_atomically(path, [&](std::ostream& out) {
        out << cube_mesh_ply_header(voxel_count, 0, 0);
        const MeshCounts counts = stream_layers(
            faces, voxels, path, &out, slab_layers, Corners::Numbered, progress, vertex_pass,
            mesh_maker(faces, path),
            [&](const LayerMesh&, const LayerMesh& mesh, int64_t z, BlockWriter& w) {
                for (size_t i = 0; i < mesh.points.size(); ++i) {
                    if (mesh.origin[i] & kFromBelow) continue;
                    const uint64_t p = mesh.points[i];
                    w.little_endian(world_coordinate(grid, 0, int64_t(p & kPointX)));
                    w.little_endian(
                        world_coordinate(grid, 1, int64_t(p >> kPointYShift & kPointX)));
                    w.little_endian(world_coordinate(grid, 2, z + (p & kTopPlane ? 1 : 0)));
                }
            });
        stream_layers(faces, voxels, path, &out, slab_layers, Corners::Numbered, progress,
                      face_pass, mesh_maker(faces, path),
                      [&](const LayerMesh& below, const LayerMesh& mesh, int64_t, BlockWriter& w) {
                          for (const auto& quad : mesh.quads) {
                              w.character(char(4));
                              for (const uint32_t corner : quad)
                                  w.little_endian(int32_t(number_of(below, mesh, corner)));
                          }
                      });
        out.seekp(0);
        out << cube_mesh_ply_header(voxel_count, counts.vertices, counts.faces);
        progress.finish();
    });
}

// STL has no shared vertices: each exposed face is two triangles, made with its layer, and the
// count, known at the end, is written into the header then. A grid whose faces could pass STL's
// 32-bit count (more than 2^32 / 12 voxels: 6 faces each, 2 triangles a face) is counted in a
// walk of its own first, so that one over the limit is refused before its file is written.
void write_cube_mesh_stl(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, int64_t slab_layers) {
    const Grid& grid = voxels.grid();
    const ExposedFaces faces(voxels);
    const uint64_t voxel_count = faces.voxels_set();
    const bool may_pass_limit = 12 * voxel_count > std::numeric_limits<uint32_t>::max();
    const size_t counting = may_pass_limit ? progress.add(1) : 0, face_pass = progress.add(1);
    // make: the layer's faces as triangles to `bytes` (none when counting).
    auto facets = [&](const BrickLayer& bricks, int64_t z, LayerScratch& scratch, LayerMesh&,
                      BlockWriter* bytes) {
        uint64_t count = 0;
        faces.for_each(bricks, z, scratch.rows, [&](int64_t x, int64_t y, int direction) {
            ++count;
            if (!bytes) return;
            // The quad of make_layer_mesh, split along its first diagonal.
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
            // The face's normal, +-axis: what the corners give, exactly (their differences are
            // +0 or positive, so the products are, and the length is the one component).
            std::array<double, 3> n{};
            n[size_t(axis)] = positive ? 1.0 : -1.0;
            if (positive) {
                write_stl_facet(*bytes, n, a, b, c);
                write_stl_facet(*bytes, n, a, c, d);
            } else {
                write_stl_facet(*bytes, n, a, d, c);
                write_stl_facet(*bytes, n, a, c, b);
            }
        });
        return count;
    };
    auto no_bytes = [](const LayerMesh&, const LayerMesh&, int64_t, BlockWriter&) {};
    if (may_pass_limit) {
        const MeshCounts counts =
            stream_layers(faces, voxels, path, nullptr, slab_layers, Corners::None, progress,
                          counting, facets, no_bytes);
        if (2 * counts.faces > std::numeric_limits<uint32_t>::max())
            throw OutputError("cannot write " + path +
                              ": the surface has more than 2^32 triangles");
    }
    write_file_atomically(path, [&](std::ostream& out) {
        {
            BlockWriter w(out);
            write_stl_header(
                w, "oclvox: exposed faces of " + std::to_string(voxel_count) + " voxels", 0);
            w.flush();
        }
        const MeshCounts counts =
            stream_layers(faces, voxels, path, &out, slab_layers, Corners::None, progress,
                          face_pass, facets, no_bytes);
        out.seekp(kStlCountOffset);
        write_le(out, uint32_t(2 * counts.faces));
        progress.finish();
    });
}

}  // namespace oclvox::detail
