// oclvox: conservative mesh voxelization on OpenCL devices.
//
// The public API is a handful of value types (Mesh, Grid, SparseVoxels, options and stats), plain
// functions that take and return them, and one handle (Device) that hides every OpenCL object.
// No OpenCL header is needed to use it. Library code never prints: it reports through
// VoxelizeStats and the progress callback, and fails by throwing an oclvox::Error subclass.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

// The library is built with hidden visibility; what these headers declare is its interface.
#pragma GCC visibility push(default)

namespace oclvox {

// Progress and cancellation of a long run: called on the calling thread as the work goes on with
// how much is done of a total that does not change during the run, done never going back; return
// false to cancel (the run throws Cancelled). Voxelization counts bricks and calls it after each
// batch; mesh loading, the distance fields (SdfOptions) and meshing (field.hpp) count fractions
// of a fixed total.
using ProgressCallback = std::function<bool(uint64_t done, uint64_t total)>;

// ---------------------------------------------------------------------------------------------
// Errors. Every failure names the problem; none is reported as an empty result.
// ---------------------------------------------------------------------------------------------
struct Error : std::runtime_error {
    using std::runtime_error::runtime_error;
};
// The input mesh file or mesh data is unusable (missing, malformed, NaN, no triangles, ...).
struct InputError : Error {
    using Error::Error;
};
// The requested grid cannot be built (zero or absurd resolution, memory limits, bad options).
struct GridError : Error {
    using Error::Error;
};
// An OpenCL call failed, or no (matching) device exists.
struct DeviceError : Error {
    using Error::Error;
};
// A kernel failed to compile; build_log() holds the compiler's output.
struct KernelBuildError : DeviceError {
    KernelBuildError(const std::string& what, std::string log)
        : DeviceError(what + "\n--- build log ---\n" + log), log_(std::move(log)) {}
    const std::string& build_log() const { return log_; }

  private:
    std::string log_;
};
// Writing an output file failed (nothing is left under the final name).
struct OutputError : Error {
    using Error::Error;
};
// The progress callback asked to stop.
struct Cancelled : Error {
    using Error::Error;
};

// ---------------------------------------------------------------------------------------------
// Meshes
// ---------------------------------------------------------------------------------------------
// An indexed triangle mesh in double precision. Polygons are triangulated on load and all
// objects/groups/solids of a file are merged.
struct Mesh {
    std::vector<std::array<double, 3>> positions;
    std::vector<std::array<uint32_t, 3>> triangles;
};

// Loads OBJ, STL (ASCII and binary), PLY (ascii and binary) and OFF exactly in double, and glTF
// 2.0 (.gltf, .glb) and 3MF through assimp (every node transform applied, all meshes merged).
// The format follows from the file extension (case-insensitive). Polygons are triangulated and
// equal positions welded. Throws InputError naming the file and the problem. `progress` is called
// as the file is parsed, triangulated and welded, as SdfOptions::progress is (done / total the
// fraction of the estimated work; returning false cancels: Cancelled).
Mesh load_mesh(const std::string& path, const ProgressCallback& progress = {});

// Throws InputError if the mesh has no triangles, an index out of range, or a non-finite
// coordinate in a used vertex.
void validate_mesh(const Mesh& mesh);

// The mesh of just these triangles of `mesh` (in the order given) and the vertices they use (in
// their order in `mesh`); the work is linear in the triangles kept, whatever the mesh's size.
// Throws InputError for a triangle index out of range.
Mesh submesh(const Mesh& mesh, const std::vector<uint32_t>& triangles);

// ---------------------------------------------------------------------------------------------
// Grids
// ---------------------------------------------------------------------------------------------
// Voxel (i,j,k) is the closed box [origin + (i,j,k)*voxel_size, origin + (i+1,j+1,k+1)*voxel_size].
struct Grid {
    std::array<double, 3> origin{0, 0, 0};
    double voxel_size = 1.0;
    std::array<int64_t, 3> dims{0, 0, 0};

