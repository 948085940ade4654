#include "pnet/sim/integrator_settings.hpp"

namespace pnet {

namespace {

template <class Part>
void add_fields(std::vector<OptionField<IntegratorSettings>>& out, const std::vector<OptionField<Part>>& fields,
                Part IntegratorSettings::*part) {
    for (const OptionField<Part>& f : fields) out.push_back(f.within(part));
}

}  // namespace

const std::vector<OptionField<IntegratorSettings>>& integrator_option_fields() {
    static const std::vector<OptionField<IntegratorSettings>> fields = [] {
        std::vector<OptionField<IntegratorSettings>> all;
        add_fields(all, implicit_option_fields(), &IntegratorSettings::implicit);
        add_fields(all, mpm_option_fields(), &IntegratorSettings::mpm);
        add_fields(all, fem_option_fields(), &IntegratorSettings::fem);
        add_fields(all, coupling_option_fields(), &IntegratorSettings::coupling);
        return all;
    }();
    return fields;
}

const OptionField<IntegratorSettings>* find_option_field(const std::string& key_or_flag) {
    return find_field(integrator_option_fields(), key_or_flag);
}

IntegratorSettings IntegratorSettings::from_scene(const Scene& scene) {
    IntegratorSettings s;
    s.name = scene.integrator.name;
    s.dt = scene.integrator.dt;
    s.cfl = scene.integrator.cfl;
    s.read_options(scene.integrator.options, scene.file);
    return s;
}

void IntegratorSettings::read_options(const nlohmann::json& block, const std::string& context) {
    pnet::read_options(integrator_option_fields(), *this, block, context);
}

nlohmann::json IntegratorSettings::options_json() const {
    return options_to_json(integrator_option_fields(), *this);
}

}  // namespace pnet
