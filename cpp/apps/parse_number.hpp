#pragma once
// Command-line numbers, shared by the pnet commands: the whole argument must be one number.
#include <optional>
#include <stdexcept>
#include <string>

namespace pnet::apps {

/// text as a double if all of it is one number (std::stod's syntax: "1e-3", "nan", "inf"),
/// nullopt otherwise (empty, trailing characters, out of range).
inline std::optional<double> parse_number(const std::string& text) {
    std::size_t used = 0;
    double value = 0.0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        return std::nullopt;
    }
    if (used != text.size()) return std::nullopt;
    return value;
}

}  // namespace pnet::apps