    uint64_t voxel_count() const {
        return uint64_t(dims[0]) * uint64_t(dims[1]) * uint64_t(dims[2]);
    }
};

// How to fit a grid to a mesh. Defaults: the mesh bounding box with `resolution` voxels along the
// longest axis, cubic voxels, the other axes as many voxels as they need.
struct GridFit {
    int64_t resolution = 256;  // voxels along the longest axis (ignored if voxel_size > 0)
    // resolution^3 grid placed by cubic_anchor: Centre puts the centre of the mesh box at the
    // centre of the cube (cuda_voxelizer's convention), Minimum puts the box minimum at the
    // cube's corner, so the mesh touches the low faces (binvox's: translate = box minimum, scale =
    // longest box side).
    bool cubic = false;
    enum class CubicAnchor { Centre, Minimum } cubic_anchor = CubicAnchor::Centre;
    double voxel_size = 0;    // > 0: use this voxel size instead of resolution
    bool has_origin = false;  // use `origin` instead of the fitted one
    std::array<double, 3> origin{0, 0, 0};
    bool has_dims = false;  // use `dims` instead of the fitted ones
    std::array<int64_t, 3> dims{0, 0, 0};
    int64_t pad = 0;  // empty voxels added on every side
};

// Largest number of voxels along one axis that any grid may have.
constexpr int64_t kMaxGridAxis = int64_t(1) << 20;

// Throws GridError on zero/negative/absurd sizes or a degenerate mesh box.
Grid fit_grid(const Mesh& mesh, const GridFit& fit);
void validate_grid(const Grid& grid);
// The same voxels: equal origin, voxel size and dims.
bool same_grid(const Grid& a, const Grid& b);
// "NXxNYxNZ voxels of SIZE at (X, Y, Z)", for messages.
std::string to_string(const Grid& grid);

// ---------------------------------------------------------------------------------------------
// Sparse voxel results
// ---------------------------------------------------------------------------------------------
namespace detail {
struct SparseVoxelsAccess;
}

// A bit grid stored as cubic bricks of `brick_size`^3 voxels; only bricks with at least one set
// voxel are stored. Inside a brick, voxels are grouped in 4x4x4 blocks, one uint64_t each (bit
// x + 4*(y + 4*z) of the block), blocks ordered x-fastest. Voxels outside the grid are never set.
class SparseVoxels {
  public:
    static constexpr int kBlock = 4;

    SparseVoxels() = default;
    SparseVoxels(const Grid& grid, int brick_size);
    // Copies are deep: a copy's bricks are its own.
    SparseVoxels(const SparseVoxels& other);
    SparseVoxels& operator=(const SparseVoxels& other);
    SparseVoxels(SparseVoxels&&) noexcept = default;
    SparseVoxels& operator=(SparseVoxels&&) noexcept = default;

    const Grid& grid() const { return grid_; }
    int brick_size() const { return brick_size_; }
    int blocks_per_brick_axis() const { return brick_size_ / kBlock; }
    size_t blocks_per_brick() const;
    std::array<int64_t, 3> brick_dims() const;  // bricks along each axis (ceil)

    bool get(int64_t i, int64_t j, int64_t k) const;  // false outside the grid
    void set(int64_t i, int64_t j, int64_t k);        // throws std::out_of_range outside
    uint64_t count() const;                           // number of set voxels
    size_t brick_count() const { return bricks_.size(); }

    // The linear indices bx + nbx*(by + nby*bz) of the stored bricks (those with a set voxel), in
    // increasing order.
    std::vector<uint64_t> brick_indices() const;
    // The blocks_per_brick() words of a stored brick, or nullptr if the brick has no set voxel.
    const uint64_t* brick_blocks(uint64_t brick_index) const;
    // Adds (ORs) a brick's blocks; all-zero bricks are dropped. Throws GridError for a brick
    // index outside the grid.
    void merge_brick(uint64_t brick_index, const uint64_t* blocks);
    // Merges `count` bricks as merge_brick would one after another: brick i is brick_index(i),
    // and fill(i, blocks) writes its blocks_per_brick() words into `blocks` (zeroed). fill runs on
    // several threads at once, so the bricks' storage is allocated and written in parallel (its
    // fresh pages are most of the cost); only putting them in place is serial.
    void merge_bricks(size_t count, const std::function<uint64_t(size_t)>& brick_index,
                      const std::function<void(size_t, uint64_t*)>& fill);

