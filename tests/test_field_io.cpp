// Reading .npy fields and occupancies under hostile input, and the output-path checks that run
// before any work. Every hostile file here is written byte by byte by the test, and every
// failure must be an InputError / OutputError naming the file: no other exception, no large
// allocation before the problem is found.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <variant>

#include "atomic_file.hpp"
#include "oclvox/sdf.hpp"
#include "test_support.hpp"

namespace oclvox {
namespace {

namespace fs = std::filesystem;

// A fresh folder per test, removed afterwards.
class FieldIo : public ::testing::Test {
  protected:
    void SetUp() override {
        folder_ = fs::path(::testing::TempDir()) /
                  ("oclvox_field_io_" + std::to_string(getpid()) + "_" +
                   ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(folder_);
        fs::create_directories(folder_);
    }
    void TearDown() override { fs::remove_all(folder_); }

    std::string path(const std::string& name) const { return (folder_ / name).string(); }

    std::vector<std::string> entries() const {
        std::vector<std::string> names;
        for (const auto& e : fs::directory_iterator(folder_))
            names.push_back(e.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    }

    fs::path folder_;
};

// A version 1.0 .npy header for `dict`, padded as numpy pads it.
std::string npy_header(std::string dict) {
    dict += std::string((64 - (10 + dict.size() + 1) % 64) % 64, ' ') + "\n";
    std::string bytes("\x93NUMPY\x01\x00", 8);
    bytes += char(dict.size() & 0xff);
    bytes += char(dict.size() >> 8);
    return bytes + dict;
}

void write_bytes(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary) << bytes;
}

const char* kSidecar = R"({"origin": [1, 2, 3], "voxel_size": 0.5})";

// read_npy must throw InputError (and nothing else) whose message names `must_name` and
// contains `reason`.
void expect_input_error(const std::string& path, const std::string& must_name,
                        const std::string& reason) {
    try {
        read_npy(path);
        ADD_FAILURE() << path << " was read without error";
    } catch (const InputError& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find(must_name), std::string::npos) << message;
        EXPECT_NE(message.find(reason), std::string::npos) << message;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "not an InputError: " << typeid(e).name() << ": " << e.what();
    }
}

// Peak resident memory of this process so far, in MiB.
long peak_rss_mib() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return usage.ru_maxrss / 1024;
}

TEST_F(FieldIo, HostileShapesAreInputErrorsNamingTheFile) {
    struct Case {
        const char* dict;
        const char* reason;
    };
    const Case cases[] = {
        // 20 digits: std::stoll used to throw std::out_of_range.
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (12345678901234567890, 2, 2), }",
         "exceeds the maximum"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2097152, 2, 2), }",
         "exceeds the maximum"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, 0, 2), }", "empty axis"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, -3, 2), }", "whole number"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3.0, 2), }", "','"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2), }", "3-D"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2, 2, 2), }", "3-D"},
        {"{'descr': '<i4', 'fortran_order': True, 'shape': (2, 2, 2), }", "dtype"},
        {"{'descr': '>f4', 'fortran_order': True, 'shape': (2, 2, 2), }", "big-endian"},
        {"{'descr': '<f4', 'fortran_order': Maybe, 'shape': (2, 2, 2), }", "fortran_order"},
        {"{'descr': '<f4', 'descr': '<f4', 'fortran_order': True, 'shape': (2, 2, 2), }", "twice"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2, 2), 'x': 1}", "unexpected key"},
        {"{'descr': '<f4', 'shape': (2, 2, 2), }", "lacks"},
        {"{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2, 2), } junk", "after"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.dict);
        const std::string file = path("bad.npy");
        write_bytes(file, npy_header(c.dict) + std::string(32, '\0'));
        write_bytes(file + ".json", kSidecar);
        expect_input_error(file, file, c.reason);
    }
}

