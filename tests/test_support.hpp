// Shared helpers for the voxelization tests: small meshes built by hand, and the independent
// double-precision checks that every result is measured against.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <map>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "oclvox/oclvox.hpp"
#include "opencl_runtime.hpp"
#include "overlap_double.hpp"

namespace oclvox::test {

using detail::Vec3d;

// The selector of the OpenCL device the tests run on: $OCLVOX_DEVICE, else the library's default
// choice.
inline std::string device_selector() {
    const char* selector = std::getenv("OCLVOX_DEVICE");
    return selector ? selector : "";
}
// That device, opened once per test process.
inline Device& device() {
    static Device d = Device::open(device_selector());
    return d;
}

// The same device used as a GPU is: its programs built with a GPU's options (no OV_WIDE_BLOCKS,
// so the surface kernels take ov_P_block4 and no prefetch) and its memory treated as its own
// (uploaded inputs, bit buffers it fills, compact downloads by default, no host-memory batch
// cap). On a CPU device that runs, in every run of the suite, the paths a GPU takes, which
// otherwise run only where a GPU is lent. (The kernel cache keeps these builds apart: its key
// holds the options.)
inline Device& device_used_as_a_gpu() {
    static Device d = [] {
        Device opened = Device::open(device_selector());
        Device::Impl& cl = detail::device_impl(opened);
        cl.info.host_unified_memory = false;
        cl.build_options = detail::build_options(cl.device.getInfo<CL_DEVICE_SINGLE_FP_CONFIG>(),
                                                 CL_DEVICE_TYPE_GPU);
        return opened;
    }();
    return d;
}

// $OCLVOX_HOST_MEMORY_MIB set (or unset, for nullptr) for one scope.
class ScopedBudget {
  public:
    explicit ScopedBudget(const char* mib) {
        if (const char* old = std::getenv(kName)) saved_ = old, had_ = true;
        if (mib)
            setenv(kName, mib, 1);
        else
            unsetenv(kName);
    }
    ~ScopedBudget() {
        if (had_)
            setenv(kName, saved_.c_str(), 1);
        else
            unsetenv(kName);
    }

