#include "pnet/fem/element_energy_form.hpp"

#include "pnet/fem/fem_potential.hpp"

namespace pnet {

template <int dim>
void ElementEnergyForm<dim>::begin_step(const std::vector<Mat<dim>>& plastic_inverse) {
    const ElementRest<dim>& rest = problem_.rest();
    const std::size_t elements = plastic_inverse.size();
    grad_.resize(elements);
    for (std::size_t e = 0; e < elements; ++e)
        for (int a = 0; a <= dim; ++a) grad_[e][a] = plastic_inverse[e].transpose() * rest.grad[e][a];
    FE_.resize(elements);
    P_.resize(elements);
    psi_.resize(elements);
    H_.resize(elements);
    energy_.begin_step();
}

template <int dim>
void ElementEnergyForm<dim>::deformation(const VecX& v, std::vector<Mat<dim>>& FE) const {
    const Mesh<dim>& mesh = problem_.mesh();
    const std::vector<Vec<dim>>& x_start = problem_.start_positions();
    const double dt = problem_.dt();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(mesh.elements.size());
    FE.resize(n);
#pragma omp parallel for schedule(static) if (n >= 256)
    for (std::ptrdiff_t e = 0; e < n; ++e) {
        Mat<dim> F = Mat<dim>::Zero();
        for (int a = 0; a <= dim; ++a) {
            const int node = mesh.elements[e][a];
            const Vec<dim> x = x_start[node] + dt * v.template segment<dim>(dim * node);
            F.noalias() += x * grad_[e][a].transpose();
        }
        FE[e] = F;
    }
}

template <int dim>
void ElementEnergyForm<dim>::evaluate(const VecX& v, typename ParticleEnergy<dim>::Order order) {
    deformation(v, FE_);
    energy_.evaluate(FE_, order, psi_.data(), P_.data(), H_.data(), project_psd_);
}

template <int dim>
double ElementEnergyForm<dim>::potential_sum() const {
    const std::vector<double>& volume = problem_.rest().volume;
    double sum = 0.0;  // in element order: independent of the thread count
    for (std::size_t e = 0; e < psi_.size(); ++e) sum += volume[e] * psi_[e];
    return sum;
}

template <int dim>
void ElementEnergyForm<dim>::scatter_gradient(VecX& g) const {
    const Mesh<dim>& mesh = problem_.mesh();
    const std::vector<double>& volume = problem_.rest().volume;
    const double dt = problem_.dt();
    for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
        const Mat<dim> Q = (volume[e] * dt) * P_[e];
        for (int a = 0; a <= dim; ++a) g.template segment<dim>(dim * mesh.elements[e][a]).noalias() += Q * grad_[e][a];
    }
}

template <int dim>
double ElementEnergyForm<dim>::value(const VecX& v) {
    evaluate(v, ParticleEnergy<dim>::Order::Value);
    return potential_sum();
}

template <int dim>
double ElementEnergyForm<dim>::add_gradient(const VecX& v, VecX& g) {
    evaluate(v, ParticleEnergy<dim>::Order::Gradient);
    scatter_gradient(g);
    return potential_sum();
}

template <int dim>
void ElementEnergyForm<dim>::prepare_hessian(const VecX& v) {
    evaluate(v, ParticleEnergy<dim>::Order::Hessian);
}

template <int dim>
double ElementEnergyForm<dim>::add_gradient_hessian(const VecX& v, VecX& g) {
    prepare_hessian(v);  // the Hessian pass leaves psi and P at v
    scatter_gradient(g);
    return potential_sum();
}

template <int dim>
template <typename F>
void ElementEnergyForm<dim>::for_each_entry(std::size_t e, F&& f) const {
    const auto& element = problem_.mesh().elements[e];
    const VecX& free = problem_.free_components();
    const double dt = problem_.dt();
    const double scale = problem_.rest().volume[e] * dt * dt;
    const Tensor4<dim>& H = H_[e];
    for (int a = 0; a <= dim; ++a)
        for (int b = 0; b <= dim; ++b) {
            const Vec<dim>& ga = grad_[e][a];
            const Vec<dim>& gb = grad_[e][b];
            for (int i = 0; i < dim; ++i)
                for (int k = 0; k < dim; ++k) {
                    const Eigen::Index row = dim * element[a] + i, col = dim * element[b] + k;
                    if (free[row] == 0.0 || free[col] == 0.0) {
                        f(row, col, 0.0);
                        continue;
                    }
                    double s = 0.0;
                    for (int j = 0; j < dim; ++j)
                        for (int l = 0; l < dim; ++l) s += ga[j] * H(i * dim + j, k * dim + l) * gb[l];
                    f(row, col, scale * s);
                }
        }
}

template <int dim>
void ElementEnergyForm<dim>::add_hessian_triplets(std::vector<Triplet>& triplets) const {
    const std::size_t elements = problem_.mesh().elements.size();
    triplets.reserve(triplets.size() + elements * (dim + 1) * (dim + 1) * dim * dim);
    for (std::size_t e = 0; e < elements; ++e)
        for_each_entry(e, [&](Eigen::Index row, Eigen::Index col, double h) { triplets.emplace_back(row, col, h); });
}

template <int dim>
void ElementEnergyForm<dim>::add_hessian_values(double* values, const int* slots) const {
    // Each entry is added where it is formed (so that the compiler may fuse the product and the sum).
    for (std::size_t e = 0; e < H_.size(); ++e)
        for_each_entry(e, [&](Eigen::Index, Eigen::Index, double h) { values[*slots++] += h; });
}

template <int dim>
void ElementEnergyForm<dim>::add_hessian_multiply(const VecX& d, VecX& out) const {
    for (std::size_t e = 0; e < H_.size(); ++e)
        for_each_entry(e, [&](Eigen::Index row, Eigen::Index col, double h) { out[row] += h * d[col]; });
}

template <int dim>
void ElementEnergyForm<dim>::add_hessian_diagonal(VecX& diagonal) const {
    for (std::size_t e = 0; e < H_.size(); ++e)
        for_each_entry(e, [&](Eigen::Index row, Eigen::Index col, double h) {
            if (row == col) diagonal[row] += h;
        });
}

template <int dim>
void ElementEnergyForm<dim>::add_hessian_block_diagonal(VecX& blocks) const {
    for (std::size_t e = 0; e < H_.size(); ++e)
        for_each_entry(e, [&](Eigen::Index row, Eigen::Index col, double h) {
            if (row / dim == col / dim) blocks[(row / dim) * dim * dim + (row % dim) * dim + col % dim] += h;
        });
}

template class ElementEnergyForm<2>;
template class ElementEnergyForm<3>;

}  // namespace pnet
