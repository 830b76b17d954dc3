// The OpenVDB headers the library uses, declared with default visibility. The library compiles
// with hidden visibility, but OpenVDB's templates keep registries in static members (of grid,
// tree and metadata types) that must be the very objects libopenvdb uses: instantiated hidden
// here they would be private copies, and openvdb::initialize() crashes on them.
#pragma once

#pragma GCC visibility push(default)
#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/ValueAccessor.h>
#pragma GCC visibility pop
