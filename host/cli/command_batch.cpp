// `oclvox batch`: every mesh of a folder or a list file into one voxel file each, on a Dask
// cluster (a local one by default), through the Python package (see cluster.hpp).
#include "cluster.hpp"
#include "commands.hpp"
#include "options.hpp"

namespace oclvox_cli {

namespace {

struct BatchArgs {
    std::string input, output_dir;
    std::string output_format = "binvox";
    oclvox::GridFit fit;
    VoxelizationArgs voxelization;
    DeviceArgs device;
    TilingArgs tiling;
    ReportingArgs reporting;
    ClusterArgs cluster;
};

void add_options(CLI::App& command, BatchArgs& args) {
    command
        .add_option("input", args.input,
                    std::string("a folder of meshes (its ") + kMeshFormatsText +
                        " files, not recursive) or a list file (one mesh path a line, relative "
                        "to the list's folder; blank lines and # comments skipped)")
        ->type_name("SOURCE")
        ->required();
    command
        .add_option("-o,--output", args.output_dir,
                    "output folder (made if missing): one <mesh name><format> per mesh; a file "
                    "already there is complete (files are written under a temporary name and "
                    "renamed) and is skipped, so a stopped batch resumes where it was")
        ->type_name("DIR")
        ->required();
    command
        .add_option("--output-format", args.output_format,
                    "format of the outputs, as an extension: vdb, binvox, npy, vox, obj, ply, stl")
        ->type_name("EXT")
        ->capture_default_str()
        ->group("Files");
    add_grid_options(command, args.fit);
    add_voxelization_options(command, args.voxelization);
    add_device_options(command, args.device, "Voxelization");
    add_tiling_options(command, args.tiling);
    command.add_flag("-q,--quiet", args.reporting.quiet, "print neither progress nor the summary")
        ->group("Reporting");
    add_cluster_options(command, args.cluster, false);
}

int run(BatchArgs& args) {
    if (!args.cluster.wanted()) args.cluster.workers = 1;
    run_on_cluster(
        {{"batch", args.input, "-o", args.output_dir, "--output-format", args.output_format},
         voxelize_keywords(args.voxelization, args.tiling),
         &args.cluster,
         &args.fit,
         &args.device,
         &args.reporting});
}

}  // namespace

Command add_batch_command(CLI::App& app) {
    CLI::App* command = app.add_subcommand(
        "batch", "voxelize every mesh of a folder or list file, one output each, on Dask");
    command->footer(std::string(kExitCodesText) +
                    "A mesh that fails (twice: each is retried once) is reported at the end and "
                    "makes the exit code 1; the others are written.\n"
                    "Example: oclvox batch models/ -o voxels/ -r 128 --workers 4\n"
                    "         oclvox batch list.txt -o voxels/ --output-format vdb --scheduler "
                    "tcp://head:8786");
    auto args = std::make_shared<BatchArgs>();
    add_options(*command, *args);
    return {command, [args] { return run(*args); }};
}

}  // namespace oclvox_cli
