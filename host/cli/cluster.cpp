// The hand-over to oclvox.distributed (see cluster.hpp).
#include "cluster.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>
#include <stdexcept>

namespace oclvox_cli {

namespace {

// Run with `python -c`: like `python -m oclvox.distributed`, but a missing package (or one too
// old to have the module) is named as such instead of as a traceback, and the current directory
// is taken off the module path, so that a folder named oclvox there is never imported instead.
const char* const kBootstrap =
    "import sys\n"
    "if sys.path and sys.path[0] == '':\n"
    "    del sys.path[0]\n"
    "try:\n"
    "    from oclvox.distributed import main\n"
    "except ImportError as error:\n"
    "    sys.exit(f'oclvox: error: the distributed path needs the Python package: pip install . "
    "({error})')\n"
    "sys.exit(main(sys.argv[1:]))\n";

// The grid's keyword options, as every Python call takes them.
void add_grid_keywords(const oclvox::GridFit& fit, bool reference, nlohmann::json& keywords) {
    keywords["pad"] = fit.pad;
    keywords["cubic"] = fit.cubic;
    keywords["reference"] = reference;
    if (fit.voxel_size > 0) keywords["voxel_size"] = fit.voxel_size;
    if (fit.has_origin) keywords["origin"] = fit.origin;
    if (fit.has_dims) keywords["dims"] = fit.dims;
}

void refuse_unsupported(const ClusterRun& run) {
    const char* const where = "with --workers/--scheduler";
    if (run.fit->cubic && run.fit->cubic_anchor == oclvox::GridFit::CubicAnchor::Minimum)
        throw UsageError(std::string("--cubic=min is not available ") + where +
                         " (the Python package centres cubic grids only)");
    if (run.reporting->stats || run.reporting->json || !run.reporting->stats_json.empty())
        throw UsageError(std::string("--stats, --json and --stats-json are not available ") +
                         where + " (the workers' runs are not summed into one report)");
}

}  // namespace

nlohmann::json voxelize_keywords(const VoxelizationArgs& voxelization, const TilingArgs& tiling) {
    return {{"mode", voxelization.mode},       {"test", voxelization.test},
            {"inside", voxelization.inside},   {"boundary", voxelization.boundary},
            {"brick_size", tiling.brick_size}, {"device_memory", tiling.device_mib},
            {"host_memory", tiling.host_mib},  {"download", tiling.download}};
}

void add_cluster_options(CLI::App& command, ClusterArgs& args, bool sharded) {
    auto* workers = command
                        .add_option("--workers", args.workers,
                                    "run on a local Dask cluster of N worker processes, each with "
                                    "its own OpenCL device (needs the Python package and Dask)")
                        ->type_name("N")
                        ->check(CLI::Range(1, 4096))
                        ->group("Cluster");
    command
        .add_option("--scheduler", args.scheduler,
                    "run on the Dask cluster of this scheduler, e.g. tcp://host:8786 (needs the "
                    "Python package and Dask here and on the workers)")
        ->type_name("ADDR")
        ->excludes(workers)
        ->group("Cluster");
    if (sharded)
        command
            .add_option("--shard-bricks", args.shard_bricks,
                        "bricks per task when one grid is split over a cluster (default: about "
                        "four tasks per worker, at least 64 bricks each)")
            ->type_name("K")
            ->check(CLI::Range(int64_t(1), int64_t(1) << 40))
            ->group("Cluster");
}

void run_on_cluster(const ClusterRun& run) {
    refuse_unsupported(run);
    const char* python_env = std::getenv("OCLVOX_PYTHON");
    const std::string python = python_env && *python_env ? python_env : "python3";

    std::vector<std::string> args{python, "-c", kBootstrap};
    args.insert(args.end(), run.command.begin(), run.command.end());
    if (run.cluster->scheduler.empty())
        args.insert(args.end(), {"--workers", std::to_string(run.cluster->workers)});
    else
        args.insert(args.end(), {"--scheduler", run.cluster->scheduler});
    args.insert(args.end(), {"-r", std::to_string(run.fit->resolution)});
    if (run.device->selector_given) args.insert(args.end(), {"--device", run.device->selector});
    nlohmann::json keywords = run.keywords;
    add_grid_keywords(*run.fit, run.device->reference, keywords);
    // dump() doubles as the shortest text that reads back to the same double.
    args.insert(args.end(), {"--options", keywords.dump()});
    if (run.reporting->quiet) args.push_back("--quiet");

    std::vector<char*> argv;
    for (std::string& arg : args) argv.push_back(arg.data());
    argv.push_back(nullptr);
    std::fflush(nullptr);
    execvp(python.c_str(), argv.data());
    throw std::runtime_error("cannot run the Python interpreter '" + python +
                             "' for --workers/--scheduler/batch (" + std::strerror(errno) +
                             "; set OCLVOX_PYTHON to the python that has the oclvox package)");
}

}  // namespace oclvox_cli