    // Calls f(i, j, k) for every set voxel, brick by brick (order unspecified across bricks).
    void for_each(const std::function<void(int64_t, int64_t, int64_t)>& f) const;

    // Dense occupancy, x fastest: index i + nx*(j + ny*k). Throws GridError if it cannot fit.
    std::vector<uint8_t> to_dense() const;

    // A dense window for streaming writers: for every set voxel (i,j,k) in the box [lo, hi),
    // writes 1 at out[(i-lo[0])*strides[0] + (j-lo[1])*strides[1] + (k-lo[2])*strides[2]].
    // Other bytes are left as they are (zero them first). Costs one lookup per brick the box
    // touches plus one step per set voxel, so slabs of any orientation are cheap.
    void mark_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi,
                  const std::array<int64_t, 3>& strides, uint8_t* out) const;

    // The number of set voxels in the box [lo, hi) (clipped to the grid): a popcount per 4x4x4
    // block of the stored bricks it meets, whatever the box's size.
    uint64_t count_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi) const;
    // Sets every voxel of the box [lo, hi) (clipped to the grid), a 4x4x4 block at a time.
    void set_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& hi);

    // Same grid and same set voxels (brick size may differ).
    bool same_voxels(const SparseVoxels& other) const;

  private:
    friend struct detail::SparseVoxelsAccess;
    uint64_t* writable_brick(uint64_t brick_index);  // the brick's words, made zero if absent

    Grid grid_{};
    int brick_size_ = 0;
    // Each stored brick's blocks_per_brick() words. A pointer shares the ownership of the memory
    // the words lie in: the brick's own, or a run of bricks taken whole (a device batch's results,
    // written in the host's memory, are kept where the device wrote them instead of copied).
    std::unordered_map<uint64_t, std::shared_ptr<uint64_t>> bricks_;
};

// ---------------------------------------------------------------------------------------------
// Voxelization
// ---------------------------------------------------------------------------------------------
// Triangle/box overlap test. In exact arithmetic both give the same voxels; in float they can
// differ only where a voxel touches a triangle to within rounding.
enum class OverlapTest {
    SAT,  // separating axis theorem, 13 axes
    PEF,  // plane test + three projected edge-function tests (Schwarz & Seidel 2010)
};
const char* to_string(OverlapTest test);
OverlapTest overlap_test_from_string(const std::string& name);  // "sat" / "pef"

// What a voxel set means.
enum class VoxelizeMode {
    Surface,  // conservative, 26-separating: every voxel whose closed box touches a triangle
    Thin,     // 6-separating surface (Schwarz & Seidel 2010): thinner, still 6-gap-free
    Solid,    // voxels whose centre is inside the mesh
    Filled,   // Solid united with Surface
};
const char* to_string(VoxelizeMode mode);
VoxelizeMode voxelize_mode_from_string(const std::string& name);

// How Solid decides "inside".
enum class InsideTest {
    Auto,     // Parity for closed meshes (whatever their orientation), Winding otherwise
    Parity,   // crossing parity along voxel columns (Schwarz & Seidel)
    Winding,  // generalized winding number > 0.5 (Jacobson et al. 2013)
};
const char* to_string(InsideTest test);
InsideTest inside_test_from_string(const std::string& name);

// Voxel boxes for faces that lie exactly on voxel faces.
enum class Boundary {
    Closed,    // [i, i+1]: a face on a voxel face marks both voxels (the conservative definition)
    HalfOpen,  // [i, i+1): such a face marks exactly one layer
};
const char* to_string(Boundary boundary);
Boundary boundary_from_string(const std::string& name);

// How a device's voxels come back to the host, batch by batch. Either way the result is the same,
// bit for bit; what differs is the bytes moved.
enum class Download {
    Auto,            // NonEmptyBlocks from a device with memory of its own, else Whole (CPUs)
    Whole,           // every 4^3 block of the batch's bricks, read in place where the device can
    NonEmptyBlocks,  // only the blocks with a voxel set, compacted on the device (12 bytes each)
};
const char* to_string(Download download);
Download download_from_string(const std::string& name);  // "auto", "whole" or "blocks"

