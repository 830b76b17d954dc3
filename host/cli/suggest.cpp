#include "suggest.hpp"

#include <algorithm>

namespace oclvox_cli {

size_t edit_distance(const std::string& a, const std::string& b) {
    // d[i][j]: distance between the first i characters of a and the first j of b.
    std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
    for (size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
    for (size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
    for (size_t i = 1; i <= a.size(); ++i)
        for (size_t j = 1; j <= b.size(); ++j) {
            const size_t substitution = d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1);
            d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, substitution});
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
                d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
        }
    return d[a.size()][b.size()];
}

std::string closest(const std::string& typed, const std::vector<std::string>& candidates) {
    const size_t limit = std::clamp<size_t>(typed.size() / 3, 1, 3);
    std::string best;
    size_t best_distance = limit + 1;
    for (const std::string& candidate : candidates) {
        const size_t distance = edit_distance(typed, candidate);
        if (distance < best_distance) {
            best = candidate;
            best_distance = distance;
        }
    }
    return best;
}

namespace {

// Every long and short name of the command's options, with dashes ("--resolution", "-r").
std::vector<std::string> option_names(const CLI::App& command) {
    std::vector<std::string> names;
    for (const CLI::Option* option : command.get_options()) {
        for (const std::string& name : option->get_lnames()) names.push_back("--" + name);
        for (const std::string& name : option->get_snames()) names.push_back("-" + name);
    }
    return names;
}

}  // namespace

std::string typo_message(const CLI::App& app, int argc, const char* const* argv) {
    // Phase 1: the subcommand, the first argument that is not an option of the tool itself.
    const CLI::App* command = nullptr;
    int first = 1;
    std::vector<std::string> commands;
    for (const CLI::App* sub : app.get_subcommands({})) commands.push_back(sub->get_name());
    for (; first < argc; ++first) {
        const std::string word = argv[first];
        if (word.empty() || word[0] == '-') continue;
        for (const CLI::App* sub : app.get_subcommands({}))
            if (sub->get_name() == word) command = sub;
        if (command) break;
        const std::string suggestion = closest(word, commands);
        return "unknown command '" + word + "'" +
               (suggestion.empty() ? "" : "; did you mean '" + suggestion + "'?") + " (commands: " +
               [&] {
                   std::string list;
                   for (const std::string& c : commands) list += (list.empty() ? "" : ", ") + c;
                   return list;
               }() +
               ")";
    }
    if (!command) return "";

    // Phase 2: options after the subcommand that it does not have ("--name=value" counts by its
    // name; "-" alone is stdin or stdout, and everything after "--" is positional).
    const std::vector<std::string> names = option_names(*command);
    for (int i = first + 1; i < argc; ++i) {
        std::string word = argv[i];
        if (word == "--") break;
        if (word.size() < 2 || word[0] != '-') continue;
        if (word[1] != '-') {
            // Short options may carry their value ("-r32") or be negative numbers ("-5").
            if (std::isdigit(static_cast<unsigned char>(word[1]))) continue;
            word = word.substr(0, 2);
        }
        word = word.substr(0, word.find('='));
        if (std::find(names.begin(), names.end(), word) != names.end()) continue;
        const std::string suggestion = closest(word, names);
        return "unknown option '" + word + "' for '" + command->get_name() + "'" +
               (suggestion.empty() ? "" : "; did you mean '" + suggestion + "'?");
    }
    return "";
}

}  // namespace oclvox_cli
