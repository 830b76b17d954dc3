// oclvox: the command-line tool. `oclvox devices` lists the OpenCL devices; `oclvox voxelize`
// turns a mesh file into a voxel file. This file parses and checks the command line, times the
// phases and reports; all the work is the library's.
//
// Exit codes: 0 success, 1 error (the message names the problem), 2 command-line usage error,
// 130 cancelled by Ctrl-C.
#include <signal.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>

#include "oclvox/oclvox.hpp"
#include "progress_bar.hpp"

// CMake passes the project version; the fallback only labels builds made outside CMake.
#ifndef OCLVOX_VERSION
#define OCLVOX_VERSION "unknown"
#endif

namespace {

namespace fs = std::filesystem;

constexpr int kExitError = 1;
constexpr int kExitUsage = 2;
constexpr int kExitCancelled = 130;  // the shell convention for "ended by SIGINT"

// ---------------------------------------------------------------------------------------------
// Ctrl-C
// ---------------------------------------------------------------------------------------------
// Set on Ctrl-C; the progress callback turns it into a clean cancellation, so the library stops
// between batches and no half-written output is left behind.
std::atomic<bool> g_interrupted{false};

// Ctrl-C is taken by a watcher thread with sigwait rather than by a signal handler. SIGINT stays
// blocked everywhere else, and a blocked signal is inherited by the processes the OpenCL runtime
// spawns: PoCL runs a linker while it compiles a kernel, and a terminal's Ctrl-C (sent to the
// whole process group) would otherwise kill that linker and make the runtime abort.
// Call before any other thread exists, so that every thread inherits the block.
void start_interrupt_watcher() {
    sigset_t interrupt;
    sigemptyset(&interrupt);
    sigaddset(&interrupt, SIGINT);
    pthread_sigmask(SIG_BLOCK, &interrupt, nullptr);
    std::thread([interrupt] {
        int signal = 0;
        sigwait(&interrupt, &signal);
        g_interrupted = true;
        // A second Ctrl-C ends the process at once, for phases that report no progress (such as
        // loading a huge mesh).
        sigwait(&interrupt, &signal);
        std::_Exit(kExitCancelled);
    }).detach();
}

void stop_if_interrupted() {
    if (g_interrupted) throw oclvox::Cancelled("cancelled");
}

// ---------------------------------------------------------------------------------------------
// Option values
// ---------------------------------------------------------------------------------------------
struct VoxelizeArgs {
    std::string input, output;
    oclvox::GridFit fit;
    std::string test = "pef";
    std::string mode = "surface";
    std::string inside = "auto";
    std::string boundary = "closed";
    std::string device;
    bool reference = false;
    int brick_size = oclvox::VoxelizeOptions{}.brick_size;
    uint64_t device_mib = oclvox::VoxelizeOptions{}.device_budget_bytes >> 20;
    uint64_t host_mib = 0;
    bool quiet = false;
    bool stats = false;
    std::string stats_json;
};

// Reads a whole string as one number; strtod/strtoll alone accept trailing garbage.
bool parse_number(const std::string& text, double& value) {
    char* end = nullptr;
    errno = 0;
    value = std::strtod(text.c_str(), &end);
    return !text.empty() && end == text.c_str() + text.size() && errno == 0;
}

bool parse_number(const std::string& text, int64_t& value) {
    char* end = nullptr;
    errno = 0;
    value = std::strtoll(text.c_str(), &end, 10);
    return !text.empty() && end == text.c_str() + text.size() && errno == 0;
}

// "A,B,C" for --origin and --dims: exactly three numbers, each accepted by `valid`.
template <class T, class Valid>
std::array<T, 3> parse_triple(const std::string& option, const std::string& text,
                              const std::string& expected, Valid valid) {
    std::array<T, 3> values{};
    size_t begin = 0;
    for (int axis = 0; axis < 3; ++axis) {
        // The last number runs to the end, so "1,2,3,4" fails on "3,4".
        const size_t end = axis < 2 ? text.find(',', begin) : text.size();
        if (end == std::string::npos ||
            !parse_number(text.substr(begin, end - begin), values[axis]) || !valid(values[axis]))
            throw CLI::ValidationError(option, "expected " + expected + ", got '" + text + "'");
        begin = end + 1;
    }
    return values;
}

// CLI11's PositiveNumber lets NaN through (NaN <= 0 is false), so voxel sizes get their own check.
const CLI::Validator kPositiveFinite(
    [](std::string& text) -> std::string {
        double value = 0;
        if (!parse_number(text, value) || !std::isfinite(value) || !(value > 0))
            return "must be a positive finite number, got '" + text + "'";
        return {};
    },
    "POSITIVE");

const CLI::Validator kBrickSize(
    [](std::string& text) -> std::string {
        int64_t value = 0;
        if (!parse_number(text, value) || value < 4 || value > 1024 || value % 4 != 0)
            return "must be a multiple of 4 in [4, 1024], got '" + text + "'";
        return {};
    },
    "4..1024");

// ---------------------------------------------------------------------------------------------
// Output files
// ---------------------------------------------------------------------------------------------
std::string lowercase_extension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

// Mistakes in output paths are cheap to find before the run and expensive after a long one, so
// they are checked up front. The format list mirrors what write_voxels accepts.
void check_output_path(const std::string& path, bool voxel_file) {
    const fs::path parent = fs::path(path).parent_path();
    if (!parent.empty() && !fs::is_directory(parent))
        throw oclvox::OutputError("cannot write '" + path + "': folder '" + parent.string() +
                                  "' does not exist");
    if (!voxel_file) return;
    const std::string ext = lowercase_extension(path);
    if (ext != ".binvox" && ext != ".npy" && ext != ".vox" && ext != ".obj" && ext != ".ply")
        throw oclvox::OutputError(
            "cannot write '" + path + "': " +
            (ext.empty() ? "the file name has no extension" : "unknown extension '" + ext + "'") +
            " (supported: .binvox, .npy, .vox, .obj, .ply)");
}

// Same contract as the library's outputs: a temporary file beside the target, renamed into
// place, so a reader never sees a half-written file.
void write_text_atomically(const std::string& path, const std::string& text) {
    const fs::path target(path);
    const fs::path temp = target.parent_path() /
                          ("." + target.filename().string() + ".tmp-" + std::to_string(getpid()));
    std::ofstream out(temp, std::ios::binary);
    if (!out)
        throw oclvox::OutputError("cannot write '" + temp.string() + "': " + std::strerror(errno));
    out << text;
    out.close();
    if (!out) {
        fs::remove(temp);
        throw oclvox::OutputError("cannot write '" + path + "': write failed");
    }
    if (std::rename(temp.c_str(), path.c_str()) != 0) {
        const int error = errno;
        fs::remove(temp);
        throw oclvox::OutputError("cannot write '" + path + "': " + std::strerror(error));
    }
}

// ---------------------------------------------------------------------------------------------
// Timing and reports
// ---------------------------------------------------------------------------------------------
struct Timings {
    double load = 0, fit = 0, device = 0, voxelize = 0, write = 0, total = 0;
};

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

template <class F>
auto timed(double& seconds, F&& work) {
    const Clock::time_point start = Clock::now();
    auto result = work();
    seconds = seconds_since(start);
    return result;
}

// Everything a report needs about one finished run.
struct RunReport {
    const VoxelizeArgs& args;
    const oclvox::Mesh& mesh;
    const oclvox::Grid& grid;
    const oclvox::DeviceInfo* device;  // null for the CPU reference
    const oclvox::VoxelizeStats& stats;
    const Timings& timings;
};

std::string dims_text(const oclvox::Grid& grid) {
    return std::to_string(grid.dims[0]) + "x" + std::to_string(grid.dims[1]) + "x" +
           std::to_string(grid.dims[2]);
}

std::string bytes_text(uint64_t bytes) {
    char text[32];
    if (bytes >= (uint64_t(1) << 30))
        std::snprintf(text, sizeof text, "%.1f GiB", double(bytes) / double(1 << 30));
    else
        std::snprintf(text, sizeof text, "%.1f MiB", double(bytes) / double(1 << 20));
    return text;
}

// 1234567 -> "1.23 M": throughputs span too many orders of magnitude for plain digits.
std::string rate_text(double per_second) {
    const char* suffixes[] = {"", " k", " M", " G", " T"};
    int index = 0;
    while (per_second >= 1000 && index < 4) {
        per_second /= 1000;
        ++index;
    }
    char text[32];
    std::snprintf(text, sizeof text, "%.3g%s", per_second, suffixes[index]);
    return text;
}

// Throughputs are over the voxelize call (binning to download), which is the part that scales
// with the grid; loading and writing depend on file formats and disks.
double per_second(double amount, double seconds) {
    return seconds > 0 ? amount / seconds : 0;
}

void print_summary(const RunReport& r) {
    const oclvox::Grid& g = r.grid;
    std::printf("input    %s (%zu triangles)\n", r.args.input.c_str(), r.mesh.triangles.size());
    std::printf("grid     %s voxels of size %g, origin (%g, %g, %g)\n", dims_text(g).c_str(),
                g.voxel_size, g.origin[0], g.origin[1], g.origin[2]);
    if (r.args.mode == "thin")
        std::printf("mode     thin (6-separating), boundary %s\n", r.args.boundary.c_str());
    else
        std::printf("mode     %s, test %s, boundary %s\n", r.args.mode.c_str(), r.args.test.c_str(),
                    r.args.boundary.c_str());
    if (!r.stats.inside_test.empty())
        std::printf("inside   %s (%s)\n", r.stats.inside_test.c_str(),
                    r.stats.inside_test_reason.c_str());
    if (r.device)
        std::printf("device   %s (%s)\n", r.device->name.c_str(), r.device->platform.c_str());
    else
        std::printf("device   CPU reference\n");
    std::printf("voxels   %llu set\n", (unsigned long long)r.stats.voxels_set);
    std::printf("output   %s\n", r.args.output.c_str());
    std::printf("time     %.3f s\n", r.timings.total);
}

void print_stats(const RunReport& r) {
    const Timings& t = r.timings;
    const oclvox::VoxelizeStats& s = r.stats;
    std::printf("timing (seconds)\n");
    std::printf("  load          %9.4f\n", t.load);
    std::printf("  fit           %9.4f\n", t.fit);
    std::printf("  device open   %9.4f  (OpenCL context, queue and programs)\n", t.device);
    std::printf("  voxelize      %9.4f\n", t.voxelize);
    std::printf("    binning     %9.4f\n", s.seconds_binning);
    std::printf("    upload      %9.4f\n", s.seconds_upload);
    std::printf("    kernels     %9.4f\n", s.seconds_kernels);
    std::printf("    download    %9.4f\n", s.seconds_download);
    std::printf("  write         %9.4f\n", t.write);
    std::printf("  total         %9.4f\n", t.total);
    std::printf("counts\n");
    std::printf("  triangles     %llu (%llu inside the grid)\n", (unsigned long long)s.triangles_in,
                (unsigned long long)s.triangles_used);
    std::printf("  bricks        %llu active of %llu, %llu batches\n",
                (unsigned long long)s.bricks_active, (unsigned long long)s.bricks_total,
                (unsigned long long)s.batches);
    std::printf("  brick pairs   %llu\n", (unsigned long long)s.brick_pairs);
    std::printf("  work items    %llu\n", (unsigned long long)s.work_items);
    std::printf("  voxels set    %llu of %llu\n", (unsigned long long)s.voxels_set,
                (unsigned long long)r.grid.voxel_count());
    std::printf("throughput (over voxelize)\n");
    std::printf("  triangles/s   %s\n",
                rate_text(per_second(double(s.triangles_in), t.voxelize)).c_str());
    std::printf("  grid voxels/s %s\n",
                rate_text(per_second(double(r.grid.voxel_count()), t.voxelize)).c_str());
}

nlohmann::ordered_json stats_json(const RunReport& r) {
    const Timings& t = r.timings;
    const oclvox::VoxelizeStats& s = r.stats;
    nlohmann::ordered_json j;
    j["oclvox_version"] = OCLVOX_VERSION;
    j["input"] = r.args.input;
    j["output"] = r.args.output;
    j["backend"] = r.device ? "opencl" : "reference";
    if (r.device)
        j["device"] = {{"id", r.device->id},
                       {"name", r.device->name},
                       {"platform", r.device->platform},
                       {"type", r.device->type},
                       {"opencl_version", r.device->version},
                       {"driver_version", r.device->driver_version}};
    else
        j["device"] = nullptr;
    j["test"] = r.args.test;
    j["mode"] = r.args.mode;
    j["boundary"] = r.args.boundary;
    if (!r.stats.inside_test.empty())
        j["inside"] = {{"test", r.stats.inside_test}, {"reason", r.stats.inside_test_reason}};
    j["brick_size"] = r.args.brick_size;
    j["grid"] = {{"dims", r.grid.dims},
                 {"voxel_size", r.grid.voxel_size},
                 {"origin", r.grid.origin},
                 {"voxels", r.grid.voxel_count()}};
    j["seconds"] = {{"load", t.load},
                    {"fit", t.fit},
                    {"device_open", t.device},
                    {"voxelize", t.voxelize},
                    {"binning", s.seconds_binning},
                    {"upload", s.seconds_upload},
                    {"kernels", s.seconds_kernels},
                    {"download", s.seconds_download},
                    {"write", t.write},
                    {"total", t.total}};
    j["triangles"] = s.triangles_in;
    j["triangles_used"] = s.triangles_used;
    j["bricks_total"] = s.bricks_total;
    j["bricks_active"] = s.bricks_active;
    j["batches"] = s.batches;
    j["brick_pairs"] = s.brick_pairs;
    j["work_items"] = s.work_items;
    j["voxels_set"] = s.voxels_set;
    j["triangles_per_second"] = per_second(double(s.triangles_in), t.voxelize);
    j["grid_voxels_per_second"] = per_second(double(r.grid.voxel_count()), t.voxelize);
    return j;
}

// ---------------------------------------------------------------------------------------------
// Commands
// ---------------------------------------------------------------------------------------------
int run_devices() {
    const std::vector<oclvox::DeviceInfo> devices = oclvox::list_devices();
    if (devices.empty()) throw oclvox::DeviceError("OpenCL platforms exist but have no devices");
    for (const oclvox::DeviceInfo& d : devices) {
        std::printf("%s  %s  %s\n", d.id.c_str(), d.type.c_str(), d.name.c_str());
        std::printf("     platform  %s\n", d.platform.c_str());
        std::printf("     version   %s\n", d.version.c_str());
        std::printf("     driver    %s\n", d.driver_version.c_str());
        std::printf("     memory    %s global, %s per allocation\n",
                    bytes_text(d.global_memory).c_str(), bytes_text(d.max_alloc).c_str());
    }
    return 0;
}

int run_voxelize(const VoxelizeArgs& args) {
    const Clock::time_point start = Clock::now();
    Timings timings;
    start_interrupt_watcher();

    // Phase 1: output paths, before any work is spent.
    check_output_path(args.output, true);
    if (!args.stats_json.empty()) check_output_path(args.stats_json, false);

    // Phase 2: the mesh and the grid around it.
    const oclvox::Mesh mesh = timed(timings.load, [&] { return oclvox::load_mesh(args.input); });
    const oclvox::Grid grid = timed(timings.fit, [&] { return oclvox::fit_grid(mesh, args.fit); });
    stop_if_interrupted();

    // Phase 3: the device. Opening it builds (or loads cached) kernels, timed apart from the run.
    std::optional<oclvox::Device> device;
    if (!args.reference)
        device.emplace(timed(timings.device, [&] { return oclvox::Device::open(args.device); }));
    stop_if_interrupted();

    // Phase 4: voxelize, drawing progress and checking for Ctrl-C after every batch.
    oclvox::VoxelizeOptions options;
    options.test = oclvox::overlap_test_from_string(args.test);
    options.mode = oclvox::voxelize_mode_from_string(args.mode);
    options.inside = oclvox::inside_test_from_string(args.inside);
    options.boundary = oclvox::boundary_from_string(args.boundary);
    options.brick_size = args.brick_size;
    options.device_budget_bytes = args.device_mib << 20;
    options.host_budget_bytes = args.host_mib << 20;
    oclvox::VoxelizeStats stats;
    const oclvox::SparseVoxels voxels = timed(timings.voxelize, [&] {
        oclvox_cli::ProgressBar bar("voxelizing", "bricks", !args.quiet && isatty(STDERR_FILENO));
        options.progress = [&](uint64_t done, uint64_t total) {
            bar.update(done, total);
            return !g_interrupted;
        };
        return device ? device->voxelize(mesh, grid, options, &stats)
                      : oclvox::voxelize_reference(mesh, grid, options, &stats);
    });
    stop_if_interrupted();

    // Phase 5: the voxel file, then the reports.
    const Clock::time_point write_start = Clock::now();
    oclvox::write_voxels(args.output, voxels);
    timings.write = seconds_since(write_start);
    timings.total = seconds_since(start);

    const RunReport report{args, mesh, grid, device ? &device->info() : nullptr, stats, timings};
    if (!args.quiet) print_summary(report);
    if (args.stats) print_stats(report);
    if (!args.stats_json.empty())
        write_text_atomically(args.stats_json, stats_json(report).dump(2) + "\n");
    return 0;
}

void add_voxelize_options(CLI::App& command, VoxelizeArgs& args) {
    command.add_option("input", args.input, "mesh file: .obj, .stl, .ply or .off")
        ->type_name("INPUT")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "voxel file; the format follows from the extension: .binvox, .npy (with a "
                    ".json sidecar), .vox (MagicaVoxel), .obj or .ply (exposed cube faces)")
        ->type_name("OUTPUT")
        ->required();

