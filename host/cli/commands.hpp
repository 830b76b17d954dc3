// The subcommands. Each add_*_command registers its options on `app` and returns the subcommand
// with the function that runs it after a successful parse (its option values live with it).
#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace oclvox_cli {

struct Command {
    CLI::App* app;
    std::function<int()> run;
};

// "Exit codes: ..." for every command's help footer.
extern const char* const kExitCodesText;

Command add_devices_command(CLI::App& app);
Command add_voxelize_command(CLI::App& app);
Command add_sdf_command(CLI::App& app);
Command add_csg_command(CLI::App& app);
Command add_mesh_command(CLI::App& app);
Command add_batch_command(CLI::App& app);

}  // namespace oclvox_cli
