// "Did you mean ...?" for mistyped subcommands and options.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace oclvox_cli {

// Optimal string alignment distance: insertions, deletions, substitutions and transpositions of
// neighbours each cost 1 (so "resolutoin" is one step from "resolution").
size_t edit_distance(const std::string& a, const std::string& b);

// The candidate closest to `typed`, if it is close enough to be a plausible typo (distance at
// most a third of its length, at least 1, at most 3); "" otherwise.
std::string closest(const std::string& typed, const std::vector<std::string>& candidates);

// After a failed parse: a message for the first argument that names no subcommand or no option of
// the command given, with the closest valid name; "" when the failure is of another kind.
std::string typo_message(const CLI::App& app, int argc, const char* const* argv);

}  // namespace oclvox_cli
