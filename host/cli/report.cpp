// The summary, --stats and JSON renderings of a RunRecord. The summary is what a person reads
// after a run; --stats adds the breakdown; the JSON document holds all of it for programs.
#include "report.hpp"

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <sstream>

// CMake passes the project version; the fallback only labels builds made outside CMake.
#ifndef OCLVOX_VERSION
#define OCLVOX_VERSION "unknown"
#endif

namespace oclvox_cli {

namespace {

using Json = nlohmann::ordered_json;

// printf into a std::string, so every rendering can go to either stream.
template <class... Args>
std::string format(const char* pattern, Args... args) {
    const int size = std::snprintf(nullptr, 0, pattern, args...);
    std::string text(size_t(size) + 1, '\0');
    std::snprintf(text.data(), text.size(), pattern, args...);
    text.resize(size_t(size));
    return text;
}

using ull = unsigned long long;

std::string bytes_text(uint64_t bytes) {
    if (bytes >= (uint64_t(1) << 30)) return format("%.1f GiB", double(bytes) / double(1 << 30));
    return format("%.1f MiB", double(bytes) / double(1 << 20));
}

// 1234567 -> "1.23 M": throughputs span too many orders of magnitude for plain digits.
std::string rate_text(double per_second) {
    const char* suffixes[] = {"", " k", " M", " G", " T"};
    int index = 0;
    while (per_second >= 1000 && index < 4) {
        per_second /= 1000;
        ++index;
    }
    return format("%.3g%s", per_second, suffixes[index]);
}

// Throughputs are over the voxelize call (binning to download), which is the part that scales
// with the grid; loading and writing depend on file formats and disks.
double per_second(double amount, double seconds) {
    return seconds > 0 ? amount / seconds : 0;
}

std::string setting(const RunRecord& r, const char* key) {
    return r.settings.contains(key) ? r.settings[key].get<std::string>() : std::string();
}

bool is_voxelize(const RunRecord& r) {
    return r.command == "voxelize";
}

std::string input_text(const InputRecord& input) {
    if (input.kind == "mesh")
        return input.path + " (" + std::to_string(input.triangles) + " triangles)";
    return input.path + " (" + input.kind + ")";
}

std::string output_text(const std::string& path) {
    return path == "-" ? "- (stdout)" : path;
}

// Warnings go with the summary, or to stderr when the summary is not printed on stdout.
std::vector<std::string> warnings(const RunRecord& r) {
    std::vector<std::string> list;
    if (r.border_inside)
        list.push_back(format(
            "the shape reaches the grid border (%llu border samples inside): the grid cuts its "
            "surface, so the field is truncated and meshes are open there; grow the grid (--pad, "
            "--dims)",
            ull(r.border_inside)));
    return list;
}

std::string devices_text(const RunRecord& r) {
    std::string text;
    for (const oclvox::DeviceInfo& d : r.devices) {
        text += format("%s  %s  %s\n", d.id.c_str(), d.type.c_str(), d.name.c_str());
        text += format("     platform  %s\n", d.platform.c_str());
        text += format("     version   %s\n", d.version.c_str());
        text += format("     driver    %s\n", d.driver_version.c_str());
        text += format("     memory    %s global, %s per allocation%s\n",
                       bytes_text(d.global_memory).c_str(), bytes_text(d.max_alloc).c_str(),
                       d.host_unified_memory ? ", the host's" : ", its own");
    }
    return text;
}

std::string summary_text(const RunRecord& r) {
    if (r.command == "devices") return devices_text(r);
    std::string text;
    for (const InputRecord& input : r.inputs) text += "input    " + input_text(input) + "\n";
    if (r.grid) {
        const oclvox::Grid& g = *r.grid;
        text += format("grid     %lldx%lldx%lld voxels of size %g, origin (%g, %g, %g)\n",
                       (long long)g.dims[0], (long long)g.dims[1], (long long)g.dims[2],
                       g.voxel_size, g.origin[0], g.origin[1], g.origin[2]);
    }
    if (is_voxelize(r)) {
        if (setting(r, "mode") == "thin")
            text += "mode     thin (6-separating), boundary " + setting(r, "boundary") + "\n";
        else
            text += "mode     " + setting(r, "mode") + ", test " + setting(r, "test") +
                    ", boundary " + setting(r, "boundary") + "\n";
    }
    if (r.stats && !r.stats->inside_test.empty())
        text += "inside   " + r.stats->inside_test + " (" + r.stats->inside_test_reason + ")\n";
    if (r.device)
        text += "device   " + r.device->name + " (" + r.device->platform + ")\n";
    else
        text += "device   CPU reference\n";
    if (r.stats && r.stats->allocation_retries)
        text += format("memory   device allocations failed; %llu batches retried smaller\n",
                       ull(r.stats->allocation_retries));
    if (is_voxelize(r) && r.stats) text += format("voxels   %llu set\n", ull(r.stats->voxels_set));
    if (r.mesh_made)
        text += format("mesh     %zu triangles, %zu vertices\n", r.mesh_made->first,
                       r.mesh_made->second);
    for (const std::string& output : r.outputs) text += "output   " + output_text(output) + "\n";
    for (const std::string& warning : warnings(r)) text += "warning  " + warning + "\n";
    text += format("time     %.3f s\n", r.seconds.total);
    return text;
}

// The voxelize phase beyond its four measured parts: kernel programs loaded from the cache (or
// compiled), a solid's choice of inside test (the closed-mesh check) and snapping, and the
// sparse result's bookkeeping.
constexpr const char* kOtherComputeText = "program loading, inside-test choice, bookkeeping";
double other_compute_seconds(const RunRecord& r) {
    const oclvox::VoxelizeStats& s = *r.stats;
    return std::max(0.0, r.seconds.compute - s.seconds_binning - s.seconds_upload -
                             s.seconds_kernels - s.seconds_download);
}

std::string stats_text(const RunRecord& r) {
    if (r.command == "devices") return "";
    const Timings& t = r.seconds;
    std::string text = "timing (seconds)\n";
    text += format("  load          %9.4f\n", t.load);
    text += format("  fit           %9.4f\n", t.fit);
    text += format(
        "  device open   %9.4f  (OpenCL platform, context, queue and kernels; %.4f more beside "
        "loading)\n",
        t.device_open, t.device_open_overlapped);
    if (is_voxelize(r)) {
        text += format("  voxelize      %9.4f\n", t.compute);
        if (r.stats) {
            text += format("    binning     %9.4f\n", r.stats->seconds_binning);
            text += format("    upload      %9.4f\n", r.stats->seconds_upload);
            text += format("    kernels     %9.4f\n", r.stats->seconds_kernels);
            text += format("    download    %9.4f  (%.1f MiB)\n", r.stats->seconds_download,
                           double(r.stats->bytes_downloaded) / (1 << 20));
            text += format("    other       %9.4f  (%s)\n", other_compute_seconds(r),
                           kOtherComputeText);
        }
    } else {
        text += format("  field         %9.4f\n", t.compute);
        text += format("  mesh          %9.4f\n", t.mesh);
    }
    text += format("  write         %9.4f\n", t.write);
    text += format("  total         %9.4f\n", t.total);
    text += "counts\n";
    const uint64_t grid_voxels = r.grid ? r.grid->voxel_count() : 0;
    if (r.stats) {
        const oclvox::VoxelizeStats& s = *r.stats;
        text += format("  triangles     %llu (%llu inside the grid)\n", ull(s.triangles_in),
                       ull(s.triangles_used));
        if (is_voxelize(r)) {
            text += format("  bricks        %llu active of %llu, %llu batches\n",
                           ull(s.bricks_active), ull(s.bricks_total), ull(s.batches));
            text += format("  brick pairs   %llu\n", ull(s.brick_pairs));
        } else if (s.bricks_total > 0) {
            // A sparse field's bricks are its 8x8x8 leaves.
            text += format("  leaves        %llu of %llu (8^3), %llu batches\n",
                           ull(s.bricks_active), ull(s.bricks_total), ull(s.batches));
        }
        text += format("  work items    %llu\n", ull(s.work_items));
        if (is_voxelize(r))
            text += format("  voxels set    %llu of %llu\n", ull(s.voxels_set), ull(grid_voxels));
        else
            text += format("  inside voxels %llu\n", ull(s.voxels_set));
    }
    if (!is_voxelize(r)) text += format("  grid voxels   %llu\n", ull(grid_voxels));
    if (r.mesh_made)
        text += format("  mesh out      %zu triangles, %zu vertices\n", r.mesh_made->first,
                       r.mesh_made->second);
    if (is_voxelize(r) && r.stats) {
        text += "throughput (over voxelize)\n";
        text += "  triangles/s   " +
                rate_text(per_second(double(r.stats->triangles_in), t.compute)) + "\n";
        text += "  grid voxels/s " + rate_text(per_second(double(grid_voxels), t.compute)) + "\n";
    }
    return text;
}

Json device_json(const oclvox::DeviceInfo& d) {
    return {{"id", d.id},
            {"name", d.name},
            {"platform", d.platform},
            {"vendor", d.vendor},
            {"type", d.type},
            {"opencl_version", d.version},
            {"driver_version", d.driver_version},
            {"global_memory_bytes", d.global_memory},
            {"max_allocation_bytes", d.max_alloc},
            {"host_unified_memory", d.host_unified_memory}};
}

Json record_json(const RunRecord& r) {
    Json j;
    j["oclvox_version"] = OCLVOX_VERSION;
    j["command"] = r.command;
    if (r.command == "devices") {
        j["devices"] = Json::array();
        for (const oclvox::DeviceInfo& d : r.devices) j["devices"].push_back(device_json(d));
        return j;
    }
    // The first input and output by themselves, then all of them with what they are.
    j["input"] = r.inputs.empty() ? "" : r.inputs.front().path;
    j["output"] = r.outputs.empty() ? "" : r.outputs.front();
    j["inputs"] = Json::array();
    for (const InputRecord& input : r.inputs) {
        Json entry = {{"path", input.path}, {"kind", input.kind}};
        if (input.kind == "mesh") entry["triangles"] = input.triangles;
        j["inputs"].push_back(entry);
    }
    j["outputs"] = r.outputs;
    j["backend"] = r.device ? "opencl" : "reference";
    j["device"] = r.device ? device_json(*r.device) : Json(nullptr);
    for (const auto& [key, value] : r.settings.items()) j[key] = value;
    if (r.stats && !r.stats->inside_test.empty())
        j["inside"] = {{"test", r.stats->inside_test}, {"reason", r.stats->inside_test_reason}};
    if (r.grid)
        j["grid"] = {{"dims", r.grid->dims},
                     {"voxel_size", r.grid->voxel_size},
                     {"origin", r.grid->origin},
                     {"voxels", r.grid->voxel_count()}};

    const Timings& t = r.seconds;
    Json seconds = {{"load", t.load},
                    {"fit", t.fit},
                    {"device_open", t.device_open},
                    {"device_open_overlapped", t.device_open_overlapped}};
    if (is_voxelize(r)) {
        seconds["voxelize"] = t.compute;
        if (r.stats) {
            seconds["binning"] = r.stats->seconds_binning;
            seconds["upload"] = r.stats->seconds_upload;
            seconds["kernels"] = r.stats->seconds_kernels;
            seconds["download"] = r.stats->seconds_download;
            seconds["other"] = other_compute_seconds(r);
        }
    } else {
        seconds["field"] = t.compute;
        seconds["mesh"] = t.mesh;
    }
    seconds["write"] = t.write;
    seconds["total"] = t.total;
    j["seconds"] = seconds;

    if (r.stats) {
        const oclvox::VoxelizeStats& s = *r.stats;
        j["triangles"] = s.triangles_in;
        j["triangles_used"] = s.triangles_used;
        j["bricks_total"] = s.bricks_total;
        j["bricks_active"] = s.bricks_active;
        j["batches"] = s.batches;
        j["allocation_retries"] = s.allocation_retries;
        j["bytes_downloaded"] = s.bytes_downloaded;
        j["brick_pairs"] = s.brick_pairs;
        j["work_items"] = s.work_items;
        j["voxels_set"] = s.voxels_set;
        if (is_voxelize(r)) {
            j["triangles_per_second"] = per_second(double(s.triangles_in), t.compute);
            j["grid_voxels_per_second"] =
                per_second(double(r.grid ? r.grid->voxel_count() : 0), t.compute);
        }
    }
    if (r.mesh_made)
        j["mesh"] = {{"triangles", r.mesh_made->first}, {"vertices", r.mesh_made->second}};
    if (!is_voxelize(r)) j["border_samples_inside"] = r.border_inside;
    j["warnings"] = warnings(r);
    return j;
}

}  // namespace

void report_run(const RunRecord& record, const ReportingArgs& reporting, bool stdout_has_data) {
    // --stats-json first: a run whose summary cannot be saved has failed.
    const Json json = record_json(record);
    if (!reporting.stats_json.empty())
        oclvox::write_text_file(reporting.stats_json, json.dump(2) + "\n");

    if (reporting.json) {
        for (const std::string& warning : warnings(record))
            std::cerr << "oclvox: warning: " << warning << "\n";
        std::cout << json.dump(2) << "\n";
        return;
    }
    // Human text goes where it does not mix with data.
    std::ostream& human = stdout_has_data ? std::cerr : std::cout;
    if (!reporting.quiet) human << summary_text(record);
    if (reporting.stats) human << stats_text(record);
    human.flush();
}

}  // namespace oclvox_cli
