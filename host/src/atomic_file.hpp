// Output files are written to a temporary file beside the target and renamed into place, so an
// interrupted run never leaves a half-written file under the final name. check_output_path
// (public, in oclvox.hpp) is implemented beside this writer because it probes exactly what the
// writer will need: a temporary file in the target's folder and a rename over the target.
#pragma once

#include <fstream>
#include <functional>
#include <string>

namespace oclvox::detail {

// Calls write(stream) on a temporary file in the folder of `path`, flushes and closes it, checks
// for errors, then renames it to `path`. On any failure (including an exception from write) the
// temporary file is removed and OutputError is thrown naming `path` (never the temporary file)
// and the reason; a Cancelled from write passes through as it is.
void write_file_atomically(const std::string& path,
                           const std::function<void(std::ostream&)>& write);

}  // namespace oclvox::detail
