// oclvox: the command-line tool. `oclvox devices` lists the OpenCL devices; `oclvox voxelize`
// turns a mesh file into a voxel file; `oclvox sdf` writes a signed distance field, `oclvox csg`
// combines two meshes (or fields) and `oclvox mesh` meshes a field's iso-surface. This file parses
// and checks the command line, times the phases and reports; all the work is the library's.
//
// Exit codes: 0 success, 1 error (the message names the problem), 2 command-line usage error,
// 130 stopped by SIGINT (Ctrl-C), 143 stopped by SIGTERM.
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
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "file_names.hpp"
#include "oclvox/field.hpp"
#include "oclvox/oclvox.hpp"
#include "oclvox/sdf.hpp"
#include "progress_bar.hpp"

// CMake passes the project version; the fallback only labels builds made outside CMake.
#ifndef OCLVOX_VERSION
#define OCLVOX_VERSION "unknown"
#endif

namespace {

namespace fs = std::filesystem;

constexpr int kExitError = 1;
constexpr int kExitUsage = 2;

// ---------------------------------------------------------------------------------------------
// SIGINT (Ctrl-C) and SIGTERM
// ---------------------------------------------------------------------------------------------
// A stop leaves no output and ends the process within 2 s with 128 + the signal's number (130 for
// SIGINT, 143 for SIGTERM, the shell convention).
constexpr auto kStopGrace = std::chrono::milliseconds(1500);

// Set on SIGINT or SIGTERM; the progress callback turns it into a clean cancellation, so the
// library stops between batches.
std::atomic<bool> g_interrupted{false};
std::atomic<int> g_stop_signal{SIGINT};

int stopped_exit_code() {
    return 128 + g_stop_signal;
}

// The signals are taken by a watcher thread with sigwait rather than by a signal handler. They
// stay blocked everywhere else, and a blocked signal is inherited by the processes the OpenCL
// runtime spawns: PoCL runs a linker while it compiles a kernel, and a terminal's Ctrl-C (sent to
// the whole process group) would otherwise kill that linker and make the runtime abort.
// Call before any other thread exists, so that every thread inherits the block.
void start_interrupt_watcher() {
    sigset_t stop;
    sigemptyset(&stop);
    sigaddset(&stop, SIGINT);
    sigaddset(&stop, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop, nullptr);
    std::thread([stop] {
        int signal = 0;
        sigwait(&stop, &signal);
        g_stop_signal = signal;
        g_interrupted = true;
        // From here on no output appears: writes in progress lose their temporary file, later
        // ones fail with Cancelled.
        oclvox::abandon_pending_writes();
        // The run has kStopGrace to stop by itself and return its exit code. Phases that report
        // no progress (loading a huge mesh, one long batch) are ended here, as is everything on a
        // second signal; nothing is left to clean up.
        const auto grace = std::chrono::duration_cast<std::chrono::nanoseconds>(kStopGrace);
        const timespec wait{time_t(grace.count() / 1000000000), long(grace.count() % 1000000000)};
        sigtimedwait(&stop, nullptr, &wait);
        std::_Exit(stopped_exit_code());
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
    std::string test = "sat";
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
using oclvox::detail::lowercase_extension;

// Mistakes in output paths are cheap to find before the run and expensive after a long one, so
// every output is checked before any input is read: its extension against the formats the
// command writes (`allowed`; empty: any), then the library's check_output_path (folder exists and
// is writable, not a directory, not one of the inputs), also for a .npy output's .json sidecar.
void check_output(const std::string& path, const std::vector<std::string>& inputs,
                  const std::vector<std::string>& allowed) {
    const std::string ext = lowercase_extension(path);
    if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), ext) == allowed.end()) {
        std::string list;
        for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
        throw oclvox::OutputError(
            "cannot write '" + path + "': " +
            (ext.empty() ? "the file name has no extension" : "unknown extension '" + ext + "'") +
            " (supported: " + list + ")");
    }
    oclvox::check_output_path(path, inputs);
    if (ext == ".npy") oclvox::check_output_path(path + ".json", inputs);
}

// What write_voxels accepts.
const std::vector<std::string> kVoxelExtensions{".vdb", ".binvox", ".npy", ".vox",
                                                ".obj", ".ply",    ".stl"};

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
    if (r.stats.allocation_retries)
        std::printf("memory   device allocations failed; %llu batches retried with fewer bricks\n",
                    (unsigned long long)r.stats.allocation_retries);
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
    std::printf("  device open   %9.4f  (OpenCL platform, context and queue)\n", t.device);
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
    j["allocation_retries"] = s.allocation_retries;
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

// The device, unless the CPU reference was asked for. Kernels are built (or loaded from the disk
// cache) when first used; a build, which only the first run on a device pays, is announced on
// stderr because it can take tens of seconds.
std::optional<oclvox::Device> open_device(bool reference, const std::string& selector,
                                          double& seconds) {
    std::optional<oclvox::Device> device;
    if (!reference) {
        device.emplace(timed(seconds, [&] { return oclvox::Device::open(selector); }));
        device->on_kernel_compile([](const oclvox::Device::KernelCompile& c) {
            if (!c.finished)
                std::fprintf(stderr,
                             "compiling kernels '%s' for this device (first run; cached for later "
                             "runs)...\n",
                             c.program.c_str());
            else
                std::fprintf(stderr, "compiled kernels '%s' in %.1f s\n", c.program.c_str(),
                             c.seconds);
        });
    }
    stop_if_interrupted();
    return device;
}

int run_voxelize(const VoxelizeArgs& args) {
    const Clock::time_point start = Clock::now();
    Timings timings;
    start_interrupt_watcher();

    // Phase 1: output paths, before any work is spent.
    check_output(args.output, {args.input}, kVoxelExtensions);
    if (!args.stats_json.empty()) check_output(args.stats_json, {args.input}, {});

    // Phase 2: the mesh and the grid around it.
    const oclvox::Mesh mesh = timed(timings.load, [&] { return oclvox::load_mesh(args.input); });
    const oclvox::Grid grid = timed(timings.fit, [&] { return oclvox::fit_grid(mesh, args.fit); });
    stop_if_interrupted();

    // Phase 3: the device. Opening it builds (or loads cached) kernels, timed apart from the run.
    std::optional<oclvox::Device> device = open_device(args.reference, args.device, timings.device);

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
        oclvox::write_text_file(args.stats_json, stats_json(report).dump(2) + "\n");
    return 0;
}

// Grid options shared by voxelize, sdf, csg and mesh. Returns them so that a command can tell
// whether any was given (they do not apply to field inputs).
std::vector<CLI::Option*> add_grid_options(CLI::App& command, oclvox::GridFit& fit) {
    auto* resolution =
        command.add_option("-r,--resolution", fit.resolution, "voxels along the longest axis")
            ->type_name("N")
            ->check(CLI::Range(int64_t(1), oclvox::kMaxGridAxis))
            ->capture_default_str()
            ->group("Grid");
    auto* cubic =
        command
            .add_flag("--cubic{centre}",
                      "resolution^3 grid. --cubic (or --cubic=centre) centres the mesh box in the "
                      "cube, as cuda_voxelizer does; --cubic=min puts the box minimum at the "
                      "cube's corner, as binvox does (translate = box minimum, scale = longest "
                      "side)")
            ->check(CLI::IsMember({"centre", "min"}))
            ->each([&fit](const std::string& anchor) {
                fit.cubic = true;
                fit.cubic_anchor = anchor == "min" ? oclvox::GridFit::CubicAnchor::Minimum
                                                   : oclvox::GridFit::CubicAnchor::Centre;
            })
            ->group("Grid");
    auto* voxel_size = command
                           .add_option("--voxel-size", fit.voxel_size,
                                       "edge length of a voxel, instead of --resolution")
                           ->type_name("H")
                           ->check(kPositiveFinite)
                           ->excludes(resolution)
                           ->group("Grid");
    auto* origin = command
                       .add_option_function<std::string>(
                           "--origin",
                           [&fit](const std::string& text) {
                               fit.origin = parse_triple<double>(
                                   "--origin", text, "three finite numbers X,Y,Z",
                                   [](double v) { return std::isfinite(v); });
                               fit.has_origin = true;
                           },
                           "corner of voxel (0,0,0), instead of the fitted one")
                       ->type_name("X,Y,Z")
                       ->group("Grid");
    auto* dims = command
                     .add_option_function<std::string>(
                         "--dims",
                         [&fit](const std::string& text) {
                             fit.dims = parse_triple<int64_t>(
                                 "--dims", text,
                                 "three whole numbers NX,NY,NZ in [1, " +
                                     std::to_string(oclvox::kMaxGridAxis) + "]",
                                 [](int64_t n) { return n >= 1 && n <= oclvox::kMaxGridAxis; });
                             fit.has_dims = true;
                         },
                         "voxels along each axis, instead of the fitted ones")
                     ->type_name("NX,NY,NZ")
                     ->group("Grid");
    cubic->excludes(voxel_size)->excludes(dims);
    auto* pad = command.add_option("--pad", fit.pad, "empty voxels added on every side")
                    ->type_name("N")
                    ->check(CLI::Range(int64_t(0), oclvox::kMaxGridAxis))
                    ->capture_default_str()
                    ->group("Grid");
    return {resolution, cubic, voxel_size, origin, dims, pad};
}

// --device / --reference (mutually exclusive), shared by every command that runs OpenCL work.
void add_device_options(CLI::App& command, std::string& selector, bool& reference,
                        const std::string& group) {
    if (const char* env = std::getenv("OCLVOX_DEVICE")) selector = env;
    auto* device = command
                       .add_option("--device", selector,
                                   "OpenCL device: \"P:D\" indices (see `oclvox devices`) or part "
                                   "of the device or platform name. Default: $OCLVOX_DEVICE, else "
                                   "the first GPU, else the first device. A device that does not "
                                   "exist is an error, never a fallback")
                       ->type_name("SEL")
                       ->group(group);
    command
        .add_flag("--reference", reference,
                  "run the CPU reference implementation instead of an OpenCL device (needs no "
                  "OpenCL)")
        ->excludes(device)
        ->group(group);
}

// --quiet, --stats and (where the command has one) --stats-json.
void add_reporting_options(CLI::App& command, bool& quiet, bool& stats, std::string* stats_json) {
    command.add_flag("-q,--quiet", quiet, "print neither progress nor the summary")
        ->group("Reporting");
    command.add_flag("--stats", stats, "print a timing breakdown and counts")->group("Reporting");
    if (stats_json)
        command
            .add_option("--stats-json", *stats_json,
                        "write the timing breakdown, counts and run details to this JSON file")
            ->type_name("FILE")
            ->group("Reporting");
}

void add_voxelize_options(CLI::App& command, VoxelizeArgs& args) {
    command.add_option("input", args.input, "mesh file: .obj, .stl, .ply or .off")
        ->type_name("INPUT")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "voxel file; the format follows from the extension: .vdb (OpenVDB, sparse), "
                    ".binvox, .npy (with a .json sidecar), .vox (MagicaVoxel), .obj, .ply or .stl "
                    "(exposed cube faces)")
        ->type_name("OUTPUT")
        ->required();