    // Grid
    auto* resolution =
        command.add_option("-r,--resolution", args.fit.resolution, "voxels along the longest axis")
            ->type_name("N")
            ->check(CLI::Range(int64_t(1), oclvox::kMaxGridAxis))
            ->capture_default_str()
            ->group("Grid");
    auto* cubic = command
                      .add_flag("--cubic", args.fit.cubic,
                                "resolution^3 grid with the mesh centred (the binvox convention)")
                      ->group("Grid");
    auto* voxel_size = command
                           .add_option("--voxel-size", args.fit.voxel_size,
                                       "edge length of a voxel, instead of --resolution")
                           ->type_name("H")
                           ->check(kPositiveFinite)
                           ->excludes(resolution)
                           ->group("Grid");
    command
        .add_option_function<std::string>(
            "--origin",
            [&args](const std::string& text) {
                args.fit.origin =
                    parse_triple<double>("--origin", text, "three finite numbers X,Y,Z",
                                         [](double v) { return std::isfinite(v); });
                args.fit.has_origin = true;
            },
            "corner of voxel (0,0,0), instead of the fitted one")
        ->type_name("X,Y,Z")
        ->group("Grid");
    auto* dims = command
                     .add_option_function<std::string>(
                         "--dims",
                         [&args](const std::string& text) {
                             args.fit.dims = parse_triple<int64_t>(
                                 "--dims", text,
                                 "three whole numbers NX,NY,NZ in [1, " +
                                     std::to_string(oclvox::kMaxGridAxis) + "]",
                                 [](int64_t n) { return n >= 1 && n <= oclvox::kMaxGridAxis; });
                             args.fit.has_dims = true;
                         },
                         "voxels along each axis, instead of the fitted ones")
                     ->type_name("NX,NY,NZ")
                     ->group("Grid");
    cubic->excludes(voxel_size)->excludes(dims);
    command.add_option("--pad", args.fit.pad, "empty voxels added on every side")
        ->type_name("N")
        ->check(CLI::Range(int64_t(0), oclvox::kMaxGridAxis))
        ->capture_default_str()
        ->group("Grid");

