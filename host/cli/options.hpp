// The option groups every command shares (grid fit, device, tiling, reporting, input and output
// files), their validators, and the checks run on output paths before any work. One vocabulary:
// an option means the same and is spelled the same on every command that has it.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "oclvox/oclvox.hpp"
#include "report.hpp"

namespace oclvox_cli {

constexpr int kExitError = 1;
constexpr int kExitUsage = 2;

// A usage error found after parsing (an option that does not apply to the inputs given): exit 2.
struct UsageError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// The input formats load_mesh reads, for help texts.
extern const char* const kMeshFormatsText;  // ".obj, .stl, .ply, .off, .gltf, .glb or .3mf"

// What write_voxels accepts, what write_mesh accepts, what write_field accepts.
extern const std::vector<std::string> kVoxelExtensions;
extern const std::vector<std::string> kMeshExtensions;
extern const std::vector<std::string> kFieldExtensions;

// The grid options (-r, --cubic, --voxel-size, --origin, --dims, --pad). Returns them so that a
// command can tell whether any was given (they do not apply to field inputs).
std::vector<CLI::Option*> add_grid_options(CLI::App& command, oclvox::GridFit& fit);
bool any_given(const std::vector<CLI::Option*>& options);

// --test, --mode, --inside, --boundary: what voxelize computes (the library's names, validated).
struct VoxelizationArgs {
    std::string test = "sat";
    std::string mode = "surface";
    std::string inside = "auto";
    std::string boundary = "closed";
};
void add_voxelization_options(CLI::App& command, VoxelizationArgs& args);

// --device / --reference (mutually exclusive; $OCLVOX_DEVICE is the default selector).
struct DeviceArgs {
    std::string selector;
    bool selector_given = false;  // --device on the command line, not just $OCLVOX_DEVICE
    bool reference = false;
};
void add_device_options(CLI::App& command, DeviceArgs& args, const std::string& group);
// The device, unless the CPU reference was asked for, opened on a thread of its own from
// construction on, so that an OpenCL platform's start (a quarter of a second on NVIDIA's driver,
// 20 ms for PoCL) passes while the command loads its inputs; that thread then runs `prepare` (the
// command's kernels loaded ahead: a few milliseconds from the disk cache, up to tens of seconds
// for the first run's build). wait() hands the device over, booking the time it waited as the
// device-open phase and the rest of the thread's time, spent beside the caller's work, as
// `device_open_overlapped`, and rethrows the thread's error (a DeviceError, a KernelBuildError)
// there. A build, which only the first run on a device pays, is announced on stderr (by wait()'s
// thread alone) because it can take tens of seconds; kernels not loaded ahead are built when
// first used, and announced then.
class DeviceOpening {
  public:
    explicit DeviceOpening(const DeviceArgs& args,
                           std::function<void(oclvox::Device&)> prepare = {});
    std::optional<oclvox::Device> wait(Timings& seconds);

  private:
    struct Opened {
        oclvox::Device device;
        double seconds;  // the thread's own wall time
    };
    // The builds the thread ran: the one running now, and those finished.
    struct Builds {
        std::mutex mutex;
        std::optional<std::string> running;
        std::vector<oclvox::Device::KernelCompile> finished;
    };
    std::shared_ptr<Builds> builds_ = std::make_shared<Builds>();
    std::future<Opened> opening_;  // not valid for the CPU reference
};

// Closes a device the command no longer needs on a thread of its own, so that the driver's
// teardown (70-85 ms for NVIDIA's OpenCL on an H200 machine, after every run) passes while the
// command writes its files. Takes the device, leaving `device` empty, and keeps its info for the
// report; the destructor waits for the teardown, so the command ends after it.
class DeviceClosing {
  public:
    explicit DeviceClosing(std::optional<oclvox::Device>& device);
    std::optional<oclvox::DeviceInfo> info;  // empty where there was no device (the CPU reference)

  private:
    std::future<void> closing_;  // waits in its destructor (std::async)
};

// --brick-size, --device-memory, --host-memory, --download.
struct TilingArgs {
    int brick_size = oclvox::VoxelizeOptions{}.brick_size;
    uint64_t device_mib = oclvox::VoxelizeOptions{}.device_budget_bytes >> 20;
    uint64_t host_mib = 0;
    std::string download = "auto";
};
void add_tiling_options(CLI::App& command, TilingArgs& args);

// --quiet, --stats (where the command has a breakdown), --json, --stats-json.
void add_reporting_options(CLI::App& command, ReportingArgs& args, bool has_breakdown = true);

// The input file, "-" for stdin, and --input-format for stdin. The output, "-" for stdout, and
// --output-format for stdout.
struct FileArgs {
    std::string input_format;
    std::string output_format;
};
void add_input_format_option(CLI::App& command, FileArgs& args);
void add_output_format_option(CLI::App& command, FileArgs& args);

// The extension an output is written in: the file's, or for "-" the --output-format.
std::string output_extension(const std::string& path, const FileArgs& files);

// Mistakes in output paths are cheap to find before the run and expensive after a long one, so
// every output is checked before any input is read: its extension against the formats the
// command writes (`allowed`; empty: any), then the library's check_output_path (folder exists and
// is writable, not a directory, not one of the inputs), also for a .npy output's .json sidecar.
// "-" (stdout) is checked against what can stream.
void check_output(const std::string& path, const std::vector<std::string>& inputs,
                  const std::vector<std::string>& allowed, const FileArgs& files = {});

// Checks the reporting outputs and that stdout carries at most one thing.
void check_reporting(const ReportingArgs& reporting, const std::vector<std::string>& inputs,
                     const std::vector<std::string>& outputs);

// Reads a whole string as one number; strtod/strtoll alone accept trailing garbage.
bool parse_number(const std::string& text, double& value);

// The validators shared by several commands.
extern const CLI::Validator kPositiveFinite;
extern const CLI::Validator kFinite;

}  // namespace oclvox_cli
