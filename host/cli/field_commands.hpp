// What the field commands (sdf, csg, mesh) share: their options, the signed distance and meshing
// calls on a device or the CPU reference, and .npy field inputs.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "oclvox/field.hpp"
#include "oclvox/oclvox.hpp"
#include "oclvox/sdf.hpp"
#include "options.hpp"
#include "report.hpp"

namespace oclvox_cli {

struct FieldArgs {
    std::string input, op, input_b, output, mesh_output;
    FileArgs files;
    oclvox::GridFit fit;
    std::vector<CLI::Option*> grid_options;  // to reject them for .npy field inputs
    double band = 3.0;
    bool full = false;
    std::string inside = "auto";
    // Marching Cubes by default: its meshes are closed and manifold (Surface Nets' are not where
    // a cell face has four sign changes, which CSG results and thin parts produce).
    std::string mesher = "marching-cubes";
    double iso = 0.0;
    DeviceArgs device;
    ReportingArgs reporting;
};

void add_mesher_option(CLI::App& command, FieldArgs& args);
// --band and --inside.
void add_distance_options(CLI::App& command, FieldArgs& args);
// sdf and csg pad fitted grids by default (field_fit): say so in their --pad help.
void describe_field_padding(const std::vector<CLI::Option*>& grid_options);

// A field file: .npy (dense) or .vdb (a level set, read sparse).
bool is_field_path(const std::string& path);
bool is_sparse_field_path(const std::string& path);
bool is_mesh_output(const std::string& path, const FileArgs& files);

// The grid fit of sdf and csg: a fitted grid gets field_padding(band) voxels on every side, so the
// zero level set closes inside it, unless the user places the grid (--pad, --origin or --dims).
oclvox::GridFit field_fit(const FieldArgs& args);

// The narrow band of a mesh's signed distance field, and of the CSG of two meshes' fields, as a
// sparse field (oclvox::signed_distance_sparse, oclvox::csg_sparse) on the device or the CPU
// reference, drawing a progress bar and stopping on Ctrl-C.
oclvox::SparseField signed_distance_sparse(std::optional<oclvox::Device>& device,
                                           const oclvox::Mesh& mesh, const oclvox::Grid& grid,
                                           const FieldArgs& args, oclvox::VoxelizeStats* stats);
oclvox::SparseField csg_sparse(std::optional<oclvox::Device>& device, const oclvox::Mesh& a,
                               const oclvox::Mesh& b, oclvox::CsgOp op, const oclvox::Grid& grid,
                               const FieldArgs& args, oclvox::VoxelizeStats* stats);

// A field given a layer at a time by `layer` (k = 0, 1, ...), written to `path` as it comes (the
// band found from its values) unless the path is empty, and with `meshing_view` gathered into its
// meshing view (MeshingViewBuilder), which meshes and previews as the whole field does. Memory
// holds a layer, the view's 16 and its leaves (and for .vdb OpenVDB's tree of every sample).
struct StreamedField {
    uint64_t border_inside = 0;  // border_samples_inside of the whole field
    std::optional<oclvox::SparseField> meshing_view;
};
StreamedField stream_field(const std::string& path, bool meshing_view, const oclvox::Grid& grid,
                           const oclvox::FieldLayer& layer);

// A full-grid field (--full) streamed so, computed a slab of layers at a time
// (SdfOptions::first_layer / end_layer): memory holds one slab, never the whole field.
// compute(options, stats) is the field of options' layers (signed_distance or csg with those
// options), which equals the whole field there bit for bit, so the file is the one the whole
// field gives. One progress bar runs over the slabs; Ctrl-C stops between them and leaves no
// file. The slabs' stats are summed into `stats`; the record gets their compute time, the rest as
// writing time, and the field's border_samples_inside. Returns the meshing view if asked for.
using SlabField = std::function<oclvox::ScalarField(const oclvox::SdfOptions& options,
                                                    oclvox::VoxelizeStats* stats)>;
std::optional<oclvox::SparseField> full_field_in_slabs(
    const std::string& path, bool meshing_view, const oclvox::Grid& grid,
    const std::optional<oclvox::Device>& device, const FieldArgs& args, const SlabField& compute,
    oclvox::VoxelizeStats& stats, RunRecord& record);

// The iso-surface by --mesher of a sparse field (a narrow band, a level set, or a meshing view),
// on the host's cores without a dense copy (the mesh its dense copy gives), with a progress bar,
// stopping on Ctrl-C.
oclvox::Mesh extract_surface(const oclvox::SparseField& field, const FieldArgs& args, float iso);

// write_mesh with a "writing" progress bar (and Ctrl-C checked through it).
void write_mesh_output(const std::string& path, const oclvox::Mesh& mesh, const FieldArgs& args);

// write_field with a "writing" progress bar (and Ctrl-C checked through it).
void write_field_output(const std::string& path, const oclvox::SparseField& field,
                        const FieldArgs& args);

// A .vdb level set as a sparse field (read_sparse_field); the record's kind is "level set". With
// `onto`, on its voxel lattice with its band (rebuilt there if it is not).
oclvox::SparseField read_sparse_field_input(const std::string& path, InputRecord& record,
                                            const oclvox::SparseField* onto = nullptr);

// The settings every field command reports.
void record_field_settings(RunRecord& record, const FieldArgs& args);

}  // namespace oclvox_cli
