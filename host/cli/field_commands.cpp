#include "field_commands.hpp"

#include <algorithm>
#include <variant>

#include "file_names.hpp"
#include "host_memory.hpp"
#include "interrupt.hpp"
#include "progress_bar.hpp"

namespace oclvox_cli {

void add_mesher_option(CLI::App& command, FieldArgs& args) {
    command
        .add_option("--mesher", args.mesher,
                    "iso-surface method: marching-cubes (asymptotic decider: closed and "
                    "manifold meshes) or surface-nets (Naive Surface Nets: fewer slivers, but "
                    "non-manifold where a cell face has four sign changes, as at CSG seams)")
        ->type_name("METHOD")
        ->check(CLI::IsMember({"surface-nets", "marching-cubes"}))
        ->capture_default_str()
        ->group("Meshing");
}

void describe_field_padding(const std::vector<CLI::Option*>& grid_options) {
    for (CLI::Option* o : grid_options)
        if (o->check_name("--pad"))
            o->description(
                 "empty voxels added on every side; by default band + 1 (band rounded up) so the "
                 "zero level set closes inside the grid, or 0 when --origin or --dims place it")
                ->default_str("band+1");
}

void add_distance_options(CLI::App& command, FieldArgs& args) {
    command
        .add_option("--band", args.band,
                    "half-width of the band of exact distances, in voxels; outside it a "
                    "narrow-band field holds +-band * voxel size")
        ->type_name("VOXELS")
        ->check(kPositiveFinite)
        ->capture_default_str()
        ->group("Distance");
    command
        .add_option("--inside", args.inside,
                    "inside test that gives the sign: auto (parity for closed meshes, winding "
                    "number otherwise), parity or winding")
        ->type_name("TEST")
        ->check(CLI::IsMember({"auto", "parity", "winding"}))
        ->capture_default_str()
        ->group("Distance");
    command
        .add_flag("--full", args.full,
                  "exact distances in every voxel, not only in the narrow band (computed, "
                  "written and meshed a slab of layers at a time)")
        ->group("Distance");
}

bool is_field_path(const std::string& path) {
    return oclvox::detail::lowercase_extension(path) == ".npy" || is_sparse_field_path(path);
}

bool is_sparse_field_path(const std::string& path) {
    return oclvox::detail::lowercase_extension(path) == ".vdb";
}

bool is_mesh_output(const std::string& path, const FileArgs& files) {
    const std::string ext = output_extension(path, files);
    return std::find(kMeshExtensions.begin(), kMeshExtensions.end(), ext) != kMeshExtensions.end();
}

oclvox::GridFit field_fit(const FieldArgs& args) {
    oclvox::GridFit fit = args.fit;
    const bool placed =
        std::any_of(args.grid_options.begin(), args.grid_options.end(), [](const CLI::Option* o) {
            return o->count() > 0 &&
                   (o->check_name("--pad") || o->check_name("--origin") || o->check_name("--dims"));
        });
    if (!placed) fit.pad = oclvox::field_padding(args.band);
    return fit;
}

namespace {

oclvox::SdfOptions sdf_options(const FieldArgs& args) {
    oclvox::SdfOptions options;
    options.band_voxels = args.band;
    options.full_grid = args.full;
    options.inside = oclvox::inside_test_from_string(args.inside);
    return options;
}

}  // namespace

namespace {

// run(options) with the field options of args and a progress bar named `what`.
template <class Run>
auto with_progress(const FieldArgs& args, const char* what, Run&& run) {
    oclvox::SdfOptions options = sdf_options(args);
    ProgressBar bar(what, "", args.reporting);
    options.progress = bar.callback();
    return run(options);
}

}  // namespace

oclvox::SparseField signed_distance_sparse(std::optional<oclvox::Device>& device,
                                           const oclvox::Mesh& mesh, const oclvox::Grid& grid,
                                           const FieldArgs& args, oclvox::VoxelizeStats* stats) {
    return with_progress(args, "distance field", [&](const oclvox::SdfOptions& options) {
        return device ? oclvox::signed_distance_sparse(*device, mesh, grid, options, stats)
                      : oclvox::signed_distance_sparse_reference(mesh, grid, options, stats);
    });
}

oclvox::SparseField csg_sparse(std::optional<oclvox::Device>& device, const oclvox::Mesh& a,
                               const oclvox::Mesh& b, oclvox::CsgOp op, const oclvox::Grid& grid,
                               const FieldArgs& args, oclvox::VoxelizeStats* stats) {
    return with_progress(args, "distance fields", [&](const oclvox::SdfOptions& options) {
        return device ? oclvox::csg_sparse(*device, a, b, op, grid, options, stats)
                      : oclvox::csg_sparse_reference(a, b, op, grid, options, stats);
    });
}

namespace {

// Layers per slab of a full grid written in slabs: their field and squared distances (8 bytes a
// voxel on the host, 4 in one device buffer) within a quarter of the host memory budget, at most
// 256 MiB (thinner slabs cost little: spot at 256 took 2.27 s whole, 2.32 s in 16 MiB slabs), and
// the device's allocation limit; whole bricks of the sign's solid where they fit (a slab voxelizes
// its bricks' whole columns, so a brick cut by slabs is voxelized twice), else a multiple of 8
// layers.
int64_t slab_layers(const oclvox::Grid& grid, const std::optional<oclvox::Device>& device,
                    int brick_size) {
    const uint64_t per_layer = uint64_t(grid.dims[0]) * uint64_t(grid.dims[1]);
    uint64_t bytes = std::min<uint64_t>(oclvox::detail::host_budget(0) / 4, uint64_t(256) << 20);
    if (device) bytes = std::min(bytes, 2 * device->info().max_alloc);
    int64_t layers = int64_t(bytes / (8 * per_layer));
    layers -= layers % (layers >= brick_size ? brick_size : 8);
    return std::min<int64_t>(std::max<int64_t>(layers, 8), grid.dims[2]);  // nz may be below 8
}

void add_slab_stats(oclvox::VoxelizeStats& sum, const oclvox::VoxelizeStats& slab) {
    sum.seconds_binning += slab.seconds_binning;
    sum.seconds_upload += slab.seconds_upload;
    sum.seconds_kernels += slab.seconds_kernels;
    sum.seconds_download += slab.seconds_download;
    sum.triangles_in = slab.triangles_in;
    sum.triangles_used = std::max(sum.triangles_used, slab.triangles_used);
    sum.work_items += slab.work_items;
    sum.allocation_retries += slab.allocation_retries;
    sum.voxels_set += slab.voxels_set;
    sum.inside_test = slab.inside_test;
    sum.inside_test_reason = slab.inside_test_reason;
}

}  // namespace

StreamedField stream_field(const std::string& path, bool meshing_view, const oclvox::Grid& grid,
                           const oclvox::FieldLayer& layer) {
    std::optional<oclvox::MeshingViewBuilder> view;
    if (meshing_view) view.emplace(grid, 0.0f);
    StreamedField result;
    auto take = [&](int64_t k, float* samples) {
        layer(k, samples);
        result.border_inside += oclvox::border_samples_inside(grid, k, samples);
        if (view) view->add_layer(samples);
    };
    if (!path.empty()) {
        oclvox::write_field(path, grid, 0.0, take);
    } else {
        std::vector<float> samples(size_t(grid.dims[0]) * size_t(grid.dims[1]));
        for (int64_t k = 0; k < grid.dims[2]; ++k) take(k, samples.data());
    }
    if (view) result.meshing_view = view->finish();
    return result;
}

std::optional<oclvox::SparseField> full_field_in_slabs(
    const std::string& path, bool meshing_view, const oclvox::Grid& grid,
    const std::optional<oclvox::Device>& device, const FieldArgs& args, const SlabField& compute,
    oclvox::VoxelizeStats& stats, RunRecord& record) {
    const Clock::time_point start = Clock::now();
    double seconds_compute = 0;
    const int64_t nz = grid.dims[2];
    const oclvox::SdfOptions defaults = sdf_options(args);
    const int64_t thickness = slab_layers(grid, device, defaults.brick_size);
    const size_t per_layer = size_t(grid.dims[0]) * size_t(grid.dims[1]);
    ProgressBar bar("distance field", "", args.reporting);
    const oclvox::ProgressCallback progress = bar.callback();
    oclvox::ScalarField slab;
    int64_t slab_first = 0;
    // Each slab is computed when its first layer is asked for; its progress is its share of the
    // layers.
    StreamedField field = stream_field(path, meshing_view, grid, [&](int64_t k, float* out) {
        if (k == slab_first + slab.grid.dims[2] || slab.values.empty()) {
            const Clock::time_point slab_start = Clock::now();
            slab_first = k;
            oclvox::SdfOptions options = defaults;
            options.first_layer = k;
            options.end_layer = std::min(k + thickness, nz);
            const uint64_t depth = uint64_t(options.end_layer - k);
            options.progress = [&](uint64_t done, uint64_t total) {
                constexpr uint64_t kSteps = 1000000;
                const double share = double(done) / double(std::max<uint64_t>(total, 1));
                return progress(
                    uint64_t((double(k) + share * double(depth)) / double(nz) * double(kSteps)),
                    kSteps);
            };
            slab = oclvox::ScalarField{};  // before the next one is allocated
            oclvox::VoxelizeStats slab_stats;
            slab = compute(options, &slab_stats);
            add_slab_stats(stats, slab_stats);
            seconds_compute += seconds_since(slab_start);
        }
        std::copy_n(&slab.values[size_t(k - slab_first) * per_layer], per_layer, out);
    });
    record.border_inside = field.border_inside;
    record.seconds.compute += seconds_compute;
    record.seconds.write += seconds_since(start) - seconds_compute;
    return std::move(field.meshing_view);
}

oclvox::Mesh extract_surface(const oclvox::SparseField& field, const FieldArgs& args, float iso) {
    ProgressBar bar("meshing", "", args.reporting);
    return args.mesher == "marching-cubes" ? oclvox::marching_cubes(field, iso, bar.callback())
                                           : oclvox::surface_nets(field, iso, bar.callback());
}

void write_mesh_output(const std::string& path, const oclvox::Mesh& mesh, const FieldArgs& args) {
    ProgressBar bar("writing", "", args.reporting);
    oclvox::write_mesh(path, mesh, bar.callback());
}

void write_field_output(const std::string& path, const oclvox::SparseField& field,
                        const FieldArgs& args) {
    ProgressBar bar("writing", "", args.reporting);
    oclvox::write_field(path, field, bar.callback());
}

oclvox::SparseField read_sparse_field_input(const std::string& path, InputRecord& record,
                                            const oclvox::SparseField* onto) {
    if (path == "-") throw UsageError("a .vdb field cannot be read from stdin");
    record = {path, "level set", 0};
    return onto ? oclvox::read_sparse_field(path, onto->grid(), onto->band_voxels())
                : oclvox::read_sparse_field(path);
}

void record_field_settings(RunRecord& record, const FieldArgs& args) {
    if (!args.op.empty()) record.settings["op"] = args.op;
    if (record.command != "mesh") {
        record.settings["band"] = args.band;
        record.settings["full"] = args.full;
    } else {
        record.settings["iso"] = args.iso;
    }
    record.settings["mesher"] = args.mesher;
}

}  // namespace oclvox_cli
