// `oclvox csg`: union, intersection or difference of two meshes (through their signed distance
// fields on one grid) or of two fields: .npy (dense) or .vdb level sets (sparse).
#include <memory>
#include <optional>
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
        .add_option("a", args.input,
                    std::string("first mesh file (") + kMeshFormatsText +
                        "; - reads stdin), or a signed distance field: .npy, or a .vdb level "
                        "set (combined sparse, leaf by leaf)")
        ->type_name("A")
        ->required();
    command.add_option("op", args.op, "union, intersection or difference (A minus B)")
        ->type_name("OP")
        ->check(CLI::IsMember({"union", "intersection", "difference"}))
        ->required();
    command
        .add_option("b", args.input_b,
                    "second mesh file, or a field of A's kind (.npy: on A's grid)")
        ->type_name("B")
        ->required();
    command
        .add_option("-o,--output", args.output,
                    "a mesh (.obj, .ply, .stl: the result's zero level set) or a field (.npy, "
                    ".vdb); - writes stdout (with --output-format)")
        ->type_name("OUTPUT")
        ->required();
    add_input_format_option(command, args.files);
    add_output_format_option(command, args.files);
    args.grid_options = add_grid_options(command, args.fit);
    describe_field_padding(args.grid_options);
    add_distance_options(command, args);
    add_device_options(command, args.device, "Distance");
    add_mesher_option(command, args);
    add_reporting_options(command, args.reporting);
}

// A .npy operand given a layer at a time: a field read from its file, or the smoothed field of an
// occupancy (occupancy_to_field's, made a layer at a time), as `mesh` makes it.
class NpyOperand {
  public:
    explicit NpyOperand(const std::string& path) {
        if (oclvox::npy_holds_field(path)) {
            field_.emplace(path);
            return;
        }
        voxels_ = std::make_unique<oclvox::SparseVoxels>(
            std::get<oclvox::SparseVoxels>(oclvox::read_npy(path)));
        smoothed_.emplace(*voxels_);
    }
    const char* kind() const { return field_ ? "field" : "occupancy"; }
    const oclvox::Grid& grid() const { return field_ ? field_->grid() : smoothed_->grid(); }
    void next_layer(float* samples) {
        field_ ? field_->read_layer(samples) : smoothed_->next_layer(samples);
    }

  private:
    std::optional<oclvox::FieldLayerReader> field_;
    std::unique_ptr<oclvox::SparseVoxels> voxels_;  // where smoothed_ reads them
    std::optional<oclvox::OccupancyFieldLayers> smoothed_;
};

