#include "pnet/metrics/run_comparison.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>

#include "pnet/io/ply.hpp"
#include "pnet/metrics/deposit_shape.hpp"
#include "pnet/metrics/iou.hpp"

namespace pnet {
namespace {

namespace fs = std::filesystem;

// Two grids of this many nodes (8 bytes each) are held at once: 2^27 nodes is 2 GiB in all.
constexpr double kMaxGridNodes = double(1 << 27);

/// The last component of a directory path, ignoring a trailing separator ("runs/sand/" -> "sand").
std::string base_name(const std::string& dir) {
    fs::path p = fs::absolute(fs::path(dir)).lexically_normal();
    if (p.filename().empty()) p = p.parent_path();
    return p.filename().string();
}

double positive_number(const nlohmann::json& j, const std::string& file, const char* key) {
    if (!j.contains(key)) throw RunInputError(file + ": missing \"" + key + "\"");
    const nlohmann::json& v = j.at(key);
    if (!v.is_number() || !std::isfinite(v.get<double>()) || !(v.get<double>() > 0.0))
        throw RunInputError(file + ": " + key + ": expected a positive number, got " + v.dump());
    return v.get<double>();
}

std::array<double, 3> point(const nlohmann::json& j, const std::string& file, const char* key, int dim) {
    if (!j.contains(key)) throw RunInputError(file + ": missing \"" + key + "\"");
    const nlohmann::json& v = j.at(key);
    bool ok = v.is_array() && v.size() == static_cast<std::size_t>(dim);
    std::array<double, 3> p{};
    for (int d = 0; ok && d < dim; ++d) {
        ok = v[d].is_number() && std::isfinite(v[d].get<double>());
        if (ok) p[d] = v[d].get<double>();
    }
    if (!ok)
        throw RunInputError(file + ": " + key + ": expected " + std::to_string(dim) + " finite numbers, got " +
                            v.dump());
    return p;
}

bool same(double a, double b, double scale) {
    return std::abs(a - b) <= 1e-9 * scale;
}

/// Errors, naming B's run.json and the field, if B cannot be compared frame by frame with A.
void check_consistent(const RunInfo& a, const RunInfo& b) {
    auto differs = [&](const std::string& field, const std::string& va, const std::string& vb) {
        return RunInputError(b.json_file + ": " + field + " is " + vb + " but " + a.json_file + " has " + va +
                             "; the runs cannot be compared");
    };
    auto list = [](const std::array<double, 3>& p, int dim) {
        return nlohmann::json(std::vector<double>(p.begin(), p.begin() + dim)).dump();
    };
    if (a.dim != b.dim) throw differs("dim", std::to_string(a.dim), std::to_string(b.dim));
    auto kind = [](const RunInfo& r) {
        return std::string(r.particles && r.meshes ? "particles and meshes" : r.meshes ? "meshes" : "particles");
    };
    if (a.particles != b.particles || a.meshes != b.meshes) throw differs("what the frames hold", kind(a), kind(b));
    for (int d = 0; d < a.dim; ++d) {
        const double extent = a.domain_max[d] - a.domain_min[d];
        if (!same(a.domain_min[d], b.domain_min[d], extent))
            throw differs("domain_min", list(a.domain_min, a.dim), list(b.domain_min, b.dim));
        if (!same(a.domain_max[d], b.domain_max[d], extent))
            throw differs("domain_max", list(a.domain_max, a.dim), list(b.domain_max, b.dim));
    }
    // Frames are paired by number, so they must be the same times.
    if (!same(a.frame_dt, b.frame_dt, a.frame_dt))
        throw differs("frame_dt", nlohmann::json(a.frame_dt).dump(), nlohmann::json(b.frame_dt).dump());
}

/// One frame's particles, with some mass.
PlyParticles read_frame(const std::string& path, const RunInfo& run) {
    PlyParticles p;
    try {
        // read_particles_ply's errors start with the path; requiring run.json's dim checks the file against it.
        p = read_particles_ply(path, run.dim);
    } catch (const std::runtime_error& e) {
        throw RunInputError(e.what());
    }
    double total = 0.0;
    for (double m : p.mass) total += m;
    if (!(total > 0.0))
        throw RunInputError(path + ": no particle mass to compare (" + std::to_string(p.size()) + " particles)");
    if (!run.run_id.empty() && p.run_id != run.run_id)
        throw RunInputError(path + ": not written by the run in " + run.json_file + " (" +
                            (p.run_id.empty() ? std::string("no run id") : "run_id " + p.run_id) + ", run.json has " +
                            run.run_id + "); the folder mixes runs: simulate again with --overwrite");
    return p;
}

/// One frame's particle mass on the comparison grid; adds the particles put at the domain's edge to clamped.
GridField rasterize_frame(const PlyParticles& p, const std::string& path, const RunInfo& run, double dx,
                          std::size_t& clamped) {
    std::size_t c = 0;
    GridField g;
    try {
        g = rasterize_mass(run.dim, p.position, p.mass, run.domain_min.data(), run.domain_max.data(), dx, &c);
    } catch (const std::invalid_argument& e) {
        throw RunInputError(path + ": " + e.what());
    }
    clamped += c;
    return g;
}

}  // namespace

RunInfo read_run_info(const std::string& dir) {
    RunInfo run;
    run.dir = dir;
    run.name = base_name(dir);
    std::error_code ec;
    if (!fs::is_directory(dir, ec))
        throw RunInputError(dir + (fs::exists(dir, ec) ? ": not a directory" : ": no such directory"));
    run.json_file = (fs::path(dir) / "run.json").string();
    std::ifstream in(run.json_file);
    if (!in) throw RunInputError(run.json_file + ": cannot read (is " + dir + " the output of pnet simulate?)");
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
        throw RunInputError(run.json_file + ": not valid JSON: " + e.what());
    }
    if (!j.is_object()) throw RunInputError(run.json_file + ": expected a JSON object");
    if (!j.contains("dim")) throw RunInputError(run.json_file + ": missing \"dim\"");
    const nlohmann::json& dim = j.at("dim");
    if (!dim.is_number_integer() || (dim.get<int>() != 2 && dim.get<int>() != 3))
        throw RunInputError(run.json_file + ": dim: expected 2 or 3, got " + dim.dump());
    run.dim = dim.get<int>();
    run.domain_min = point(j, run.json_file, "domain_min", run.dim);
    run.domain_max = point(j, run.json_file, "domain_max", run.dim);
    for (int d = 0; d < run.dim; ++d)
        if (!(run.domain_max[d] > run.domain_min[d]))
            throw RunInputError(run.json_file + ": domain_max: must exceed domain_min on every axis, got " +
                                j.at("domain_max").dump() + " and " + j.at("domain_min").dump());
    // The region the run's pictures show (runs written before it existed: the domain).
    run.view_min = j.contains("view_min") ? point(j, run.json_file, "view_min", run.dim) : run.domain_min;
    run.view_max = j.contains("view_max") ? point(j, run.json_file, "view_max", run.dim) : run.domain_max;
    for (int d = 0; d < run.dim; ++d)
        if (!(run.view_max[d] > run.view_min[d]))
            throw RunInputError(run.json_file + ": view_max: must exceed view_min on every axis, got " +
                                j.at("view_max").dump() + " and " + j.at("view_min").dump());
    // A run with meshes says how many elements it has; a FEM run has no particles, and no grid.
    run.meshes = j.contains("elements");
    run.particles = !run.meshes || j.contains("particles");
    if (run.particles) run.dx = positive_number(j, run.json_file, "dx");
    run.frame_dt = positive_number(j, run.json_file, "frame_dt");
    if (run.meshes) {
        if (j.contains("mesh_first_node")) {  // [0, end of mesh 0, ...]: mesh 0 is the body compared
            const nlohmann::json& first = j.at("mesh_first_node");
            if (!first.is_array() || first.size() < 2 || !first[1].is_number_integer() || first[1].get<long>() <= 0)
                throw RunInputError(run.json_file + ": mesh_first_node: expected [0, n1, ...] with n1 > 0, got " +
                                    first.dump());
            run.body_nodes = first[1].get<std::size_t>();
        }
        if (j.contains("bbox_diagonal")) run.body_size = positive_number(j, run.json_file, "bbox_diagonal");
    }
    if (j.contains("run_id")) {
        if (!j.at("run_id").is_string())
            throw RunInputError(run.json_file + ": run_id: expected a string, got " + j.at("run_id").dump());
        run.run_id = j.at("run_id").get<std::string>();
    }