    // Voxelization
    command
        .add_option("--test", args.test,
                    "triangle/box overlap test; both are always available: pef (default, plane "
                    "and projected edge functions) or sat (separating axes)")
        ->type_name("TEST")
        ->check(CLI::IsMember({"pef", "sat"}))
        ->capture_default_str()
        ->group("Voxelization");
    command
        .add_option("--mode", args.mode,
                    "surface (conservative, 26-separating: every voxel touching a triangle), "
                    "thin (6-separating, Schwarz & Seidel), solid (voxel centres inside the "
                    "mesh) or filled (solid and surface)")
        ->type_name("MODE")
        ->check(CLI::IsMember({"surface", "thin", "solid", "filled"}))
        ->capture_default_str()
        ->group("Voxelization");
    command
        .add_option("--inside", args.inside,
                    "inside test for solid/filled: auto (parity for closed meshes, winding "
                    "number otherwise), parity or winding")
        ->type_name("TEST")
        ->check(CLI::IsMember({"auto", "parity", "winding"}))
        ->capture_default_str()
        ->group("Voxelization");
    command
        .add_option("--boundary", args.boundary,
                    "closed (voxels are closed boxes: a face on a voxel face marks both voxels) "
                    "or half-open ([i, i+1): it marks exactly one layer)")
        ->type_name("RULE")
        ->check(CLI::IsMember({"closed", "half-open"}))
        ->capture_default_str()
        ->group("Voxelization");
    if (const char* selector = std::getenv("OCLVOX_DEVICE")) args.device = selector;
    auto* device = command
                       .add_option("--device", args.device,
                                   "OpenCL device: \"P:D\" indices (see `oclvox devices`) or part "
                                   "of the device or platform name. Default: $OCLVOX_DEVICE, else "
                                   "the first GPU, else the first device. A device that does not "
                                   "exist is an error, never a fallback")
                       ->type_name("SEL")
                       ->group("Voxelization");
    command
        .add_flag("--reference", args.reference,
                  "run the CPU reference implementation instead of an OpenCL device (needs no "
                  "OpenCL)")
        ->excludes(device)
        ->group("Voxelization");
    command.add_option("--brick-size", args.brick_size, "voxels per brick edge")
        ->type_name("B")
        ->check(kBrickSize)
        ->capture_default_str()
        ->group("Voxelization");
    command
        .add_option("--device-memory", args.device_mib,
                    "device memory for one batch of bricks, in MiB")
        ->type_name("MIB")
        ->check(CLI::Range(uint64_t(1), uint64_t(1) << 24))
        ->capture_default_str()
        ->group("Voxelization");
    command
        .add_option("--host-memory", args.host_mib,
                    "host memory for the result, in MiB; 0 means half of physical memory")
        ->type_name("MIB")
        ->check(CLI::Range(uint64_t(0), uint64_t(1) << 24))
        ->capture_default_str()
        ->group("Voxelization");

