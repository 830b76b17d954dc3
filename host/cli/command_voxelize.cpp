// `oclvox voxelize`: a mesh file into a voxel file.
#include <unistd.h>

#include "cluster.hpp"
#include "commands.hpp"
#include "interrupt.hpp"
#include "options.hpp"
#include "preview.hpp"
#include "progress_bar.hpp"
#include "report.hpp"
#include "stdio_files.hpp"

namespace oclvox_cli {

namespace {

struct VoxelizeArgs {
    std::string input, output, preview;
    FileArgs files;
    oclvox::GridFit fit;
    VoxelizationArgs voxelization;
    DeviceArgs device;
    TilingArgs tiling;
    ReportingArgs reporting;
    ClusterArgs cluster;
};

void add_options(CLI::App& command, VoxelizeArgs& args) {
    command
        .add_option("input", args.input,
                    std::string("mesh file: ") + kMeshFormatsText + "; - reads stdin")
        ->type_name("INPUT")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "voxel file; the format follows from the extension: .vdb (OpenVDB, sparse), "
                    ".binvox, .npy (with a .json sidecar), .vox (MagicaVoxel), .obj, .ply or .stl "
                    "(exposed cube faces); - writes stdout (with --output-format)")
        ->type_name("OUTPUT")
        ->required();
    add_input_format_option(command, args.files);
    add_output_format_option(command, args.files);
    command
        .add_option("--preview", args.preview,
                    "also write a PNG: the voxels' orthographic max-projections along x, y and z "
                    "side by side, with a scale bar")
        ->type_name("FILE.png")
        ->group("Files");

    add_grid_options(command, args.fit);

    add_voxelization_options(command, args.voxelization);
    add_device_options(command, args.device, "Voxelization");
    add_tiling_options(command, args.tiling);
    add_reporting_options(command, args.reporting);
    add_cluster_options(command, args.cluster, true);
}

// --workers / --scheduler: the same checks of the output, then the Python back end does the run.
[[noreturn]] void run_sharded(const VoxelizeArgs& args) {
    if (args.input == "-" || args.output == "-" || !args.preview.empty())
        throw UsageError(
            "stdin, stdout and --preview are not available with --workers/--scheduler");
    check_output(args.output, {args.input}, kVoxelExtensions, args.files);
    std::vector<std::string> command{"voxelize", args.input, "-o", args.output};
    if (args.cluster.shard_bricks > 0)
        command.insert(command.end(),
                       {"--shard-bricks", std::to_string(args.cluster.shard_bricks)});
    run_on_cluster({command, voxelize_keywords(args.voxelization, args.tiling), &args.cluster,
                    &args.fit, &args.device, &args.reporting});
}

int run(const VoxelizeArgs& args) {
    if (args.cluster.wanted()) run_sharded(args);
    const Clock::time_point start = Clock::now();
    RunRecord record;
    record.command = "voxelize";
    start_interrupt_watcher();

    // Phase 1: output paths, before any work is spent.
    check_output(args.output, {args.input}, kVoxelExtensions, args.files);
    if (!args.preview.empty()) check_output(args.preview, {args.input}, {".png"});
    check_reporting(args.reporting, {args.input}, {args.output, args.preview});
    const OutputTarget output(args.output, output_extension(args.output, args.files));
    oclvox::VoxelizeOptions options;
    options.test = oclvox::overlap_test_from_string(args.voxelization.test);
    options.mode = oclvox::voxelize_mode_from_string(args.voxelization.mode);
    options.inside = oclvox::inside_test_from_string(args.voxelization.inside);
    options.boundary = oclvox::boundary_from_string(args.voxelization.boundary);
    options.brick_size = args.tiling.brick_size;
    options.device_budget_bytes = args.tiling.device_mib << 20;
    options.host_budget_bytes = args.tiling.host_mib << 20;
    options.download = oclvox::download_from_string(args.tiling.download);

    // Phase 2: the mesh and the grid around it, while the device opens and loads its kernels.
    DeviceOpening opening(args.device,
                          [options](oclvox::Device& device) { device.load_kernels(options); });
    const MeshInput input(args.input, args.files.input_format);
    const oclvox::Mesh mesh =
        timed(record.seconds.load, [&] { return load_mesh_input(input, args.reporting); });
    const oclvox::Grid grid =
        timed(record.seconds.fit, [&] { return oclvox::fit_grid(mesh, args.fit); });
    stop_if_interrupted();

    // Phase 3: the device.
    std::optional<oclvox::Device> device = opening.wait(record.seconds);

    // Phase 4: voxelize, drawing progress and checking for Ctrl-C after every batch.
    oclvox::VoxelizeStats stats;
    const oclvox::SparseVoxels voxels = timed(record.seconds.compute, [&] {
        ProgressBar bar("voxelizing", "bricks", args.reporting);
        options.progress = bar.callback();
        return device ? device->voxelize(mesh, grid, options, &stats)
                      : oclvox::voxelize_reference(mesh, grid, options, &stats);
    });
    stop_if_interrupted();

    // Phase 5: the files while the device closes, then the report.
    const DeviceClosing closing(device);
    timed(record.seconds.write, [&] {
        ProgressBar bar("writing", "", args.reporting);
        oclvox::write_voxels(output.path(), voxels, bar.callback());
        if (!args.preview.empty()) write_preview(args.preview, voxels);
        output.finish();
        return 0;
    });
    record.seconds.total = seconds_since(start);

    record.inputs = {{input.name(), "mesh", mesh.triangles.size()}};
    record.outputs = {args.output};
    if (!args.preview.empty()) record.outputs.push_back(args.preview);
    record.grid = grid;
    record.device = closing.info;
    record.settings = {{"test", args.voxelization.test},
                       {"mode", args.voxelization.mode},
                       {"boundary", args.voxelization.boundary},
                       {"brick_size", args.tiling.brick_size}};
    record.stats = stats;
    report_run(record, args.reporting, output.is_stdout());
    return 0;
}

}  // namespace

Command add_voxelize_command(CLI::App& app) {
    CLI::App* command = app.add_subcommand("voxelize", "voxelize a mesh file into a voxel file");
    command->footer(std::string(kExitCodesText) +
                    "Example: oclvox voxelize bunny.obj -r 512 -o bunny.binvox --stats\n"
                    "         oclvox voxelize city.obj -r 16384 -o city.vdb --scheduler "
                    "tcp://head:8786\n"
                    "         cat part.stl | oclvox voxelize - -r 64 -o - --output-format binvox "
                    "> part.binvox");
    auto args = std::make_shared<VoxelizeArgs>();
    add_options(*command, *args);
    return {command, [args] { return run(*args); }};
}

}  // namespace oclvox_cli
