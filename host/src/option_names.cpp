// Names of the options' enumerations (overlap test, mode, inside test, boundary, download), for
// command lines, summaries and messages: to_string and the strict parse back.
#include <algorithm>
#include <cctype>

#include "file_names.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox {

const char* to_string(OverlapTest test) {
    return test == OverlapTest::SAT ? "sat" : "pef";
}

OverlapTest overlap_test_from_string(const std::string& name) {
    const std::string n = detail::lowercase(name);
    if (n == "sat") return OverlapTest::SAT;
    if (n == "pef") return OverlapTest::PEF;
    throw GridError("unknown overlap test '" + name + "' (expected sat or pef)");
}

const char* to_string(VoxelizeMode mode) {
    switch (mode) {
        case VoxelizeMode::Surface:
            return "surface";
        case VoxelizeMode::Thin:
            return "thin";
        case VoxelizeMode::Solid:
            return "solid";
        case VoxelizeMode::Filled:
            return "filled";
    }
    return "?";
}

VoxelizeMode voxelize_mode_from_string(const std::string& name) {
    const std::string n = detail::lowercase(name);
    for (VoxelizeMode m :
         {VoxelizeMode::Surface, VoxelizeMode::Thin, VoxelizeMode::Solid, VoxelizeMode::Filled})
        if (n == to_string(m)) return m;
    throw GridError("unknown mode '" + name + "' (expected surface, thin, solid or filled)");
}

const char* to_string(InsideTest test) {
    switch (test) {
        case InsideTest::Auto:
            return "auto";
        case InsideTest::Parity:
            return "parity";
        case InsideTest::Winding:
            return "winding";
    }
    return "?";
}

InsideTest inside_test_from_string(const std::string& name) {
    const std::string n = detail::lowercase(name);
    for (InsideTest t : {InsideTest::Auto, InsideTest::Parity, InsideTest::Winding})
        if (n == to_string(t)) return t;
    throw GridError("unknown inside test '" + name + "' (expected auto, parity or winding)");
}

const char* to_string(Boundary boundary) {
    return boundary == Boundary::Closed ? "closed" : "half-open";
}

Boundary boundary_from_string(const std::string& name) {
    const std::string n = detail::lowercase(name);
    if (n == "closed") return Boundary::Closed;
    if (n == "half-open") return Boundary::HalfOpen;
    throw GridError("unknown boundary rule '" + name + "' (expected closed or half-open)");
}

const char* to_string(Download download) {
    switch (download) {
        case Download::Auto:
            return "auto";
        case Download::Whole:
            return "whole";
        case Download::NonEmptyBlocks:
            return "blocks";
    }
    return "?";
}

Download download_from_string(const std::string& name) {
    const std::string n = detail::lowercase(name);
    for (Download d : {Download::Auto, Download::Whole, Download::NonEmptyBlocks})
        if (n == to_string(d)) return d;
    throw GridError("unknown download '" + name + "' (expected auto, whole or blocks)");
}

}  // namespace oclvox
