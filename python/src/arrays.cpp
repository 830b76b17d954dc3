#include "arrays.hpp"

#include <cstring>
#include <memory>
#include <string>
#include <vector>

namespace py = pybind11;

namespace oclvox_python {
namespace {

std::string shape_text(const py::array& array) {
    std::string text = "(";
    for (py::ssize_t d = 0; d < array.ndim(); ++d)
        text += (d ? ", " : "") + std::to_string(array.shape(d));
    return text + (array.ndim() == 1 ? ",)" : ")");
}

// `object` as an array of exactly `ndim` dimensions; `what` names it in the error.
py::array as_array(py::handle object, py::ssize_t ndim, const char* what) {
    py::array array = py::array::ensure(object);
    if (!array) throw oclvox::InputError(std::string(what) + " must be an array");
    if (array.ndim() != ndim)
        throw oclvox::InputError(std::string(what) + " must have " + std::to_string(ndim) +
                                 " dimensions, got shape " + shape_text(array));
    return array;
}

// The voxel count of an (nx, ny, nz) array, with the dims written into `grid`.
void take_dims(const py::array& array, oclvox::Grid& grid) {
    for (int axis = 0; axis < 3; ++axis) grid.dims[size_t(axis)] = int64_t(array.shape(axis));
    oclvox::validate_grid(grid);
}

// Fortran-ordered (nx, ny, nz) strides for elements of `item` bytes.
std::array<py::ssize_t, 3> fortran_strides(const oclvox::Grid& grid, py::ssize_t item) {
    return {item, item * grid.dims[0], item * grid.dims[0] * grid.dims[1]};
}

}  // namespace

oclvox::Mesh mesh_from_arrays(py::handle vertices_object, py::handle faces_object) {
    // Phase 1: shapes and dtypes, before anything is copied.
    const py::array vertices_in = as_array(vertices_object, 2, "vertices");
    const py::array faces_in = as_array(faces_object, 2, "faces");
    if (vertices_in.shape(1) != 3)
        throw oclvox::InputError("vertices must have shape (N, 3), got " + shape_text(vertices_in));
    if (faces_in.shape(1) != 3)
        throw oclvox::InputError("faces must have shape (M, 3), got " + shape_text(faces_in));
    const char vertex_kind = vertices_in.dtype().kind(), face_kind = faces_in.dtype().kind();
    if (vertex_kind != 'f' && vertex_kind != 'i' && vertex_kind != 'u')
        throw oclvox::InputError("vertices must be real numbers, got dtype " +
                                 std::string(py::str(vertices_in.dtype())));
    if (face_kind != 'i' && face_kind != 'u')
        throw oclvox::InputError("faces must be integers, got dtype " +
                                 std::string(py::str(faces_in.dtype())));

    // Phase 2: one copy of each into the library's storage (converted on the way where needed).
    using Vertices = py::array_t<double, py::array::c_style | py::array::forcecast>;
    using Faces = py::array_t<int64_t, py::array::c_style | py::array::forcecast>;
    const Vertices vertices = Vertices::ensure(vertices_in);
    const Faces faces = Faces::ensure(faces_in);
    if (!vertices || !faces) throw py::error_already_set();
    oclvox::Mesh mesh;
    mesh.positions.resize(size_t(vertices.shape(0)));
    if (!mesh.positions.empty())
        std::memcpy(mesh.positions.data(), vertices.data(), mesh.positions.size() * 3 * 8);
    mesh.triangles.resize(size_t(faces.shape(0)));
    const int64_t vertex_count = int64_t(vertices.shape(0));
    const int64_t* index = faces.data();
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
        for (size_t c = 0; c < 3; ++c, ++index) {
            // Checked here since the library stores 32-bit indices: a negative or huge index
            // must not wrap into a valid one.
            if (*index < 0 || *index >= vertex_count)
                throw oclvox::InputError("face " + std::to_string(t) + " refers to vertex " +
                                         std::to_string(*index) + ", but there are " +
                                         std::to_string(vertex_count) + " vertices");
            mesh.triangles[t][c] = uint32_t(*index);
        }

    // Phase 3: the library's own checks (no triangles, non-finite coordinates).
    oclvox::validate_mesh(mesh);
    return mesh;
}

py::array_t<double> vertices_view(oclvox::Mesh& mesh, py::handle owner) {
    const py::ssize_t n = py::ssize_t(mesh.positions.size());
    return py::array_t<double>({n, py::ssize_t(3)}, {py::ssize_t(24), py::ssize_t(8)},
                               mesh.positions.empty() ? nullptr : mesh.positions.data()->data(),
                               owner);
}

py::array_t<int64_t> faces_array(const oclvox::Mesh& mesh) {
    py::array_t<int64_t> faces({py::ssize_t(mesh.triangles.size()), py::ssize_t(3)});
    int64_t* out = faces.mutable_data();
    for (const auto& triangle : mesh.triangles)
        for (const uint32_t index : triangle) *out++ = int64_t(index);
    return faces;
}

py::array_t<uint8_t> occupancy_array(const oclvox::SparseVoxels& voxels) {
    // The dense vector moves into a capsule that the array owns: no second copy.
    auto dense = std::make_unique<std::vector<uint8_t>>();
    {
        py::gil_scoped_release release;
        *dense = voxels.to_dense();
    }
    const oclvox::Grid& grid = voxels.grid();
    uint8_t* data = dense->data();
    py::capsule owner(dense.get(),
                      [](void* pointer) { delete static_cast<std::vector<uint8_t>*>(pointer); });
    dense.release();
    return py::array_t<uint8_t>({grid.dims[0], grid.dims[1], grid.dims[2]},
                                fortran_strides(grid, 1), data, owner);
}

oclvox::SparseVoxels voxels_from_array(py::handle occupancy_object, const oclvox::Grid& grid_base,
                                       int brick_size) {
    using Occupancy = py::array_t<bool, py::array::f_style | py::array::forcecast>;
    const Occupancy occupancy = Occupancy::ensure(as_array(occupancy_object, 3, "occupancy"));
    if (!occupancy) throw py::error_already_set();
    oclvox::Grid grid = grid_base;
    take_dims(occupancy, grid);
    oclvox::SparseVoxels voxels(grid, brick_size);
    const bool* value = occupancy.data();
    for (int64_t k = 0; k < grid.dims[2]; ++k)
        for (int64_t j = 0; j < grid.dims[1]; ++j)
            for (int64_t i = 0; i < grid.dims[0]; ++i, ++value)
                if (*value) voxels.set(i, j, k);
    return voxels;
}

py::array_t<float> field_view(const oclvox::ScalarField& field, py::handle owner) {
    py::array_t<float> view({field.grid.dims[0], field.grid.dims[1], field.grid.dims[2]},
                            fortran_strides(field.grid, 4), field.values.data(), owner);
    // The field's samples are shared, not copied: writing through the view would change a field
    // that other calls may be meshing.
    view.attr("flags").attr("writeable") = false;
    return view;
}

oclvox::ScalarField field_from_array(py::handle values_object, const oclvox::Grid& grid_base) {
    using Values = py::array_t<float, py::array::f_style | py::array::forcecast>;
    const py::array values_in = as_array(values_object, 3, "field values");
    const char kind = values_in.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u')
        throw oclvox::InputError("field values must be real numbers, got dtype " +
                                 std::string(py::str(values_in.dtype())));
    const Values values = Values::ensure(values_in);
    if (!values) throw py::error_already_set();
    oclvox::ScalarField field;
    field.grid = grid_base;
    take_dims(values, field.grid);
    field.values.assign(values.data(), values.data() + values.size());
    return field;
}

}  // namespace oclvox_python