TEST_F(FieldIo, DataLengthIsCheckedAgainstTheFileBeforeAllocating) {
    // 128 bytes claiming 1024^3 float32 (4 GiB): found short before anything is allocated.
    const std::string file = path("huge.npy");
    const std::string header =
        npy_header("{'descr': '<f4', 'fortran_order': True, 'shape': (1024, 1024, 1024), }");
    write_bytes(file, header + std::string(128 - header.size(), '\0'));
    write_bytes(file + ".json", kSidecar);
    const long before = peak_rss_mib();
    expect_input_error(file, file, "needs 4294967296 bytes of data but the file holds");
    EXPECT_LT(peak_rss_mib() - before, 64) << "MiB allocated before the error";

    // One byte too many or too few is as wrong as four gigabytes.
    const std::string small =
        npy_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }");
    write_bytes(file, small + std::string(2 * 3 * 4 * 4 + 1, '\0'));
    expect_input_error(file, file, "needs 96 bytes of data but the file holds 97");
    write_bytes(file, small + std::string(2 * 3 * 4 * 4 - 1, '\0'));
    expect_input_error(file, file, "needs 96 bytes of data but the file holds 95");
    write_bytes(file, small.substr(0, 30));
    expect_input_error(file, file, "truncated header");
}

TEST_F(FieldIo, DataBeyondTheMemoryBudgetIsRefusedBeforeAllocating) {
    // A sparse file really holding 8 TiB of float32 (no machine has 16 TiB of memory).
    const std::string file = path("sparse.npy");
    write_bytes(file, npy_header("{'descr': '<f4', 'fortran_order': True, 'shape': (1048576, "
                                 "1048576, 2), }"));
    write_bytes(file + ".json", kSidecar);
    std::error_code error;
    fs::resize_file(file, fs::file_size(file) + (uint64_t(1) << 43), error);
    if (error) GTEST_SKIP() << "this file system cannot hold an 8 TiB sparse file: " << error;
    const long before = peak_rss_mib();
    expect_input_error(file, file, "over the memory budget");
    EXPECT_LT(peak_rss_mib() - before, 64) << "MiB allocated before the error";
}

TEST_F(FieldIo, HostileSidecarsAreInputErrorsNamingTheSidecar) {
    const std::string file = path("f.npy");
    write_bytes(file, npy_header("{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3, 4), }") +
                          std::string(2 * 3 * 4 * 4, '\0'));
    struct Case {
        const char* json;
        const char* reason;
    };
    const Case cases[] = {
        {R"({"origin": [1, 2, 3], "voxel_size": NaN})", "not JSON"},
        {R"({"origin": [1, 2, 3], "voxel_size": 1e999})", "not JSON"},
        {R"({"origin": [1, 2, 3], "voxel_size": "0.5"})", "'voxel_size' is not a number"},
        {R"({"origin": [1, 2, 3], "voxel_size": -0.5})", "positive finite"},
        {R"({"origin": [1, 2, 3], "voxel_size": 0})", "positive finite"},
        {R"({"origin": [1, "2", 3], "voxel_size": 0.5})", "'origin' holds a value"},
        {R"({"origin": [1, 2], "voxel_size": 0.5})", "'origin' is not a list of 3"},
        {R"({"voxel_size": 0.5})", "'origin' is missing"},
        {R"({"origin": [1, 2, 3], "voxel_size": 0.5, "dims": [-2, 3, 4]})", "disagree"},
        {R"({"origin": [1, 2, 3], "voxel_size": 0.5, "dims": [4, 3, 2]})", "disagree"},
        {R"({"origin": [1, 2, 3], "voxel_size": 0.5, "dims": [2.0, 3, 4]})", "whole number"},
        {R"([1, 2, 3])", "not a JSON object"},
        {R"({"origin": [1, 2, 3], "voxel_size": 0.5)", "not JSON"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.json);
        write_bytes(file + ".json", c.json);
        expect_input_error(file, file + ".json", c.reason);
    }
    fs::remove(file + ".json");
    expect_input_error(file, file + ".json", "missing");
    write_bytes(file + ".json", R"({"origin": [1, 2, 3], "voxel_size": 0.5, "dims": [2, 3, 4]})");
    EXPECT_NO_THROW(read_field(file));
}

