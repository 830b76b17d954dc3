// SAT and PEF on every real test mesh at 512 voxels along the longest axis (the fitted grid and
// the cubic, centred one: different origins round the triangles differently), each computed on
// the device and checked against the independent double-precision SAT: within 1e-4 voxel, the
// voxels set are exactly the voxels the triangles meet. So the two tests also differ only on
// voxels that touch a triangle to within 1e-4 voxel.
#include <algorithm>
#include <atomic>
#include <filesystem>
#include <mutex>
#include <thread>
#include <tuple>

#include "test_support.hpp"

namespace oclvox::test {
namespace {

constexpr double kEps = 1e-4;  // voxels

// Every mesh file of the shared mesh folder, sorted by name. A missing folder becomes one name
// that fails to load, naming the folder, rather than no test at all.
std::vector<std::string> mesh_files() {
    std::error_code error;
    std::filesystem::directory_iterator folder(OCLVOX_MESH_DIR, error);
    if (error) return {"missing mesh folder"};
    std::vector<std::string> names;
    for (const auto& entry : folder) {
        std::string ext = entry.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(),
                       [](unsigned char c) { return char(std::tolower(c)); });
        if (ext == ".obj" || ext == ".off" || ext == ".ply" || ext == ".stl")
            names.push_back(entry.path().filename().string());
    }
    std::sort(names.begin(), names.end());
    return names;
}

// A dense bit per grid voxel that several threads may set at once.
class AtomicBits {
  public:
    explicit AtomicBits(const Grid& g) : g_(g), words_((g.voxel_count() + 63) / 64) {}
    void set(int64_t i, int64_t j, int64_t k) {
        const uint64_t n = index(i, j, k);
        words_[n / 64].fetch_or(uint64_t(1) << (n % 64), std::memory_order_relaxed);
    }
    bool get(int64_t i, int64_t j, int64_t k) const {
        const uint64_t n = index(i, j, k);
        return words_[n / 64].load(std::memory_order_relaxed) >> (n % 64) & 1;
    }

  private:
    uint64_t index(int64_t i, int64_t j, int64_t k) const {
        return uint64_t(i) + uint64_t(g_.dims[0]) * (uint64_t(j) + uint64_t(g_.dims[1]) * k);
    }
    Grid g_;
    std::vector<std::atomic<uint64_t>> words_;
};

// Calls f(i, j, k) for every grid voxel that could come within kEps of triangle (a, b, c): the
// voxels of its bounding box (grown by kEps) whose column along the normal's dominant axis meets
// the triangle's plane near them. This keeps the double-precision check proportional to the
// surface, not to the bounding boxes of large slanted triangles.
template <typename F>
void for_each_candidate_voxel(const Grid& g, const Vec3d& a, const Vec3d& b, const Vec3d& c, F f) {
    int64_t lo[3], hi[3];
    for (int k = 0; k < 3; ++k) {
        lo[k] = std::max<int64_t>(0, int64_t(std::floor(std::min({a[k], b[k], c[k]}) - kEps)) - 1);
        hi[k] = std::min<int64_t>(g.dims[k] - 1,
                                  int64_t(std::floor(std::max({a[k], b[k], c[k]}) + kEps)));
        if (lo[k] > hi[k]) return;
    }
    const Vec3d ab = sub(b, a), ac = sub(c, a);
    const Vec3d n{ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2],
                  ab[0] * ac[1] - ab[1] * ac[0]};
    const int w = std::abs(n[0]) >= std::abs(n[1]) && std::abs(n[0]) >= std::abs(n[2]) ? 0
                  : std::abs(n[1]) >= std::abs(n[2])                                   ? 1
                                                                                       : 2;
    const int u = (w + 1) % 3, v = (w + 2) % 3;
    int64_t at[3];
    for (at[v] = lo[v]; at[v] <= hi[v]; ++at[v])
        for (at[u] = lo[u]; at[u] <= hi[u]; ++at[u]) {
            int64_t from = lo[w], to = hi[w];
            // Plane n.(p - a) = 0 over the column's (grown) square: x_w = a_w - (n_u du + n_v
            // dv) / n_w. Outside a generous slack, no voxel of the column is near the plane. A
            // degenerate triangle (n = 0) keeps the whole bounding-box column.
            if (n[w] != 0) {
                double w_lo = INFINITY, w_hi = -INFINITY;
                for (double du : {double(at[u]) - kEps, double(at[u] + 1) + kEps})
                    for (double dv : {double(at[v]) - kEps, double(at[v] + 1) + kEps}) {
                        const double x = a[w] - (n[u] * (du - a[u]) + n[v] * (dv - a[v])) / n[w];
                        w_lo = std::min(w_lo, x);
                        w_hi = std::max(w_hi, x);
                    }
                // Clamped before the conversion: a near-degenerate triangle has a steep plane.
                w_lo = std::max(w_lo, double(lo[w]) - 2);
                w_hi = std::min(w_hi, double(hi[w]) + 2);
                from = std::max(from, int64_t(std::floor(w_lo - kEps)) - 1);
                to = std::min(to, int64_t(std::floor(w_hi + kEps)) + 1);
            }
            for (at[w] = from; at[w] <= to; ++at[w]) f(at[0], at[1], at[2]);
        }
}

