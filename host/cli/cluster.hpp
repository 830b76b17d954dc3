// Runs on a Dask cluster: `voxelize --workers N / --scheduler ADDR` and `batch`. Dask is Python,
// so such a command checks its arguments as every command does and then replaces itself with the
// Python package's back end (oclvox.distributed), handing over the parsed options in the Python
// API's terms. The interpreter is $OCLVOX_PYTHON, else python3 on PATH.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "oclvox/oclvox.hpp"
#include "options.hpp"

namespace oclvox_cli {

// --workers N (a local cluster of N worker processes) or --scheduler ADDR (a running one), and
// for one mesh split into shards, --shard-bricks.
struct ClusterArgs {
    int workers = 0;  // 0: not asked for
    std::string scheduler;
    int64_t shard_bricks = 0;  // 0: about four shards per worker (oclvox.distributed)
    bool wanted() const { return workers > 0 || !scheduler.empty(); }
};
void add_cluster_options(CLI::App& command, ClusterArgs& args, bool sharded);

// What the back end is asked to do: its command ("voxelize", "batch" or "sdf") with its own
// arguments (input, -o, ...), the Python call's keyword options (beside the grid's, which
// run_on_cluster adds from `fit`), and where it runs.
struct ClusterRun {
    std::vector<std::string> command;
    nlohmann::json keywords;
    const ClusterArgs* cluster;
    const oclvox::GridFit* fit;
    const DeviceArgs* device;  // its selector goes to the workers only if given as --device;
                               // else each worker picks its own
    const ReportingArgs* reporting;
};

// oclvox.voxelize's keyword options (without the grid's) for voxelize and batch.
nlohmann::json voxelize_keywords(const VoxelizationArgs& voxelization, const TilingArgs& tiling);

// Refuses what the back end cannot do (--cubic=min, --stats, --json, --stats-json) with a
// UsageError, then execs the back end. Returns only if that fails, with an Error naming the
// interpreter.
[[noreturn]] void run_on_cluster(const ClusterRun& run);

}  // namespace oclvox_cli