    add_grid_options(command, args.fit);

    // Voxelization
    command
        .add_option("--test", args.test,
                    "triangle/box overlap test; both are always available: sat (default, 13 "
                    "separating axes) or pef (plane and projected edge functions)")
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
    add_device_options(command, args.device, args.reference, "Voxelization");
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
    add_reporting_options(command, args.quiet, args.stats, &args.stats_json);
}

// ---------------------------------------------------------------------------------------------
// Distance fields: sdf, csg, mesh
// ---------------------------------------------------------------------------------------------
// A usage error found after parsing (an option that does not apply to the inputs given): exit 2.
struct UsageError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

struct FieldArgs {
    std::string input, op, input_b, output, mesh_output;
    oclvox::GridFit fit;
    std::vector<CLI::Option*> grid_options;  // to reject them for .npy field inputs
    double band = 3.0;
    bool full = false;
    std::string inside = "auto";
    // Marching Cubes by default: its meshes are closed and manifold (Surface Nets' are not where
    // a cell face has four sign changes, which CSG results and thin parts produce).
    std::string mesher = "marching-cubes";
    double iso = 0.0;
    std::string device;
    bool reference = false;
    bool quiet = false;
    bool stats = false;
};

struct FieldTimings {
    double load = 0, fit = 0, device = 0, compute = 0, mesh = 0, write = 0, total = 0;
};