class EveryMesh : public ::testing::TestWithParam<std::tuple<std::string, bool>> {};

TEST_P(EveryMesh, SatAndPefAreExactUpToRoundingAt512) {
    const auto& [file, cubic] = GetParam();
    const Mesh m = load_mesh(mesh_path(file));
    GridFit fit;
    fit.resolution = 512;
    fit.cubic = cubic;
    const Grid g = fit_grid(m, fit);

    VoxelizeOptions options;
    options.test = OverlapTest::SAT;
    const SparseVoxels sat = device().voxelize(m, g, options);
    options.test = OverlapTest::PEF;
    const SparseVoxels pef = device().voxelize(m, g, options);

    // The double-precision oracle, triangle by triangle, over threads: `near` holds the voxels
    // some triangle meets once the voxel is grown by kEps; the voxels a triangle meets even
    // shrunk by kEps must be set by both tests (only checked where one of them is not set).
    AtomicBits near(g), sat_bits(g), pef_bits(g);
    sat.for_each([&](int64_t i, int64_t j, int64_t k) { sat_bits.set(i, j, k); });
    pef.for_each([&](int64_t i, int64_t j, int64_t k) { pef_bits.set(i, j, k); });
    std::atomic<uint64_t> missed_sat{0}, missed_pef{0};
    std::atomic<size_t> next{0};
    std::mutex report;
    auto work = [&] {
        for (size_t t; (t = next.fetch_add(1)) < m.triangles.size();) {
            const Vec3d a = to_grid(g, m.positions[m.triangles[t][0]]);
            const Vec3d b = to_grid(g, m.positions[m.triangles[t][1]]);
            const Vec3d c = to_grid(g, m.positions[m.triangles[t][2]]);
            for_each_candidate_voxel(g, a, b, c, [&](int64_t i, int64_t j, int64_t k) {
                const Vec3d grown_lo{i - kEps, j - kEps, k - kEps};
                const Vec3d grown_hi{i + 1 + kEps, j + 1 + kEps, k + 1 + kEps};
                if (!detail::triangle_box_overlap_double(a, b, c, grown_lo, grown_hi)) return;
                near.set(i, j, k);
                if (sat_bits.get(i, j, k) && pef_bits.get(i, j, k)) return;
                const Vec3d shrunk_lo{i + kEps, j + kEps, k + kEps};
                const Vec3d shrunk_hi{i + 1 - kEps, j + 1 - kEps, k + 1 - kEps};
                if (!detail::triangle_box_overlap_double(a, b, c, shrunk_lo, shrunk_hi)) return;
                for (const auto& [result, missed, name] :
                     {std::tuple{&sat_bits, &missed_sat, "SAT"},
                      std::tuple{&pef_bits, &missed_pef, "PEF"}})
                    if (!result->get(i, j, k) && (*missed)++ < 5) {
                        std::lock_guard<std::mutex> lock(report);
                        ADD_FAILURE() << name << " misses voxel " << i << "," << j << "," << k
                                      << " that triangle " << t << " meets";
                    }
            });
        }
    };
    std::vector<std::thread> threads(std::max(1u, std::thread::hardware_concurrency()));
    for (auto& thread : threads) thread = std::thread(work);
    for (auto& thread : threads) thread.join();
    EXPECT_EQ(missed_sat, 0u);
    EXPECT_EQ(missed_pef, 0u);

    // No set voxel is further than kEps from every triangle.
    for (const auto& [result, name] : {std::pair{&sat, "SAT"}, std::pair{&pef, "PEF"}}) {
        uint64_t unjustified = 0;
        result->for_each([&](int64_t i, int64_t j, int64_t k) {
            if (!near.get(i, j, k) && unjustified++ < 5)
                ADD_FAILURE() << name << " sets voxel " << i << "," << j << "," << k
                              << " but no triangle comes within " << kEps << " voxels of it";
        });
        EXPECT_EQ(unjustified, 0u) << name;
    }
}

INSTANTIATE_TEST_SUITE_P(SharedMeshes, EveryMesh,
                         ::testing::Combine(::testing::ValuesIn(mesh_files()), ::testing::Bool()),
                         [](const auto& info) {
                             std::string name = std::get<0>(info.param);
                             for (char& c : name)
                                 if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                             return name + (std::get<1>(info.param) ? "_cubic" : "_fitted");
                         });

}  // namespace
}  // namespace oclvox::test
