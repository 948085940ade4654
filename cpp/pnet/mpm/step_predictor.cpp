#include "pnet/mpm/step_predictor.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pnet {

bool predicts_newton_start(const std::string& newton_start, Method method) {
    return newton_start == "last_step" || (newton_start == "auto" && integrator_info(method).predicts_newton_start);
}

template <int dim>
void StepPredictor<dim>::predict(const IncrementalPotential<dim>& potential, double dt, VecX& v) const {
    if (nodes_.empty()) return;
    const Grid<dim>& grid = potential.grid();
    const VecX& scale = potential.residual_scale();  // 0 on held components
    double heaviest = 0.0;
    for (std::size_t k = 0; k < potential.nodes(); ++k)
        heaviest = std::max(heaviest, grid.node(potential.dof_node(k)).mass);
    for (std::size_t i = 0; i < nodes_.size(); ++i) {
        const int k = potential.node_dof(nodes_[i]);
        if (k < 0) continue;
        bool held = false;
        for (int a = 0; a < dim; ++a) held = held || !(scale[dim * k + a] > 0.0);
        if (held) continue;
        // The lighter of the node's masses then and now: a rate recorded on a light node is faded even
        // where the node has since gained mass.
        const double m = std::min(masses_[i], grid.node(nodes_[i]).mass);
        v.template segment<dim>(dim * k) += (dt * m / (m + kFade * heaviest)) * rates_[i];
    }
}

template <int dim>
void StepPredictor<dim>::record(const IncrementalPotential<dim>& potential, const VecX& v, double dt) {
    const VecX& v_star = potential.v_star();
    const std::size_t nodes = potential.nodes();
    nodes_.resize(nodes);
    rates_.resize(nodes);
    masses_.resize(nodes);
    for (std::size_t k = 0; k < nodes; ++k) {
        nodes_[k] = potential.dof_node(k);
        masses_[k] = potential.grid().node(nodes_[k]).mass;
        rates_[k] = (v.template segment<dim>(dim * k) - v_star.template segment<dim>(dim * k)) / dt;
    }
}

template <int dim>
std::vector<Mat<dim>> StepPredictor<dim>::state() const {
    std::vector<Mat<dim>> state(nodes_.size(), Mat<dim>::Zero());
    for (std::size_t i = 0; i < nodes_.size(); ++i) {
        state[i].col(0) = rates_[i];
        state[i](0, 1) = static_cast<double>(nodes_[i]);
        state[i](1, 1) = masses_[i];
    }
    return state;
}

template <int dim>
void StepPredictor<dim>::restore(const std::vector<Mat<dim>>& state, std::int64_t storage_size,
                                 const std::string& where) {
    std::vector<std::int64_t> nodes;
    std::vector<Vec<dim>> rates;
    std::vector<double> masses;
    for (std::size_t i = 0; i < state.size(); ++i) {
        const double index = state[i](0, 1);
        if (!(index >= 0.0 && index < static_cast<double>(storage_size) && index == std::floor(index)))
            throw std::invalid_argument(where + ": the Newton start's node " + std::to_string(i) + " has grid index " +
                                        std::to_string(index) + ", expected an integer in [0, " +
                                        std::to_string(storage_size) + ")");
        if (!state[i].col(0).allFinite())
            throw std::invalid_argument(where + ": the Newton start's node " + std::to_string(i) +
                                        " has a rate that is not finite");
        if (!(state[i](1, 1) >= 0.0) || !std::isfinite(state[i](1, 1)))
            throw std::invalid_argument(where + ": the Newton start's node " + std::to_string(i) + " has mass " +
                                        std::to_string(state[i](1, 1)) + ", expected a finite number >= 0");
        nodes.push_back(static_cast<std::int64_t>(index));
        rates.push_back(state[i].col(0));
        masses.push_back(state[i](1, 1));
    }
    nodes_.swap(nodes);  // nothing changes on a refused state
    rates_.swap(rates);
    masses_.swap(masses);
}

template class StepPredictor<2>;
template class StepPredictor<3>;

}  // namespace pnet
