// Text output of doubles for the text formats (OBJ).
#pragma once

#include <charconv>
#include <ostream>

namespace oclvox::detail {

// The shortest decimal text that reads back as the same double.
inline void write_shortest_number(std::ostream& out, double value) {
    char text[32];
    const auto result = std::to_chars(text, text + sizeof text, value);
    out.write(text, result.ptr - text);
}

}  // namespace oclvox::detail
