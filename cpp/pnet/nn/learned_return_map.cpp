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
    // Elastic states (no yield) return unchanged: the network runs on the yielding ones only, which
    // in a crushed frame are the few elements of its hinges.
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
    std::vector<char> yields(n);
#pragma omp parallel for schedule(static) if (count >= 256)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        const Vec<dim> Sc = clamp_singular_values<dim>(Sigma[p]);
        const Vec<dim> eps = Sc.array().log().matrix();
        yields[p] = (eps.array() - eps.mean()).matrix().norm() > 0.0 && material_.yield_function(Sc, hardening[p]) > 0.0;
        out[p] = {Sc, hardening[p], ReturnBranch::Elastic};
    }
    std::vector<std::size_t> yielding;
    for (std::size_t p = 0; p < n; ++p)
        if (yields[p]) yielding.push_back(p);
    if (yielding.empty()) return;
    const std::size_t m = yielding.size();
    std::vector<double> x(m * (dim + 1)), dgamma(m);
    for (std::size_t k = 0; k < m; ++k) {
        const std::size_t p = yielding[k];
        for (int i = 0; i < dim; ++i) x[k * (dim + 1) + i] = out[p].Sigma[i];
        x[k * (dim + 1) + dim] = metadata_.network_hardening(hardening[p]);  // clamped to the trained range
    }
    net_.evaluate(x.data(), m, FusedMlp::Order::Value, dgamma.data());
    for (std::size_t k = 0; k < m; ++k) {
        ReturnResult<dim>& r = out[yielding[k]];
        const Vec<dim> eps = r.Sigma.array().log().matrix();
        const Vec<dim> dev = eps.array() - eps.mean();
        const double dg = std::min(dgamma[k], dev.norm());
        r.Sigma = (eps - (dg / dev.norm()) * dev).array().exp().matrix();
        r.hardening += xi_ * dg;
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

template <int dim>
void LearnedReturnMap<dim>::elastoplastic_stress(const Mat<dim>* F, const double* hardening, std::size_t n,
                                                 Mat<dim>* P) const {
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
    std::vector<PolarSVD<dim>> svd(n);
    std::vector<Vec<dim>> Sigma(n);
#pragma omp parallel for schedule(static) if (count >= 256)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        svd[p] = clamped_svd<dim>(F[p]);
        Sigma[p] = svd[p].Sigma;
    }
    std::vector<ReturnResult<dim>> Z(n);
    return_map(Sigma.data(), hardening, n, Z.data());
#pragma omp parallel for schedule(static) if (count >= 256)
    for (std::ptrdiff_t p = 0; p < count; ++p)
        P[p] = svd[p].compose(material_.elasticity().tau(Z[p].Sigma).cwiseQuotient(svd[p].Sigma));
}

template class LearnedReturnMap<2>;
template class LearnedReturnMap<3>;

}  // namespace pnet