    // frame_NNNNN.ply: at least 5 digits (%05d); temporary files of an atomic write (".tmp.<pid>") do not match.
    static const std::regex frame_name(R"(frame_(\d{5,9})(_mesh)?\.ply)");
    for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
        std::smatch m;
        const std::string name = e.path().filename().string();
        if (!std::regex_match(name, m, frame_name)) continue;
        const bool mesh_file = m[2].matched || !run.particles;  // FEM: frame_NNNNN.ply holds the meshes
        (mesh_file ? run.mesh_frames : run.frames)[std::stoi(m[1].str())] = e.path().string();
    }
    if (ec) throw RunInputError(dir + ": cannot list the directory: " + ec.message());
    return run;
}

RunPair pair_runs(const std::string& dir_a, const std::string& dir_b, double dx) {
    RunPair pair;
    pair.a = read_run_info(dir_a);
    pair.b = read_run_info(dir_b);
    const RunInfo& a = pair.a;
    const RunInfo& b = pair.b;
    check_consistent(a, b);
    if (a.particles) {
        pair.dx = dx > 0.0 ? dx : a.dx;
        double nodes = 1.0;
        for (int d = 0; d < a.dim; ++d) nodes *= std::ceil((a.domain_max[d] - a.domain_min[d]) / pair.dx) + 1.0;
        if (nodes > kMaxGridNodes)
            throw RunInputError("dx = " + nlohmann::json(pair.dx).dump() + " gives a grid of " +
                                nlohmann::json(nodes).dump() + " nodes; choose a coarser --dx");
    }
    // The frames compared: those of the particles, or of the meshes of a FEM run (a coupled run has both).
    const auto& frames_a = a.particles ? a.frames : a.mesh_frames;
    const auto& frames_b = b.particles ? b.frames : b.mesh_frames;
    for (const auto& [frame, path] : frames_a) (frames_b.count(frame) ? pair.common : pair.only_a).push_back(frame);
    for (const auto& [frame, path] : frames_b)
        if (!frames_a.count(frame)) pair.only_b.push_back(frame);
    if (pair.common.empty())
        throw RunInputError("no frame_NNNNN.ply present in both " + a.dir + " (" +
                            (frames_a.empty() ? "none" : frame_ranges(pair.only_a)) + ") and " + b.dir + " (" +
                            (frames_b.empty() ? "none" : frame_ranges(pair.only_b)) + ")");
    return pair;
}