int run(const FieldArgs& args) {
    const Clock::time_point start = Clock::now();
    RunRecord record;
    record.command = "csg";
    start_interrupt_watcher();

    // Phase 1: the operands' kinds and the output paths, before any work is spent.
    const oclvox::CsgOp op = oclvox::csg_op_from_string(args.op);
    const bool mesh_out = is_mesh_output(args.output, args.files);
    check_output(args.output, {args.input, args.input_b}, {".obj", ".ply", ".stl", ".npy", ".vdb"},
                 args.files);
    check_reporting(args.reporting, {args.input, args.input_b}, {args.output});
    if (args.input == "-" && args.input_b == "-")
        throw UsageError("only one of A and B can be read from stdin (-)");
    if (!args.files.input_format.empty() && args.input != "-" && args.input_b != "-")
        throw UsageError("--input-format applies to stdin (-) only; A and B are files");
    const bool fields_in = is_field_path(args.input) && is_field_path(args.input_b);
    if (!fields_in && (is_field_path(args.input) || is_field_path(args.input_b)))
        throw UsageError("csg takes two meshes or two fields, not one of each");
    const bool level_sets_in = fields_in && is_sparse_field_path(args.input);
    if (fields_in && level_sets_in != is_sparse_field_path(args.input_b))
        throw UsageError("csg takes two .npy fields or two .vdb level sets, not one of each");
    if (fields_in && args.device.selector_given)
        throw UsageError(
            "two field files are combined and meshed on the host's cores; --device applies to "
            "meshes");
    // occupancy_to_field's values step by +-0.5 across the surface; they are not distances. The
    // headers say which .npy files hold occupancies.
    if (fields_in && !level_sets_in && !mesh_out &&
        !(oclvox::npy_holds_field(args.input) && oclvox::npy_holds_field(args.input_b)))
        throw UsageError(
            "csg of an occupancy .npy writes a mesh (.obj, .ply, .stl), not a distance field");
    if (fields_in && any_given(args.grid_options))
        throw UsageError("grid options do not apply to field inputs (their grids are used)");
    const OutputTarget output(args.output, output_extension(args.output, args.files));

    // Phase 2: both operands as fields on one grid, combined: .vdb level sets and narrow bands of
    // meshes sparse (and meshed sparse), .npy files a layer at a time and full grids of meshes a
    // slab of layers at a time (written as they come, or meshed through their meshing view).
    std::optional<oclvox::SparseField> sparse;
    bool streamed = false;  // a field made a layer at a time: written as it comes
    std::optional<oclvox::Device> device;
    if (level_sets_in) {
        record.inputs.resize(2);
        std::optional<oclvox::SparseField> a, b;
        timed(record.seconds.load, [&] {
            a = read_sparse_field_input(args.input, record.inputs[0]);
            b = read_sparse_field_input(args.input_b, record.inputs[1], &*a);
            return 0;
        });
        // B on A's lattice (rebuilt there if it was not): the result covers both grids, so its
        // grid is the one to report.
        sparse = timed(record.seconds.compute, [&] { return oclvox::csg(*a, *b, op); });
        record.grid = sparse->grid();
        stop_if_interrupted();
    } else if (fields_in) {
        std::optional<NpyOperand> a, b;
        timed(record.seconds.load, [&] {
            a.emplace(args.input);
            b.emplace(args.input_b);
            return 0;
        });
        record.inputs = {{args.input, a->kind(), 0}, {args.input_b, b->kind(), 0}};
        if (!oclvox::same_grid(a->grid(), b->grid()))
            throw oclvox::GridError(
                "csg of two .npy files needs them on one grid (the same "
                "dims, origin and voxel size), got " +
                oclvox::to_string(a->grid()) + " and " + oclvox::to_string(b->grid()));
        record.grid = a->grid();
        oclvox::Grid layer_grid = a->grid();
        layer_grid.dims[2] = 1;
        const size_t per_layer = size_t(layer_grid.dims[0]) * size_t(layer_grid.dims[1]);
        oclvox::ScalarField layer_a{layer_grid, std::vector<float>(per_layer)},
            layer_b{layer_grid, std::vector<float>(per_layer)};
        ProgressBar bar("combining", "", args.reporting);
        const oclvox::ProgressCallback progress = bar.callback();
        streamed = true;
        timed(record.seconds.write, [&] {
            StreamedField field = stream_field(
                mesh_out ? std::string() : output.path(), mesh_out, a->grid(),
                [&](int64_t k, float* out) {
                    a->next_layer(layer_a.values.data());
                    b->next_layer(layer_b.values.data());
                    const oclvox::ScalarField layer = oclvox::csg(layer_a, layer_b, op);
                    std::copy(layer.values.begin(), layer.values.end(), out);
                    progress(uint64_t(k + 1), uint64_t(a->grid().dims[2]));
                    stop_if_interrupted();
                });
            record.border_inside = field.border_inside;
            sparse = std::move(field.meshing_view);
            return 0;
        });
    } else {
        const MeshInput input_a(args.input, args.input == "-" ? args.files.input_format : "");
        const MeshInput input_b(args.input_b, args.input_b == "-" ? args.files.input_format : "");
        DeviceOpening opening(args.device);
        oclvox::Mesh mesh_a, mesh_b;
        timed(record.seconds.load, [&] {
            mesh_a = load_mesh_input(input_a, args.reporting);
            mesh_b = load_mesh_input(input_b, args.reporting);
            return 0;
        });
        record.grid = timed(record.seconds.fit,
                            [&] { return oclvox::fit_grid(mesh_a, mesh_b, field_fit(args)); });
        record.inputs = {{input_a.name(), "mesh", mesh_a.triangles.size()},
                         {input_b.name(), "mesh", mesh_b.triangles.size()}};
        stop_if_interrupted();
        device = opening.wait(record.seconds);
        oclvox::VoxelizeStats stats;
        // A full grid is computed a slab of layers at a time: written to a field file as it
        // comes, or gathered into its meshing view for a mesh.
        if (args.full) {
            streamed = true;
            sparse = full_field_in_slabs(
                mesh_out ? std::string() : output.path(), mesh_out, *record.grid, device, args,
                [&](const oclvox::SdfOptions& options, oclvox::VoxelizeStats* slab_stats) {
                    return device ? oclvox::csg(*device, mesh_a, mesh_b, op, *record.grid, options,
                                                slab_stats)
                                  : oclvox::csg_reference(mesh_a, mesh_b, op, *record.grid, options,
                                                          slab_stats);
                },
                stats, record);
        } else {
            sparse = timed(record.seconds.compute, [&] {
                return csg_sparse(device, mesh_a, mesh_b, op, *record.grid, args, &stats);
            });
        }
        stop_if_interrupted();
        record.stats = stats;
    }
    const DeviceClosing closing(device);  // closes while the host meshes and writes

    // Phase 3: mesh if the output is a mesh.
    std::optional<oclvox::Mesh> surface;
    if (mesh_out) {
        surface = timed(record.seconds.mesh, [&] { return extract_surface(*sparse, args, 0.0f); });
        stop_if_interrupted();
    }

    // Phase 4: the file (a streamed field is written already), then the report.
    timed(record.seconds.write, [&] {
        if (surface)
            write_mesh_output(output.path(), *surface, args);
        else if (!streamed)
            write_field_output(output.path(), *sparse, args);
        output.finish();
        return 0;
    });
    record.seconds.total = seconds_since(start);

    record.outputs = {args.output};
    record.device = closing.info;
    record_field_settings(record, args);
    if (surface) record.mesh_made = {{surface->triangles.size(), surface->positions.size()}};
    if (!streamed) record.border_inside = oclvox::border_samples_inside(*sparse);
    report_run(record, args.reporting, output.is_stdout());
    return 0;
}

}  // namespace

Command add_csg_command(CLI::App& app) {
    CLI::App* command = app.add_subcommand(
        "csg", "union, intersection or difference of two meshes (or two .npy or .vdb fields)");
    command->footer(
        std::string(kExitCodesText) +
        "Both signed distance fields are computed on one grid fitted to both meshes and\n"
        "padded by band + 1 voxels, so the result's surface closes inside it. Two .npy fields\n"
        "need one grid and are combined a layer at a time. Two .vdb level sets combine on A's\n"
        "voxel lattice, covering the box of both; B on another lattice (voxel size, or voxel\n"
        "centres not whole voxels apart) is first rebuilt on A's by OpenVDB's levelSetRebuild,\n"
        "whose distances are to a polygonization of B's surface (within a fraction of a voxel).\n"
        "Example: oclvox csg a.obj difference b.obj -r 128 -o a_minus_b.obj");
    auto args = std::make_shared<FieldArgs>();
    add_options(*command, *args);
    return {command, [args] { return run(*args); }};
}

}  // namespace oclvox_cli
