// Voxelization benchmark: time per phase and throughput of SAT and PEF on real meshes over a
// range of resolutions, on one OpenCL device. Prints a Markdown table (with the machine, device,
// driver and commit it ran on) and optionally writes the same as JSON.
//
//   oclvox_bench [--device SEL] [--repeat N] [--brick B] [--json FILE] [--commit HASH]
//                MESH... -- RES...
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <oclvox/oclvox.hpp>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

std::string cpu_model() {
    std::ifstream in("/proc/cpuinfo");
    for (std::string line; std::getline(in, line);)
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

std::string base_name(const std::string& path) {
    return path.substr(path.find_last_of('/') + 1);
}

struct Run {
    std::string mesh, test;
    int64_t resolution = 0;
    std::array<int64_t, 3> dims{};
    uint64_t triangles = 0;
    oclvox::VoxelizeStats stats;  // of the median run
    double total = 0;             // median wall time of Device::voxelize
};

}  // namespace

int main(int argc, char** argv) {
    std::string selector, json_path, commit = "unknown";
    int repeat = 3, brick = 64;
    std::vector<std::string> meshes;
    std::vector<int64_t> resolutions;
    bool after_separator = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--device" && i + 1 < argc)
            selector = argv[++i];
        else if (a == "--repeat" && i + 1 < argc)
            repeat = std::max(1, std::atoi(argv[++i]));
        else if (a == "--brick" && i + 1 < argc)
            brick = std::atoi(argv[++i]);
        else if (a == "--json" && i + 1 < argc)
            json_path = argv[++i];
        else if (a == "--commit" && i + 1 < argc)
            commit = argv[++i];
        else if (a == "--")
            after_separator = true;
        else if (after_separator)
            resolutions.push_back(std::atoll(a.c_str()));
        else
            meshes.push_back(a);
    }
    if (meshes.empty() || resolutions.empty()) {
        std::fprintf(stderr, "usage: oclvox_bench [options] MESH... -- RES...\n");
        return 2;
    }
    try {
        oclvox::Device device = oclvox::Device::open(selector);
        const auto& info = device.info();
        std::printf("machine: %s\ndevice: %s (%s, %s), driver %s\ncommit: %s\n",
                    cpu_model().c_str(), info.name.c_str(), info.platform.c_str(),
                    info.type.c_str(), info.driver_version.c_str(), commit.c_str());
        std::printf("brick %d, median of %d runs after one warm-up\n\n", brick, repeat);
        std::printf(
            "| mesh | tris | res | grid | test | bin s | upload s | kernel s | download s | "
            "total s | Mtri/s | Mvox/s (kernel) | voxels | bricks active |\n"
            "|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
        std::vector<Run> runs;
        for (const std::string& path : meshes) {
            const oclvox::Mesh mesh = oclvox::load_mesh(path);
            for (int64_t res : resolutions) {
                oclvox::GridFit fit;
                fit.resolution = res;
                const oclvox::Grid grid = oclvox::fit_grid(mesh, fit);
                for (auto test : {oclvox::OverlapTest::SAT, oclvox::OverlapTest::PEF}) {
                    oclvox::VoxelizeOptions options;
                    options.test = test;
                    options.brick_size = brick;
                    device.voxelize(mesh, grid, options);  // warm-up: program build, caches
                    std::vector<std::pair<double, oclvox::VoxelizeStats>> samples;
                    for (int r = 0; r < repeat; ++r) {
                        oclvox::VoxelizeStats stats;
                        const auto t0 = Clock::now();
                        device.voxelize(mesh, grid, options, &stats);
                        samples.emplace_back(
                            std::chrono::duration<double>(Clock::now() - t0).count(), stats);
                    }
                    std::sort(samples.begin(), samples.end(),
                              [](const auto& a, const auto& b) { return a.first < b.first; });
                    Run run{base_name(path),
                            oclvox::to_string(test),
                            res,
                            grid.dims,
                            mesh.triangles.size(),
                            samples[samples.size() / 2].second,
                            samples[samples.size() / 2].first};
                    const auto& s = run.stats;
                    std::printf(
                        "| %s | %llu | %lld | %lldx%lldx%lld | %s | %.3f | %.3f | %.3f | "
                        "%.3f | %.3f | %.2f | %.1f | %llu | %llu |\n",
                        run.mesh.c_str(), (unsigned long long)run.triangles, (long long)res,
                        (long long)grid.dims[0], (long long)grid.dims[1], (long long)grid.dims[2],
                        run.test.c_str(), s.seconds_binning, s.seconds_upload, s.seconds_kernels,
                        s.seconds_download, run.total, double(run.triangles) / run.total / 1e6,
                        double(s.voxels_set) / s.seconds_kernels / 1e6,
                        (unsigned long long)s.voxels_set, (unsigned long long)s.bricks_active);
                    std::fflush(stdout);
                    runs.push_back(run);
                }
            }
        }
        if (!json_path.empty()) {
            nlohmann::json j;
            j["machine"] = cpu_model();
            j["device"] = {{"name", info.name},
                           {"platform", info.platform},
                           {"type", info.type},
                           {"driver", info.driver_version}};
            j["commit"] = commit;
            j["brick"] = brick;
            for (const Run& r : runs)
                j["runs"].push_back({{"mesh", r.mesh},
                                     {"triangles", r.triangles},
                                     {"resolution", r.resolution},
                                     {"dims", r.dims},
                                     {"test", r.test},
                                     {"seconds_total", r.total},
                                     {"seconds_binning", r.stats.seconds_binning},
                                     {"seconds_upload", r.stats.seconds_upload},
                                     {"seconds_kernels", r.stats.seconds_kernels},
                                     {"seconds_download", r.stats.seconds_download},
                                     {"voxels_set", r.stats.voxels_set},
                                     {"bricks_active", r.stats.bricks_active},
                                     {"work_items", r.stats.work_items}});
            std::ofstream(json_path) << j.dump(2) << "\n";
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "oclvox_bench: error: %s\n", e.what());
        return 1;
    }
    return 0;
}