bool is_field_path(const std::string& path) {
    return lowercase_extension(path) == ".npy";
}

const std::vector<std::string> kMeshExtensions{".obj", ".ply", ".stl"};
const std::vector<std::string> kFieldExtensions{".npy", ".vdb"};

bool is_mesh_output(const std::string& path) {
    const std::string ext = lowercase_extension(path);
    return std::find(kMeshExtensions.begin(), kMeshExtensions.end(), ext) != kMeshExtensions.end();
}

bool any_given(const std::vector<CLI::Option*>& options) {
    return std::any_of(options.begin(), options.end(),
                       [](const CLI::Option* o) { return o->count() > 0; });
}

// The grid fit of sdf and csg: a fitted grid gets field_padding(band) voxels on every side, so the
// zero level set closes inside it, unless the user places the grid (--pad, --origin or --dims).
oclvox::GridFit field_fit(const FieldArgs& args) {
    oclvox::GridFit fit = args.fit;
    const bool placed =
        std::any_of(args.grid_options.begin(), args.grid_options.end(), [](const CLI::Option* o) {
            return o->count() > 0 &&
                   (o->check_name("--pad") || o->check_name("--origin") || o->check_name("--dims"));
        });
    if (!placed) fit.pad = oclvox::field_padding(args.band);
    return fit;
}

