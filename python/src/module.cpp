// The `oclvox._oclvox` extension module: the library's value types and functions, typed and
// strict. The `oclvox` package (python/oclvox/__init__.py) builds the friendly API on it: meshes
// given as arrays, paths or trimesh-like objects, keyword options, docstrings.
//
// Every call that does real work (device or CPU reference) releases the GIL while it runs, so other
// Python threads go on; device calls take the device's lock so that one device serves one call at a
// time. The long ones (voxelize, sdf, csg of meshes, mesh) take a progress callback, which takes
// the GIL back only while it runs (ProgressBridge).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <mutex>
#include <oclvox/field.hpp>
#include <oclvox/oclvox.hpp>
#include <oclvox/sdf.hpp>
#include <optional>
#include <string>
#include <type_traits>

#include "arrays.hpp"
#include "devices.hpp"
#include "errors.hpp"
#include "progress.hpp"

namespace py = pybind11;
using namespace py::literals;

namespace oclvox_python {
namespace {

// ---- result objects -----------------------------------------------------------------------------

// A voxelization result: the sparse voxels with the run's counts and timings.
struct VoxelGrid {
    oclvox::SparseVoxels voxels;
    oclvox::VoxelizeStats stats;
    std::string device;  // the device's name, or "reference"
};

// A scalar field (SDF or CSG result, or made from an array), with the band its file writers use.
struct Field {
    oclvox::ScalarField field;
    double band_voxels = 0;  // 0: taken from the values when written (see oclvox::write_field)
    oclvox::VoxelizeStats stats;
    std::string device;
};

// A narrow-band field kept sparse (oclvox::SparseField): what sdf and csg of meshes give with
// sparse=True, for grids whose dense field would not fit.
struct SparseField {
    oclvox::SparseField field;
    oclvox::VoxelizeStats stats;
    std::string device;
};

py::tuple origin_tuple(const oclvox::Grid& grid) {
    return py::make_tuple(grid.origin[0], grid.origin[1], grid.origin[2]);
}
py::tuple dims_tuple(const oclvox::Grid& grid) {
    return py::make_tuple(grid.dims[0], grid.dims[1], grid.dims[2]);
}

py::dict stats_dict(const oclvox::VoxelizeStats& s) {
    py::dict d("seconds_binning"_a = s.seconds_binning, "seconds_upload"_a = s.seconds_upload,
               "seconds_kernels"_a = s.seconds_kernels, "seconds_download"_a = s.seconds_download,
               "bytes_downloaded"_a = s.bytes_downloaded, "triangles_in"_a = s.triangles_in,
               "triangles_used"_a = s.triangles_used, "brick_pairs"_a = s.brick_pairs,
               "work_items"_a = s.work_items, "bricks_total"_a = s.bricks_total,
               "bricks_active"_a = s.bricks_active, "batches"_a = s.batches,
               "voxels_set"_a = s.voxels_set);
    if (!s.inside_test.empty()) {
        d["inside_test"] = s.inside_test;
        d["inside_test_reason"] = s.inside_test_reason;
    }
    return d;
}

// ---- arguments ----------------------------------------------------------------------------------

oclvox::GridFit make_fit(int64_t resolution, std::optional<double> voxel_size,
                         std::optional<std::array<double, 3>> origin,
                         std::optional<std::array<int64_t, 3>> dims, int64_t pad, bool cubic) {
    oclvox::GridFit fit;
    fit.resolution = resolution;
    fit.cubic = cubic;
    fit.pad = pad;
    if (voxel_size) {
        // The library reads voxel_size <= 0 as "not given"; a caller who gave one means it.
        if (!(*voxel_size > 0) || !std::isfinite(*voxel_size))
            throw oclvox::GridError("voxel_size must be a positive finite number, got " +
                                    std::to_string(*voxel_size));
        fit.voxel_size = *voxel_size;
    }
    if (origin) {
        fit.has_origin = true;
        fit.origin = *origin;
    }
    if (dims) {
        fit.has_dims = true;
        fit.dims = *dims;
    }
    return fit;
}

oclvox::Grid grid_base(const std::array<double, 3>& origin, double voxel_size) {
    oclvox::Grid grid;
    grid.origin = origin;
    grid.voxel_size = voxel_size;
    return grid;
}

// The device a call runs on: none for the CPU reference, else `device` (a selector string) or,
// when None, $OCLVOX_DEVICE or the default device, as the CLI picks it.
std::shared_ptr<SharedDevice> pick_device(const py::object& device, bool reference) {
    if (reference) {
        if (!device.is_none())
            throw py::value_error("device and reference=True exclude each other");
        return nullptr;
    }
    std::string selector;
    if (!device.is_none())
        selector = device.cast<std::string>();
    else if (const char* env = std::getenv("OCLVOX_DEVICE"))
        selector = env;
    return shared_device(selector);
}

std::string device_name(const std::shared_ptr<SharedDevice>& device) {
    return device ? device->device.info().name : "reference";
}

// Brick indices from any 1-D array-like of non-negative integers.
std::vector<uint64_t> brick_list(const py::object& bricks) {
    if (bricks.is_none()) return {};
    const auto array =
        py::array_t<uint64_t, py::array::c_style | py::array::forcecast>::ensure(bricks);
    if (!array || array.ndim() != 1)
        throw py::value_error("bricks must be a 1-D sequence of brick indices");
    return std::vector<uint64_t>(array.data(), array.data() + array.size());
}

py::array_t<uint64_t> brick_array(const std::vector<uint64_t>& bricks) {
    py::array_t<uint64_t> out(py::ssize_t(bricks.size()));
    std::copy(bricks.begin(), bricks.end(), out.mutable_data());
    return out;
}

// Triangle indices from any 1-D array-like of integers, each checked against the mesh (a
// cast to uint32 would wrap out-of-range values onto real triangles).
std::vector<uint32_t> triangle_list(const py::object& triangles, const oclvox::Mesh& mesh) {
    const auto array =
        py::array_t<int64_t, py::array::c_style | py::array::forcecast>::ensure(triangles);
    if (!array || array.ndim() != 1)
        throw py::value_error("triangles must be a 1-D sequence of triangle indices");
    std::vector<uint32_t> out(size_t(array.size()));
    for (py::ssize_t i = 0; i < array.size(); ++i) {
        const int64_t t = array.data()[i];
        if (t < 0 || uint64_t(t) >= mesh.triangles.size())
            throw py::index_error("triangle index " + std::to_string(t) +
                                  " is out of range: the mesh has " +
                                  std::to_string(mesh.triangles.size()) + " triangles");
        out[size_t(i)] = uint32_t(t);
    }
    return out;
}

oclvox::VoxelizeOptions voxelize_options(const std::string& mode, const std::string& test,
                                         const std::string& inside, const std::string& boundary,
                                         int brick_size, std::optional<uint64_t> device_mib,
                                         std::optional<uint64_t> host_mib,
                                         const py::object& bricks = py::none(),
                                         const std::string& download = "auto") {
    oclvox::VoxelizeOptions options;
    options.mode = oclvox::voxelize_mode_from_string(mode);
    options.test = oclvox::overlap_test_from_string(test);
    options.inside = oclvox::inside_test_from_string(inside);
    options.boundary = oclvox::boundary_from_string(boundary);
    options.brick_size = brick_size;
    if (device_mib) options.device_budget_bytes = *device_mib << 20;
    if (host_mib) options.host_budget_bytes = *host_mib << 20;
    options.bricks = brick_list(bricks);
    options.download = oclvox::download_from_string(download);
    return options;
}

oclvox::SdfOptions sdf_options(double band, bool full_grid, const std::string& inside,
                               int brick_size,
                               std::optional<std::array<int64_t, 2>> layers = std::nullopt) {
    oclvox::SdfOptions options;
    if (layers) {
        options.first_layer = (*layers)[0];
        options.end_layer = (*layers)[1];
    }
    options.band_voxels = band;
    options.full_grid = full_grid;
    options.inside = oclvox::inside_test_from_string(inside);
    options.brick_size = brick_size;
    return options;
}

// The pickled state of sparse voxels: the grid, the brick size and the stored bricks: their
// indices, a bitmap per brick of its non-zero block words, and those words alone. A sparse result
// travels between processes without a dense copy, and a surface brick (mostly empty blocks) costs
// its set blocks, not its 8 bytes per block: about a tenth of the words, on bunny00's bricks.
constexpr size_t kVoxelsStateSize = 7;

py::tuple voxels_state(const oclvox::SparseVoxels& v) {
    const std::vector<uint64_t> indices = v.brick_indices();
    const size_t blocks = v.blocks_per_brick(), mask_bytes = (blocks + 7) / 8;
    py::array_t<uint8_t> masks({py::ssize_t(indices.size()), py::ssize_t(mask_bytes)});
    std::fill_n(masks.mutable_data(), masks.size(), uint8_t(0));
    std::vector<uint64_t> words;
    for (size_t b = 0; b < indices.size(); ++b) {
        const uint64_t* brick = v.brick_blocks(indices[b]);
        uint8_t* mask = masks.mutable_data(py::ssize_t(b), 0);
        for (size_t w = 0; w < blocks; ++w)
            if (brick[w]) {
                mask[w / 8] |= uint8_t(1u << (w % 8));
                words.push_back(brick[w]);
            }
    }
    return py::make_tuple(origin_tuple(v.grid()), v.grid().voxel_size, dims_tuple(v.grid()),
                          v.brick_size(), brick_array(indices), masks, brick_array(words));
}

// voxels_state's inverse, from state[first] on; `not_this` names the pickled type in errors.
oclvox::SparseVoxels voxels_from_state(const py::tuple& state, size_t first,
                                       const std::string& not_this) {
    oclvox::Grid grid =
        grid_base(state[first].cast<std::array<double, 3>>(), state[first + 1].cast<double>());
    grid.dims = state[first + 2].cast<std::array<int64_t, 3>>();
    oclvox::validate_grid(grid);
    oclvox::SparseVoxels voxels(grid, state[first + 3].cast<int>());
    const std::vector<uint64_t> indices = brick_list(state[first + 4]);
    const auto masks =
        py::array_t<uint8_t, py::array::c_style | py::array::forcecast>::ensure(state[first + 5]);
    const std::vector<uint64_t> words = brick_list(state[first + 6]);
    const size_t blocks = voxels.blocks_per_brick(), mask_bytes = (blocks + 7) / 8;
    if (!masks || masks.ndim() != 2 || size_t(masks.shape(0)) != indices.size() ||
        size_t(masks.shape(1)) != mask_bytes)
        throw py::value_error(not_this + ": brick masks do not match");
    std::vector<uint64_t> brick(blocks);
    size_t next = 0;
    for (size_t b = 0; b < indices.size(); ++b) {
        const uint8_t* mask = masks.data(py::ssize_t(b), 0);
        for (size_t w = 0; w < blocks; ++w) {
            const bool set = mask[w / 8] >> (w % 8) & 1;
            if (set && next == words.size())
                throw py::value_error(not_this + ": fewer words than masks");
            brick[w] = set ? words[next++] : 0;
        }
        voxels.merge_brick(indices[b], brick.data());
    }
    if (next != words.size()) throw py::value_error(not_this + ": more words than masks");
    return voxels;
}

// A VoxelGrid's pickled state: its voxels' and the device's name.
py::tuple voxel_grid_state(const VoxelGrid& g) {
    return voxels_state(g.voxels) + py::make_tuple(g.device);
}

VoxelGrid voxel_grid_from_state(const py::tuple& state) {
    const std::string kNotAGrid = "not a pickled oclvox.VoxelGrid";
    if (state.size() != kVoxelsStateSize + 1) throw py::value_error(kNotAGrid);
    VoxelGrid g;
    g.voxels = voxels_from_state(state, 0, kNotAGrid);
    g.stats.voxels_set = g.voxels.count();
    g.device = state[kVoxelsStateSize].cast<std::string>();
    return g;
}

// A SparseField's pickled state: its inside voxels', the band, the leaf indices, the leaves'
// samples (one row of kLeafSamples per leaf) and the device's name.
py::tuple sparse_field_state(const SparseField& f) {
    const oclvox::SparseField& field = f.field;
    const size_t leaves = field.leaf_count();
    py::array_t<float> samples(
        {py::ssize_t(leaves), py::ssize_t(oclvox::SparseField::kLeafSamples)});
    if (leaves)
        std::copy_n(field.leaf_samples(0), leaves * oclvox::SparseField::kLeafSamples,
                    samples.mutable_data());
    return voxels_state(field.inside()) + py::make_tuple(field.band_voxels(),
                                                         brick_array(field.leaf_indices()), samples,
                                                         f.device);
}

SparseField sparse_field_from_state(const py::tuple& state) {
    const std::string kNotAField = "not a pickled oclvox.SparseField";
    constexpr size_t n = kVoxelsStateSize;
    if (state.size() != n + 4) throw py::value_error(kNotAField);
    oclvox::SparseVoxels inside = voxels_from_state(state, 0, kNotAField);
    const oclvox::Grid grid = inside.grid();
    SparseField f;
    f.field = oclvox::SparseField(grid, state[n].cast<double>(), std::move(inside));
    const std::vector<uint64_t> leaves = brick_list(state[n + 1]);
    const auto samples =
        py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(state[n + 2]);
    if (!samples || samples.ndim() != 2 || size_t(samples.shape(0)) != leaves.size() ||
        size_t(samples.shape(1)) != oclvox::SparseField::kLeafSamples)
        throw py::value_error(kNotAField + ": leaf samples do not match the leaves");
    f.field.reserve_leaves(leaves.size());
    for (size_t l = 0; l < leaves.size(); ++l)
        f.field.append_leaf(leaves[l], samples.data(py::ssize_t(l), 0));
    f.stats.bricks_active = leaves.size();
    f.device = state[n + 3].cast<std::string>();
    return f;
}

// ORs `other`'s voxels into `into`; both must have the same grid and brick size.
void merge_voxel_grids(VoxelGrid& into, const VoxelGrid& other) {
    const oclvox::Grid &a = into.voxels.grid(), &b = other.voxels.grid();
    if (a.origin != b.origin || a.voxel_size != b.voxel_size || a.dims != b.dims ||
        into.voxels.brick_size() != other.voxels.brick_size())
        throw oclvox::GridError("merge needs two VoxelGrids with the same grid and brick size");
    py::gil_scoped_release release;
    for (const uint64_t brick : other.voxels.brick_indices())
        into.voxels.merge_brick(brick, other.voxels.brick_blocks(brick));
    into.stats.voxels_set = into.voxels.count();
}

// ---- work ---------------------------------------------------------------------------------------

VoxelGrid voxelize(const oclvox::Mesh& mesh, const oclvox::GridFit& fit,
                   oclvox::VoxelizeOptions options, const py::object& device_selector,
                   bool reference, py::object progress) {
    ProgressBridge bridge(std::move(progress));
    const std::shared_ptr<SharedDevice> device = pick_device(device_selector, reference);
    VoxelGrid result;
    result.device = device_name(device);
    bridge.run_released([&](oclvox::ProgressCallback callback) {
        options.progress = std::move(callback);
        const oclvox::Grid grid = oclvox::fit_grid(mesh, fit);
        if (device) {
            std::lock_guard<std::mutex> lock(device->in_use);
            result.voxels = device->device.voxelize(mesh, grid, options, &result.stats);
        } else {
            result.voxels = oclvox::voxelize_reference(mesh, grid, options, &result.stats);
        }
        return 0;
    });
    return result;
}

// The signed distance field of a mesh, dense (Field) or sparse (SparseField), on the picked
// device or the reference.
template <class Result>
Result sdf(const oclvox::Mesh& mesh, const oclvox::GridFit& fit, oclvox::SdfOptions options,
           const py::object& device_selector, bool reference, py::object progress) {
    constexpr bool kSparse = std::is_same_v<Result, SparseField>;
    ProgressBridge bridge(std::move(progress));
    const std::shared_ptr<SharedDevice> device = pick_device(device_selector, reference);
    Result result;
    result.device = device_name(device);
    if constexpr (!kSparse) result.band_voxels = options.full_grid ? 0 : options.band_voxels;
    bridge.run_released([&](oclvox::ProgressCallback callback) {
        options.progress = std::move(callback);
        const oclvox::Grid grid = oclvox::fit_grid(mesh, fit);
        std::unique_lock<std::mutex> lock;
        if (device) lock = std::unique_lock<std::mutex>(device->in_use);
        if constexpr (kSparse)
            result.field = device ? oclvox::signed_distance_sparse(device->device, mesh, grid,
                                                                   options, &result.stats)
                                  : oclvox::signed_distance_sparse_reference(mesh, grid, options,
                                                                             &result.stats);
        else
            result.field =
                device ? oclvox::signed_distance(device->device, mesh, grid, options, &result.stats)
                       : oclvox::signed_distance_reference(mesh, grid, options, &result.stats);
        return 0;
    });
    return result;
}

// The CSG of two meshes through their fields, dense (Field) or sparse (SparseField).
template <class Result>
Result csg_meshes(const oclvox::Mesh& a, const std::string& op_name, const oclvox::Mesh& b,
                  const oclvox::GridFit& fit, oclvox::SdfOptions options,
                  const py::object& device_selector, bool reference, py::object progress) {
    constexpr bool kSparse = std::is_same_v<Result, SparseField>;
    const oclvox::CsgOp op = oclvox::csg_op_from_string(op_name);
    ProgressBridge bridge(std::move(progress));
    const std::shared_ptr<SharedDevice> device = pick_device(device_selector, reference);
    Result result;
    result.device = device_name(device);
    if constexpr (!kSparse) result.band_voxels = options.full_grid ? 0 : options.band_voxels;
    bridge.run_released([&](oclvox::ProgressCallback callback) {
        options.progress = std::move(callback);
        // Both fields on one grid around both meshes, as the CLI's csg does.
        const oclvox::Grid grid = oclvox::fit_grid(a, b, fit);
        std::unique_lock<std::mutex> lock;
        if (device) lock = std::unique_lock<std::mutex>(device->in_use);
        if constexpr (kSparse)
            result.field =
                device ? oclvox::csg_sparse(device->device, a, b, op, grid, options, &result.stats)
                       : oclvox::csg_sparse_reference(a, b, op, grid, options, &result.stats);
        else
            result.field = device
                               ? oclvox::csg(device->device, a, b, op, grid, options, &result.stats)
                               : oclvox::csg_reference(a, b, op, grid, options, &result.stats);
        return 0;
    });
    return result;
}

// Two Fields, or two SparseFields (which may lie on different grids of one lattice).
template <typename F>
F csg_fields(const F& a, const std::string& op_name, const F& b) {
    const oclvox::CsgOp op = oclvox::csg_op_from_string(op_name);
    F result;
    py::gil_scoped_release release;
    result.field = oclvox::csg(a.field, b.field, op);
    return result;
}

VoxelGrid csg_voxels(const VoxelGrid& a, const std::string& op_name, const VoxelGrid& b) {
    const oclvox::CsgOp op = oclvox::csg_op_from_string(op_name);
    VoxelGrid result;
    py::gil_scoped_release release;
    result.voxels = oclvox::csg(a.voxels, b.voxels, op);
    result.stats.voxels_set = result.voxels.count();
    return result;
}

oclvox::Mesh extract_surface(const Field& field, float iso, const std::string& method,
                             const py::object& device_selector, bool reference,
                             py::object progress) {
    const bool marching_cubes = method == "marching-cubes";
    if (!marching_cubes && method != "surface-nets")
        throw oclvox::GridError("unknown meshing method '" + method +
                                "' (expected marching-cubes or surface-nets)");
    ProgressBridge bridge(std::move(progress));
    const std::shared_ptr<SharedDevice> device = pick_device(device_selector, reference);
    return bridge.run_released([&](const oclvox::ProgressCallback& callback) {
        // On a CPU the host meshers are faster than the kernels, with the same mesh (as the CLI).
        if (!device || device->device.info().type == "CPU")
            return marching_cubes ? oclvox::marching_cubes(field.field, iso, callback)
                                  : oclvox::surface_nets(field.field, iso, callback);
        std::lock_guard<std::mutex> lock(device->in_use);
        return marching_cubes ? oclvox::marching_cubes(device->device, field.field, iso, callback)
                              : oclvox::surface_nets(device->device, field.field, iso, callback);
    });
}

// A sparse field's iso-surface, on the host (the sparse mesher has no device path).
oclvox::Mesh extract_sparse_surface(const SparseField& field, float iso, const std::string& method,
                                    py::object progress) {
    const bool marching_cubes = method == "marching-cubes";
    if (!marching_cubes && method != "surface-nets")
        throw oclvox::GridError("unknown meshing method '" + method +
                                "' (expected marching-cubes or surface-nets)");
    ProgressBridge bridge(std::move(progress));
    return bridge.run_released([&](const oclvox::ProgressCallback& callback) {
        return marching_cubes ? oclvox::marching_cubes(field.field, iso, callback)
                              : oclvox::surface_nets(field.field, iso, callback);
    });
}

py::list devices() {
    std::vector<oclvox::DeviceInfo> infos;
    {
        py::gil_scoped_release release;
        infos = oclvox::list_devices();
    }
    py::list list;
    for (const oclvox::DeviceInfo& i : infos)
        list.append(py::dict("id"_a = i.id, "platform"_a = i.platform, "name"_a = i.name,
                             "vendor"_a = i.vendor, "version"_a = i.version,
                             "driver_version"_a = i.driver_version, "type"_a = i.type,
                             "global_memory"_a = i.global_memory, "max_alloc"_a = i.max_alloc,
                             "host_unified_memory"_a = i.host_unified_memory));
    return list;
}

}  // namespace
}  // namespace oclvox_python

