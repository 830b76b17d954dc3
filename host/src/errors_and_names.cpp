// Names of enumerations, for options and summaries.
#include "oclvox/oclvox.hpp"

namespace oclvox {

const char* to_string(OverlapTest test) { return test == OverlapTest::SAT ? "sat" : "pef"; }

OverlapTest overlap_test_from_string(const std::string& name) {
    if (name == "sat" || name == "SAT") return OverlapTest::SAT;
    if (name == "pef" || name == "PEF") return OverlapTest::PEF;
    throw GridError("unknown overlap test '" + name + "' (expected sat or pef)");
}

}  // namespace oclvox