  private:
    static constexpr const char* kName = "OCLVOX_HOST_MEMORY_MIB";
    std::string saved_;
    bool had_ = false;
};

inline Grid unit_grid(int64_t nx, int64_t ny, int64_t nz) {
    Grid g;
    g.dims = {nx, ny, nz};
    return g;
}

inline void add_triangle(Mesh& m, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const auto base = uint32_t(m.positions.size());
    m.positions.push_back(a);
    m.positions.push_back(b);
    m.positions.push_back(c);
    m.triangles.push_back({base, base + 1, base + 2});
}

// Closed box [lo, hi] as 12 outward-facing triangles over 8 shared vertices.
inline Mesh box_mesh(const Vec3d& lo, const Vec3d& hi) {
    Mesh m;
    for (int i = 0; i < 8; ++i)
        m.positions.push_back(
            {i & 1 ? hi[0] : lo[0], i & 2 ? hi[1] : lo[1], i & 4 ? hi[2] : lo[2]});
    const uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                  {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& q : quads) {
        m.triangles.push_back({q[0], q[1], q[2]});
        m.triangles.push_back({q[0], q[2], q[3]});
    }
    return m;
}

// Double-precision vector helpers and the closest point on a triangle (Ericson, Real-Time
// Collision Detection, 5.1.5), written here rather than taken from the library so that they
// check it.
inline Vec3d sub(const Vec3d& a, const Vec3d& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
inline double dot(const Vec3d& a, const Vec3d& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline double norm(const Vec3d& a) {
    return std::sqrt(dot(a, a));
}

inline Vec3d closest_point(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const Vec3d ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return a;
    const Vec3d bp = sub(p, b);
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return b;
    const double vc = d1 * d4 - d3 * d2;
    auto along = [](const Vec3d& o, const Vec3d& e, double t) {
        return Vec3d{o[0] + t * e[0], o[1] + t * e[1], o[2] + t * e[2]};
    };
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return along(a, ab, d1 / (d1 - d3));
    const Vec3d cp = sub(p, c);
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return along(a, ac, d2 / (d2 - d6));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return along(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6)));
    const double denom = 1 / (va + vb + vc);
    const double v = vb * denom, w = vc * denom;
    return {a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w,
            a[2] + ab[2] * v + ac[2] * w};
}

inline double point_triangle_distance(const Vec3d& p, const Vec3d& a, const Vec3d& b,
                                      const Vec3d& c) {
    return norm(sub(p, closest_point(p, a, b, c)));
}

// Icosahedron subdivided `levels` times, vertices on the sphere (centre, radius), wound
// counter-clockwise seen from outside.
inline Mesh icosphere(const Vec3d& centre, double radius, int levels) {
    const double t = (1 + std::sqrt(5.0)) / 2;
    std::vector<Vec3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                            {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                            {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    std::vector<std::array<uint32_t, 3>> f = {
        {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
        {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
        {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
    for (int level = 0; level < levels; ++level) {
        std::map<std::pair<uint32_t, uint32_t>, uint32_t> middle;
        auto mid = [&](uint32_t a, uint32_t b) {
            const auto key = std::minmax(a, b);
            const auto found = middle.find(key);
            if (found != middle.end()) return found->second;
            v.push_back(
                {(v[a][0] + v[b][0]) / 2, (v[a][1] + v[b][1]) / 2, (v[a][2] + v[b][2]) / 2});
            return middle[key] = uint32_t(v.size() - 1);
        };
        std::vector<std::array<uint32_t, 3>> next;
        for (const auto& tri : f) {
            const uint32_t a = mid(tri[0], tri[1]), b = mid(tri[1], tri[2]),
                           c = mid(tri[2], tri[0]);
            next.push_back({tri[0], a, c});
            next.push_back({tri[1], b, a});
            next.push_back({tri[2], c, b});
            next.push_back({a, b, c});
        }
        f = next;
    }
    Mesh m;
    for (const auto& p : v) {
        const double s = radius / norm(p);
        m.positions.push_back({centre[0] + p[0] * s, centre[1] + p[1] * s, centre[2] + p[2] * s});
    }
    m.triangles = f;
    return m;
}

// Triangles with vertices uniform in [lo, hi)^3, each of size up to `span`.
inline Mesh random_triangles(int count, double lo, double hi, double span, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> where(lo, hi), offset(-span, span);
    Mesh m;
    for (int t = 0; t < count; ++t) {
        const Vec3d a{where(rng), where(rng), where(rng)};
        Vec3d b = a, c = a;
        for (int k = 0; k < 3; ++k) {
            b[k] += offset(rng);
            c[k] += offset(rng);
        }
        add_triangle(m, a, b, c);
    }
    return m;
}

inline Vec3d to_grid(const Grid& g, const Vec3d& p) {
    return {(p[0] - g.origin[0]) / g.voxel_size, (p[1] - g.origin[1]) / g.voxel_size,
            (p[2] - g.origin[2]) / g.voxel_size};
}

// Does the closed voxel box, grown (eps > 0) or shrunk (eps < 0) by |eps| voxels, meet the
// triangle in double precision?
inline bool voxel_meets_triangle(const Grid& g, const Mesh& m, size_t t, int64_t i, int64_t j,
                                 int64_t k, double eps) {
    const Vec3d a = to_grid(g, m.positions[m.triangles[t][0]]);
    const Vec3d b = to_grid(g, m.positions[m.triangles[t][1]]);
    const Vec3d c = to_grid(g, m.positions[m.triangles[t][2]]);
    const Vec3d lo{double(i) - eps, double(j) - eps, double(k) - eps};
    const Vec3d hi{double(i + 1) + eps, double(j + 1) + eps, double(k + 1) + eps};
    return detail::triangle_box_overlap_double(a, b, c, lo, hi);
}

// Calls f(t, i, j, k) for every triangle t and grid voxel within `pad` voxels of its box.
template <typename F>
void for_each_nearby_voxel(const Grid& g, const Mesh& m, int pad, F f) {
    for (size_t t = 0; t < m.triangles.size(); ++t) {
        int64_t lo[3], hi[3];
        for (int k = 0; k < 3; ++k) {
            double mn = INFINITY, mx = -INFINITY;
            for (uint32_t v : m.triangles[t]) {
                const double x = to_grid(g, m.positions[v])[k];
                mn = std::min(mn, x);
                mx = std::max(mx, x);
            }
            lo[k] = std::max<int64_t>(0, int64_t(std::floor(mn)) - pad);
            hi[k] = std::min<int64_t>(g.dims[k] - 1, int64_t(std::floor(mx)) + pad);
        }
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
            for (int64_t y = lo[1]; y <= hi[1]; ++y)
                for (int64_t x = lo[0]; x <= hi[0]; ++x) f(t, x, y, z);
    }
}

// The two halves of "exact up to rounding", against the double-precision SAT on the original
// (unrounded) triangles:
//  - conservative: every voxel that a triangle meets even after shrinking the voxel by eps is set;
//  - no false positives: every set voxel meets some triangle once the voxel is grown by eps.
inline void expect_exact_up_to(const SparseVoxels& v, const Mesh& m, double eps) {
    const Grid& g = v.grid();
    SparseVoxels justified(g, v.brick_size());
    uint64_t missing = 0;
    for_each_nearby_voxel(g, m, 1, [&](size_t t, int64_t i, int64_t j, int64_t k) {
        if (voxel_meets_triangle(g, m, t, i, j, k, eps)) justified.set(i, j, k);
        if (voxel_meets_triangle(g, m, t, i, j, k, -eps) && !v.get(i, j, k) && missing++ < 5)
            ADD_FAILURE() << "voxel " << i << "," << j << "," << k << " meets triangle " << t
                          << " but is not set";
    });
    uint64_t unjustified = 0;
    v.for_each([&](int64_t i, int64_t j, int64_t k) {
        if (!justified.get(i, j, k) && unjustified++ < 5)
            ADD_FAILURE() << "voxel " << i << "," << j << "," << k
                          << " is set but no triangle comes within " << eps << " voxels of it";
    });
    EXPECT_EQ(missing, 0u);
    EXPECT_EQ(unjustified, 0u);
}

// A compact download (Download::NonEmptyBlocks) brings back 12 bytes (index and two words) per
// non-empty 4^3 block of the result, counted here from its voxels, plus a 4-byte count per 64
// blocks of each batch (at most 1/128 of the whole download, and one partial group per batch).
inline void expect_compact_download(const SparseVoxels& result, const VoxelizeStats& whole,
                                    const VoxelizeStats& compact) {
    std::vector<uint64_t> blocks;
    result.for_each([&](int64_t i, int64_t j, int64_t k) {
        blocks.push_back(uint64_t(i / 4) | uint64_t(j / 4) << 21 | uint64_t(k / 4) << 42);
    });
    std::sort(blocks.begin(), blocks.end());
    const uint64_t non_empty = std::unique(blocks.begin(), blocks.end()) - blocks.begin();
    EXPECT_GE(whole.bytes_downloaded, 8 * non_empty);
    EXPECT_GE(compact.bytes_downloaded, 12 * non_empty);
    EXPECT_LE(compact.bytes_downloaded,
              12 * non_empty + whole.bytes_downloaded / 128 + 4 * compact.batches);
}

// Voxels set in exactly one of a and b must all be touching cases: within eps of some triangle,
// and not met by any triangle once shrunk by eps.
inline uint64_t expect_differ_only_where_touching(const SparseVoxels& a, const SparseVoxels& b,
                                                  const Mesh& m, double eps) {
    const Grid& g = a.grid();
    SparseVoxels near(g, a.brick_size()), solid(g, a.brick_size());
    for_each_nearby_voxel(g, m, 1, [&](size_t t, int64_t i, int64_t j, int64_t k) {
        if (voxel_meets_triangle(g, m, t, i, j, k, eps)) near.set(i, j, k);
        if (voxel_meets_triangle(g, m, t, i, j, k, -eps)) solid.set(i, j, k);
    });
    uint64_t differing = 0;
    auto check = [&](const SparseVoxels& x, const SparseVoxels& y) {
        x.for_each([&](int64_t i, int64_t j, int64_t k) {
            if (y.get(i, j, k)) return;
            ++differing;
            EXPECT_TRUE(near.get(i, j, k) && !solid.get(i, j, k))
                << "voxel " << i << "," << j << "," << k << " differs but is not a touching case";
        });
    };
    check(a, b);
    check(b, a);
    return differing;
}

// ---- mesh topology, independent of the meshing code
// ----------------------------------------------

struct Topology {
    bool closed_and_oriented = true;  // every directed edge once, its reverse once
    bool vertex_manifold = true;      // the triangles around every vertex form one fan
    int64_t vertices = 0, edges = 0, faces = 0, components = 0, unused_vertices = 0;
    int64_t euler() const { return vertices - edges + faces; }
};

inline Topology topology(const Mesh& mesh) {
    Topology t;
    t.faces = int64_t(mesh.triangles.size());
    std::map<std::pair<uint32_t, uint32_t>, int> directed;
    std::vector<std::map<uint32_t, uint32_t>> link(mesh.positions.size());  // vertex -> (b -> c)
    std::vector<uint32_t> parent(mesh.positions.size());
    std::iota(parent.begin(), parent.end(), 0u);
    std::function<uint32_t(uint32_t)> root = [&](uint32_t v) {
        return parent[v] == v ? v : parent[v] = root(parent[v]);
    };
    std::vector<bool> used(mesh.positions.size(), false);
    for (const auto& tri : mesh.triangles) {
        for (int i = 0; i < 3; ++i) {
            const uint32_t a = tri[i], b = tri[(i + 1) % 3], c = tri[(i + 2) % 3];
            if (a == b) t.closed_and_oriented = false;
            ++directed[{a, b}];
            used[a] = true;
            if (!link[a].emplace(b, c).second) t.vertex_manifold = false;
            parent[root(a)] = root(b);
        }
    }
    for (const auto& [edge, count] : directed) {
        auto reverse = directed.find({edge.second, edge.first});
        if (count != 1 || reverse == directed.end() || reverse->second != 1)
            t.closed_and_oriented = false;
    }
    t.edges = int64_t(directed.size()) / 2;
    for (size_t v = 0; v < link.size(); ++v) {
        if (!used[v]) {
            ++t.unused_vertices;
            continue;
        }
        ++t.vertices;
        if (root(uint32_t(v)) == v) ++t.components;
        // Walk the fan: following b -> c must return to the start after visiting every triangle.
        size_t steps = 0;
        uint32_t at = link[v].begin()->first;
        do {
            auto next = link[v].find(at);
            if (next == link[v].end()) break;
            at = next->second;
            ++steps;
        } while (at != link[v].begin()->first && steps <= link[v].size());
        if (steps != link[v].size() || at != link[v].begin()->first) t.vertex_manifold = false;
    }
    return t;
}

// The mesh with bit-identical positions merged into one vertex (loaders may keep duplicates, e.g.
// at texture seams), so that its topology is that of the surface.
inline Mesh welded(const Mesh& mesh) {
    Mesh out;
    std::map<Vec3d, uint32_t> index;
    std::vector<uint32_t> remap(mesh.positions.size());
    for (size_t v = 0; v < mesh.positions.size(); ++v) {
        auto [it, added] = index.emplace(mesh.positions[v], uint32_t(out.positions.size()));
        if (added) out.positions.push_back(mesh.positions[v]);
        remap[v] = it->second;
    }
    for (const auto& t : mesh.triangles)
        out.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
    return out;
}

// Two .vdb files' bytes are the same but for the random UUID every file carries (36 characters
// after the 21 header bytes).
inline void expect_vdb_bytes_equal_but_uuid(const std::string& ours, std::string theirs) {
    constexpr size_t kUuidAt = 21, kUuidSize = 36;
    ASSERT_GT(theirs.size(), kUuidAt + kUuidSize);
    ASSERT_GT(ours.size(), kUuidAt + kUuidSize);
    theirs.replace(kUuidAt, kUuidSize, ours, kUuidAt, kUuidSize);
    ASSERT_EQ(ours.size(), theirs.size());
    const auto differ = std::mismatch(ours.begin(), ours.end(), theirs.begin());
    EXPECT_TRUE(differ.first == ours.end())
        << "first difference at byte " << (differ.first - ours.begin()) << " of " << ours.size();
}

inline std::string mesh_path(const std::string& name) {
    return std::string(OCLVOX_MESH_DIR) + "/" + name;
}

// Records every call of a progress callback and checks the contract of the field functions'
// callbacks: the total never changes, done never goes back or past it, the last call has done ==
// total. Optionally answers false (cancels) at the first call with done >= cancel_from * total.
struct ProgressLog {
    std::vector<std::pair<uint64_t, uint64_t>> calls;
    double cancel_from = 2;  // never
    // Sleep past the library's reporting interval (50 ms) in every call, so that no report is
    // dropped and each phase's reports reach the callback.
    bool slow = false;
    bool cancelled = false;

    ProgressCallback callback() {
        return [this](uint64_t done, uint64_t total) {
            calls.push_back({done, total});
            if (slow) std::this_thread::sleep_for(std::chrono::milliseconds(55));
            cancelled = double(done) >= cancel_from * double(total);
            return !cancelled;
        };
    }

    void expect_contract(const std::string& what) const {
        ASSERT_FALSE(calls.empty()) << what << ": never called";
        for (size_t i = 0; i < calls.size(); ++i) {
            EXPECT_EQ(calls[i].second, calls[0].second) << what << ": total changed at call " << i;
            EXPECT_LE(calls[i].first, calls[i].second) << what << ": past the total at call " << i;
            if (i > 0)
                EXPECT_GE(calls[i].first, calls[i - 1].first)
                    << what << ": went back at call " << i;
        }
        EXPECT_EQ(calls.back().first, calls.back().second) << what << ": did not end at the total";
    }

    // How many different values of done lie strictly between 0 and the total.
    size_t steps_inside() const {
        std::vector<uint64_t> inside;
        for (const auto& [done, total] : calls)
            if (done > 0 && done < total) inside.push_back(done);
        return size_t(std::unique(inside.begin(), inside.end()) - inside.begin());
    }
};

}  // namespace oclvox::test
