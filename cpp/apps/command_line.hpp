#pragma once
// What the pnet commands share on their command line: a usage error (the message, the usage text, exit
// status 2), an option's value, and numbers where the whole argument must be one number.
#include <optional>
#include <stdexcept>
#include <string>

namespace pnet::apps {

/// A command line the command cannot run: printed with its usage, exit status 2.
class UsageError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

/// The value after option argv[i] ("--out DIR"), moving i onto it; UsageError "<option> needs a value" at
/// the end of the line.
inline std::string option_value(int argc, char** argv, int& i) {
    if (i + 1 >= argc) throw UsageError(std::string(argv[i]) + " needs a value");
    return argv[++i];
}

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
