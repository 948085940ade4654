#pragma once
// What the pnet commands share on their command line: a usage error (the message, the usage text, exit
// status 2), an option's value, and numbers where the whole argument must be one number.
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

/// A path after option argv[i], moving i onto it; UsageError "<option>: empty path" if it is empty.
inline std::string path_value(int argc, char** argv, int& i) {
    std::string path = option_value(argc, argv, i);
    if (path.empty()) throw UsageError(std::string(argv[i - 1]) + ": empty path");
    return path;
}

/// A number after option argv[i] that ok(x) accepts, moving i onto it; UsageError "<option>: expected
/// <expected>, got "<text>"" otherwise.
template <typename Ok>
double number_value(int argc, char** argv, int& i, Ok&& ok, const std::string& expected) {
    const std::string text = option_value(argc, argv, i);
    const std::optional<double> x = parse_number(text);
    if (!x || !ok(*x)) throw UsageError(std::string(argv[i - 1]) + ": expected " + expected + ", got \"" + text + "\"");
    return *x;
}

}  // namespace pnet::apps