struct VoxelizeOptions {
    VoxelizeMode mode = VoxelizeMode::Surface;
    InsideTest inside = InsideTest::Auto;
    Boundary boundary = Boundary::Closed;
    OverlapTest test = OverlapTest::SAT;  // measured faster on most meshes (bench/RESULTS.md)
    int brick_size = 64;                  // voxels per brick edge, a multiple of 4 in [4, 1024]
    // Device memory for brick bits per batch. A device working in the host's memory (a CPU)
    // takes batches of at most 64 MiB whatever this says, unless one brick needs more: its
    // buffers are fresh host pages, and smaller batches reuse them.
    uint64_t device_budget_bytes = 256u << 20;
    uint64_t host_budget_bytes = 0;  // 0: half of physical memory
    Download download = Download::Auto;
    ProgressCallback progress;
    // Compute only these bricks of the whole grid (linear indices bx + nbx*(by + nby*bz) of
    // brick_size bricks, as SparseVoxels::brick_indices gives them; any order). The result holds
    // exactly the voxels of the unrestricted run that lie in them, bit for bit, so runs over
    // disjoint selections can be merged into the whole (e.g. on several machines). Empty: every
    // brick. Surface, Thin and parity Solid do only the selected bricks' work; the winding number
    // does the whole grid's work and keeps the selected bricks (its flood crosses bricks).
    std::vector<uint64_t> bricks;
};

// The bricks that can hold set voxels of a run with these options (a sorted superset of the
// result's bricks), found on the host without a device: for Surface and Thin, the bricks the
// binning gives triangles; for Solid and Filled, every brick meeting the mesh's bounding box grown
// by one voxel. For splitting a run into VoxelizeOptions::bricks selections. Throws like
// voxelize for a bad mesh or grid, and GridError if there are more than 2^31 such bricks.
std::vector<uint64_t> candidate_bricks(const Mesh& mesh, const Grid& grid,
                                       const VoxelizeOptions& options);

// For running one voxelization as several over brick selections (VoxelizeOptions::bricks) on
// machines that each hold only part of the mesh: which triangles each selection needs.
struct SelectionTriangles {
    // The inside test of the whole run: for Solid and Filled, options.inside with Auto resolved on
    // the whole mesh. Give it to the runs on parts of the mesh, whose own Auto could choose
    // differently (a part of a closed mesh is open).
    InsideTest inside = InsideTest::Auto;
    // Every selection needs the whole mesh (the winding number: every triangle counts in every
    // voxel); `triangles` is then empty.
    bool whole_mesh = false;
    // triangles[s]: the ascending indices of the triangles that the run with
    // bricks = selections[s] reads. That run on submesh(mesh, triangles[s]), with the same grid
    // and options and `inside`, gives the same voxels bit for bit; with no triangles it has none.
    std::vector<std::vector<uint32_t>> triangles;
};
// One pass over the triangles' (triangle, brick) pairs, the binning's own: linear in triangles and
// pairs. An empty selection means every brick, as in VoxelizeOptions::bricks. Throws like voxelize
// for a bad mesh, grid or brick index.
SelectionTriangles selection_triangles(const Mesh& mesh, const Grid& grid,
                                       const VoxelizeOptions& options,
                                       const std::vector<std::vector<uint64_t>>& selections);

// Timing breakdown and counts of one run (seconds).
struct VoxelizeStats {
    double seconds_binning = 0, seconds_upload = 0, seconds_kernels = 0, seconds_download = 0;
    uint64_t bytes_downloaded = 0;  // voxel results read back from the device (Download)
    uint64_t triangles_in = 0;      // triangles in the mesh
    uint64_t triangles_used = 0;    // after dropping those outside the grid (after clipping)
    uint64_t brick_pairs = 0;       // (triangle, brick) pairs after binning
    // Work items launched (surface: one per triangle and run of up to 8 4^3 blocks of a brick);
    // for distance fields, the (triangle, 4^3 block) pairs the band's culls examine.
    uint64_t work_items = 0;
    uint64_t bricks_total = 0;        // bricks in the grid
    uint64_t bricks_active = 0;       // bricks with at least one triangle
    uint64_t batches = 0;             // device batches
    uint64_t allocation_retries = 0;  // batches retried smaller after a device allocation failure
    uint64_t voxels_set = 0;
    std::string inside_test;         // Solid/Filled: "parity" or "winding"
    std::string inside_test_reason;  // why (e.g. "forced by options", "mesh is closed")
};