oclvox::SdfOptions sdf_options(const FieldArgs& args) {
    oclvox::SdfOptions options;
    options.band_voxels = args.band;
    options.full_grid = args.full;
    options.inside = oclvox::inside_test_from_string(args.inside);
    return options;
}

oclvox::ScalarField signed_distance(std::optional<oclvox::Device>& device, const oclvox::Mesh& mesh,
                                    const oclvox::Grid& grid, const FieldArgs& args,
                                    oclvox::VoxelizeStats* stats) {
    return device ? oclvox::signed_distance(*device, mesh, grid, sdf_options(args), stats)
                  : oclvox::signed_distance_reference(mesh, grid, sdf_options(args), stats);
}

oclvox::Mesh extract_surface(std::optional<oclvox::Device>& device,
                             const oclvox::ScalarField& field, const std::string& mesher,
                             float iso) {
    if (mesher == "marching-cubes")
        return device ? oclvox::marching_cubes(*device, field, iso)
                      : oclvox::marching_cubes(field, iso);
    return device ? oclvox::surface_nets(*device, field, iso) : oclvox::surface_nets(field, iso);
}

// What a field command's summary and --stats report.
struct FieldReport {
    std::vector<std::string> inputs;  // "path (N triangles)" or "path (field)"
    const oclvox::Grid& grid;
    const oclvox::DeviceInfo* device;
    const oclvox::VoxelizeStats* stats;  // null when no distance/voxelize run happened
    const oclvox::Mesh* mesh;            // null when no mesh was made
    std::vector<std::string> outputs;
    const FieldTimings& timings;
    uint64_t border_inside;  // border samples inside: the grid cuts the shape (see below)
};

void print_field_summary(const FieldReport& r) {
    for (const std::string& input : r.inputs) std::printf("input    %s\n", input.c_str());
    const oclvox::Grid& g = r.grid;
    std::printf("grid     %s voxels of size %g, origin (%g, %g, %g)\n", dims_text(g).c_str(),
                g.voxel_size, g.origin[0], g.origin[1], g.origin[2]);
    if (r.stats && !r.stats->inside_test.empty())
        std::printf("inside   %s (%s)\n", r.stats->inside_test.c_str(),
                    r.stats->inside_test_reason.c_str());
    if (r.device)
        std::printf("device   %s (%s)\n", r.device->name.c_str(), r.device->platform.c_str());
    else
        std::printf("device   CPU reference\n");
    if (r.mesh)
        std::printf("mesh     %zu triangles, %zu vertices\n", r.mesh->triangles.size(),
                    r.mesh->positions.size());
    for (const std::string& output : r.outputs) std::printf("output   %s\n", output.c_str());
    if (r.border_inside)
        std::printf(
            "warning  the shape reaches the grid border (%llu border samples inside): the grid "
            "cuts its surface, so the field is truncated and meshes are open there; grow the grid "
            "(--pad, --dims)\n",
            (unsigned long long)r.border_inside);
    std::printf("time     %.3f s\n", r.timings.total);
}

void print_field_stats(const FieldReport& r) {
    const FieldTimings& t = r.timings;
    std::printf("timing (seconds)\n");
    std::printf("  load          %9.4f\n", t.load);
    std::printf("  fit           %9.4f\n", t.fit);
    std::printf("  device open   %9.4f  (OpenCL platform, context and queue)\n", t.device);
    std::printf("  field         %9.4f\n", t.compute);
    std::printf("  mesh          %9.4f\n", t.mesh);
    std::printf("  write         %9.4f\n", t.write);
    std::printf("  total         %9.4f\n", t.total);
    std::printf("counts\n");
    if (r.stats) {
        std::printf("  triangles     %llu (%llu used)\n", (unsigned long long)r.stats->triangles_in,
                    (unsigned long long)r.stats->triangles_used);
        std::printf("  work items    %llu\n", (unsigned long long)r.stats->work_items);
        std::printf("  inside voxels %llu\n", (unsigned long long)r.stats->voxels_set);
    }
    std::printf("  grid voxels   %llu\n", (unsigned long long)r.grid.voxel_count());
    if (r.mesh)
        std::printf("  mesh out      %zu triangles, %zu vertices\n", r.mesh->triangles.size(),
                    r.mesh->positions.size());
}

