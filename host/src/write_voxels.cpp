// write_voxels: chooses the output format from the file extension.
#include "file_names.hpp"
#include "oclvox/oclvox.hpp"
#include "writers.hpp"

namespace oclvox {

namespace {

constexpr const char* kSupportedExtensions = ".vdb, .binvox, .npy, .vox, .obj, .ply, .stl";

}  // namespace

void write_voxels(const std::string& path, const SparseVoxels& voxels,
                  const ProgressCallback& progress) {
    // A default-constructed or zero-sized result has no grid to describe; every format needs one.
    if (voxels.grid().voxel_count() == 0)
        throw OutputError("cannot write " + path + ": the voxel grid is empty (dimensions " +
                          std::to_string(voxels.grid().dims[0]) + "x" +
                          std::to_string(voxels.grid().dims[1]) + "x" +
                          std::to_string(voxels.grid().dims[2]) + ")");

    const std::string extension = detail::lowercase_extension(path);
    detail::ProgressPhases phases(progress, "writing " + path);
    if (extension == ".vdb") return detail::write_vdb(path, voxels, phases);
    if (extension == ".binvox") return detail::write_binvox(path, voxels, phases);
    if (extension == ".npy") return detail::write_npy(path, voxels, phases);
    if (extension == ".vox") return detail::write_vox(path, voxels, phases);
    if (extension == ".obj") return detail::write_cube_mesh_obj(path, voxels, phases);
    if (extension == ".ply") return detail::write_cube_mesh_ply(path, voxels, phases);
    if (extension == ".stl") return detail::write_cube_mesh_stl(path, voxels, phases);

    const std::string what = extension.empty() ? "the file name has no extension"
                                               : "unknown extension '" + extension + "'";
    throw OutputError("cannot write " + path + ": " + what +
                      " (supported: " + kSupportedExtensions + ")");
}

}  // namespace oclvox
