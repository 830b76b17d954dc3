// `oclvox mesh`: the iso-surface of a .npy field, or a mesh remeshed through a voxel field.
#include <variant>

#include "commands.hpp"
#include "field_commands.hpp"
#include "interrupt.hpp"
#include "progress_bar.hpp"
#include "stdio_files.hpp"

namespace oclvox_cli {

namespace {

void add_options(CLI::App& command, FieldArgs& args) {
    command
        .add_option("input", args.input,
                    std::string("a .npy scalar field (with its .json sidecar; read a layer at a "
                                "time) or a .vdb level set (read sparse), meshed at --iso on the "
                                "host's cores; an occupancy .npy (what voxelize writes) or a "
                                "mesh file (") +
                        kMeshFormatsText +
                        "; - reads stdin), which is voxelized (mode solid, on the grid options' "
                        "grid) if a mesh, turned into a field by occupancy_to_field (one "
                        "smoothing pass) and meshed: a remeshed voxel surface, not the original")
        ->type_name("INPUT")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "mesh file: .obj, .ply or .stl; - writes stdout (with --output-format)")
        ->type_name("OUTPUT")
        ->required();
    add_input_format_option(command, args.files);
    add_output_format_option(command, args.files);
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
    add_device_options(command, args.device, "Meshing");
    add_reporting_options(command, args.reporting);
}

int run(const FieldArgs& args) {
    const Clock::time_point start = Clock::now();
    RunRecord record;
    record.command = "mesh";
    start_interrupt_watcher();

    // Phase 1: output paths, before any work is spent.
    check_output(args.output, {args.input}, kMeshExtensions, args.files);
    check_reporting(args.reporting, {args.input}, {args.output});
    const bool field_in = is_field_path(args.input);
    if (field_in && any_given(args.grid_options))
        throw UsageError("grid options do not apply to a field input (its grid is used)");
    // A field file's header says whether it holds a field or an occupancy.
    const bool level_set_in = is_sparse_field_path(args.input);
    const bool npy_field_in = field_in && !level_set_in && oclvox::npy_holds_field(args.input);
    if (field_in && args.device.selector_given)
        throw UsageError(
            "a field or occupancy file is meshed on the host's cores; --device applies to "
            "voxelizing a mesh input");
    if (field_in && !args.files.input_format.empty())
        throw UsageError("--input-format applies to a mesh read from stdin (-) only");
    const OutputTarget output(args.output, output_extension(args.output, args.files));

    // Phase 2: the field as a sparse field: a level set read sparse; a .npy field, or the smoothed
    // field of an occupancy (read, or the mesh's solid voxels), a layer at a time into its meshing
    // view. Memory follows the surface (and the voxels), never the field's volume.
    std::optional<oclvox::SparseField> sparse;
    std::optional<oclvox::SparseVoxels> voxels;
    std::optional<oclvox::Device> device;
    if (level_set_in) {
        record.inputs.resize(1);
        sparse = timed(record.seconds.load,
                       [&] { return read_sparse_field_input(args.input, record.inputs[0]); });
    } else if (npy_field_in) {
        record.inputs = {{args.input, "field", 0}};
        sparse = timed(record.seconds.load, [&] {
            ProgressBar bar("loading", "", args.reporting);
            return oclvox::read_meshing_view(args.input, float(args.iso), bar.callback());
        });
    } else if (field_in) {
        record.inputs = {{args.input, "occupancy", 0}};
        voxels = timed(record.seconds.load, [&] {
            return std::get<oclvox::SparseVoxels>(oclvox::read_npy(args.input));
        });
    } else {
        DeviceOpening opening(args.device);
        const MeshInput input(args.input, args.files.input_format);
        const oclvox::Mesh mesh =
            timed(record.seconds.load, [&] { return load_mesh_input(input, args.reporting); });
        const oclvox::Grid grid =
            timed(record.seconds.fit, [&] { return oclvox::fit_grid(mesh, args.fit); });
        record.inputs = {{input.name(), "mesh", mesh.triangles.size()}};
        stop_if_interrupted();
        device = opening.wait(record.seconds);
        oclvox::VoxelizeOptions options;
        options.mode = oclvox::VoxelizeMode::Solid;
        options.inside = oclvox::inside_test_from_string(args.inside);
        oclvox::VoxelizeStats stats;
        voxels = timed(record.seconds.compute, [&] {
            ProgressBar bar("voxelizing", "bricks", args.reporting);
            options.progress = bar.callback();
            return device ? device->voxelize(mesh, grid, options, &stats)
                          : oclvox::voxelize_reference(mesh, grid, options, &stats);
        });
        record.stats = stats;
    }
    const DeviceClosing closing(device);  // closes while the host meshes and writes
    stop_if_interrupted();
    if (voxels) {
        sparse = timed(record.seconds.compute,
                       [&] { return oclvox::occupancy_meshing_view(*voxels, 1, float(args.iso)); });
        stop_if_interrupted();
    }

    // Phase 3: the surface, the file, the report.
    const oclvox::Mesh surface =
        timed(record.seconds.mesh, [&] { return extract_surface(*sparse, args, float(args.iso)); });
    stop_if_interrupted();
    timed(record.seconds.write, [&] {
        write_mesh_output(output.path(), surface, args);
        output.finish();
        return 0;
    });
    record.seconds.total = seconds_since(start);

    record.outputs = {args.output};
    record.grid = sparse->grid();
    record.device = closing.info;
    record_field_settings(record, args);
    record.mesh_made = {{surface.triangles.size(), surface.positions.size()}};
    record.border_inside = oclvox::border_samples_inside(*sparse, float(args.iso));
    report_run(record, args.reporting, output.is_stdout());
    return 0;
}

}  // namespace

Command add_mesh_command(CLI::App& app) {
    CLI::App* command = app.add_subcommand(
        "mesh",
        "mesh the iso-surface of a .npy or .vdb field, or remesh a mesh through a voxel "
        "field");
    command->footer(std::string(kExitCodesText) +
                    "A mesh INPUT is voxelized (mode solid) and meshed via occupancy_to_field.\n"
                    "Example: oclvox mesh bunny.npy --iso 0 -o bunny.ply --mesher marching-cubes");
    auto args = std::make_shared<FieldArgs>();
    add_options(*command, *args);
    return {command, [args] { return run(*args); }};
}

}  // namespace oclvox_cli