void report_field_run(const FieldArgs& args, const FieldReport& report) {
    if (!args.quiet) print_field_summary(report);
    if (args.stats) print_field_stats(report);
}

std::string mesh_input_text(const std::string& path, const oclvox::Mesh& mesh) {
    return path + " (" + std::to_string(mesh.triangles.size()) + " triangles)";
}

// A .npy input as a field. An occupancy (what `voxelize` writes) becomes a field through
// occupancy_to_field, as a mesh input's voxels do in `mesh`; `occupancy` says which it was.
oclvox::ScalarField read_field_input(const std::string& path, bool& occupancy) {
    std::variant<oclvox::ScalarField, oclvox::SparseVoxels> data = oclvox::read_npy(path);
    occupancy = std::holds_alternative<oclvox::SparseVoxels>(data);
    if (occupancy) return oclvox::occupancy_to_field(std::get<oclvox::SparseVoxels>(data));
    return std::get<oclvox::ScalarField>(std::move(data));
}

std::string field_input_text(const std::string& path, bool occupancy) {
    return path + (occupancy ? " (occupancy)" : " (field)");
}

int run_sdf(const FieldArgs& args) {
    const Clock::time_point start = Clock::now();
    FieldTimings timings;
    start_interrupt_watcher();

    check_output(args.output, {args.input}, kFieldExtensions);
    if (!args.mesh_output.empty()) check_output(args.mesh_output, {args.input}, kMeshExtensions);

    const oclvox::Mesh mesh = timed(timings.load, [&] { return oclvox::load_mesh(args.input); });
    const oclvox::Grid grid =
        timed(timings.fit, [&] { return oclvox::fit_grid(mesh, field_fit(args)); });
    stop_if_interrupted();
    std::optional<oclvox::Device> device = open_device(args.reference, args.device, timings.device);

    oclvox::VoxelizeStats stats;
    const oclvox::ScalarField field =
        timed(timings.compute, [&] { return signed_distance(device, mesh, grid, args, &stats); });
    stop_if_interrupted();
    std::optional<oclvox::Mesh> surface;
    if (!args.mesh_output.empty()) {
        surface =
            timed(timings.mesh, [&] { return extract_surface(device, field, args.mesher, 0.0f); });
        stop_if_interrupted();
    }

    const Clock::time_point write_start = Clock::now();
    oclvox::write_field(args.output, field, args.full ? 0.0 : args.band);
    if (surface) oclvox::write_mesh(args.mesh_output, *surface);
    timings.write = seconds_since(write_start);
    timings.total = seconds_since(start);

    std::vector<std::string> outputs{args.output};
    if (surface) outputs.push_back(args.mesh_output);
    report_field_run(args, {{mesh_input_text(args.input, mesh)},
                            grid,
                            device ? &device->info() : nullptr,
                            &stats,
                            surface ? &*surface : nullptr,
                            outputs,
                            timings,
                            oclvox::border_samples_inside(field)});
    return 0;
}

