// --preview FILE.png: three orthographic max-projections of a result (along x, y and z, side by
// side) with a scale bar, so a user can see a result without another tool.
#pragma once

#include <string>

#include "oclvox/field.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox_cli {

// A pixel is lit where any voxel on its ray is set (voxels) or inside, value < iso (fields).
// Panels: along x (y right, z up), along y (x right, z up), along z (x right, y up). Grids up to
// 256 voxels are scaled up by a whole factor; larger ones take the maximum over square blocks of
// a whole number of voxels, so no panel is wider than 512 pixels. The layout (panel rectangles,
// scale, bar length in mesh units) is stored in the PNG's "oclvox-layout" text chunk as JSON.
// Written through libpng and the atomic writer; throws OutputError naming `path`.
void write_preview(const std::string& path, const oclvox::SparseVoxels& voxels);
void write_preview(const std::string& path, const oclvox::ScalarField& field, float iso);
// The same image of a sparse field, without a dense copy: its inside voxels outside the stored
// leaves, its leaves' samples below iso.
void write_preview(const std::string& path, const oclvox::SparseField& field, float iso);

}  // namespace oclvox_cli
