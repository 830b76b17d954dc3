// oclvox: the command-line tool. `oclvox devices` lists the OpenCL devices; `oclvox voxelize`
// turns a mesh file into a voxel file; `oclvox sdf` writes a signed distance field, `oclvox csg`
// combines two meshes (or fields) and `oclvox mesh` meshes a field's iso-surface; `oclvox batch`
// (and `voxelize --workers/--scheduler`) hand over to the Python package's Dask back end. Each
// command lives in its own file (command_*.cpp); the option groups they share are in options.cpp,
// and every run reports through report.cpp. All the work is the library's.
//
// Exit codes: 0 success, 1 error (the message names the problem), 2 command-line usage error,
// 130 stopped by SIGINT (Ctrl-C), 143 stopped by SIGTERM.
#include <CLI/CLI.hpp>
#include <cstdlib>
#include <iostream>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#if defined(__linux__)
#include <sched.h>
#include <unistd.h>
#endif
#include <new>
#include <vector>

#include "commands.hpp"
#include "interrupt.hpp"
#include "oclvox/oclvox.hpp"
#include "options.hpp"
#include "suggest.hpp"

// CMake passes the project version; the fallback only labels builds made outside CMake.
#ifndef OCLVOX_VERSION
#define OCLVOX_VERSION "unknown"
#endif

namespace oclvox_cli {
const char* const kExitCodesText =
    "Exit codes: 0 success, 1 error, 2 usage error, 130 SIGINT (Ctrl-C), 143 SIGTERM.\n";
}  // namespace oclvox_cli

// A run allocates and frees buffers of megabytes phase after phase (the file's text, the parsed
// parts, the prepared triangles, the batches). glibc maps each of over 128 KiB (more once one is
// freed) afresh and unmaps it when freed, so the next phase faults in new pages again, at about
// 2.4 us a page on a VM. Kept in the heap (below 32 MiB, the largest this setting allows) and not
// trimmed below 512 MiB, they are reused: 20% fewer page faults and 10-20 ms less a run at 1024^3
// (buildings, motorBike, stanford-bunny), for a peak RSS 2-15% higher. The library leaves the
// process's allocator to its host; this program is its own host.
static void keep_freed_memory_for_reuse() {
#if defined(__GLIBC__)
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 512 << 20);
#endif
}

// PoCL's worker threads, left to the scheduler, often share one core for part of a kernel: through
// PoCL on 2 cores the kernel phase of buildings at 1024^3 took 31 ms in some runs and 50 ms in
// most, for the same work. Pinned (POCL_AFFINITY=1: worker i on CPU i) it took 31 ms every time,
// and the kernel phases of the other shared meshes were as fast or faster with a smaller spread.
// PoCL pins to CPUs 0..n-1 whatever CPU set the process was given, so this asks for it only where
// the process may run on every online CPU, and never over the user's own choice.
static void pin_pocl_threads_where_allowed() {
#if defined(__linux__)
    if (std::getenv("POCL_AFFINITY")) return;
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    const long online = sysconf(_SC_NPROCESSORS_ONLN);
    if (sched_getaffinity(0, sizeof(allowed), &allowed) != 0 || online < 1 || online > CPU_SETSIZE)
        return;
    for (long cpu = 0; cpu < online; ++cpu)
        if (!CPU_ISSET(cpu, &allowed)) return;
    setenv("POCL_AFFINITY", "1", 0);
#endif
}

int main(int argc, char** argv) {
    keep_freed_memory_for_reuse();
    pin_pocl_threads_where_allowed();  // before any thread starts, and before PoCL reads it
    using namespace oclvox_cli;
    CLI::App app{"oclvox: conservative mesh voxelization on OpenCL devices", "oclvox"};
    app.set_version_flag("--version", std::string("oclvox ") + OCLVOX_VERSION);
    app.require_subcommand(1);
    const std::vector<Command> commands{add_devices_command(app), add_voxelize_command(app),
                                        add_sdf_command(app),     add_csg_command(app),
                                        add_mesh_command(app),    add_batch_command(app)};

    // Phase 1: the command line. Help and --version end here with exit code 0; a mistyped
    // command or option is named with the closest valid one.
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e);
        const std::string typo = typo_message(app, argc, argv);
        std::cerr << "oclvox: error: " << (typo.empty() ? e.what() : typo)
                  << "\nRun with --help for more information.\n";
        return kExitUsage;
    }

    // Phase 2: the command. Library errors already name the file, option or device at fault.
    try {
        for (const Command& command : commands)
            if (command.app->parsed()) return command.run();
        return kExitUsage;  // require_subcommand(1) makes this unreachable
    } catch (const UsageError& e) {
        std::cerr << "oclvox: error: " << e.what() << "\nRun with --help for more information.\n";
        return kExitUsage;
    } catch (const oclvox::Cancelled&) {
        std::cerr << "oclvox: cancelled by " << stop_signal_name() << "\n";
        return stopped_exit_code();
    } catch (const std::bad_alloc&) {
        std::cerr << "oclvox: error: out of memory (try a lower --resolution)\n";
        return kExitError;
    } catch (const std::exception& e) {
        std::cerr << "oclvox: error: " << e.what() << "\n";
        return kExitError;
    }
}