// The occupancy .npy write_voxels writes reads back as the same voxels on the same grid.
TEST_F(FieldIo, OccupancyWrittenByWriteVoxelsReadsBackExactly) {
    Grid grid;
    grid.origin = {-1.5, 0.25, 7};
    grid.voxel_size = 0.125;
    grid.dims = {9, 5, 70};  // more than one brick along z
    SparseVoxels voxels(grid, 8);
    const int64_t set[][3] = {{0, 0, 0}, {8, 4, 69}, {3, 1, 64}, {5, 2, 10}};
    for (const auto& v : set) voxels.set(v[0], v[1], v[2]);
    const std::string file = path("occupancy.npy");
    write_voxels(file, voxels);

    const std::variant<ScalarField, SparseVoxels> back = read_npy(file);
    ASSERT_TRUE(std::holds_alternative<SparseVoxels>(back));
    const SparseVoxels& read = std::get<SparseVoxels>(back);
    EXPECT_EQ(read.grid().origin, grid.origin);
    EXPECT_EQ(read.grid().voxel_size, grid.voxel_size);
    EXPECT_EQ(read.grid().dims, grid.dims);
    EXPECT_EQ(read.count(), 4u);
    for (const auto& v : set) EXPECT_TRUE(read.get(v[0], v[1], v[2]));

    // read_field wants float samples and says what the file holds instead.
    try {
        read_field(file);
        ADD_FAILURE() << "read_field accepted an occupancy";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("occupancy"), std::string::npos) << e.what();
    }
}

TEST_F(FieldIo, COrderOccupancyIsTransposedAndChecked) {
    // numpy's default C order (z fastest) bool array of shape (2, 3, 4) with arr[1, 2, 3] set.
    const std::string file = path("c_order.npy");
    std::string data(2 * 3 * 4, '\0');
    data[3 + 4 * (2 + 3 * 1)] = 1;
    write_bytes(
        file, npy_header("{'descr': '|b1', 'fortran_order': False, 'shape': (2, 3, 4), }") + data);
    write_bytes(file + ".json", kSidecar);
    const SparseVoxels voxels = std::get<SparseVoxels>(read_npy(file));
    EXPECT_EQ(voxels.count(), 1u);
    EXPECT_TRUE(voxels.get(1, 2, 3));

    data[5] = 2;
    write_bytes(
        file, npy_header("{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3, 4), }") + data);
    expect_input_error(file, file, "neither 0 nor 1");
}

// Layers read one at a time are the samples the file holds, hand-written in both orders and both
// float widths: value(i, j, k) = i + 10 j + 100 k at x-fastest index i + 2 (j + 3 k) in Fortran
// order, at C index k + 4 (j + 3 i) in C order.
TEST_F(FieldIo, LayersReadOneAtATimeAreTheFilesSamplesInEitherOrder) {
    auto value = [](int i, int j, int k) { return float(i + 10 * j + 100 * k); };
    for (const bool fortran : {true, false})
        for (const bool doubles : {false, true}) {
            SCOPED_TRACE(std::string(fortran ? "Fortran" : "C") + (doubles ? " f8" : " f4"));
            std::string data(24 * (doubles ? 8 : 4), '\0');
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 3; ++j)
                    for (int i = 0; i < 2; ++i) {
                        const size_t at =
                            fortran ? size_t(i + 2 * (j + 3 * k)) : size_t(k + 4 * (j + 3 * i));
                        if (doubles) {
                            const double v = value(i, j, k);
                            std::memcpy(&data[at * 8], &v, 8);
                        } else {
                            const float v = value(i, j, k);
                            std::memcpy(&data[at * 4], &v, 4);
                        }
                    }
            const std::string file = path("layers.npy");
            write_bytes(file, npy_header(std::string("{'descr': '<f") + (doubles ? "8" : "4") +
                                         "', 'fortran_order': " + (fortran ? "True" : "False") +
                                         ", 'shape': (2, 3, 4), }") +
                                  data);
            write_bytes(file + ".json", kSidecar);
            EXPECT_TRUE(npy_holds_field(file));
            FieldLayerReader reader(file);
            EXPECT_EQ(reader.grid().dims, (std::array<int64_t, 3>{2, 3, 4}));
            EXPECT_EQ(reader.grid().origin, (std::array<double, 3>{1, 2, 3}));
            for (int k = 0; k < 4; ++k) {
                float layer[6];
                reader.read_layer(layer);
                for (int j = 0; j < 3; ++j)
                    for (int i = 0; i < 2; ++i) EXPECT_EQ(layer[i + 2 * j], value(i, j, k));
            }
            float extra[6];
            EXPECT_THROW(reader.read_layer(extra), InputError);
        }

    // A file cut short after it was opened is named when a layer it no longer holds is read (64 KiB
    // of samples, beyond what the stream buffered on opening); an occupancy is not a field.
    const std::string file = path("cut.npy");
    const std::string header =
        npy_header("{'descr': '<f4', 'fortran_order': True, 'shape': (64, 64, 4), }");
    write_bytes(file, header + std::string(64 * 64 * 4 * 4, '\0'));
    write_bytes(file + ".json", kSidecar);
    FieldLayerReader reader(file);
    fs::resize_file(file, header.size() + 64 * 64 * 4 + 100);  // the first layer and a little
    std::vector<float> layer(64 * 64);
    reader.read_layer(layer.data());
    try {
        reader.read_layer(layer.data());
        ADD_FAILURE() << "a cut file was read";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    }
    write_bytes(file, npy_header("{'descr': '|u1', 'fortran_order': True, 'shape': (2, 3, 4), }") +
                          std::string(24, '\0'));
    EXPECT_FALSE(npy_holds_field(file));
    EXPECT_THROW(FieldLayerReader{file}, InputError);
    EXPECT_THROW(FieldLayerReader{path("missing.npy")}, InputError);
}

