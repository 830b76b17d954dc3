// .npy header and sidecar; see npy_format.hpp.
#include "npy_format.hpp"

#include <cstdio>

#include "atomic_file.hpp"
#include "file_names.hpp"
#include "little_endian.hpp"

namespace oclvox::detail {

void write_npy_header(std::ostream& out, const std::string& descr,
                      const std::array<int64_t, 3>& dims) {
    const std::string dict = "{'descr': '" + descr + "', 'fortran_order': True, 'shape': (" +
                             std::to_string(dims[0]) + ", " + std::to_string(dims[1]) + ", " +
                             std::to_string(dims[2]) + "), }";
    const size_t preamble = 6 + 2 + 2;  // magic, version, header length
    const size_t unpadded = preamble + dict.size() + 1;
    const std::string header = dict + std::string((64 - unpadded % 64) % 64, ' ') + '\n';

    out.write("\x93NUMPY", 6);
    out.put(char(1));
    out.put(char(0));
    write_le(out, uint16_t(header.size()));
    out << header;
}

nlohmann::json npy_sidecar(const std::string& npy_path, const Grid& grid) {
    return {
        {"file", file_name_of(npy_path)},
        {"dims", grid.dims},
        {"origin", grid.origin},
        {"voxel_size", grid.voxel_size},
        {"axis_order",
         "arr[i, j, k] is voxel (x=i, y=j, z=k); stored in Fortran order (x fastest)"},
    };
}

void write_npy_with_sidecar(const std::string& path, const std::string& descr, const Grid& grid,
                            const std::function<void(std::ostream&)>& write_data,
                            const std::function<nlohmann::json()>& make_sidecar) {
    write_file_atomically(path, [&](std::ostream& out) {
        write_npy_header(out, descr, grid.dims);
        write_data(out);
    });
    try {
        const std::string text = make_sidecar().dump(2) + "\n";
        write_file_atomically(path + ".json", [&](std::ostream& out) { out << text; });
    } catch (...) {
        std::remove(path.c_str());
        throw;
    }
}

}  // namespace oclvox::detail