PYBIND11_MODULE(_oclvox, m) {
    using namespace oclvox_python;
    m.doc() = "oclvox extension module; use the oclvox package's functions instead.";
    register_errors(m);

    py::class_<oclvox::Mesh>(m, "Mesh")
        .def(py::init(&mesh_from_arrays), "vertices"_a, "faces"_a)
        .def_property_readonly(
            "vertices",
            [](py::object self) { return vertices_view(self.cast<oclvox::Mesh&>(), self); },
            "float64 (N, 3) view of the mesh's own vertices")
        .def_property_readonly("faces", &faces_array, "int64 (M, 3) copy of the triangles")
        .def(
            "submesh",
            [](const oclvox::Mesh& mesh, const py::object& triangles) {
                const std::vector<uint32_t> list = triangle_list(triangles, mesh);
                py::gil_scoped_release release;
                return oclvox::submesh(mesh, list);
            },
            "triangles"_a,
            "The mesh of just these triangles (indices, in the order given) and the vertices they "
            "use (in their order here)")
        .def(
            "save",
            [](const oclvox::Mesh& mesh, const std::filesystem::path& path, py::object progress) {
                ProgressBridge bridge(std::move(progress));
                bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                    oclvox::write_mesh(path.string(), mesh, callback);
                });
            },
            "path"_a, "progress"_a = py::none(),
            "Writes .obj, .ply or .stl; progress(done, total) as for sdf, False cancelling with no "
            "file left")
        .def("__repr__",
             [](const oclvox::Mesh& mesh) {
                 return "<oclvox.Mesh " + std::to_string(mesh.positions.size()) + " vertices, " +
                        std::to_string(mesh.triangles.size()) + " triangles>";
             })
        .def(py::pickle(
            [](py::object self) {
                oclvox::Mesh& mesh = self.cast<oclvox::Mesh&>();
                return py::make_tuple(vertices_view(mesh, self), faces_array(mesh));
            },
            [](const py::tuple& state) {
                if (state.size() != 2) throw py::value_error("not a pickled oclvox.Mesh");
                return mesh_from_arrays(state[0], state[1]);
            }));

    py::class_<oclvox::GridFit>(m, "GridFit")
        .def(py::init(&make_fit), "resolution"_a, "voxel_size"_a, "origin"_a, "dims"_a, "pad"_a,
             "cubic"_a);

    py::class_<VoxelGrid>(m, "VoxelGrid")
        .def_property_readonly("origin",
                               [](const VoxelGrid& g) { return origin_tuple(g.voxels.grid()); })
        .def_property_readonly("voxel_size",
                               [](const VoxelGrid& g) { return g.voxels.grid().voxel_size; })
        .def_property_readonly("dims",
                               [](const VoxelGrid& g) { return dims_tuple(g.voxels.grid()); })
        .def_property_readonly("count", [](const VoxelGrid& g) { return g.voxels.count(); })
        .def_property_readonly("brick_size",
                               [](const VoxelGrid& g) { return g.voxels.brick_size(); })
        .def_property_readonly("brick_count",
                               [](const VoxelGrid& g) { return g.voxels.brick_count(); })
        .def_property_readonly("stats", [](const VoxelGrid& g) { return stats_dict(g.stats); })
        .def_property_readonly("device", [](const VoxelGrid& g) { return g.device; })
        .def("to_numpy", [](const VoxelGrid& g) { return occupancy_array(g.voxels); })
        .def("__repr__",
             [](const VoxelGrid& g) {
                 const oclvox::Grid& grid = g.voxels.grid();
                 return "<oclvox.VoxelGrid " + std::to_string(grid.dims[0]) + "x" +
                        std::to_string(grid.dims[1]) + "x" + std::to_string(grid.dims[2]) + ", " +
                        std::to_string(g.voxels.count()) + " voxels set>";
             })
        .def("merge", &merge_voxel_grids, "other"_a,
             "ORs another VoxelGrid's voxels into this one (same grid and brick size), e.g. "
             "the results of voxelize(..., bricks=shard) over the shards of a split.")
        .def(
            "same_voxels",
            [](const VoxelGrid& a, const VoxelGrid& b) {
                py::gil_scoped_release release;
                return a.voxels.same_voxels(b.voxels);
            },
            "other"_a, "Whether both have the same grid and the same set voxels.")
        .def(
            "brick_indices",
            [](const VoxelGrid& g) { return brick_array(g.voxels.brick_indices()); },
            "The linear indices of the stored (non-empty) bricks, ascending, as uint64.")
        .def(py::pickle(&voxel_grid_state, &voxel_grid_from_state))
        .def(
            "to_field",
            [](const VoxelGrid& g, int smoothing) {
                Field result;
                py::gil_scoped_release release;
                result.field = oclvox::occupancy_to_field(g.voxels, smoothing);
                return result;
            },
            "smoothing"_a)
        .def(
            "meshing_view",
            [](const VoxelGrid& g, int smoothing, float iso) {
                SparseField result;
                py::gil_scoped_release release;
                result.field = oclvox::occupancy_meshing_view(g.voxels, smoothing, iso);
                return result;
            },
            "smoothing"_a, "iso"_a,
            "to_field(smoothing)'s meshing view at iso, made a layer at a time (never the dense "
            "field)")
        .def(
            "save",
            [](const VoxelGrid& g, const std::filesystem::path& path, py::object progress) {
                ProgressBridge bridge(std::move(progress));
                bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                    oclvox::write_voxels(path.string(), g.voxels, callback);
                });
            },
            "path"_a, "progress"_a = py::none(),
            "Writes by extension (.vdb .binvox .npy .vox .obj .ply .stl); progress(done, total) "
            "as for sdf, False cancelling with no file left")
        .def_static(
            "from_numpy",
            [](py::handle occupancy, std::array<double, 3> origin, double voxel_size,
               int brick_size) {
                VoxelGrid result;
                result.voxels =
                    voxels_from_array(occupancy, grid_base(origin, voxel_size), brick_size);
                result.stats.voxels_set = result.voxels.count();
                return result;
            },
            "occupancy"_a, "origin"_a = std::array<double, 3>{0, 0, 0}, "voxel_size"_a = 1.0,
            "brick_size"_a = 64,
            "A VoxelGrid from a (nx, ny, nz) array: every non-zero element is a set voxel.");

    py::class_<Field>(m, "Field")
        .def(py::init([](py::handle values, std::array<double, 3> origin, double voxel_size,
                         double band) {
                 Field result;
                 result.field = field_from_array(values, grid_base(origin, voxel_size));
                 result.band_voxels = band;
                 return result;
             }),
             "values"_a, "origin"_a = std::array<double, 3>{0, 0, 0}, "voxel_size"_a = 1.0,
             "band"_a = 0.0,
             "A field from a (nx, ny, nz) array of samples at voxel centres (copied as float32). "
             "band: the narrow band in voxels for .vdb output (0: the largest |value|).")
        .def_property_readonly("origin", [](const Field& f) { return origin_tuple(f.field.grid); })
        .def_property_readonly("voxel_size", [](const Field& f) { return f.field.grid.voxel_size; })
        .def_property_readonly("dims", [](const Field& f) { return dims_tuple(f.field.grid); })
        .def_property_readonly("band", [](const Field& f) { return f.band_voxels; })
        .def_property_readonly("stats", [](const Field& f) { return stats_dict(f.stats); })
        .def_property_readonly("device", [](const Field& f) { return f.device; })
        .def("to_numpy",
             [](py::object self) { return field_view(self.cast<const Field&>().field, self); })
        .def("__repr__",
             [](const Field& f) {
                 const oclvox::Grid& grid = f.field.grid;
                 return "<oclvox.Field " + std::to_string(grid.dims[0]) + "x" +
                        std::to_string(grid.dims[1]) + "x" + std::to_string(grid.dims[2]) + ">";
             })
        .def(
            "save",
            [](const Field& f, const std::filesystem::path& path, py::object progress) {
                ProgressBridge bridge(std::move(progress));
                bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                    oclvox::write_field(path.string(), f.field, f.band_voxels, callback);
                });
            },
            "path"_a, "progress"_a = py::none(),
            "Writes .npy (+ .json) or .vdb; progress(done, total) as for sdf, False cancelling "
            "with no file left");

    py::class_<SparseField>(m, "SparseField")
        .def_property_readonly("origin",
                               [](const SparseField& f) { return origin_tuple(f.field.grid()); })
        .def_property_readonly("voxel_size",
                               [](const SparseField& f) { return f.field.grid().voxel_size; })
        .def_property_readonly("dims",
                               [](const SparseField& f) { return dims_tuple(f.field.grid()); })
        .def_property_readonly("band", [](const SparseField& f) { return f.field.band_voxels(); })
        .def_property_readonly("leaf_count",
                               [](const SparseField& f) { return f.field.leaf_count(); })
        .def_property_readonly("stats", [](const SparseField& f) { return stats_dict(f.stats); })
        .def_property_readonly("device", [](const SparseField& f) { return f.device; })
        .def(
            "to_field",
            [](const SparseField& f) {
                Field result;
                py::gil_scoped_release release;
                result.field = f.field.to_dense();
                result.band_voxels = f.field.band_voxels();
                result.stats = f.stats;
                result.device = f.device;
                return result;
            },
            "The dense Field (checked against the host memory budget first).")
        .def("__repr__",
             [](const SparseField& f) {
                 const oclvox::Grid& grid = f.field.grid();
                 return "<oclvox.SparseField " + std::to_string(grid.dims[0]) + "x" +
                        std::to_string(grid.dims[1]) + "x" + std::to_string(grid.dims[2]) + ", " +
                        std::to_string(f.field.leaf_count()) + " leaves>";
             })
        .def(
            "save",
            [](const SparseField& f, const std::filesystem::path& path, py::object progress) {
                ProgressBridge bridge(std::move(progress));
                bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                    oclvox::write_field(path.string(), f.field, callback);
                });
            },
            "path"_a, "progress"_a = py::none(),
            "Writes .vdb from the leaves or .npy (+ .json) a layer at a time; progress as for "
            "Field.save")
        .def(
            "merge",
            [](SparseField& into, const SparseField& other) {
                py::gil_scoped_release release;
                into.field.merge(other.field);
                into.stats.bricks_active = into.field.leaf_count();
            },
            "other"_a,
            "Adds another SparseField's leaves and inside voxels (same grid, band and brick "
            "size; no leaf in both), e.g. the fields of sdf(..., sparse=True, layers=...) over "
            "disjoint layer ranges, which merge into the whole grid's field.")
        .def(py::pickle(&sparse_field_state, &sparse_field_from_state));

    m.def(
        "load_mesh",
        [](const std::filesystem::path& path, py::object progress) {
            ProgressBridge bridge(std::move(progress));
            return bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                return oclvox::load_mesh(path.string(), callback);
            });
        },
        "path"_a, "progress"_a = py::none());
    m.def(
        "load_field",
        [](const std::filesystem::path& path) {
            Field result;
            py::gil_scoped_release release;
            result.field = oclvox::read_field(path.string());
            return result;
        },
        "path"_a);
    m.def(
        "write_field_layers",
        [](const std::filesystem::path& path, const std::array<double, 3>& origin,
           double voxel_size, const std::array<int64_t, 3>& dims, double band_voxels,
           py::function layer, py::object progress) {
            oclvox::Grid grid;
            grid.origin = origin;
            grid.voxel_size = voxel_size;
            grid.dims = dims;
            oclvox::validate_grid(grid);
            const size_t per_layer = size_t(dims[0]) * size_t(dims[1]);
            // An exception `layer` raises stops the write as a cancel (no file is left) and is
            // raised again as it was, not as the write's error.
            std::optional<py::error_already_set> raised;
            ProgressBridge bridge(std::move(progress));
            try {
                bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                    oclvox::write_field(
                        path.string(), grid, band_voxels,
                        [&](int64_t k, float* out) {
                            py::gil_scoped_acquire gil;
                            py::object given;
                            try {
                                given = layer(k);
                            } catch (py::error_already_set& e) {
                                raised.emplace(std::move(e));
                                throw oclvox::Cancelled("the layer callable raised");
                            }
                            // (nx, ny) in x-fastest order, whatever the callable returned.
                            const auto samples =
                                py::array_t<float, py::array::f_style |
                                                       py::array::forcecast>::ensure(given);
                            if (!samples || samples.ndim() != 2 || samples.shape(0) != dims[0] ||
                                samples.shape(1) != dims[1])
                                throw oclvox::InputError(
                                    "layer " + std::to_string(k) + " must be an (nx, ny) = (" +
                                    std::to_string(dims[0]) + ", " + std::to_string(dims[1]) +
                                    ") array of numbers");
                            std::copy_n(samples.data(), per_layer, out);
                        },
                        callback);
                });
            } catch (const oclvox::Cancelled&) {
                if (!raised) throw;
                py::error_already_set error = std::move(*raised);
                raised.reset();
                throw error;
            }
        },
        "path"_a, "origin"_a, "voxel_size"_a, "dims"_a, "band"_a, "layer"_a,
        "progress"_a = py::none());
    m.def(
        "load_meshing_view",
        [](const std::filesystem::path& path, float iso, py::object progress) {
            SparseField result;
            ProgressBridge bridge(std::move(progress));
            result.field = bridge.run_released([&](const oclvox::ProgressCallback& callback) {
                return oclvox::read_meshing_view(path.string(), iso, callback);
            });
            return result;
        },
        "path"_a, "iso"_a, "progress"_a = py::none());
    m.def(
        "load_sparse_field",
        [](const std::filesystem::path& path) {
            SparseField result;
            py::gil_scoped_release release;
            result.field = oclvox::read_sparse_field(path.string());
            return result;
        },
        "path"_a);
    m.def(
        "load_sparse_field_onto",
        [](const std::filesystem::path& path, const SparseField& onto) {
            SparseField result;
            py::gil_scoped_release release;
            result.field = oclvox::read_sparse_field(path.string(), onto.field.grid(),
                                                     onto.field.band_voxels());
            return result;
        },
        "path"_a, "onto"_a);
    m.def(
        "voxelize",
        [](const oclvox::Mesh& mesh, const oclvox::GridFit& fit, const std::string& mode,
           const std::string& test, const std::string& inside, const std::string& boundary,
           int brick_size, std::optional<uint64_t> device_memory,
           std::optional<uint64_t> host_memory, const std::string& download, py::object device,
           bool reference, py::object progress, py::object bricks) {
            return voxelize(mesh, fit,
                            voxelize_options(mode, test, inside, boundary, brick_size,
                                             device_memory, host_memory, bricks, download),
                            device, reference, std::move(progress));
        },
        "mesh"_a, "fit"_a, "mode"_a, "test"_a, "inside"_a, "boundary"_a, "brick_size"_a,
        "device_memory"_a, "host_memory"_a, "download"_a, "device"_a, "reference"_a, "progress"_a,
        "bricks"_a = py::none());
    m.def(
        "candidate_bricks",
        [](const oclvox::Mesh& mesh, const oclvox::GridFit& fit, const std::string& mode,
           const std::string& inside, const std::string& boundary, int brick_size) {
            const oclvox::VoxelizeOptions options =
                voxelize_options(mode, "sat", inside, boundary, brick_size, {}, {});
            std::vector<uint64_t> bricks;
            {
                py::gil_scoped_release release;
                bricks = oclvox::candidate_bricks(mesh, oclvox::fit_grid(mesh, fit), options);
            }
            return brick_array(bricks);
        },
        "mesh"_a, "fit"_a, "mode"_a, "inside"_a, "boundary"_a, "brick_size"_a);
    m.def(
        "selection_triangles",
        [](const oclvox::Mesh& mesh, const oclvox::GridFit& fit, const std::string& mode,
           const std::string& inside, const std::string& boundary, int brick_size,
           const py::iterable& selections) {
            const oclvox::VoxelizeOptions options =
                voxelize_options(mode, "sat", inside, boundary, brick_size, {}, {});
            std::vector<std::vector<uint64_t>> lists;
            for (const py::handle selection : selections)
                lists.push_back(brick_list(py::reinterpret_borrow<py::object>(selection)));
            oclvox::SelectionTriangles plan;
            {
                py::gil_scoped_release release;
                plan =
                    oclvox::selection_triangles(mesh, oclvox::fit_grid(mesh, fit), options, lists);
            }
            py::list triangles;
            for (const std::vector<uint32_t>& list : plan.triangles) {
                py::array_t<uint32_t> array(py::ssize_t(list.size()));
                std::copy(list.begin(), list.end(), array.mutable_data());
                triangles.append(array);
            }
            return py::make_tuple(oclvox::to_string(plan.inside), plan.whole_mesh, triangles);
        },
        "mesh"_a, "fit"_a, "mode"_a, "inside"_a, "boundary"_a, "brick_size"_a, "selections"_a);
    m.def(
        "sdf",
        [](const oclvox::Mesh& mesh, const oclvox::GridFit& fit, double band, bool full_grid,
           const std::string& inside, int brick_size, py::object device, bool reference,
           py::object progress, std::optional<std::array<int64_t, 2>> layers,
           bool sparse) -> py::object {
            const oclvox::SdfOptions options =
                sdf_options(band, full_grid, inside, brick_size, layers);
            if (sparse)
                return py::cast(
                    sdf<SparseField>(mesh, fit, options, device, reference, std::move(progress)));
            return py::cast(sdf<Field>(mesh, fit, options, device, reference, std::move(progress)));
        },
        "mesh"_a, "fit"_a, "band"_a, "full_grid"_a, "inside"_a, "brick_size"_a, "device"_a,
        "reference"_a, "progress"_a, "layers"_a = py::none(), "sparse"_a = false);
    m.def(
        "csg_meshes",
        [](const oclvox::Mesh& a, const std::string& op, const oclvox::Mesh& b,
           const oclvox::GridFit& fit, double band, bool full_grid, const std::string& inside,
           int brick_size, py::object device, bool reference, py::object progress,
           bool sparse) -> py::object {
            const oclvox::SdfOptions options = sdf_options(band, full_grid, inside, brick_size);
            if (sparse)
                return py::cast(csg_meshes<SparseField>(a, op, b, fit, options, device, reference,
                                                        std::move(progress)));
            return py::cast(
                csg_meshes<Field>(a, op, b, fit, options, device, reference, std::move(progress)));
        },
        "a"_a, "op"_a, "b"_a, "fit"_a, "band"_a, "full_grid"_a, "inside"_a, "brick_size"_a,
        "device"_a, "reference"_a, "progress"_a, "sparse"_a = false);
    m.def("csg_fields", &csg_fields<Field>, "a"_a, "op"_a, "b"_a);
    m.def("csg_fields", &csg_fields<SparseField>, "a"_a, "op"_a, "b"_a);
    m.def("csg_voxels", &csg_voxels, "a"_a, "op"_a, "b"_a);
    m.def("mesh", &extract_surface, "field"_a, "iso"_a, "method"_a, "device"_a, "reference"_a,
          "progress"_a);
    m.def("mesh_sparse", &extract_sparse_surface, "field"_a, "iso"_a, "method"_a, "progress"_a);
    m.def("devices", &devices);
    m.def("field_padding", &oclvox::field_padding, "band_voxels"_a);
    // The grid a call with this fit works on, without the work: (origin, voxel_size, dims). For
    // oclvox.distributed, which splits a grid before any worker computes on it.
    m.def(
        "fit_grid",
        [](const oclvox::Mesh& mesh, const oclvox::GridFit& fit) {
            const oclvox::Grid grid = oclvox::fit_grid(mesh, fit);
            return py::make_tuple(origin_tuple(grid), grid.voxel_size, dims_tuple(grid));
        },
        "mesh"_a, "fit"_a);
    // The classes are documented and used as oclvox.Mesh, oclvox.VoxelGrid, oclvox.Field.
    for (const char* name : {"Mesh", "GridFit", "VoxelGrid", "Field", "SparseField"})
        m.attr(name).attr("__module__") = "oclvox";

    // Devices are released before the interpreter tears down the module.
    py::module_::import("atexit").attr("register")(py::cpp_function(&forget_devices));
}