int run_csg(const FieldArgs& args) {
    const Clock::time_point start = Clock::now();
    FieldTimings timings;
    start_interrupt_watcher();

    const oclvox::CsgOp op = oclvox::csg_op_from_string(args.op);
    const bool mesh_out = is_mesh_output(args.output);
    check_output(args.output, {args.input, args.input_b}, {".obj", ".ply", ".stl", ".npy", ".vdb"});

    const bool fields_in = is_field_path(args.input) && is_field_path(args.input_b);
    if (!fields_in && (is_field_path(args.input) || is_field_path(args.input_b)))
        throw UsageError("csg takes two meshes or two .npy fields, not one of each");
    if (fields_in && any_given(args.grid_options))
        throw UsageError("grid options do not apply to .npy field inputs (their grids are used)");

    std::optional<oclvox::ScalarField> a, b;
    std::optional<oclvox::Mesh> mesh_a, mesh_b;
    std::optional<oclvox::Grid> grid;
    std::vector<std::string> inputs;
    oclvox::VoxelizeStats stats_a, stats_b;
    std::optional<oclvox::Device> device;
    if (fields_in) {
        bool occupancy_a = false, occupancy_b = false;
        timed(timings.load, [&] {
            a = read_field_input(args.input, occupancy_a);
            b = read_field_input(args.input_b, occupancy_b);
            return 0;
        });
        grid = a->grid;
        inputs = {field_input_text(args.input, occupancy_a),
                  field_input_text(args.input_b, occupancy_b)};
        // occupancy_to_field's values step by +-0.5 across the surface; they are not distances.
        if ((occupancy_a || occupancy_b) && !mesh_out)
            throw UsageError(
                "csg of an occupancy .npy writes a mesh (.obj, .ply, .stl), not a "
                "distance field");
        stop_if_interrupted();
        if (mesh_out) device = open_device(args.reference, args.device, timings.device);
    } else {
        timed(timings.load, [&] {
            mesh_a = oclvox::load_mesh(args.input);
            mesh_b = oclvox::load_mesh(args.input_b);
            return 0;
        });
        grid =
            timed(timings.fit, [&] { return oclvox::fit_grid(*mesh_a, *mesh_b, field_fit(args)); });
        inputs = {mesh_input_text(args.input, *mesh_a), mesh_input_text(args.input_b, *mesh_b)};
        stop_if_interrupted();
        device = open_device(args.reference, args.device, timings.device);
        timed(timings.compute, [&] {
            a = signed_distance(device, *mesh_a, *grid, args, &stats_a);
            stop_if_interrupted();
            b = signed_distance(device, *mesh_b, *grid, args, &stats_b);
            return 0;
        });
        stop_if_interrupted();
    }
    const oclvox::ScalarField combined = oclvox::csg(*a, *b, op);
    a.reset();
    b.reset();

    std::optional<oclvox::Mesh> surface;
    if (mesh_out) {
        surface = timed(timings.mesh,
                        [&] { return extract_surface(device, combined, args.mesher, 0.0f); });
        stop_if_interrupted();
    }
    const Clock::time_point write_start = Clock::now();
    if (surface)
        oclvox::write_mesh(args.output, *surface);
    else
        oclvox::write_field(args.output, combined, fields_in || args.full ? 0.0 : args.band);
    timings.write = seconds_since(write_start);
    timings.total = seconds_since(start);

    oclvox::VoxelizeStats stats = stats_a;  // both runs' counts together
    stats.triangles_in += stats_b.triangles_in;
    stats.triangles_used += stats_b.triangles_used;
    stats.work_items += stats_b.work_items;
    report_field_run(args, {inputs,
                            *grid,
                            device ? &device->info() : nullptr,
                            fields_in ? nullptr : &stats,
                            surface ? &*surface : nullptr,
                            {args.output},
                            timings,
                            oclvox::border_samples_inside(combined)});
    return 0;
}

int run_mesh(const FieldArgs& args) {
    const Clock::time_point start = Clock::now();
    FieldTimings timings;
    start_interrupt_watcher();

    check_output(args.output, {args.input}, kMeshExtensions);
    const bool field_in = is_field_path(args.input);
    if (field_in && any_given(args.grid_options))
        throw UsageError("grid options do not apply to a .npy field input (its grid is used)");

    std::optional<oclvox::ScalarField> field;
    std::string input_text;
    oclvox::VoxelizeStats stats;
    std::optional<oclvox::Device> device;
    if (field_in) {
        bool occupancy = false;
        field = timed(timings.load, [&] { return read_field_input(args.input, occupancy); });
        input_text = field_input_text(args.input, occupancy);
        stop_if_interrupted();
        device = open_device(args.reference, args.device, timings.device);
    } else {
        const oclvox::Mesh mesh =
            timed(timings.load, [&] { return oclvox::load_mesh(args.input); });
        const oclvox::Grid grid =
            timed(timings.fit, [&] { return oclvox::fit_grid(mesh, args.fit); });
        input_text = mesh_input_text(args.input, mesh);
        stop_if_interrupted();
        device = open_device(args.reference, args.device, timings.device);
        oclvox::VoxelizeOptions options;
        options.mode = oclvox::VoxelizeMode::Solid;
        options.inside = oclvox::inside_test_from_string(args.inside);
        field = timed(timings.compute, [&] {
            oclvox_cli::ProgressBar bar("voxelizing", "bricks",
                                        !args.quiet && isatty(STDERR_FILENO));
            options.progress = [&](uint64_t done, uint64_t total) {
                bar.update(done, total);
                return !g_interrupted;
            };
            const oclvox::SparseVoxels voxels =
                device ? device->voxelize(mesh, grid, options, &stats)
                       : oclvox::voxelize_reference(mesh, grid, options, &stats);
            return oclvox::occupancy_to_field(voxels);
        });
        stop_if_interrupted();
    }

    const oclvox::Mesh surface = timed(timings.mesh, [&] {
        return extract_surface(device, *field, args.mesher, float(args.iso));
    });
    stop_if_interrupted();
    const Clock::time_point write_start = Clock::now();
    oclvox::write_mesh(args.output, surface);
    timings.write = seconds_since(write_start);
    timings.total = seconds_since(start);

    report_field_run(args, {{input_text},
                            field->grid,
                            device ? &device->info() : nullptr,
                            field_in ? nullptr : &stats,
                            &surface,
                            {args.output},
                            timings,
                            oclvox::border_samples_inside(*field, float(args.iso))});
    return 0;
}

