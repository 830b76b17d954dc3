// The signals are taken by a watcher thread with sigwait rather than by a signal handler. They
// stay blocked everywhere else, and a blocked signal is inherited by the processes the OpenCL
// runtime spawns: PoCL runs a linker while it compiles a kernel, and a terminal's Ctrl-C (sent to
// the whole process group) would otherwise kill that linker and make the runtime abort.
#include "interrupt.hpp"

#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <set>
#include <thread>

#include "oclvox/oclvox.hpp"

namespace oclvox_cli {

namespace {

// How long a run has, after the signal, to stop by itself and return its exit code.
constexpr auto kStopGrace = std::chrono::milliseconds(1500);

std::atomic<bool> g_interrupted{false};
std::atomic<int> g_stop_signal{SIGINT};

// Files to remove on a stop. Never destroyed: a signal may arrive while static objects are being
// destroyed at exit.
struct OwnFiles {
    std::mutex lock;
    std::set<std::string> paths;
};
OwnFiles& own_files() {
    static OwnFiles* const files = new OwnFiles;
    return *files;
}

}  // namespace

void start_interrupt_watcher() {
    sigset_t stop;
    sigemptyset(&stop);
    sigaddset(&stop, SIGINT);
    sigaddset(&stop, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop, nullptr);
    std::thread([stop] {
        int signal = 0;
        sigwait(&stop, &signal);
        g_stop_signal = signal;
        g_interrupted = true;
        // From here on no output appears: writes in progress lose their temporary file, later
        // ones fail with Cancelled.
        oclvox::abandon_pending_writes();
        {
            OwnFiles& files = own_files();
            const std::lock_guard<std::mutex> hold(files.lock);
            for (const std::string& path : files.paths) std::remove(path.c_str());
        }
        // Phases that report no progress (loading a huge mesh, one long batch) are ended here,
        // as is everything on a second signal; nothing is left to clean up.
        const auto grace = std::chrono::duration_cast<std::chrono::nanoseconds>(kStopGrace);
        const timespec wait{time_t(grace.count() / 1000000000), long(grace.count() % 1000000000)};
        sigtimedwait(&stop, nullptr, &wait);
        std::_Exit(stopped_exit_code());
    }).detach();
}

bool interrupted() {
    return g_interrupted;
}

void stop_if_interrupted() {
    if (g_interrupted) throw oclvox::Cancelled("cancelled");
}

int stopped_exit_code() {
    return 128 + g_stop_signal;
}

const char* stop_signal_name() {
    return g_stop_signal == SIGTERM ? "SIGTERM" : "SIGINT";
}

void remove_on_stop(const std::string& path) {
    OwnFiles& files = own_files();
    const std::lock_guard<std::mutex> hold(files.lock);
    files.paths.insert(path);
}

void forget_on_stop(const std::string& path) {
    OwnFiles& files = own_files();
    const std::lock_guard<std::mutex> hold(files.lock);
    files.paths.erase(path);
}

}  // namespace oclvox_cli
