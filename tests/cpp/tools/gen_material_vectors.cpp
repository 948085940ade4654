// Writes the C++ side of the material cross-check vectors, which pytest
// compares with the Python material library (tests/python/test_cross_check_cpp.py).
//
//   gen_material_vectors --out tests/data/material_vectors_cpp.json
//   gen_material_vectors --check tests/data/material_vectors_cpp.json
//
// --check regenerates the cases and fails if the committed file no longer
// matches this build (so the file cannot silently go stale).
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <random>

#include "support/material_vectors.hpp"
#include "support/random.hpp"

namespace {

using namespace pnet;
using nlohmann::json;

struct Kind {
    std::string label;
    MaterialDescription description;
    std::pair<double, double> hardening_range;
};

std::vector<Kind> kinds() {
    std::vector<Kind> out;
    out.push_back({"sand", material_preset("sand"), {0.0, 0.0}});
    out.push_back({"snow", material_preset("snow"), {-1.0, 0.0}});
    MaterialDescription snow_paper = material_preset("snow");
    snow_paper.name = "snow_paper";
    snow_paper.cam_clay.variant = CamClayVariant::Paper;
    out.push_back({"snow_paper", snow_paper, {-1.0, 0.0}});
    out.push_back({"metal", material_preset("metal"), {0.0, 0.5}});
    out.push_back({"metal_nh", material_preset("metal_nh"), {0.0, 0.5}});
    for (const char* name : {"metal", "metal_nh"}) {
        MaterialDescription m = material_preset(name);
        m.name = std::string(name) + "_no_hardening";
        m.von_mises.hardening_coefficient = 0.0;
        out.push_back({m.name, m, {0.0, 0.5}});
    }
    for (auto model : {ElasticityModel::StvkHencky, ElasticityModel::NeoHookeanSnow, ElasticityModel::NeoHookeanMetal}) {
        MaterialDescription m;
        m.name = "elastic_" + to_string(model);
        m.elasticity = model;
        m.elastic = {2.5e4, 0.35};
        out.push_back({m.name, m, {0.0, 0.0}});
    }
    return out;
}

// Deformation categories: eps ranges of the log singular values.
struct Category {
    const char* name;
    double lo, hi;
    bool reflect;
};
const Category kCategories[] = {
    {"near_identity", -0.005, 0.005, false}, {"moderate", -0.3, 0.3, false},  {"large_stretch", 0.5, 1.0, false},
    {"large_compression", -1.0, -0.5, false}, {"mixed_large", -1.0, 1.0, false}, {"reflected", -0.3, 0.3, true},
};

/// The branch at Sigma must not change under relative perturbations of 1e-6,
/// so that both implementations take the same branch.
template <int dim>
bool branch_is_stable(const Material<dim>& material, const Vec<dim>& Sigma, double h) {
    const ReturnBranch branch = material.return_map(Sigma, h).branch;
    for (int i = 0; i < dim; ++i)
        for (double s : {1.0 - 1e-6, 1.0 + 1e-6}) {
            Vec<dim> perturbed = Sigma;
            perturbed[i] *= s;
            if (material.return_map(perturbed, h).branch != branch) return false;
        }
    return true;
}

template <int dim>
void generate(const Kind& kind, test::Random& rng, json& cases) {
    const Material<dim> material(kind.description);
    std::map<std::pair<std::string, std::string>, int> count;  // (branch, category) -> cases kept
    for (const Category& category : kCategories) {
        for (int attempt = 0; attempt < 400; ++attempt) {
            Vec<dim> eps = rng.template uniform_vec<dim>(category.lo, category.hi);
            Mat<dim> F = rng.template rotation<dim>() * Vec<dim>(eps.array().exp().matrix()).asDiagonal() *
                         rng.template rotation<dim>();
            if (category.reflect) F.col(0) *= -1.0;
            const double h = rng.uniform(kind.hardening_range.first, kind.hardening_range.second);
            const PolarSVD<dim> svd = clamped_svd<dim>(F);
            if (!branch_is_stable<dim>(material, svd.Sigma, h)) continue;
            const std::string branch = to_string(material.return_map(svd.Sigma, h).branch);
            int& n = count[{branch, category.name}];
            if (n >= 2) continue;
            char name[160];
            std::snprintf(name, sizeof name, "%s/%dd/%s/%s/%d", kind.label.c_str(), dim, branch.c_str(), category.name, n);
            ++n;
            cases.push_back({{"name", name},
                             {"dim", dim},
                             {"material", material_to_json(kind.description)},
                             {"F", test::to_json_array(F)},
                             {"hardening", h},
                             {"expect", test::evaluate_case<dim>(kind.description, F, h)}});
        }
    }
}

json generate_all() {
    json cases = json::array();
    test::Random rng(20261121);
    for (const Kind& kind : kinds()) {
        generate<2>(kind, rng, cases);
        generate<3>(kind, rng, cases);
    }
    return {{"format", "plasticitynet-material-vectors"}, {"version", 1}, {"generator", "cpp"}, {"cases", cases}};
}

int check(const std::string& path) {
    std::ifstream in(path);
    if (!in) {
        std::cerr << path << ": cannot open (generate it with gen_material_vectors --out " << path << ")\n";
        return 1;
    }
    json committed;
    try {
        committed = json::parse(in);
    } catch (const std::exception& e) {
        std::cerr << path << ": not valid JSON: " << e.what() << "\n";
        return 1;
    }
    const json fresh = generate_all();
    if (committed.at("cases").size() != fresh.at("cases").size()) {
        std::cerr << path << ": " << committed.at("cases").size() << " cases, this build generates "
                  << fresh.at("cases").size() << "; regenerate with --out\n";
        return 1;
    }
    double worst = 0.0;
    for (size_t i = 0; i < fresh["cases"].size(); ++i) {
        const json& a = fresh["cases"][i];
        const json& b = committed["cases"][i];
        if (a["name"] != b["name"] || a["F"] != b["F"]) {
            std::cerr << path << ": case " << i << " differs in its inputs; regenerate with --out\n";
            return 1;
        }
        const double mu = material_from_json(b["material"]).elastic.mu();
        for (const auto& d : test::compare_expect(a["expect"], b["expect"], mu)) worst = std::max(worst, d.relative);
    }
    std::printf("%s: %zu cases, largest relative difference to this build %.3e\n", path.c_str(),
                fresh["cases"].size(), worst);
    return worst <= 1e-12 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3 || (std::string(argv[1]) != "--out" && std::string(argv[1]) != "--check")) {
        std::cerr << "usage: gen_material_vectors (--out|--check) FILE\n";
        return 2;
    }
    const std::string path = argv[2];
    if (std::string(argv[1]) == "--check") return check(path);
    const json vectors = generate_all();
    const std::string tmp = path + ".tmp";
    {
        std::ofstream out(tmp);
        out << vectors.dump(1) << "\n";
        if (!out) {
            std::cerr << tmp << ": write failed\n";
            return 1;
        }
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) {
        std::cerr << path << ": cannot rename " << tmp << "\n";
        return 1;
    }
    std::printf("wrote %zu cases to %s\n", vectors["cases"].size(), path.c_str());
    return 0;
}
