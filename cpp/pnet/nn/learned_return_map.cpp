#include "pnet/nn/learned_return_map.hpp"

#include <cmath>
#include <vector>

#include "pnet/material/constants.hpp"

namespace pnet {

template <int dim>
LearnedReturnMap<dim>::LearnedReturnMap(const ModelFile& model)
    : material_(model.metadata.material), net_(model.weights, 0),
      xi_(model.metadata.material.von_mises.hardening_coefficient),
      metadata_(model.metadata) {
    const ModelMetadata& meta = model.metadata;
    if (meta.kind != ModelKind::ReturnMap)
        throw std::invalid_argument(model.path + ": a model of kind \"" + to_string(meta.kind) +
                                    "\", not a return map");
    if (meta.dim != dim)
        throw std::invalid_argument(model.path + ": a " + std::to_string(meta.dim) + "D return map where a " +
                                    std::to_string(dim) + "D one is needed");
    if (meta.material.plasticity != PlasticityModel::VonMises)
        throw std::invalid_argument(model.path + ": the learned return mapping is for von Mises plasticity, not " +
                                    to_string(meta.material.plasticity));
}

template <int dim>
void LearnedReturnMap<dim>::return_map(const Vec<dim>* Sigma, const double* hardening, std::size_t n,
                                       ReturnResult<dim>* out) const {
    std::vector<double> x(n * (dim + 1)), dgamma(n);
    for (std::size_t p = 0; p < n; ++p) {
        const Vec<dim> Sc = clamp_singular_values<dim>(Sigma[p]);
        for (int i = 0; i < dim; ++i) x[p * (dim + 1) + i] = Sc[i];
        x[p * (dim + 1) + dim] = metadata_.network_hardening(hardening[p]);  // clamped to the trained range
    }
    net_.evaluate(x.data(), n, FusedMlp::Order::Value, dgamma.data());
    for (std::size_t p = 0; p < n; ++p) {
        const Vec<dim> Sc = clamp_singular_values<dim>(Sigma[p]);
        const Vec<dim> eps = Sc.array().log().matrix();
        const Vec<dim> dev = eps.array() - eps.mean();
        const double L = dev.norm();
        ReturnResult<dim>& r = out[p];
        if (!(L > 0.0) || !(material_.yield_function(Sc, hardening[p]) > 0.0)) {
            r = {Sc, hardening[p], ReturnBranch::Elastic};
            continue;
        }
        const double dg = std::min(dgamma[p], L);
        r.Sigma = (eps - (dg / L) * dev).array().exp().matrix();
        r.hardening = hardening[p] + xi_ * dg;
        r.branch = ReturnBranch::Yield;
    }
}

template <int dim>
ReturnResult<dim> LearnedReturnMap<dim>::return_map(const Vec<dim>& Sigma, double hardening) const {
    ReturnResult<dim> result;
    return_map(&Sigma, &hardening, 1, &result);
    return result;
}

template <int dim>
Mat<dim> LearnedReturnMap<dim>::elastoplastic_stress(const Mat<dim>& F, double hardening) const {
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    const ReturnResult<dim> Z = return_map(svd.Sigma, hardening);
    return svd.compose(material_.elasticity().tau(Z.Sigma).cwiseQuotient(svd.Sigma));
}

template class LearnedReturnMap<2>;
template class LearnedReturnMap<3>;

}  // namespace pnet
