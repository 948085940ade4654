#include "pnet/fem/fem_potential.hpp"

#include <algorithm>
#include <stdexcept>

namespace pnet {

template <int dim>
ElementRest<dim>::ElementRest(const Mesh<dim>& mesh, const std::vector<double>& density) {
    const std::size_t n = mesh.elements.size();
    if (density.size() != n) throw std::invalid_argument("ElementRest: one density per element is needed");
    volume.resize(n);
    grad.resize(n);
    node_mass.assign(mesh.nodes(), 0.0);
    for (std::size_t e = 0; e < n; ++e) {
        Mat<dim> Dm;
        for (int a = 0; a < dim; ++a) Dm.col(a) = mesh.x[mesh.elements[e][a + 1]] - mesh.x[mesh.elements[e][0]];
        volume[e] = Dm.determinant() / (dim == 2 ? 2.0 : 6.0);
        if (!(volume[e] > 0.0)) throw std::invalid_argument("ElementRest: element " + std::to_string(e) + " is not positive");
        const Mat<dim> Dm_inv = Dm.inverse();
        Vec<dim> sum = Vec<dim>::Zero();
        for (int a = 1; a <= dim; ++a) {
            grad[e][a] = Dm_inv.row(a - 1).transpose();
            sum += grad[e][a];
        }
        grad[e][0] = -sum;
        for (int a = 0; a <= dim; ++a) node_mass[mesh.elements[e][a]] += density[e] * volume[e] / (dim + 1);
    }
}

template <int dim>
Mat<dim> deformation_gradient(const Mesh<dim>& mesh, const ElementRest<dim>& rest, const std::vector<Vec<dim>>& x,
                              std::size_t e) {
    Mat<dim> F = Mat<dim>::Zero();
    for (int a = 0; a <= dim; ++a) F.noalias() += x[mesh.elements[e][a]] * rest.grad[e][a].transpose();
    return F;
}

template <int dim>
void FemPotential<dim>::begin_step(const std::vector<Vec<dim>>& x_start, const VecX& v_star, double dt,
                                   const std::vector<Mat<dim>>& plastic_inverse, const std::vector<char>& fixed) {
    const std::size_t nodes = mesh_.nodes(), elements = mesh_.elements.size();
    if (x_start.size() != nodes || v_star.size() != static_cast<Eigen::Index>(dim * nodes) ||
        plastic_inverse.size() != elements || !(fixed.empty() || fixed.size() == dim * nodes))
        throw std::invalid_argument("FemPotential::begin_step: sizes do not match the mesh");
    x_start_ = x_start;
    v_star_ = v_star;
    dt_ = dt;
    ccd_queries_ = ccd_limited_ = 0;
    mass_.resize(dim * nodes);
    free_.resize(dim * nodes);
    residual_mass_.resize(dim * nodes);
    inertia_scale_.setOnes(dim * nodes);
    fixed_ = fixed;
    for (std::size_t i = 0; i < nodes; ++i)
        for (int a = 0; a < dim; ++a) {
            const std::size_t k = dim * i + a;
            mass_[k] = rest_.node_mass[i];
            free_[k] = !fixed.empty() && fixed[k] ? 0.0 : 1.0;
            residual_mass_[k] = free_[k] * mass_[k];
        }
    grad_.resize(elements);
    for (std::size_t e = 0; e < elements; ++e)
        for (int a = 0; a <= dim; ++a) grad_[e][a] = plastic_inverse[e].transpose() * rest_.grad[e][a];
    FE_.resize(elements);
    P_.resize(elements);
    psi_.resize(elements);
    H_.resize(elements);
}

template <int dim>
void FemPotential<dim>::deformation(const VecX& v, std::vector<Mat<dim>>& FE) const {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(mesh_.elements.size());
    FE.resize(n);
#pragma omp parallel for schedule(static) if (n >= 256)
    for (std::ptrdiff_t e = 0; e < n; ++e) {
        Mat<dim> F = Mat<dim>::Zero();
        for (int a = 0; a <= dim; ++a) {
            const int node = mesh_.elements[e][a];
            const Vec<dim> x = x_start_[node] + dt_ * v.template segment<dim>(dim * node);
            F.noalias() += x * grad_[e][a].transpose();
        }
        FE[e] = F;
    }
}

template <int dim>
void FemPotential<dim>::soften_fixed(double weight) {
    for (std::size_t k = 0; k < fixed_.size(); ++k)
        if (fixed_[k]) {
            free_[k] = 1.0;
            inertia_scale_[k] = weight;
            residual_mass_[k] = mass_[k];  // their pull to the target counts in the residual
        }
}

template <int dim>
void FemPotential<dim>::harden_fixed() {
    for (std::size_t k = 0; k < fixed_.size(); ++k)
        if (fixed_[k]) {
            free_[k] = 0.0;
            inertia_scale_[k] = 1.0;
            residual_mass_[k] = 0.0;
        }
}

template <int dim>
void FemPotential<dim>::positions(const VecX& v, std::vector<Vec<dim>>& x) const {
    x.resize(x_start_.size());
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = x_start_[i] + dt_ * v.template segment<dim>(dim * i);
}

template <int dim>
double FemPotential<dim>::max_step(const VecX& v, const VecX& d) {
    if (!contact_) return 1.0;
    positions(v, x_);
    dx_.resize(x_.size());
    for (std::size_t i = 0; i < x_.size(); ++i) dx_[i] = dt_ * d.template segment<dim>(dim * i);
    const double t = contact_->max_step(x_, dx_);
    ++ccd_queries_;
    ccd_limited_ += t < 1.0;
    return t;
}

template <int dim>
void FemPotential<dim>::set_reference(const std::vector<Mat<dim>>& F0) {
    if (object_.size() != mesh_.elements.size() || hardening_.size() != mesh_.elements.size())
        throw std::logic_error("FemPotential: set_material_state() before set_reference()");
    energy_.set_reference(F0, hardening_, object_);
}

template <int dim>
double FemPotential<dim>::inertia(const VecX& v) const {
    return 0.5 * (v - v_star_).cwiseAbs2().dot(mass_.cwiseProduct(free_).cwiseProduct(inertia_scale_));
}

template <int dim>
double FemPotential<dim>::potential_sum() const {
    double sum = 0.0;  // in element order: independent of the thread count
    for (std::size_t e = 0; e < psi_.size(); ++e) sum += rest_.volume[e] * psi_[e];
    return sum;
}

template <int dim>
void FemPotential<dim>::evaluate(const VecX& v, typename ParticleEnergy<dim>::Order order) {
    deformation(v, FE_);
    energy_.evaluate(FE_, order, psi_.data(), P_.data(), H_.data(), project_psd_);
}

template <int dim>
double FemPotential<dim>::assemble_gradient(const VecX& v, VecX& gradient) {
    gradient = mass_.cwiseProduct(inertia_scale_).cwiseProduct(v - v_star_);
    for (std::size_t e = 0; e < mesh_.elements.size(); ++e) {
        const Mat<dim> Q = (rest_.volume[e] * dt_) * P_[e];
        for (int a = 0; a <= dim; ++a)
            gradient.template segment<dim>(dim * mesh_.elements[e][a]).noalias() += Q * grad_[e][a];
    }
    double e = 0.0;
    if (contact_) {
        positions(v, x_);
        e += contact_->add_gradient(x_, dt_, gradient);
    }
    if (friction_) {
        e += dt_ * friction_->value(v);
        friction_->add_gradient(v, dt_, gradient);
    }
    gradient.array() *= free_.array();
    return e;
}

template <int dim>
double FemPotential<dim>::contact_value(const VecX& v) {
    double e = 0.0;
    if (contact_) {
        positions(v, x_);
        e += contact_->value(x_);
    }
    if (friction_) e += dt_ * friction_->value(v);
    return e;
}

template <int dim>
double FemPotential<dim>::value(const VecX& v) {
    evaluate(v, ParticleEnergy<dim>::Order::Value);
    return inertia(v) + potential_sum() + contact_value(v);
}

template <int dim>
double FemPotential<dim>::value_gradient(const VecX& v, VecX& gradient) {
    evaluate(v, ParticleEnergy<dim>::Order::Gradient);
    const double contact = assemble_gradient(v, gradient);
    return inertia(v) + potential_sum() + contact;
}

template <int dim>
void FemPotential<dim>::build_hessian_pattern() {
    constexpr int nodes_per_element = dim + 1, block = nodes_per_element * nodes_per_element * dim * dim;
    const Eigen::Index n = size();
    const std::size_t elements = mesh_.elements.size();
    // Every entry an element touches, fixed components included (their values stay 0).
    std::vector<Eigen::Triplet<double>> pattern;
    pattern.reserve(elements * block + n);
    for (Eigen::Index k = 0; k < n; ++k) pattern.emplace_back(k, k, 1.0);
    for (std::size_t e = 0; e < elements; ++e)
        for (int a = 0; a <= dim; ++a)
            for (int b = 0; b <= dim; ++b)
                for (int i = 0; i < dim; ++i)
                    for (int k = 0; k < dim; ++k)
                        pattern.emplace_back(dim * mesh_.elements[e][a] + i, dim * mesh_.elements[e][b] + k, 1.0);
    element_hessian_.resize(n, n);
    element_hessian_.setFromTriplets(pattern.begin(), pattern.end());
    element_hessian_.makeCompressed();
    const auto slot = [&](Eigen::Index row, Eigen::Index col) {
        const auto* inner = element_hessian_.innerIndexPtr();
        const auto* first = inner + element_hessian_.outerIndexPtr()[col];
        const auto* last = inner + element_hessian_.outerIndexPtr()[col + 1];
        return static_cast<int>(std::lower_bound(first, last, row) - inner);
    };
    diagonal_slots_.resize(n);
    for (Eigen::Index k = 0; k < n; ++k) diagonal_slots_[k] = slot(k, k);
    element_slots_.resize(elements * block);
    for (std::size_t e = 0; e < elements; ++e) {
        int* slots = &element_slots_[e * block];
        for (int a = 0; a <= dim; ++a)
            for (int b = 0; b <= dim; ++b)
                for (int i = 0; i < dim; ++i)
                    for (int k = 0; k < dim; ++k)
                        *slots++ = slot(dim * mesh_.elements[e][a] + i, dim * mesh_.elements[e][b] + k);
    }
}

template <int dim>
void FemPotential<dim>::prepare_hessian(const VecX& v) {
    evaluate(v, ParticleEnergy<dim>::Order::Hessian);
    constexpr int block = (dim + 1) * (dim + 1) * dim * dim;
    const Eigen::Index n = size();
    if (element_hessian_.rows() != n || element_slots_.size() != mesh_.elements.size() * block) build_hessian_pattern();
    double* values = element_hessian_.valuePtr();
    std::fill(values, values + element_hessian_.nonZeros(), 0.0);
    for (Eigen::Index k = 0; k < n; ++k) values[diagonal_slots_[k]] = mass_[k] * (free_[k] > 0.0 ? inertia_scale_[k] : 1.0);
    for (std::size_t e = 0; e < mesh_.elements.size(); ++e) {
        const Tensor4<dim>& H = H_[e];
        const double scale = rest_.volume[e] * dt_ * dt_;
        const int* slots = &element_slots_[e * block];
        for (int a = 0; a <= dim; ++a)
            for (int b = 0; b <= dim; ++b) {
                const Vec<dim>& ga = grad_[e][a];
                const Vec<dim>& gb = grad_[e][b];
                for (int i = 0; i < dim; ++i)
                    for (int k = 0; k < dim; ++k) {
                        const int slot = *slots++;
                        const Eigen::Index row = dim * mesh_.elements[e][a] + i, col = dim * mesh_.elements[e][b] + k;
                        if (free_[row] == 0.0 || free_[col] == 0.0) continue;
                        double s = 0.0;
                        for (int j = 0; j < dim; ++j)
                            for (int l = 0; l < dim; ++l) s += ga[j] * H(i * dim + j, k * dim + l) * gb[l];
                        values[slot] += scale * s;
                    }
            }
    }
    with_contact_ = false;
    if (contact_ || friction_) {
        positions(v, x_);
        triplets_.clear();
        if (contact_) contact_->add_hessian(x_, dt_ * dt_, triplets_, project_psd_);
        if (friction_) friction_->add_hessian(v, dt_, triplets_);
        // Fixed components keep only their mass.
        triplets_.erase(std::remove_if(triplets_.begin(), triplets_.end(),
                                       [&](const Eigen::Triplet<double>& t) {
                                           return free_[t.row()] == 0.0 || free_[t.col()] == 0.0;
                                       }),
                        triplets_.end());
        if (!triplets_.empty()) {
            contact_hessian_.resize(n, n);
            contact_hessian_.setFromTriplets(triplets_.begin(), triplets_.end());  // duplicates summed in order
            hessian_ = element_hessian_ + contact_hessian_;
            with_contact_ = true;
        }
    }
}

template <int dim>
double FemPotential<dim>::value_gradient_hessian(const VecX& v, VecX& gradient) {
    prepare_hessian(v);  // the Hessian pass leaves psi and P at v
    const double contact = assemble_gradient(v, gradient);
    return inertia(v) + potential_sum() + contact;
}

template <int dim>
void FemPotential<dim>::hessian_multiply(const VecX& d, VecX& out) const {
    out.noalias() = hessian() * d;
}

template <int dim>
void FemPotential<dim>::hessian_diagonal(VecX& diagonal) const {
    diagonal = hessian().diagonal();
}

template <int dim>
void FemPotential<dim>::hessian_block_diagonal(VecX& blocks) const {
    const Eigen::Index nodes = size() / dim;
    blocks.setZero(nodes * dim * dim);
    for (Eigen::Index k = 0; k < nodes; ++k)
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b) blocks[k * dim * dim + a * dim + b] = hessian().coeff(dim * k + a, dim * k + b);
}

template struct ElementRest<2>;
template struct ElementRest<3>;
template Mat<2> deformation_gradient<2>(const Mesh<2>&, const ElementRest<2>&, const std::vector<Vec<2>>&, std::size_t);
template Mat<3> deformation_gradient<3>(const Mesh<3>&, const ElementRest<3>&, const std::vector<Vec<3>>&, std::size_t);
template class FemPotential<2>;
template class FemPotential<3>;

}  // namespace pnet
