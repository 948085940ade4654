#include "pnet/solver/option_field.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace pnet {

namespace {

using Kind = OptionSpec::Kind;

std::string range_text(const OptionSpec& f) {
    const bool bounded = f.hi < kNoBound;
    const auto show = [](double x) {
        nlohmann::json j = x;
        std::string t = j.dump();
        if (t.size() > 2 && t.compare(t.size() - 2, 2, ".0") == 0) t.resize(t.size() - 2);
        return t;
    };
    std::string text;
    if (f.kind == Kind::Integer)
        text = "an integer >= " + show(f.lo);
    else if (bounded)
        text = "a number in " + std::string(f.lo_open ? "(" : "[") + show(f.lo) + ", " + show(f.hi) +
               (f.hi_open ? ")" : "]");
    else if (f.lo_open && f.lo == 0.0)
        text = "a positive number";
    else
        text = std::string("a number ") + (f.lo_open ? "> " : ">= ") + show(f.lo);
    if (f.unit) text += std::string(" (") + f.unit + ")";
    return text;
}

std::string listed(const std::vector<std::string>& words, bool quoted) {
    std::string text;
    for (std::size_t k = 0; k < words.size(); ++k) {
        if (k > 0) text += k + 1 == words.size() ? " or " : ", ";
        text += quoted ? "\"" + words[k] + "\"" : words[k];
    }
    return text;
}

bool in_range(const OptionSpec& f, double x) {
    return std::isfinite(x) && (f.lo_open ? x > f.lo : x >= f.lo) && (f.hi_open ? x < f.hi : x <= f.hi);
}

/// What the option accepts, as a scene's value (quoted choices, "auto") or as the flag's word.
std::string accepted_text(const OptionSpec& f, bool as_flag) {
    switch (f.kind) {
        case Kind::Boolean:
            if (!as_flag) return "true or false";
            return f.choices.empty() ? "no value" : listed(f.choices, false);
        case Kind::Choice:
            return listed(f.choices, !as_flag);
        case Kind::NumberOrAuto:
            return range_text(f) + (as_flag ? " or auto" : " or \"auto\"");
        default:
            return range_text(f);
    }
}

}  // namespace

std::string OptionSpec::expected() const { return accepted_text(*this, false); }

std::string OptionSpec::flag_expected() const { return accepted_text(*this, true); }

bool OptionSpec::accepts(const nlohmann::json& value) const {
    switch (kind) {
        case Kind::Boolean:
            return value.is_boolean();
        case Kind::Choice:
            return value.is_string() &&
                   std::find(choices.begin(), choices.end(), value.get<std::string>()) != choices.end();
        case Kind::Integer:
            return value.is_number_integer() && in_range(*this, value.get<double>());
        case Kind::NumberOrAuto:
            if (value.is_string() && value == "auto") return true;
            [[fallthrough]];
        case Kind::Number:
            return value.is_number() && in_range(*this, value.get<double>());
    }
    return false;
}

std::optional<nlohmann::json> OptionSpec::parse_flag(const std::string& word) const {
    nlohmann::json value;
    switch (kind) {
        case Kind::Boolean:
            if (choices.empty()) return nlohmann::json(true);  // a switch
            if (word == choices[0]) return nlohmann::json(true);
            if (word == choices[1]) return nlohmann::json(false);
            return std::nullopt;
        case Kind::Choice:
            value = word;
            break;
        case Kind::NumberOrAuto:
            if (word == "auto") return nlohmann::json("auto");
            [[fallthrough]];
        case Kind::Number:
        case Kind::Integer: {
            char* end = nullptr;
            const double x = std::strtod(word.c_str(), &end);
            if (word.empty() || end != word.c_str() + word.size()) return std::nullopt;
            if (kind == Kind::Integer) {
                if (x != std::floor(x) || std::abs(x) > 2e9) return std::nullopt;
                value = static_cast<long>(x);
            } else {
                value = x;
            }
            break;
        }
    }
    if (!accepts(value)) return std::nullopt;
    return value;
}

void throw_unknown_option(const std::string& context, const std::string& key, const std::string& known) {
    throw std::invalid_argument(context + ": integrator." + key + ": unknown key (known: " + known + ")");
}

void throw_bad_option(const std::string& context, const std::string& key, const OptionSpec& spec,
                      const nlohmann::json& value) {
    throw std::invalid_argument(context + ": integrator." + key + ": expected " + spec.expected() + ", got " +
                                value.dump());
}

}  // namespace pnet