// A C-order file larger than the host memory budget is read in slabs of a quarter of the budget,
// the file once per slab: within 1 MiB a layer of 70 x 48 samples makes slabs of 16 layers, so 90
// layers take six passes, the last a partial slab (and the 70 planes of constant x are read 16 at a
// time, the last 6). Every layer is the samples hand-written at C
// index k + nz (j + ny i), value(i, j, k) = i + 100 j + 10000 k, in both float widths.
TEST_F(FieldIo, COrderFieldOverTheBudgetIsReadInSlabsLayerForLayer) {
    const int nx = 70, ny = 48, nz = 90;
    auto value = [](int i, int j, int k) { return float(i + 100 * j + 10000 * k); };
    for (const bool doubles : {false, true}) {
        SCOPED_TRACE(doubles ? "f8" : "f4");
        const size_t item = doubles ? 8 : 4;
        std::string data(size_t(nx) * ny * nz * item, '\0');
        for (int i = 0; i < nx; ++i)
            for (int j = 0; j < ny; ++j)
                for (int k = 0; k < nz; ++k) {
                    const size_t at = size_t(k + nz * (j + ny * i)) * item;
                    if (doubles) {
                        const double v = value(i, j, k);
                        std::memcpy(&data[at], &v, 8);
                    } else {
                        const float v = value(i, j, k);
                        std::memcpy(&data[at], &v, 4);
                    }
                }
        const std::string file = path("c_order_slabs.npy");
        write_bytes(file, npy_header(std::string("{'descr': '<f") + (doubles ? "8" : "4") +
                                     "', 'fortran_order': False, 'shape': (70, 48, 90), }") +
                              data);
        write_bytes(file + ".json", kSidecar);
        test::ScopedBudget budget("1");
        EXPECT_THROW(read_field(file), InputError);  // whole, it is over the budget
        FieldLayerReader reader(file);
        std::vector<float> layer(size_t(nx) * ny);
        for (int k = 0; k < nz; ++k) {
            reader.read_layer(layer.data());
            int wrong = 0;
            for (int j = 0; j < ny; ++j)
                for (int i = 0; i < nx; ++i) wrong += layer[size_t(i + nx * j)] != value(i, j, k);
            EXPECT_EQ(wrong, 0) << "layer " << k;
        }
        EXPECT_THROW(reader.read_layer(layer.data()), InputError);
    }
}

