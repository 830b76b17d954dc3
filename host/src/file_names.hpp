// File-name helpers shared by every reader and writer that picks a format by extension, and by
// whatever needs a file's folder.
#pragma once

#include <string>

namespace oclvox::detail {

// ASCII lower case: A-Z become a-z and every other byte stays, whatever the process's locale
// (std::tolower follows it: a Turkish one lowers 'I' to a dotless i, and it is a library call per
// character, a tenth of reading an ASCII STL).
inline char ascii_lower(char c) {
    return c >= 'A' && c <= 'Z' ? char(c - 'A' + 'a') : c;
}

// ASCII lower case, for case-insensitive names (extensions, option values, device names).
inline std::string lowercase(std::string text) {
    for (char& c : text) c = ascii_lower(c);
    return text;
}

// The extension of the file name, lower-cased, with its dot; "" if the name has none. Dots in
// folder names do not count (either slash separates folders).
inline std::string lowercase_extension(const std::string& path) {
    const size_t slash = path.find_last_of("/\\");
    const size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    return lowercase(path.substr(dot));
}

// The name without its folders (what a sidecar records to point at its data file).
inline std::string file_name_of(const std::string& path) {
    const size_t slash = path.find_last_of("/\\");
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

// The folder a path's file lives in, as the user would name it: "." for a bare name.
inline std::string folder_of(const std::string& path) {
    const size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

}  // namespace oclvox::detail