RunComparison compare_runs(const RunPair& pair, const std::function<void(std::size_t, std::size_t)>& progress) {
    const RunInfo& a = pair.a;
    const RunInfo& b = pair.b;
    if (!a.particles)
        throw RunInputError(a.json_file + ": the run has no particles (a FEM run: compare its meshes, compare_meshes)");
    RunComparison c;
    c.dir_a = a.dir;
    c.dir_b = b.dir;
    c.name_a = a.name;
    c.name_b = b.name;
    c.dim = a.dim;
    c.dx = pair.dx;
    c.only_a = pair.only_a;
    c.only_b = pair.only_b;
    c.frames.reserve(pair.common.size());
    for (std::size_t k = 0; k < pair.common.size(); ++k) {
        const int frame = pair.common[k];
        const std::string& path_a = a.frames.at(frame);
        const std::string& path_b = b.frames.at(frame);
        const PlyParticles pa = read_frame(path_a, a), pb = read_frame(path_b, b);
        auto compare = [&](double dx, std::size_t& clamped_a, std::size_t& clamped_b) {
            const GridField ga = rasterize_frame(pa, path_a, a, dx, clamped_a);
            const GridField gb = rasterize_frame(pb, path_b, b, dx, clamped_b);
            try {
                return iou(ga, gb);
            } catch (const std::invalid_argument& e) {
                throw RunInputError(path_a + " vs " + path_b + ": " + e.what());
            }
        };
        const IouResult r = compare(pair.dx, c.clamped_a, c.clamped_b);
        std::size_t unused_a = 0, unused_b = 0;  // the same particles as at dx
        const IouResult coarse = compare(kCoarseFactor * pair.dx, unused_a, unused_b);
        const DepositShape sa = deposit_shape(a.dim, pa.position, pa.mass), sb = deposit_shape(b.dim, pb.position, pb.mass);
        FrameIou f;
        f.frame = frame;
        f.time = frame * a.frame_dt;
        f.soft = r.soft;
        f.binary = r.binary;
        f.plasticinelab = r.plasticinelab;
        f.soft_coarse = coarse.soft;
        f.spread_a = sa.spread;
        f.spread_b = sb.spread;
        f.height_a = sa.height;
        f.height_b = sb.height;
        c.frames.push_back(f);
        if (progress) progress(k + 1, pair.common.size());
    }
    return c;
}

RunComparison compare_runs(const std::string& dir_a, const std::string& dir_b, double dx,
                           const std::function<void(std::size_t, std::size_t)>& progress) {
    return compare_runs(pair_runs(dir_a, dir_b, dx), progress);
}

std::string frame_ranges(const std::vector<int>& frames) {
    std::string s;
    for (std::size_t i = 0; i < frames.size();) {
        std::size_t j = i;
        while (j + 1 < frames.size() && frames[j + 1] == frames[j] + 1) ++j;
        if (!s.empty()) s += ", ";
        s += std::to_string(frames[i]);
        if (j > i) s += "-" + std::to_string(frames[j]);
        i = j + 1;
    }
    return s;
}

}  // namespace pnet
