// Option groups shared by the commands, and the output checks made before any work.
#include "options.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <system_error>

#include "file_names.hpp"
#include "interrupt.hpp"

namespace oclvox_cli {

using oclvox::detail::lowercase_extension;

const char* const kMeshFormatsText = ".obj, .stl, .ply, .off, .gltf, .glb or .3mf";
const std::vector<std::string> kVoxelExtensions{".vdb", ".binvox", ".npy", ".vox",
                                                ".obj", ".ply",    ".stl"};
const std::vector<std::string> kMeshExtensions{".obj", ".ply", ".stl"};
const std::vector<std::string> kFieldExtensions{".npy", ".vdb"};

bool parse_number(const std::string& text, double& value) {
    char* end = nullptr;
    errno = 0;
    value = std::strtod(text.c_str(), &end);
    return !text.empty() && end == text.c_str() + text.size() && errno == 0;
}

// Whole numbers for --dims and --brick-size (declared here only: the header offers doubles).
bool parse_number(const std::string& text, int64_t& value) {
    char* end = nullptr;
    errno = 0;
    value = std::strtoll(text.c_str(), &end, 10);
    return !text.empty() && end == text.c_str() + text.size() && errno == 0;
}

namespace {

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

const CLI::Validator kBrickSize(
    [](std::string& text) -> std::string {
        int64_t value = 0;
        if (!parse_number(text, value) || value < 4 || value > 1024 || value % 4 != 0)
            return "must be a multiple of 4 in [4, 1024], got '" + text + "'";
        return {};
    },
    "4..1024");

std::string list_text(const std::vector<std::string>& items) {
    std::string list;
    for (const std::string& item : items) list += (list.empty() ? "" : ", ") + item;
    return list;
}

// "binvox" or ".BINVOX" -> ".binvox".
std::string as_extension(const std::string& format) {
    if (format.empty()) return "";
    return lowercase_extension(format[0] == '.' ? format : "." + format);
}

}  // namespace

// CLI11's PositiveNumber lets NaN through (NaN <= 0 is false), so voxel sizes get their own check.
const CLI::Validator kPositiveFinite(
    [](std::string& text) -> std::string {
        double value = 0;
        if (!parse_number(text, value) || !std::isfinite(value) || !(value > 0))
            return "must be a positive finite number, got '" + text + "'";
        return {};
    },
    "POSITIVE");

const CLI::Validator kFinite(
    [](std::string& text) -> std::string {
        double value = 0;
        if (!parse_number(text, value) || !std::isfinite(value))
            return "must be a finite number, got '" + text + "'";
        return {};
    },
    "FINITE");

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

bool any_given(const std::vector<CLI::Option*>& options) {
    return std::any_of(options.begin(), options.end(),
                       [](const CLI::Option* o) { return o->count() > 0; });
}

void add_voxelization_options(CLI::App& command, VoxelizationArgs& args) {
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
}

void add_device_options(CLI::App& command, DeviceArgs& args, const std::string& group) {
    if (const char* env = std::getenv("OCLVOX_DEVICE")) args.selector = env;
    auto* device = command
                       .add_option("--device", args.selector,
                                   "OpenCL device: \"P:D\" indices (see `oclvox devices`) or part "
                                   "of the device or platform name. Default: $OCLVOX_DEVICE, else "
                                   "the first GPU, else the first device. A device that does not "
                                   "exist is an error, never a fallback")
                       ->each([&args](const std::string&) { args.selector_given = true; })
                       ->type_name("SEL")
                       ->group(group);
    command
        .add_flag("--reference", args.reference,
                  "run the CPU reference implementation instead of an OpenCL device (needs no "
                  "OpenCL)")
        ->excludes(device)
        ->group(group);
}

namespace {

void announce_build(const std::string& program) {
    std::fprintf(stderr,
                 "compiling kernels '%s' for this device (first run; cached for later runs)...\n",
                 program.c_str());
}

void report_build(const oclvox::Device::KernelCompile& build) {
    std::fprintf(stderr, "compiled kernels '%s' in %.1f s\n", build.program.c_str(), build.seconds);
}

}  // namespace

DeviceOpening::DeviceOpening(const DeviceArgs& args, std::function<void(oclvox::Device&)> prepare) {
    // TBB loads its allocator with dlopen on first use. Once the thread below is loading the
    // OpenCL driver (PoCL: LLVM, tens of milliseconds under the dynamic loader's lock), the mesh
    // load's first parallel loop waited for that lock: spot.obj's 3.5 ms load took 23 ms. So TBB
    // starts here, before the thread.
    if (!args.reference) tbb::parallel_for(0, 2, [](int) {});
    if (!args.reference)
        opening_ = std::async(std::launch::async, [selector = args.selector,
                                                   prepare = std::move(prepare), builds = builds_] {
            const Clock::time_point start = Clock::now();
            oclvox::Device device = oclvox::Device::open(selector);
            device.on_kernel_compile([builds](const oclvox::Device::KernelCompile& c) {
                const std::lock_guard<std::mutex> lock(builds->mutex);
                if (c.finished) {
                    builds->running.reset();
                    builds->finished.push_back(c);
                } else {
                    builds->running = c.program;
                }
            });
            if (prepare) prepare(device);
            return Opened{std::move(device), seconds_since(start)};
        });
}

std::optional<oclvox::Device> DeviceOpening::wait(Timings& seconds) {
    std::optional<oclvox::Device> device;
    if (opening_.valid()) {
        const Clock::time_point waiting = Clock::now();
        // A build still running is announced while it is waited for, once.
        std::string announced;
        while (opening_.wait_for(std::chrono::milliseconds(50)) != std::future_status::ready) {
            const std::lock_guard<std::mutex> lock(builds_->mutex);
            if (builds_->running && *builds_->running != announced) {
                announced = *builds_->running;
                announce_build(announced);
            }
        }
        Opened opened = opening_.get();
        const double waited = seconds_since(waiting);
        for (const auto& build : builds_->finished) report_build(build);
        device.emplace(std::move(opened.device));
        seconds.device_open += waited;
        seconds.device_open_overlapped += std::max(0.0, opened.seconds - waited);
        device->on_kernel_compile([](const oclvox::Device::KernelCompile& c) {
            if (c.finished)
                report_build(c);
            else
                announce_build(c.program);
        });
    }
    stop_if_interrupted();
    return device;
}

DeviceClosing::DeviceClosing(std::optional<oclvox::Device>& device) {
    if (!device) return;
    info = device->info();
    // Moved into a local of the thread's body, so that the thread, not whoever destroys the task,
    // releases it. Where no thread can be started the device is released here, as before.
    try {
        closing_ = std::async(std::launch::async, [closing = std::move(*device)]() mutable {
            const oclvox::Device released = std::move(closing);
        });
    } catch (const std::system_error&) {
    }
    device.reset();
}

void add_tiling_options(CLI::App& command, TilingArgs& args) {
    command.add_option("--brick-size", args.brick_size, "voxels per brick edge")
        ->type_name("B")
        ->check(kBrickSize)
        ->capture_default_str()
        ->group("Tiling");
    command
        .add_option("--device-memory", args.device_mib,
                    "device memory for one batch of bricks, in MiB (CPU devices: at most 64)")
        ->type_name("MIB")
        ->check(CLI::Range(uint64_t(1), uint64_t(1) << 24))
        ->capture_default_str()
        ->group("Tiling");
    command
        .add_option(
            "--host-memory", args.host_mib,
            "host memory for the result, in MiB; 0 means $OCLVOX_HOST_MEMORY_MIB, else half "
            "of physical memory")
        ->type_name("MIB")
        ->check(CLI::Range(uint64_t(0), uint64_t(1) << 24))
        ->capture_default_str()
        ->group("Tiling");
    command
        .add_option("--download", args.download,
                    "how the device's voxels come back: auto (only the non-empty 4^3 blocks from "
                    "a device with memory of its own, whole batches read in place on CPUs), whole "
                    "or blocks; the voxels are the same")
        ->type_name("HOW")
        ->check(CLI::IsMember({"auto", "whole", "blocks"}))
        ->capture_default_str()
        ->group("Tiling");
}

void add_reporting_options(CLI::App& command, ReportingArgs& args, bool has_breakdown) {
    command.add_flag("-q,--quiet", args.quiet, "print neither progress nor the summary")
        ->group("Reporting");
    if (has_breakdown)
        command.add_flag("--stats", args.stats, "print a timing breakdown and counts")
            ->group("Reporting");
    command
        .add_flag("--json", args.json,
                  "print the run summary as one JSON document on stdout (and nothing else there; "
                  "progress and warnings go to stderr)")
        ->group("Reporting");
    command
        .add_option("--stats-json", args.stats_json,
                    "write the run summary (the --json document) to this JSON file")
        ->type_name("FILE")
        ->group("Reporting");
}

void add_input_format_option(CLI::App& command, FileArgs& args) {
    command
        .add_option("--input-format", args.input_format,
                    "format of an input read from stdin (\"-\"): obj, stl, ply, off, gltf, glb or "
                    "3mf. Default: told from the content")
        ->type_name("EXT")
        ->check(CLI::IsMember({"obj", "stl", "ply", "off", "gltf", "glb", "3mf"}, CLI::ignore_case))
        ->group("Files");
}

void add_output_format_option(CLI::App& command, FileArgs& args) {
    command
        .add_option("--output-format", args.output_format,
                    "format of an output written to stdout (\"-o -\"), as an extension: e.g. "
                    "binvox, vox, vdb, obj, ply, stl (not npy: it has a sidecar file)")
        ->type_name("EXT")
        ->group("Files");
}

std::string output_extension(const std::string& path, const FileArgs& files) {
    return path == "-" ? as_extension(files.output_format) : lowercase_extension(path);
}

void check_output(const std::string& path, const std::vector<std::string>& inputs,
                  const std::vector<std::string>& allowed, const FileArgs& files) {
    const std::string ext = output_extension(path, files);
    if (path == "-") {
        // stdout: the format cannot come from a name, and a format of two files cannot stream.
        if (ext.empty())
            throw UsageError("writing to stdout (-o -) needs --output-format (one of: " +
                             list_text(allowed) + ")");
        if (ext == ".npy")
            throw UsageError(
                "a .npy output has a .json sidecar file, so it cannot go to stdout; write a file, "
                "or pick another --output-format");
    } else if (!files.output_format.empty() && as_extension(files.output_format) != ext) {
        throw UsageError("--output-format applies to -o - (stdout) only; '" + path +
                         "' has its format in its name");
    }
    if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), ext) == allowed.end()) {
        throw oclvox::OutputError(
            "cannot write '" + path + "': " +
            (ext.empty() ? "the file name has no extension" : "unknown extension '" + ext + "'") +
            " (supported: " + list_text(allowed) + ")");
    }
    if (path == "-") return;
    oclvox::check_output_path(path, inputs);
    if (ext == ".npy") oclvox::check_output_path(path + ".json", inputs);
}

void check_reporting(const ReportingArgs& reporting, const std::vector<std::string>& inputs,
                     const std::vector<std::string>& outputs) {
    const bool data_on_stdout = std::count(outputs.begin(), outputs.end(), "-") > 0;
    if (std::count(outputs.begin(), outputs.end(), "-") > 1)
        throw UsageError("only one output can go to stdout (-)");
    if (reporting.json && data_on_stdout)
        throw UsageError(
            "--json prints to stdout, which already carries the output (-o -); use "
            "--stats-json FILE");
    if (reporting.stats_json == "-")
        throw UsageError("--stats-json takes a file; --json prints the same document on stdout");
    if (!reporting.stats_json.empty()) check_output(reporting.stats_json, inputs, {});
}

}  // namespace oclvox_cli
