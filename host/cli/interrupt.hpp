// SIGINT (Ctrl-C) and SIGTERM: a stop leaves no output and ends the process within 2 s with
// 128 + the signal's number (130 for SIGINT, 143 for SIGTERM, the shell convention).
#pragma once

#include <string>

namespace oclvox_cli {

// Blocks SIGINT and SIGTERM and starts the thread that waits for them. Call before any other
// thread exists (so every thread inherits the block), once per run.
void start_interrupt_watcher();

// True once a stop signal arrived; progress callbacks return !interrupted() to cancel the run.
bool interrupted();

// Throws oclvox::Cancelled if a stop signal arrived (between phases that report no progress).
void stop_if_interrupted();

// 130 after SIGINT, 143 after SIGTERM; the name of the signal for the message.
int stopped_exit_code();
const char* stop_signal_name();

// A file of the CLI's own (a staged copy of stdin or stdout) that a stop must remove, since the
// watcher ends the process without running destructors. forget_on_stop undoes it.
void remove_on_stop(const std::string& path);
void forget_on_stop(const std::string& path);

}  // namespace oclvox_cli
