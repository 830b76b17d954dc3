// write_voxels: chooses the output format from the file extension.
#include <cctype>

#include "oclvox/oclvox.hpp"
#include "writers.hpp"

namespace oclvox {

namespace {

constexpr const char* kSupportedExtensions = ".binvox, .npy, .vox, .obj, .ply";

// The extension of the file name, lower-cased, with its dot; "" if the name has none. Dots in
// folder names do not count.
std::string lowercase_extension(const std::string& path) {
    const size_t slash = path.find_last_of('/');
    const size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string extension = path.substr(dot);
    for (char& c : extension) c = char(std::tolower(static_cast<unsigned char>(c)));
    return extension;
}

}  // namespace

void write_voxels(const std::string& path, const SparseVoxels& voxels) {
    // A default-constructed or zero-sized result has no grid to describe; every format needs one.
    if (voxels.grid().voxel_count() == 0)
        throw OutputError("cannot write " + path + ": the voxel grid is empty (dimensions " +
                          std::to_string(voxels.grid().dims[0]) + "x" +
                          std::to_string(voxels.grid().dims[1]) + "x" +
                          std::to_string(voxels.grid().dims[2]) + ")");

    const std::string extension = lowercase_extension(path);
    if (extension == ".binvox") return detail::write_binvox(path, voxels);
    if (extension == ".npy") return detail::write_npy(path, voxels);
    if (extension == ".vox") return detail::write_vox(path, voxels);
    if (extension == ".obj") return detail::write_cube_mesh_obj(path, voxels);
    if (extension == ".ply") return detail::write_cube_mesh_ply(path, voxels);

    const std::string what = extension.empty() ? "the file name has no extension"
                                               : "unknown extension '" + extension + "'";
    throw OutputError("cannot write " + path + ": " + what +
                      " (supported: " + kSupportedExtensions + ")");
}

}  // namespace oclvox