struct DeviceInfo {
    std::string platform, name, vendor, version, driver_version;
    std::string type;  // "CPU", "GPU", "ACCELERATOR", ...
    uint64_t global_memory = 0, max_alloc = 0;
    bool host_unified_memory = false;  // the device's memory is the host's (CPU devices)
    std::string id;                    // "P:D" indices as accepted by Device::open
};

// All OpenCL devices of all platforms. Throws DeviceError if no platform exists.
std::vector<DeviceInfo> list_devices();

namespace detail {
struct DeviceAccess;
}

// One OpenCL device with its context, queue and compiled programs (cached per context and on
// disk). Cheap to move, not copyable.
class Device {
  public:
    // selector: "" (first GPU, else first device), "P:D" indices, or a case-insensitive substring
    // of the platform or device name. A selector that matches nothing is a DeviceError.
    static Device open(const std::string& selector = "");
    ~Device();
    Device(Device&&) noexcept;
    Device& operator=(Device&&) noexcept;

    const DeviceInfo& info() const;

    // Kernels are compiled for a device the first time they are needed and cached on disk
    // (OCLVOX_CACHE_DIR, else $XDG_CACHE_HOME/oclvox or ~/.cache/oclvox); a compile can take tens
    // of seconds on a CPU device. The callback hears of each compile when it starts (finished =
    // false) and when it ends (finished = true, seconds it took); cached loads are not reported.
    struct KernelCompile {
        std::string program;
        bool finished = false;
        double seconds = 0;
    };
    void on_kernel_compile(std::function<void(const KernelCompile&)> callback);

    // Loads (compiling on the first run) the kernels voxelize(..., options) needs, so that call
    // does not wait for them: e.g. on another thread while the mesh loads, as the CLI does.
    // Optional: voxelize loads what is missing.
    void load_kernels(const VoxelizeOptions& options);

    SparseVoxels voxelize(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                          VoxelizeStats* stats = nullptr);

    // The OpenCL objects, reached only by the library's own algorithms (detail::device_impl).
    struct Impl;

  private:
    friend struct detail::DeviceAccess;
    explicit Device(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

// The CPU reference: same triangle preparation, same shared math header, same float arithmetic as
// the kernels, evaluated on the host. Device output must match it bit for bit.
SparseVoxels voxelize_reference(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                                VoxelizeStats* stats = nullptr);

// ---------------------------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------------------------
// Writes by extension: .binvox, .npy (+ .json sidecar), .vox (MagicaVoxel), .obj / .ply (cube
// faces that are exposed). Writes to a temporary file in the same folder, then renames it.
// `progress` counts the fraction of the writing done, out of a fixed total, as SdfOptions's does;
// its last call (done == total) comes before the file takes its name, and false from any call
// throws Cancelled and leaves no file.
void write_voxels(const std::string& path, const SparseVoxels& voxels,
                  const ProgressCallback& progress = {});

// Checks before any work that `path` can be written as an output: its folder exists and a file
// can be created there, and it is neither a directory nor the same file (by file-system identity,
// not by name) as any of `inputs`. Throws OutputError naming `path` and the reason.
void check_output_path(const std::string& path, const std::vector<std::string>& inputs = {});

// Writes `text` to `path` the way every output is written (temporary file, renamed into place).
// Throws OutputError naming `path`.
void write_text_file(const std::string& path, const std::string& text);

// For a program that must stop at once (the CLI on SIGINT or SIGTERM); callable from any thread.
// Removes the temporary files of this process's writes in progress, and makes every write that
// has not been renamed into place yet, or starts later, fail with Cancelled: from this call on,
// no output file of this process appears or is replaced. It cannot be undone.
void abandon_pending_writes();

}  // namespace oclvox

#pragma GCC visibility pop
