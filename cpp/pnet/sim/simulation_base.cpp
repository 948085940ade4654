#include "pnet/sim/simulation_base.hpp"

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "pnet/io/sha256.hpp"

namespace pnet {

namespace {

constexpr std::size_t kDigestBytes = 64;  // hexadecimal SHA-256
constexpr std::size_t kNameBytes = 16;    // integrator name, zero-padded
// The last two bytes of the name field: the integrators' naming revision. "n2" since plasticitynet
// evaluates the network on every Newton iteration (2026-11-28); before it, `plasticitynet` named what
// is now `return_map` (the return mapping's stress and consistent tangent), and the bytes were zero.
constexpr char kNamingRevision[2] = {'n', '2'};

}  // namespace

SimulationBase::SimulationBase(const Scene& scene, const IntegratorSettings& settings)
    : scene_(scene), scene_digest_(sha256_hex(scene_to_json(scene).dump())), settings_(settings) {
    if (!(settings.dt >= 0.0) || !std::isfinite(settings.dt))
        throw std::invalid_argument("dt must be >= 0 (0: the CFL step)");
    if (!(settings.cfl > 0.0 && settings.cfl <= 1.0)) throw std::invalid_argument("cfl must be in (0, 1]");
    settings.implicit.check_for(settings.method(), scene.file + ": integrator");
}

void SimulationBase::write_checkpoint_preamble(std::ostream& out, const char (&magic)[8],
                                               const std::vector<std::int64_t>& header,
                                               const std::string& integrator) const {
    out.write(magic, sizeof magic);
    out.write(reinterpret_cast<const char*>(header.data()), std::streamsize(header.size() * sizeof(std::int64_t)));
    out.write(reinterpret_cast<const char*>(&time_), sizeof time_);
    out.write(scene_digest_.data(), kDigestBytes);
    std::string name = integrator;
    if (name.size() > kNameBytes - 3) throw std::logic_error("integrator name too long for a checkpoint: " + name);
    name.resize(kNameBytes, '\0');
    name[kNameBytes - 2] = kNamingRevision[0];
    name[kNameBytes - 1] = kNamingRevision[1];
    out.write(name.data(), kNameBytes);
}

int SimulationBase::read_checkpoint_preamble(std::istream& in, const std::string& path,
                                             const std::vector<const char*>& magics, const std::string& kind,
                                             std::vector<std::int64_t>& header, double& time,
                                             const std::string& integrator) const {
    char magic[8];
    std::string digest(kDigestBytes, '\0'), name(kNameBytes, '\0');
    in.read(magic, sizeof magic);
    in.read(reinterpret_cast<char*>(header.data()), std::streamsize(header.size() * sizeof(std::int64_t)));
    in.read(reinterpret_cast<char*>(&time), sizeof time);
    in.read(digest.data(), kDigestBytes);
    in.read(name.data(), kNameBytes);
    int found = -1;
    for (std::size_t k = 0; in && found < 0 && k < magics.size(); ++k)
        if (std::memcmp(magic, magics[k], sizeof magic) == 0) found = static_cast<int>(k);
    if (found < 0)
        throw std::invalid_argument(path + ": not a PlasticityNet " + (kind.empty() ? "" : kind + " ") + "checkpoint");
    if (digest != scene_digest_)
        throw std::invalid_argument(path + ": written for a different scene (or a changed scene file)");
    const bool revised = name[kNameBytes - 2] == kNamingRevision[0] && name[kNameBytes - 1] == kNamingRevision[1];
    name.resize(name.find('\0') == std::string::npos ? name.size() : name.find('\0'));
    // Before the revision, "plasticitynet" was the classical solver: it resumes under return_map.
    if (!revised && name == to_string(Method::PlasticityNet)) {
        if (integrator == to_string(Method::ReturnMap)) return found;
        throw std::invalid_argument(path + ": written before 2026-11-28 by the integrator then called plasticitynet, "
                                           "which solved with the return mapping's consistent tangent and is now "
                                           "return_map: resume it with the integrator return_map (this run uses " +
                                    integrator + ")");
    }
    if (name != integrator)
        throw std::invalid_argument(path + ": written by the " + name + " integrator, this run uses " + integrator);
    return found;
}

void SimulationBase::restore_clock(const std::string& path, std::int64_t frame, std::int64_t steps, double time) {
    if (frame < 0 || frame > std::numeric_limits<int>::max() || steps < 0 || !std::isfinite(time) || time < 0.0)
        throw std::invalid_argument(path + ": corrupt checkpoint header (frame, step count or time)");
    frame_ = static_cast<int>(frame);
    steps_ = steps;
    time_ = time;
}

}  // namespace pnet
