#include "pnet/fem/fem_potential.hpp"

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
        if (!(volume[e] > 0.0))
            throw std::invalid_argument("ElementRest: element " + std::to_string(e) + " is not positive");
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
FemPotential<dim>::FemPotential(const Mesh<dim>& mesh, const ElementRest<dim>& rest, ParticleEnergy<dim>& energy)
    : mesh_(mesh), rest_(rest), inertia_(this->free_, dim), elements_(*this, energy) {
    this->set_assemble(true);  // CHOLMOD solves the assembled Hessian
    update_forms();
}

template <int dim>
void FemPotential<dim>::update_forms() {
    std::vector<Form*> contact;
    if (barrier_) contact.push_back(barrier_.get());
    if (friction_) contact.push_back(friction_.get());
    contact_.set_forms(std::move(contact));
    std::vector<Form*> forms{&inertia_, &elements_};
    if (!contact_.empty()) forms.push_back(&contact_);
    this->set_forms(std::move(forms));
}

template <int dim>
void FemPotential<dim>::set_contact(const ContactPotential<dim>* contact) {
    barrier_ = contact ? std::make_unique<BarrierForm<dim>>(*contact, vertices_, this->free_) : nullptr;
    if (barrier_) {
        vertices_.begin_step(x_start_, dt_);
        barrier_->begin_step();
        barrier_->set_project_psd(project_psd_);
    }
    update_forms();
}

template <int dim>
void FemPotential<dim>::set_friction(const Friction<dim>* friction) {
    friction_ = friction ? std::make_unique<FrictionForm<dim>>(*friction) : nullptr;
    if (friction_) friction_->begin_step(dt_, this->free_);
    update_forms();
}

template <int dim>
void FemPotential<dim>::set_project_psd(bool project) {
    project_psd_ = project;
    elements_.set_project_psd(project);
    if (barrier_) barrier_->set_project_psd(project);
}

template <int dim>
void FemPotential<dim>::begin_step(const std::vector<Vec<dim>>& x_start, const VecX& v_star, double dt,
                                   const std::vector<Mat<dim>>& plastic_inverse, const std::vector<char>& fixed) {
    const std::size_t nodes = mesh_.nodes(), elements = mesh_.elements.size();
    if (x_start.size() != nodes || v_star.size() != static_cast<Eigen::Index>(dim * nodes) ||
        plastic_inverse.size() != elements || !(fixed.empty() || fixed.size() == dim * nodes))
        throw std::invalid_argument("FemPotential::begin_step: sizes do not match the mesh");
    x_start_ = x_start;
    dt_ = dt;
    VecX& mass = inertia_.mass();
    VecX& free = this->free_;
    inertia_.target() = v_star;
    inertia_.weight().setOnes(dim * nodes);
    mass.resize(dim * nodes);
    free.resize(dim * nodes);
    residual_mass_.resize(dim * nodes);
    fixed_ = fixed;
    for (std::size_t i = 0; i < nodes; ++i)
        for (int a = 0; a < dim; ++a) {
            const std::size_t k = dim * i + a;
            mass[k] = rest_.node_mass[i];
            free[k] = !fixed.empty() && fixed[k] ? 0.0 : 1.0;
            residual_mass_[k] = free[k] * mass[k];
        }
    elements_.begin_step(plastic_inverse);
    vertices_.begin_step(x_start_, dt_);
    if (barrier_) barrier_->begin_step();
    if (friction_) friction_->begin_step(dt_, free);
}

template <int dim>
void FemPotential<dim>::soften_fixed(double weight) {
    for (std::size_t k = 0; k < fixed_.size(); ++k)
        if (fixed_[k]) {
            this->free_[k] = 1.0;
            inertia_.weight()[k] = weight;
            residual_mass_[k] = inertia_.mass()[k];  // their pull to the target counts in the residual
        }
}

template <int dim>
void FemPotential<dim>::harden_fixed() {
    for (std::size_t k = 0; k < fixed_.size(); ++k)
        if (fixed_[k]) {
            this->free_[k] = 0.0;
            inertia_.weight()[k] = 1.0;
            residual_mass_[k] = 0.0;
        }
}

template <int dim>
void FemPotential<dim>::positions(const VecX& v, std::vector<Vec<dim>>& x) const {
    vertices_.positions(v, x);
}

template <int dim>
void FemPotential<dim>::set_reference(const std::vector<Mat<dim>>& F0) {
    if (object_.size() != mesh_.elements.size() || hardening_.size() != mesh_.elements.size())
        throw std::logic_error("FemPotential: set_material_state() before set_reference()");
    elements_.energy().set_reference(F0, hardening_, object_);
}

template struct ElementRest<2>;
template struct ElementRest<3>;
template Mat<2> deformation_gradient<2>(const Mesh<2>&, const ElementRest<2>&, const std::vector<Vec<2>>&, std::size_t);
template Mat<3> deformation_gradient<3>(const Mesh<3>&, const ElementRest<3>&, const std::vector<Vec<3>>&, std::size_t);
template class FemPotential<2>;
template class FemPotential<3>;

}  // namespace pnet
