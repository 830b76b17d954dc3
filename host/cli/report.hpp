// One record per run, filled by the command, and the one place that turns it into what the user
// sees: the human summary, the --stats breakdown, and the JSON document of --json and
// --stats-json. Every command reports through report_run, so all share one vocabulary.
#pragma once

#include <chrono>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "oclvox/oclvox.hpp"
#include "timing.hpp"

namespace oclvox_cli {

using oclvox::detail::Clock;
using oclvox::detail::seconds_since;

// Runs work(), adds its wall time to `seconds`, returns its result.
template <class F>
auto timed(double& seconds, F&& work) {
    const Clock::time_point start = Clock::now();
    auto result = work();
    seconds += seconds_since(start);
    return result;
}

// One input as the report names it.
struct InputRecord {
    std::string path;
    std::string kind;        // "mesh", "field", "occupancy" (a .npy from voxelize), "level set"
    uint64_t triangles = 0;  // meshes only
};

// The phases every command times; a command leaves those it does not have at zero. voxelize's
// compute phase is "voxelize" (with the library's binning/upload/kernels/download inside it),
// the field commands' is "field".
struct Timings {
    double load = 0, fit = 0, device_open = 0, compute = 0, mesh = 0, write = 0, total = 0;
    // The part of the device's opening that ran beside loading (DeviceOpening); device_open is
    // only what the run waited for after it, so that the phases add up to the total.
    double device_open_overlapped = 0;
};

struct RunRecord {
    std::string command;  // "devices", "voxelize", "sdf", "csg", "mesh"
    std::vector<InputRecord> inputs;
    std::vector<std::string> outputs;  // "-" is stdout
    std::optional<oclvox::Grid> grid;
    std::optional<oclvox::DeviceInfo> device;  // empty: the CPU reference
    std::vector<oclvox::DeviceInfo> devices;   // `devices` only

    // What was asked for, by name (e.g. mode, test, boundary, band, mesher): JSON keys as given.
    nlohmann::ordered_json settings = nlohmann::ordered_json::object();

    std::optional<oclvox::VoxelizeStats> stats;          // when a voxelize or distance run happened
    std::optional<std::pair<size_t, size_t>> mesh_made;  // triangles, vertices
    uint64_t border_inside = 0;  // field samples inside on the grid's outer layer
    Timings seconds;
};

// --quiet, --stats, --json, --stats-json.
struct ReportingArgs {
    bool quiet = false;
    bool stats = false;
    bool json = false;
    std::string stats_json;
};

// The human lines go to stdout unless stdout carries data (an output "-") or the JSON document,
// in which case they go to stderr (warnings) or are left out (--json replaces the summary).
// Writes --stats-json through the atomic writer.
void report_run(const RunRecord& record, const ReportingArgs& reporting, bool stdout_has_data);

}  // namespace oclvox_cli