const CLI::Validator kFinite(
    [](std::string& text) -> std::string {
        double value = 0;
        if (!parse_number(text, value) || !std::isfinite(value))
            return "must be a finite number, got '" + text + "'";
        return {};
    },
    "FINITE");

void add_mesher_option(CLI::App& command, FieldArgs& args) {
    command
        .add_option("--mesher", args.mesher,
                    "iso-surface method: marching-cubes (asymptotic decider: closed and "
                    "manifold meshes) or surface-nets (Naive Surface Nets: fewer slivers, but "
                    "non-manifold where a cell face has four sign changes, as at CSG seams)")
        ->type_name("METHOD")
        ->check(CLI::IsMember({"surface-nets", "marching-cubes"}))
        ->capture_default_str()
        ->group("Meshing");
}

// sdf and csg pad fitted grids by default (field_fit): say so in their --pad help.
void describe_field_padding(const std::vector<CLI::Option*>& grid_options) {
    for (CLI::Option* o : grid_options)
        if (o->check_name("--pad"))
            o->description(
                 "empty voxels added on every side; by default band + 1 (band rounded up) so the "
                 "zero level set closes inside the grid, or 0 when --origin or --dims place it")
                ->default_str("band+1");
}

void add_distance_options(CLI::App& command, FieldArgs& args) {
    command
        .add_option("--band", args.band,
                    "half-width of the band of exact distances, in voxels; outside it a "
                    "narrow-band field holds +-band * voxel size")
        ->type_name("VOXELS")
        ->check(kPositiveFinite)
        ->capture_default_str()
        ->group("Distance");
    command
        .add_option("--inside", args.inside,
                    "inside test that gives the sign: auto (parity for closed meshes, winding "
                    "number otherwise), parity or winding")
        ->type_name("TEST")
        ->check(CLI::IsMember({"auto", "parity", "winding"}))
        ->capture_default_str()
        ->group("Distance");
}

void add_sdf_options(CLI::App& command, FieldArgs& args) {
    command.add_option("input", args.input, "mesh file: .obj, .stl, .ply or .off")
        ->type_name("INPUT")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "field file: .npy (float32, with a .json sidecar) or .vdb (OpenVDB level set)")
        ->type_name("OUTPUT")
        ->required();
    args.grid_options = add_grid_options(command, args.fit);
    describe_field_padding(args.grid_options);
    add_distance_options(command, args);
    command
        .add_flag("--full", args.full,
                  "distances in every voxel (jump flooding), not only in the narrow band")
        ->group("Distance");
    add_device_options(command, args.device, args.reference, "Distance");
    command
        .add_option("--mesh", args.mesh_output,
                    "also write the field's zero level set as a mesh: .obj, .ply or .stl")
        ->type_name("FILE")
        ->group("Meshing");
    add_mesher_option(command, args);
    add_reporting_options(command, args.quiet, args.stats, nullptr);
}

void add_csg_options(CLI::App& command, FieldArgs& args) {
    command.add_option("a", args.input, "first mesh file, or a .npy signed distance field")
        ->type_name("A")
        ->required();
    command.add_option("op", args.op, "union, intersection or difference (A minus B)")
        ->type_name("OP")
        ->check(CLI::IsMember({"union", "intersection", "difference"}))
        ->required();
    command.add_option("b", args.input_b, "second mesh file, or a .npy field on A's grid")
        ->type_name("B")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "a mesh (.obj, .ply, .stl: the result's zero level set) or a field (.npy, "
                    ".vdb)")
        ->type_name("OUTPUT")
        ->required();
    args.grid_options = add_grid_options(command, args.fit);
    describe_field_padding(args.grid_options);
    add_distance_options(command, args);
    command
        .add_flag("--full", args.full,
                  "distances in every voxel (jump flooding), not only in the narrow band")
        ->group("Distance");
    add_device_options(command, args.device, args.reference, "Distance");
    add_mesher_option(command, args);
    add_reporting_options(command, args.quiet, args.stats, nullptr);
}