TEST_F(FieldIo, OutputPathIsCheckedBeforeWork) {
    auto expect_refused = [](const std::string& output, const std::vector<std::string>& inputs,
                             const std::string& reason) {
        try {
            check_output_path(output, inputs);
            ADD_FAILURE() << output << " was accepted";
        } catch (const OutputError& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find("'" + output + "'"), std::string::npos) << message;
            EXPECT_NE(message.find(reason), std::string::npos) << message;
        }
    };
    fs::create_directories(path("a_dir.obj"));
    expect_refused(path("a_dir.obj"), {}, "is a directory");
    expect_refused(path("missing/out.obj"), {}, "does not exist");
    expect_refused("/proc/oclvox_out.obj", {}, "cannot be written");

    // The same file under other names: a ./ path, a symbolic link, a hard link.
    write_bytes(path("in.obj"), "v 0 0 0\n");
    fs::create_symlink(path("in.obj"), path("link.obj"));
    fs::create_hard_link(path("in.obj"), path("hard.obj"));
    const std::string dotted = (folder_ / "." / "in.obj").string();
    expect_refused(dotted, {path("in.obj")}, "is the input file");
    expect_refused(path("link.obj"), {path("in.obj")}, "is the input file");
    expect_refused(path("hard.obj"), {path("in.obj")}, "is the input file");

    // A writable folder passes and the check leaves nothing behind.
    EXPECT_NO_THROW(check_output_path(path("new.obj"), {path("in.obj")}));
    EXPECT_NO_THROW(check_output_path(path("in.obj"), {path("other.obj")}));  // overwriting
    EXPECT_EQ(entries(), (std::vector<std::string>{"a_dir.obj", "hard.obj", "in.obj", "link.obj"}));
}

// The distance to a sphere of radius 5 voxels on a 20^3 grid: a field with a band.
ScalarField sphere_field() {
    ScalarField field;
    field.grid.dims = {20, 20, 20};
    field.values.resize(field.grid.voxel_count());
    for (int64_t k = 0; k < 20; ++k)
        for (int64_t j = 0; j < 20; ++j)
            for (int64_t i = 0; i < 20; ++i)
                field.values[size_t(i + 20 * (j + 20 * k))] =
                    float(std::hypot(i - 9.5, j - 9.5, k - 9.5) - 5.0);
    return field;
}

// write_field's progress: monotone, ending at total before the file takes its name; false from
// the callback (first call or last) is Cancelled with nothing left in the folder.
TEST_F(FieldIo, WriteProgressEndsBeforeTheFileAppearsAndCancelLeavesNothing) {
    const ScalarField field = sphere_field();
    for (const char* name : {"f.npy", "f.vdb"}) {
        SCOPED_TRACE(name);
        std::vector<std::pair<uint64_t, uint64_t>> calls;
        bool file_before_last = true;
        write_field(path(name), field, 3.0, [&](uint64_t done, uint64_t total) {
            calls.push_back({done, total});
            if (done == total) file_before_last = fs::exists(path(name));
            return true;
        });
        ASSERT_FALSE(calls.empty());
        EXPECT_EQ(calls.back().first, calls.back().second);
        EXPECT_FALSE(file_before_last);
        for (size_t i = 1; i < calls.size(); ++i) EXPECT_LE(calls[i - 1].first, calls[i].first);
        EXPECT_TRUE(fs::exists(path(name)));
    }
    const std::vector<std::string> written = entries();
    for (const char* name : {"g.npy", "g.vdb"})
        for (const bool at_end : {false, true}) {
            SCOPED_TRACE(std::string(name) + (at_end ? " at the end" : " at once"));
            EXPECT_THROW(write_field(path(name), field, 3.0,
                                     [&](uint64_t done, uint64_t total) {
                                         return at_end ? done != total : false;
                                     }),
                         Cancelled);
            EXPECT_EQ(entries(), written);
        }
    EXPECT_EQ(std::get<ScalarField>(read_npy(path("f.npy"))).values, field.values);
}

TEST_F(FieldIo, AtomicWriterErrorsNameTheTargetNotTheTemporaryFile) {
    auto expect_named = [](const std::string& target) {
        try {
            detail::write_file_atomically(target, [](std::ostream& out) { out << "text"; });
            ADD_FAILURE() << target << " was written";
        } catch (const OutputError& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find(target), std::string::npos) << message;
            EXPECT_EQ(message.find(".tmp-"), std::string::npos) << message;
        }
    };
    fs::create_directories(path("a_dir.json"));
    expect_named(path("a_dir.json"));        // the rename fails
    expect_named(path("missing/out.json"));  // the temporary file cannot be created
    EXPECT_EQ(entries(), std::vector<std::string>{"a_dir.json"});
}

}  // namespace
}  // namespace oclvox
