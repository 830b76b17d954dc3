// `oclvox sdf`: the signed distance field of a mesh, as .npy or .vdb, optionally with its mesh.
#include "cluster.hpp"
#include "commands.hpp"
#include "field_commands.hpp"
#include "interrupt.hpp"
#include "preview.hpp"
#include "stdio_files.hpp"

namespace oclvox_cli {

namespace {

struct SdfArgs : FieldArgs {
    std::string preview;
    ClusterArgs cluster;
};

void add_options(CLI::App& command, SdfArgs& args) {
    command
        .add_option("input", args.input,
                    std::string("mesh file: ") + kMeshFormatsText + "; - reads stdin")
        ->type_name("INPUT")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "field file: .npy (float32, with a .json sidecar) or .vdb (OpenVDB level "
                    "set); - writes stdout (with --output-format vdb)")
        ->type_name("OUTPUT")
        ->required();
    add_input_format_option(command, args.files);
    add_output_format_option(command, args.files);
    command
        .add_option("--preview", args.preview,
                    "also write a PNG: max-projections of the inside (distance < 0) along x, y "
                    "and z side by side, with a scale bar")
        ->type_name("FILE.png")
        ->group("Files");
    args.grid_options = add_grid_options(command, args.fit);
    describe_field_padding(args.grid_options);
    add_distance_options(command, args);
    add_device_options(command, args.device, "Distance");
    command
        .add_option("--mesh", args.mesh_output,
                    "also write the field's zero level set as a mesh: .obj, .ply or .stl")
        ->type_name("FILE")
        ->group("Meshing");
    add_mesher_option(command, args);
    add_reporting_options(command, args.reporting);
    add_cluster_options(command, args.cluster, false);
}

// --workers / --scheduler: the same checks of the output, then the Python back end computes the
// field in slabs of layers (a narrow band kept sparse, a full grid dense) and writes it.
[[noreturn]] void run_sharded(const SdfArgs& args) {
    if (args.input == "-" || args.output == "-" || !args.preview.empty() ||
        !args.mesh_output.empty())
        throw UsageError(
            "stdin, stdout, --preview and --mesh are not available with --workers/--scheduler");
    check_output(args.output, {args.input}, kFieldExtensions, args.files);
    const oclvox::GridFit fit = field_fit(args);
    run_on_cluster({{"sdf", args.input, "-o", args.output},
                    {{"band", args.band}, {"inside", args.inside}, {"full_grid", args.full}},
                    &args.cluster,
                    &fit,
                    &args.device,
                    &args.reporting});
}

int run(const SdfArgs& args) {
    if (args.cluster.wanted()) run_sharded(args);
    const Clock::time_point start = Clock::now();
    RunRecord record;
    record.command = "sdf";
    start_interrupt_watcher();

    // Phase 1: output paths, before any work is spent.
    check_output(args.output, {args.input}, kFieldExtensions, args.files);
    if (!args.mesh_output.empty()) check_output(args.mesh_output, {args.input}, kMeshExtensions);
    if (!args.preview.empty()) check_output(args.preview, {args.input}, {".png"});
    check_reporting(args.reporting, {args.input}, {args.output, args.mesh_output, args.preview});
    const OutputTarget output(args.output, output_extension(args.output, args.files));

    // Phase 2: the mesh and its grid while the device opens, then the device.
    DeviceOpening opening(args.device);
    const MeshInput input(args.input, args.files.input_format);
    const oclvox::Mesh mesh =
        timed(record.seconds.load, [&] { return load_mesh_input(input, args.reporting); });
    const oclvox::Grid grid =
        timed(record.seconds.fit, [&] { return oclvox::fit_grid(mesh, field_fit(args)); });
    stop_if_interrupted();
    std::optional<oclvox::Device> device = opening.wait(record.seconds);

    // Phase 3: the distances: a narrow band as a sparse field (memory follows the surface), a full
    // grid a slab of layers at a time, written as it is computed (memory holds a slab) and, for
    // the mesh or the preview, gathered into its meshing view (leaves where it changes sign). Then
    // the mesh of the zero level set if asked for, from the sparse field.
    oclvox::VoxelizeStats stats;
    std::optional<oclvox::SparseField> sparse;
    if (args.full) {
        sparse = full_field_in_slabs(
            output.path(), !args.mesh_output.empty() || !args.preview.empty(), grid, device, args,
            [&](const oclvox::SdfOptions& options, oclvox::VoxelizeStats* slab_stats) {
                return device ? oclvox::signed_distance(*device, mesh, grid, options, slab_stats)
                              : oclvox::signed_distance_reference(mesh, grid, options, slab_stats);
            },
            stats, record);
    } else {
        sparse = timed(record.seconds.compute,
                       [&] { return signed_distance_sparse(device, mesh, grid, args, &stats); });
        record.border_inside = oclvox::border_samples_inside(*sparse);
    }
    const DeviceClosing closing(device);  // closes while the host meshes and writes
    stop_if_interrupted();
    std::optional<oclvox::Mesh> surface;
    if (!args.mesh_output.empty()) {
        surface = timed(record.seconds.mesh, [&] { return extract_surface(*sparse, args, 0.0f); });
        stop_if_interrupted();
    }

    // Phase 4: the files, then the report.
    timed(record.seconds.write, [&] {
        if (!args.full) write_field_output(output.path(), *sparse, args);
        if (surface) write_mesh_output(args.mesh_output, *surface, args);
        if (!args.preview.empty()) write_preview(args.preview, *sparse, 0.0f);
        output.finish();
        return 0;
    });
    record.seconds.total = seconds_since(start);

    record.inputs = {{input.name(), "mesh", mesh.triangles.size()}};
    record.outputs = {args.output};
    if (surface) record.outputs.push_back(args.mesh_output);
    if (!args.preview.empty()) record.outputs.push_back(args.preview);
    record.grid = grid;
    record.device = closing.info;
    record_field_settings(record, args);
    record.stats = stats;
    if (surface) record.mesh_made = {{surface->triangles.size(), surface->positions.size()}};
    report_run(record, args.reporting, output.is_stdout());
    return 0;
}

}  // namespace

Command add_sdf_command(CLI::App& app) {
    CLI::App* command = app.add_subcommand(
        "sdf", "signed distance field of a mesh (negative inside), as .npy or .vdb");
    command->footer(std::string(kExitCodesText) +
                    "Example: oclvox sdf bunny.obj -r 128 -o bunny.vdb --mesh bunny_sdf.obj");
    auto args = std::make_shared<SdfArgs>();
    add_options(*command, *args);
    return {command, [args] { return run(*args); }};
}

}  // namespace oclvox_cli
