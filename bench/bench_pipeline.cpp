// Pipeline benchmark: the stages after surface voxelization, on real meshes and one OpenCL device.
// Prints Markdown tables (with the machine, device, driver and commit they were measured on):
//  (a) solid voxelization by crossing parity against the surface pass it builds on, and by
//      generalized winding number (forced) at the lower resolutions;
//  (b) signed distance fields per band width and resolution, plus one full-grid run;
//  (c) meshing throughput of Surface Nets and Marching Cubes on the SDF, device and host;
//  (d) a CSG round trip of the first two meshes (the second scaled and moved onto the first).
// Times are medians of --repeat runs after one warm-up run that builds programs and fills caches.
//
//   oclvox_bench_pipeline [--device SEL] [--repeat N] [--commit HASH] [--winding-max RES]
//                         [--sections abcd] [--bands 1,3,6] [--no-full-grid] MESH... -- RES...
//
// --sections, --bands and --no-full-grid trim a run to the rows worth measuring at a large
// resolution, where the full matrix would take too long on a CPU device.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <oclvox/oclvox.hpp>
#include <oclvox/sdf.hpp>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

int g_repeat = 3;

std::string cpu_model() {
    std::ifstream in("/proc/cpuinfo");
    for (std::string line; std::getline(in, line);)
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

std::string base_name(const std::string& path) {
    return path.substr(path.find_last_of('/') + 1);
}

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Median wall time of f over `repeat` runs after one untimed warm-up. Slow stages pass
// repeat 1 and no warm-up: their first-run overhead is small against their own time.
double median_seconds(const std::function<void()>& f, int repeat = g_repeat, bool warm_up = true) {
    if (warm_up) f();
    std::vector<double> samples;
    for (int r = 0; r < repeat; ++r) {
        const auto t0 = Clock::now();
        f();
        samples.push_back(seconds_since(t0));
    }
    std::sort(samples.begin(), samples.end());
    return samples[samples.size() / 2];
}

std::string dims_string(const oclvox::Grid& g) {
    return std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" +
           std::to_string(g.dims[2]);
}

// Fields are meshed and combined, so the grid leaves room for the widest band around the mesh:
// surfaces then never reach the grid border and stay closed.
oclvox::GridFit padded_fit(int64_t res) {
    oclvox::GridFit fit;
    fit.resolution = res;
    fit.pad = 7;
    return fit;
}

oclvox::SdfOptions band(double voxels, bool full_grid = false) {
    oclvox::SdfOptions o;
    o.band_voxels = voxels;
    o.full_grid = full_grid;
    o.inside = oclvox::InsideTest::Parity;  // the configuration; winding is timed in (a)
    return o;
}

// b scaled to a's bounding-box diagonal and centred a quarter of a's extent along x from a's
// centre, so the two overlap without one swallowing the other.
oclvox::Mesh overlapping_copy(const oclvox::Mesh& a, const oclvox::Mesh& b) {
    auto box = [](const oclvox::Mesh& m, std::array<double, 3>& lo, std::array<double, 3>& hi) {
        lo = {1e300, 1e300, 1e300};
        hi = {-1e300, -1e300, -1e300};
        for (const auto& p : m.positions)
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], p[k]);
                hi[k] = std::max(hi[k], p[k]);
            }
    };
    std::array<double, 3> alo, ahi, blo, bhi;
    box(a, alo, ahi);
    box(b, blo, bhi);
    double da = 0, db = 0;
    for (int k = 0; k < 3; ++k) {
        da += (ahi[k] - alo[k]) * (ahi[k] - alo[k]);
        db += (bhi[k] - blo[k]) * (bhi[k] - blo[k]);
    }
    const double scale = std::sqrt(da / db) * 0.8;
    oclvox::Mesh out = b;
    for (auto& p : out.positions)
        for (int k = 0; k < 3; ++k) {
            const double shift = k == 0 ? 0.25 * (ahi[0] - alo[0]) : 0.0;
            p[k] = (p[k] - 0.5 * (blo[k] + bhi[k])) * scale + 0.5 * (alo[k] + ahi[k]) + shift;
        }
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    std::string selector, commit = "unknown";
    int64_t winding_max = 128;
    std::string sections = "abcd";
    std::vector<double> bands = {1, 3, 6};
    bool full_grid = true;
    std::vector<std::string> paths;
    std::vector<int64_t> resolutions;
    bool after_separator = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--device" && i + 1 < argc)
            selector = argv[++i];
        else if (a == "--repeat" && i + 1 < argc)
            g_repeat = std::max(1, std::atoi(argv[++i]));
        else if (a == "--commit" && i + 1 < argc)
            commit = argv[++i];
        else if (a == "--winding-max" && i + 1 < argc)
            winding_max = std::atoll(argv[++i]);
        else if (a == "--sections" && i + 1 < argc)
            sections = argv[++i];
        else if (a == "--bands" && i + 1 < argc) {
            bands.clear();
            for (const char* p = argv[++i]; *p;) {
                char* end = nullptr;
                bands.push_back(std::strtod(p, &end));
                p = *end == ',' ? end + 1 : end;
                if (end == p && *p) break;
            }
        } else if (a == "--no-full-grid")
            full_grid = false;
        else if (a == "--")
            after_separator = true;
        else if (after_separator)
            resolutions.push_back(std::atoll(a.c_str()));
        else
            paths.push_back(a);
    }
    if (paths.empty() || resolutions.empty()) {
        std::fprintf(stderr, "usage: oclvox_bench_pipeline [options] MESH... -- RES...\n");
        return 2;
    }
    std::sort(resolutions.begin(), resolutions.end());
    try {
        oclvox::Device device = oclvox::Device::open(selector);
        const auto& info = device.info();
        std::printf("machine: %s\ndevice: %s (%s, %s), driver %s\ncommit: %s\n",
                    cpu_model().c_str(), info.name.c_str(), info.platform.c_str(),
                    info.type.c_str(), info.driver_version.c_str(), commit.c_str());
        std::printf("median of %d runs after one warm-up unless noted\n\n", g_repeat);

        std::vector<oclvox::Mesh> meshes;
        for (const auto& p : paths) meshes.push_back(oclvox::load_mesh(p));

        auto wanted = [&](char section) { return sections.find(section) != std::string::npos; };

        // (a) Parity adds a column pass to the surface pass; the target is within ~2x.
        if (wanted('a')) {
            std::printf(
                "### (a) Solid voxelization vs surface pass\n\n"
                "Winding (forced) runs once, without warm-up, and only up to resolution %lld: "
                "it is slow on a CPU device.\n\n",
                (long long)winding_max);
            std::printf(
                "| mesh | tris | res | grid | surface s | parity s | parity/surface | "
                "winding s | solid voxels |\n|---|---:|---:|---|---:|---:|---:|---:|---:|\n");
            for (size_t m = 0; m < meshes.size(); ++m)
                for (int64_t res : resolutions) {
                    oclvox::GridFit fit;
                    fit.resolution = res;
                    const oclvox::Grid grid = oclvox::fit_grid(meshes[m], fit);
                    oclvox::VoxelizeOptions surface, parity, winding;
                    parity.mode = winding.mode = oclvox::VoxelizeMode::Solid;
                    parity.inside = oclvox::InsideTest::Parity;
                    winding.inside = oclvox::InsideTest::Winding;
                    oclvox::VoxelizeStats stats;
                    const double ts =
                        median_seconds([&] { device.voxelize(meshes[m], grid, surface); });
                    const double tp =
                        median_seconds([&] { device.voxelize(meshes[m], grid, parity, &stats); });
                    char tw[64] = "skipped (res > max)";
                    if (res <= winding_max)
                        std::snprintf(
                            tw, sizeof tw, "%.3f",
                            median_seconds([&] { device.voxelize(meshes[m], grid, winding); }, 1,
                                           false));
                    std::printf("| %s | %zu | %lld | %s | %.3f | %.3f | %.2f | %s | %llu |\n",
                                base_name(paths[m]).c_str(), meshes[m].triangles.size(),
                                (long long)res, dims_string(grid).c_str(), ts, tp, tp / ts, tw,
                                (unsigned long long)stats.voxels_set);
                    std::fflush(stdout);
                }
        }

        // (b) Narrow band per width, plus the full grid once at the smallest res.
        if (wanted('b')) {
            std::printf(
                "\n### (b) Signed distance field (parity sign, grid padded by 7 voxels)\n\n"
                "| mesh | res | grid | band | kind | total s (median) | kernels s (last run, "
                "distance + sign) | "
                "Mvox/s |\n|---|---:|---|---:|---|---:|---:|---:|\n");
            for (size_t m = 0; m < meshes.size(); ++m)
                for (int64_t res : resolutions) {
                    const oclvox::Grid grid = oclvox::fit_grid(meshes[m], padded_fit(res));
                    std::vector<std::pair<double, bool>> runs;
                    for (double b : bands) runs.push_back({b, false});
                    if (full_grid && res == resolutions.front()) runs.push_back({3, true});
                    for (const auto& [width, full] : runs) {
                        oclvox::VoxelizeStats stats;
                        const double t = median_seconds([&] {
                            stats = {};
                            oclvox::signed_distance(device, meshes[m], grid, band(width, full),
                                                    &stats);
                        });
                        std::printf("| %s | %lld | %s | %.0f | %s | %.3f | %.3f | %.2f |\n",
                                    base_name(paths[m]).c_str(), (long long)res,
                                    dims_string(grid).c_str(), width, full ? "full grid" : "narrow",
                                    t, stats.seconds_kernels, double(grid.voxel_count()) / t / 1e6);
                        std::fflush(stdout);
                    }
                }
        }

        // (c) Meshing the band-3 field: output triangles per second of wall time.
        if (wanted('c')) {
            std::printf(
                "\n### (c) Meshing the band-3 SDF\n\n"
                "| mesh | res | grid | method | where | s | triangles | Mtri/s |\n"
                "|---|---:|---|---|---|---:|---:|---:|\n");
            for (size_t m = 0; m < meshes.size(); ++m)
                for (int64_t res : resolutions) {
                    const oclvox::Grid grid = oclvox::fit_grid(meshes[m], padded_fit(res));
                    const oclvox::ScalarField f =
                        oclvox::signed_distance(device, meshes[m], grid, band(3));
                    struct Method {
                        const char *name, *where;
                        std::function<oclvox::Mesh()> run;
                    };
                    const Method methods[] = {
                        {"surface nets", "device", [&] { return oclvox::surface_nets(device, f); }},
                        {"surface nets", "host", [&] { return oclvox::surface_nets(f); }},
                        {"marching cubes", "device",
                         [&] { return oclvox::marching_cubes(device, f); }},
                        {"marching cubes", "host", [&] { return oclvox::marching_cubes(f); }},
                    };
                    for (const Method& method : methods) {
                        size_t tris = 0;
                        const double t =
                            median_seconds([&] { tris = method.run().triangles.size(); });
                        std::printf("| %s | %lld | %s | %s | %s | %.3f | %zu | %.2f |\n",
                                    base_name(paths[m]).c_str(), (long long)res,
                                    dims_string(grid).c_str(), method.name, method.where, t, tris,
                                    double(tris) / t / 1e6);
                        std::fflush(stdout);
                    }
                }
        }

        // (d) CSG of two real meshes on one grid: two SDFs, the per-sample operation, a mesh.
        if (wanted('d') && meshes.size() >= 2) {
            const oclvox::Mesh& a = meshes[0];
            const oclvox::Mesh b = overlapping_copy(a, meshes[1]);
            std::printf(
                "\n### (d) CSG round trip: %s with %s (scaled to 0.8x its diagonal, "
                "moved +x by a quarter of its width), band 3, Marching Cubes on the "
                "device\n\n"
                "| res | grid | SDF a s | SDF b s | op | csg s | mesh s | triangles |\n"
                "|---:|---|---:|---:|---|---:|---:|---:|\n",
                base_name(paths[0]).c_str(), base_name(paths[1]).c_str());
            for (int64_t res : resolutions) {
                const oclvox::Grid grid = oclvox::fit_grid(a, b, padded_fit(res));
                oclvox::ScalarField fa, fb;
                const double ta =
                    median_seconds([&] { fa = oclvox::signed_distance(device, a, grid, band(3)); });
                const double tb =
                    median_seconds([&] { fb = oclvox::signed_distance(device, b, grid, band(3)); });
                for (auto op : {oclvox::CsgOp::Union, oclvox::CsgOp::Intersection,
                                oclvox::CsgOp::Difference}) {
                    oclvox::ScalarField out;
                    const double tc = median_seconds([&] { out = oclvox::csg(fa, fb, op); });
                    size_t tris = 0;
                    const double tm = median_seconds(
                        [&] { tris = oclvox::marching_cubes(device, out).triangles.size(); });
                    std::printf("| %lld | %s | %.3f | %.3f | %s | %.3f | %.3f | %zu |\n",
                                (long long)res, dims_string(grid).c_str(), ta, tb,
                                oclvox::to_string(op), tc, tm, tris);
                    std::fflush(stdout);
                }
            }
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "oclvox_bench_pipeline: error: %s\n", e.what());
        return 1;
    }
    return 0;
}