    // Reporting
    command.add_flag("-q,--quiet", args.quiet, "print neither progress nor the summary")
        ->group("Reporting");
    command.add_flag("--stats", args.stats, "print a timing breakdown and counts")
        ->group("Reporting");
    command
        .add_option("--stats-json", args.stats_json,
                    "write the timing breakdown, counts and run details to this JSON file")
        ->type_name("FILE")
        ->group("Reporting");
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"oclvox: conservative mesh voxelization on OpenCL devices", "oclvox"};
    app.set_version_flag("--version", std::string("oclvox ") + OCLVOX_VERSION);
    app.require_subcommand(1);

    CLI::App* devices = app.add_subcommand("devices", "list the OpenCL platforms and devices");
    VoxelizeArgs args;
    CLI::App* voxelize = app.add_subcommand("voxelize", "voxelize a mesh file into a voxel file");
    voxelize->footer(
        "Exit codes: 0 success, 1 error, 2 usage error, 130 cancelled (Ctrl-C).\n"
        "Example: oclvox voxelize bunny.obj -r 512 -o bunny.binvox --stats");
    add_voxelize_options(*voxelize, args);

    // Phase 1: the command line. Help and --version end here with exit code 0.
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e);
        std::cerr << "oclvox: error: " << e.what() << "\nRun with --help for more information.\n";
        return kExitUsage;
    }

    // Phase 2: the command. Library errors already name the file, option or device at fault.
    try {
        return devices->parsed() ? run_devices() : run_voxelize(args);
    } catch (const oclvox::Cancelled&) {
        std::cerr << "oclvox: cancelled\n";
        return kExitCancelled;
    } catch (const std::bad_alloc&) {
        std::cerr << "oclvox: error: out of memory (try a lower --resolution)\n";
        return kExitError;
    } catch (const std::exception& e) {
        std::cerr << "oclvox: error: " << e.what() << "\n";
        return kExitError;
    }
}
