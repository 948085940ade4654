#pragma once
// One option of an integrator, declared once beside the struct that holds it: its key in a scene's
// integrator block and in Python's solver= dict, its `pnet simulate` flag, what it accepts, a line of
// help, and where its value lives. Each layer keeps the table of its own options (Newton's and the
// network's in solver/implicit_options, the advection limit in mpm/mpm_options, the kinematic stages
// in fem/fem_options, the coupled solve in coupling/coupling_options); sim/integrator_settings joins
// them into the one table the scene reader, the flags, --help and Python read (docs/architecture.md,
// "Adding an option").
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace pnet {

/// What an option accepts and how it is shown; no storage (OptionField<Options> adds it).
struct OptionSpec {
    enum class Kind { Number, NumberOrAuto, Integer, Boolean, Choice };
    const char* key = nullptr;
    const char* flag = nullptr;  // "--newton-tol"; nullptr: scenes and Python only
    Kind kind = Kind::Number;
    const char* help = nullptr;
    // Number, NumberOrAuto, Integer: the accepted range; lo_open / hi_open exclude the bound itself.
    double lo = 0.0, hi = 1e300;
    bool lo_open = false, hi_open = false;
    const char* unit = nullptr;        // in the expected text: "a positive number (m/s)"
    std::vector<std::string> choices;  // Choice: the values; Boolean: the flag's words for true and false
                                       // (empty: the flag is a switch that sets true)

    /// What a scene may give: "a number in [0, 1)", "\"jacobi\", ... or \"multigrid\"", "true or false".
    std::string expected() const;
    /// What the flag takes: "a number in [0, 1)", "jacobi, ... or multigrid", "yes or no".
    std::string flag_expected() const;
    bool accepts(const nlohmann::json& value) const;
    /// A word of the command line as this key's value; nullopt when it is none of the accepted ones.
    std::optional<nlohmann::json> parse_flag(const std::string& word) const;
    /// Whether the flag takes no value (a boolean that only sets true).
    bool is_switch() const { return kind == Kind::Boolean && choices.empty(); }
};

/// An option of the struct `Options`: its spec, and how its value is read from and written to one.
/// NumberOrAuto stores "auto" as -1.
template <class Options>
struct OptionField : OptionSpec {
    std::function<nlohmann::json(const Options&)> get;
    std::function<void(Options&, const nlohmann::json&)> set;  // the value accepts() has checked

    /// The same option as one of `Whole`'s, whose member `part` is an Options.
    template <class Whole>
    OptionField<Whole> within(Options Whole::*part) const {
        OptionField<Whole> f;
        static_cast<OptionSpec&>(f) = *this;
        f.get = [get = get, part](const Whole& w) { return get(w.*part); };
        f.set = [set = set, part](Whole& w, const nlohmann::json& v) { set(w.*part, v); };
        return f;
    }
};

inline constexpr double kNoBound = 1e300;  // no upper bound

/// A number in [lo, hi] (or the open interval where lo_open / hi_open); `unit` is shown in messages.
template <class O>
OptionField<O> number_option(const char* key, const char* flag, double lo, bool lo_open, double hi, bool hi_open,
                             double O::*member, const char* help, const char* unit = nullptr) {
    OptionField<O> f;
    f.key = key, f.flag = flag, f.kind = OptionSpec::Kind::Number, f.help = help;
    f.lo = lo, f.lo_open = lo_open, f.hi = hi, f.hi_open = hi_open, f.unit = unit;
    f.get = [member](const O& o) { return nlohmann::json(o.*member); };
    f.set = [member](O& o, const nlohmann::json& v) { o.*member = v.get<double>(); };
    return f;
}
/// A number as number_option(), or "auto" (stored as -1: the integrator's or material's own value).
template <class O>
OptionField<O> number_or_auto_option(const char* key, const char* flag, double lo, bool lo_open, double hi,
                                     bool hi_open, double O::*member, const char* help) {
    OptionField<O> f = number_option(key, flag, lo, lo_open, hi, hi_open, member, help);
    f.kind = OptionSpec::Kind::NumberOrAuto;
    f.get = [member](const O& o) { return o.*member >= 0.0 ? nlohmann::json(o.*member) : nlohmann::json("auto"); };
    f.set = [member](O& o, const nlohmann::json& v) { o.*member = v.is_string() ? -1.0 : v.get<double>(); };
    return f;
}
template <class O>
OptionField<O> integer_option(const char* key, const char* flag, int lo, int hi, int O::*member, const char* help) {
    OptionField<O> f;
    f.key = key, f.flag = flag, f.kind = OptionSpec::Kind::Integer, f.help = help;
    f.lo = lo, f.hi = hi;
    f.get = [member](const O& o) { return nlohmann::json(o.*member); };
    f.set = [member](O& o, const nlohmann::json& v) { o.*member = v.get<int>(); };
    return f;
}
/// true or false; the flag takes `words` (for true, for false), or nothing when `words` is empty.
template <class O>
OptionField<O> boolean_option(const char* key, const char* flag, bool O::*member, const char* help,
                              std::vector<std::string> words = {"yes", "no"}) {
    OptionField<O> f;
    f.key = key, f.flag = flag, f.kind = OptionSpec::Kind::Boolean, f.help = help;
    f.choices = std::move(words);
    f.get = [member](const O& o) { return nlohmann::json(o.*member); };
    f.set = [member](O& o, const nlohmann::json& v) { o.*member = v.get<bool>(); };
    return f;
}
template <class O>
OptionField<O> choice_option(const char* key, const char* flag, std::vector<std::string> values, std::string O::*member,
                             const char* help) {
    OptionField<O> f;
    f.key = key, f.flag = flag, f.kind = OptionSpec::Kind::Choice, f.help = help;
    f.choices = std::move(values);
    f.get = [member](const O& o) { return nlohmann::json(o.*member); };
    f.set = [member](O& o, const nlohmann::json& v) { o.*member = v.get<std::string>(); };
    return f;
}

/// The field of `fields` with this key or flag; nullptr if none.
template <class O>
const OptionField<O>* find_field(const std::vector<OptionField<O>>& fields, const std::string& key_or_flag) {
    for (const OptionField<O>& f : fields)
        if (key_or_flag == f.key || (f.flag && key_or_flag == f.flag)) return &f;
    return nullptr;
}

/// Throws std::invalid_argument "<context>: integrator.<key>: unknown key (known: <known>)".
[[noreturn]] void throw_unknown_option(const std::string& context, const std::string& key, const std::string& known);
/// Throws std::invalid_argument "<context>: integrator.<key>: expected <...>, got <value>".
[[noreturn]] void throw_bad_option(const std::string& context, const std::string& key, const OptionSpec& spec,
                                   const nlohmann::json& value);

/// Sets `options` from the keys of an integrator block; "name", "dt" and "cfl" (the scene's) are
/// skipped. A wrong type or range, or a key none of `fields` declares, throws std::invalid_argument
/// naming `context`, the key and the problem (the known keys for an unknown one).
template <class O>
void read_options(const std::vector<OptionField<O>>& fields, O& options, const nlohmann::json& block,
                  const std::string& context) {
    if (!block.is_object()) return;
    for (const auto& [key, value] : block.items()) {
        if (key == "name" || key == "dt" || key == "cfl") continue;
        const OptionField<O>* f = find_field(fields, key);
        if (!f || key != f->key) {
            std::string known = "name, dt, cfl";
            for (const OptionField<O>& field : fields) known += std::string(", ") + field.key;
            throw_unknown_option(context, key, known);
        }
        if (!f->accepts(value)) throw_bad_option(context, key, *f, value);
        f->set(options, value);
    }
}

/// {key: value} of every field of `fields` in `options`.
template <class O>
nlohmann::json options_to_json(const std::vector<OptionField<O>>& fields, const O& options) {
    nlohmann::json j = nlohmann::json::object();
    for (const OptionField<O>& f : fields) j[f.key] = f.get(options);
    return j;
}

}  // namespace pnet
