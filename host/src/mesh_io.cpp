// Loading triangle meshes into one welded Mesh, whatever the format (each reader is in its own
// read_*.cpp), and checking meshes before anything voxelizes them.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <sstream>

#include "file_names.hpp"
#include "mesh_reading.hpp"
#include "oclvox/oclvox.hpp"
#include "position_numbering.hpp"
#include "progress.hpp"

namespace oclvox {

namespace {

using mesh_reading::fail;
using Position = std::array<double, 3>;
using Triangle = std::array<uint32_t, 3>;

std::string position_text(const Position& p) {
    std::ostringstream text;
    text.precision(9);
    text << "(" << p[0] << ", " << p[1] << ", " << p[2] << ")";
    return text.str();
}

// ---------------------------------------------------------------------------------------------
// Welding
// ---------------------------------------------------------------------------------------------

// Merges vertices at equal coordinates and drops those no triangle uses. STL stores three
// corners per facet and a scene's meshes are merged side by side, so this is what gives them a
// shared topology. Positions are unchanged, so the geometry is too. Welded vertices are numbered
// in the order the triangles meet them, corner by corner. The triangles are renumbered in place:
// a copy would fault in as many fresh pages again.
Mesh welded(Mesh raw) {
    // Phase 1: the vertices in the order the triangles first meet them.
    constexpr uint32_t kUnmet = std::numeric_limits<uint32_t>::max();
    std::vector<uint32_t> met_as(raw.positions.size(), kUnmet);  // a vertex's place in `order`
    std::vector<uint32_t> order;
    order.reserve(raw.positions.size());
    for (const auto& triangle : raw.triangles)
        for (const uint32_t v : triangle)
            if (met_as[v] == kUnmet) {
                met_as[v] = uint32_t(order.size());
                order.push_back(v);
            }

    // Phase 2: their positions numbered in that order, equal ones alike.
    detail::NumberedPositions numbered = detail::number_positions(raw.positions, &order);

    // Phase 3: the triangles renumbered, in parallel.
    tbb::parallel_for(size_t(0), raw.triangles.size(), [&](size_t t) {
        for (uint32_t& v : raw.triangles[t]) v = numbered.numbers[met_as[v]];
    });
    Mesh mesh;
    mesh.triangles = std::move(raw.triangles);
    mesh.positions = std::move(numbered.positions);
    return mesh;
}

}  // namespace

void validate_mesh(const Mesh& mesh) {
    if (mesh.triangles.empty()) throw InputError("the mesh has no triangles");
    // Every entry point validates, so this runs several times per run over the whole mesh: fixed
    // chunks in parallel, and the first chunk with a bad triangle names it, as a serial scan would.
    constexpr size_t kChunk = 16384;
    const size_t chunks = (mesh.triangles.size() + kChunk - 1) / kChunk;
    std::vector<size_t> first_bad(chunks, mesh.triangles.size());
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        const size_t end = std::min(mesh.triangles.size(), (c + 1) * kChunk);
        for (size_t t = c * kChunk; t < end; ++t)
            for (const uint32_t v : mesh.triangles[t])
                if (v >= mesh.positions.size() || !std::isfinite(mesh.positions[v][0]) ||
                    !std::isfinite(mesh.positions[v][1]) || !std::isfinite(mesh.positions[v][2])) {
                    first_bad[c] = t;
                    return;
                }
    });
    for (const size_t t : first_bad) {
        if (t == mesh.triangles.size()) continue;
        for (const uint32_t v : mesh.triangles[t]) {
            if (v >= mesh.positions.size())
                throw InputError("triangle " + std::to_string(t) + " refers to vertex " +
                                 std::to_string(v) + ", but the mesh has only " +
                                 std::to_string(mesh.positions.size()) + " vertices");
            const Position& p = mesh.positions[v];
            if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
                throw InputError("vertex " + std::to_string(v) + " " + position_text(p) +
                                 ", used by triangle " + std::to_string(t) +
                                 ", has a coordinate that is not a finite number");
        }
    }
}

Mesh submesh(const Mesh& mesh, const std::vector<uint32_t>& triangles) {
    // Phase 1: the vertices used, ascending, found by sorting rather than by a table the size of
    // the whole mesh.
    std::vector<uint32_t> used;
    used.reserve(3 * triangles.size());
    for (const uint32_t t : triangles) {
        if (t >= mesh.triangles.size())
            throw InputError("triangle index " + std::to_string(t) +
                             " is out of range: the mesh has " +
                             std::to_string(mesh.triangles.size()) + " triangles");
        for (const uint32_t v : mesh.triangles[t]) {
            if (v >= mesh.positions.size())
                throw InputError("triangle " + std::to_string(t) + " refers to vertex " +
                                 std::to_string(v) + ", but the mesh has only " +
                                 std::to_string(mesh.positions.size()) + " vertices");
            used.push_back(v);
        }
    }
    std::sort(used.begin(), used.end());
    used.erase(std::unique(used.begin(), used.end()), used.end());

    // Phase 2: the kept vertices and the triangles renumbered to them.
    Mesh out;
    out.positions.reserve(used.size());
    for (const uint32_t v : used) out.positions.push_back(mesh.positions[v]);
    out.triangles.reserve(triangles.size());
    for (const uint32_t t : triangles) {
        std::array<uint32_t, 3> renumbered;
        for (int i = 0; i < 3; ++i)
            renumbered[i] = uint32_t(
                std::lower_bound(used.begin(), used.end(), mesh.triangles[t][i]) - used.begin());
        out.triangles.push_back(renumbered);
    }
    return out;
}

Mesh load_mesh(const std::string& path, const ProgressCallback& callback) {
    // Phase 1: read the file as it is, with its own vertex numbering, so that problems are
    // reported in the file's terms. As measured on OBJ files (motorBike, buildings), parsing is
    // about four times the triangulation and about twice the weld.
    constexpr const char* kExpected = "expected .obj, .stl, .ply, .off, .gltf, .glb or .3mf";
    detail::ProgressPhases progress(callback, "loading " + path);
    const size_t parse = progress.add(4), triangulate = progress.add(1), weld = progress.add(2);
    const mesh_reading::ParseReport report = progress.reporter(parse);
    const std::string extension = detail::lowercase_extension(path);
    mesh_reading::Polygons polygons;
    if (extension == ".obj")
        polygons = mesh_reading::read_obj(path, report);
    else if (extension == ".stl")
        polygons = mesh_reading::read_stl(path, report);
    else if (extension == ".ply")
        polygons = mesh_reading::read_ply(path, report);
    else if (extension == ".off")
        polygons = mesh_reading::read_off(path, report);
    else if (extension == ".gltf" || extension == ".glb" || extension == ".3mf")
        polygons = mesh_reading::read_scene_assimp(path);
    else if (extension.empty())
        fail(path, std::string("the file name has no extension; ") + kExpected);
    else
        fail(path, "unknown extension '" + extension + "'; " + kExpected);

    // Phase 2: triangulate (checking every index), check, then weld.
    progress.report(triangulate, 0, 1);
    Mesh raw = mesh_reading::triangulated(path, std::move(polygons));
    if (raw.triangles.empty()) fail(path, "the file contains no triangles");
    try {
        validate_mesh(raw);
    } catch (const InputError& error) {
        fail(path, error.what());
    }
    progress.report(weld, 0, 1);
    Mesh mesh = welded(std::move(raw));
    progress.finish();
    return mesh;
}

}  // namespace oclvox