void add_mesh_options(CLI::App& command, FieldArgs& args) {
    command
        .add_option("input", args.input,
                    "a .npy scalar field (with its .json sidecar), meshed at --iso; or a mesh "
                    "file (.obj, .stl, .ply, .off), which is voxelized (mode solid, on the grid "
                    "options' grid), turned into a field by occupancy_to_field (one smoothing "
                    "pass) and meshed: a remeshed voxel surface, not the original")
        ->type_name("INPUT")
        ->required();
    command.add_option("-o,--output", args.output, "mesh file: .obj, .ply or .stl")
        ->type_name("OUTPUT")
        ->required();
    args.grid_options = add_grid_options(command, args.fit);
    command
        .add_option("--inside", args.inside,
                    "inside test when voxelizing a mesh input: auto, parity or winding")
        ->type_name("TEST")
        ->check(CLI::IsMember({"auto", "parity", "winding"}))
        ->capture_default_str()
        ->group("Meshing");
    add_mesher_option(command, args);
    command.add_option("--iso", args.iso, "iso-value of the surface (inside is below it)")
        ->type_name("V")
        ->check(kFinite)
        ->capture_default_str()
        ->group("Meshing");
    add_device_options(command, args.device, args.reference, "Meshing");
    add_reporting_options(command, args.quiet, args.stats, nullptr);
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
        "Exit codes: 0 success, 1 error, 2 usage error, 130 SIGINT (Ctrl-C), 143 SIGTERM.\n"
        "Example: oclvox voxelize bunny.obj -r 512 -o bunny.binvox --stats");
    add_voxelize_options(*voxelize, args);

    const char* exits =
        "Exit codes: 0 success, 1 error, 2 usage error, 130 SIGINT (Ctrl-C), 143 SIGTERM.\n";
    FieldArgs sdf_args, csg_args, mesh_args;
    CLI::App* sdf = app.add_subcommand(
        "sdf", "signed distance field of a mesh (negative inside), as .npy or .vdb");
    sdf->footer(std::string(exits) +
                "Example: oclvox sdf bunny.obj -r 128 -o bunny.vdb --mesh bunny_sdf.obj");
    add_sdf_options(*sdf, sdf_args);
    CLI::App* csg = app.add_subcommand(
        "csg", "union, intersection or difference of two meshes (or two .npy fields)");
    csg->footer(std::string(exits) +
                "Both signed distance fields are computed on one grid fitted to both meshes and\n"
                "padded by band + 1 voxels, so the result's surface closes inside it.\n"
                "Example: oclvox csg a.obj difference b.obj -r 128 -o a_minus_b.obj");
    add_csg_options(*csg, csg_args);
    CLI::App* mesh = app.add_subcommand(
        "mesh", "mesh the iso-surface of a .npy field, or remesh a mesh through a voxel field");
    mesh->footer(std::string(exits) +
                 "A mesh INPUT is voxelized (mode solid) and meshed via occupancy_to_field.\n"
                 "Example: oclvox mesh bunny.npy --iso 0 -o bunny.ply --mesher marching-cubes");
    add_mesh_options(*mesh, mesh_args);

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
        if (devices->parsed()) return run_devices();
        if (sdf->parsed()) return run_sdf(sdf_args);
        if (csg->parsed()) return run_csg(csg_args);
        if (mesh->parsed()) return run_mesh(mesh_args);
        return run_voxelize(args);
    } catch (const UsageError& e) {
        std::cerr << "oclvox: error: " << e.what() << "\nRun with --help for more information.\n";
        return kExitUsage;
    } catch (const oclvox::Cancelled&) {
        std::cerr << "oclvox: cancelled by " << (g_stop_signal == SIGTERM ? "SIGTERM" : "SIGINT")
                  << "\n";
        return stopped_exit_code();
    } catch (const std::bad_alloc&) {
        std::cerr << "oclvox: error: out of memory (try a lower --resolution)\n";
        return kExitError;
    } catch (const std::exception& e) {
        std::cerr << "oclvox: error: " << e.what() << "\n";
        return kExitError;
    }
}
