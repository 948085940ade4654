#include "pnet/contact/barrier_form.hpp"

namespace pnet {

template <int dim>
void MeshVertices<dim>::positions(const VecX& v, std::vector<Vec<dim>>& x) const {
    if (!x_start_) {  // before the first step
        x.clear();
        return;
    }
    const std::vector<Vec<dim>>& x_start = *x_start_;
    x.resize(x_start.size());
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = x_start[i] + dt_ * v.template segment<dim>(dim * i);
}

template <int dim>
void MeshVertices<dim>::motion(const VecX& d, std::vector<Vec<dim>>& dx) const {
    dx.resize(x_start_->size());
    for (std::size_t i = 0; i < dx.size(); ++i) dx[i] = dt_ * d.template segment<dim>(dim * i);
}

template <int dim>
void BarrierForm<dim>::begin_step() {
    terms_.clear();
    this->hessians_.clear();
    gradient_pairs_ = 0;
    ccd_ = CcdCount{};
}

template <int dim>
double BarrierForm<dim>::value(const VecX& v) {
    this->vertices_.positions(v, x_);
    return contact_.value(x_);
}

template <int dim>
double BarrierForm<dim>::add_gradient(const VecX& v, VecX& g) {
    const ContactVertices<dim>& vertices = this->vertices_;
    vertices.positions(v, x_);
    contact_.pair_terms(x_, 1, false, terms_);
    gradient_pairs_ = terms_.size();
    const double c = vertices.dt() * contact_.kappa();
    Eigen::Index index[ContactVertices<dim>::kMaxUnknowns];
    double weight[ContactVertices<dim>::kMaxUnknowns];
    double sum = 0.0;
    for (const Terms& t : terms_) {
        sum += t.value;
        for (int k = 0; k < t.count; ++k) {
            const int n = vertices.unknowns(t.node[k], index, weight);
            for (int i = 0; i < n; ++i)
                g.template segment<dim>(index[i]) += (c * weight[i]) * t.gradient.template segment<dim>(dim * k);
        }
    }
    return contact_.kappa() * sum;
}

template <int dim>
void BarrierForm<dim>::prepare_hessian(const VecX& v) {
    const double dt = this->vertices_.dt();
    this->vertices_.positions(v, x_);
    contact_.pair_terms(x_, 2, project_psd_, this->hessians_);
    this->hessian_scale_ = dt * dt * contact_.kappa();
}

template <int dim>
double BarrierForm<dim>::max_step(const VecX& v, const VecX& d) {
    this->vertices_.positions(v, x_);
    this->vertices_.motion(d, dx_);
    return ccd_.record(contact_.max_step(x_, dx_));
}

template <int dim>
void VertexPairForm<dim>::add_hessian_multiply(const VecX& d, VecX& out) const {
    using Stacked = decltype(Terms::gradient);
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        // u = J d (the pair's motion per dt), y = H u, out += J^T y scale.
        Stacked u = Stacked::Zero();
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (free_[index[i] + a] > 0.0) u[dim * slot[i] + a] += weight[i] * d[index[i] + a];
        const Stacked y = scale * (H * u);
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                if (free_[index[i] + a] > 0.0) out[index[i] + a] += weight[i] * y[dim * slot[i] + a];
    });
}

template <int dim>
template <typename F>
void VertexPairForm<dim>::for_each_node_block_entry(F&& f) const {
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                for (int b = 0; b < dim; ++b)
                    if (free_[index[i] + a] > 0.0 && free_[index[i] + b] > 0.0)
                        f(index[i], a, b, scale * weight[i] * weight[i] * H(dim * slot[i] + a, dim * slot[i] + b));
    });
}

template <int dim>
void VertexPairForm<dim>::add_hessian_diagonal(VecX& diagonal) const {
    for_each_node_block_entry([&](Eigen::Index node, int a, int b, double h) {
        if (a == b) diagonal[node + a] += h;
    });
}

template <int dim>
void VertexPairForm<dim>::add_hessian_block_diagonal(VecX& blocks) const {
    for_each_node_block_entry(
        [&](Eigen::Index node, int a, int b, double h) { blocks[dim * node + a * dim + b] += h; });
}

template <int dim>
void VertexPairForm<dim>::add_hessian_triplets(std::vector<Triplet>& triplets) const {
    // Row by row of the pair's stacked Hessian (each vertex's unknowns, then its components), so
    // that a mesh's triplets come in the order of Contact::add_hessian.
    for_each_pair_hessian([&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < dim; ++a)
                for (int j = 0; j < count; ++j)
                    for (int b = 0; b < dim; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (free_[row] > 0.0 && free_[col] > 0.0)
                            triplets.emplace_back(
                                row, col, (scale * H(dim * slot[i] + a, dim * slot[j] + b)) * weight[i] * weight[j]);
                    }
    });
}

template class MeshVertices<2>;
template class MeshVertices<3>;
template class VertexPairForm<2>;
template class VertexPairForm<3>;
template class BarrierForm<2>;
template class BarrierForm<3>;

}  // namespace pnet
