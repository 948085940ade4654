#include "pnet/solver/problem.hpp"

#include <algorithm>

namespace pnet {

template <int dim>
double Problem<dim>::value(const VecX& x) {
    double e = 0.0;
    for (Form* form : forms_) e += form->value(x);
    return e;
}

template <int dim>
double Problem<dim>::value_gradient(const VecX& x, VecX& gradient) {
    gradient.setZero(size());
    double e = 0.0;
    for (Form* form : forms_) e += form->add_gradient(x, gradient);
    gradient.array() *= free_.array();  // fixed components are held: no gradient
    return e;
}

template <int dim>
void Problem<dim>::prepare_hessian(const VecX& x) {
    for (Form* form : forms_) form->prepare_hessian(x);
    if (assemble_) assemble();
    hessian_prepared(x);
}

template <int dim>
double Problem<dim>::value_gradient_hessian(const VecX& x, VecX& gradient) {
    gradient.setZero(size());
    double e = 0.0;
    for (Form* form : forms_) e += form->add_gradient_hessian(x, gradient);
    gradient.array() *= free_.array();
    if (assemble_) assemble();
    hessian_prepared(x);
    return e;
}

template <int dim>
void Problem<dim>::hessian_multiply(const VecX& d, VecX& out) const {
    if (assemble_) {
        out.noalias() = *hessian_ * d;
        return;
    }
    out.setZero(d.size());
    for (const Form* form : forms_) form->add_hessian_multiply(d, out);
}

template <int dim>
void Problem<dim>::hessian_diagonal(VecX& diagonal) const {
    if (assemble_) {
        diagonal = hessian_->diagonal();
        return;
    }
    diagonal.setZero(size());
    for (const Form* form : forms_) form->add_hessian_diagonal(diagonal);
}

template <int dim>
bool Problem<dim>::hessian_symmetric() const {
    return std::all_of(forms_.begin(), forms_.end(), [](const Form* f) { return f->symmetric_hessian(); });
}

template <int dim>
void Problem<dim>::hessian_block_diagonal(VecX& blocks) const {
    const Eigen::Index nodes = size() / dim;
    blocks.setZero(nodes * dim * dim);
    if (!assemble_) {
        for (const Form* form : forms_) form->add_hessian_block_diagonal(blocks);
        return;
    }
    for (Eigen::Index k = 0; k < nodes; ++k)
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b) blocks[k * dim * dim + a * dim + b] = hessian_->coeff(dim * k + a, dim * k + b);
}

template <int dim>
double Problem<dim>::max_step(const VecX& x, const VecX& d) {
    double t = 1.0;
    for (Form* form : forms_) t = std::min(t, form->max_step(x, d));
    return t;
}

template <int dim>
void Problem<dim>::add_hessian_triplets(std::vector<Triplet>& triplets, Eigen::Index offset) const {
    if (assemble_) {
        for (Eigen::Index c = 0; c < hessian_->outerSize(); ++c)
            for (SparseMatrix::InnerIterator it(*hessian_, c); it; ++it)
                triplets.emplace_back(offset + it.row(), offset + c, it.value());
        return;
    }
    const std::size_t first = triplets.size();
    for (const Form* form : forms_) form->add_hessian_triplets(triplets);
    if (offset != 0)
        for (std::size_t k = first; k < triplets.size(); ++k)
            triplets[k] = Triplet(offset + triplets[k].row(), offset + triplets[k].col(), triplets[k].value());
}

template <int dim>
void Problem<dim>::assemble() {
    const Eigen::Index n = size();
    if (!pattern_valid_ || fixed_hessian_.rows() != n) {
        // The fixed-pattern forms' entries, in form order, and the slot of each in the pattern.
        std::vector<Triplet> triplets;
        slot_start_.assign(1, 0);
        for (const Form* form : forms_) {
            if (!form->changing_pattern()) form->add_hessian_triplets(triplets);
            slot_start_.push_back(triplets.size());
        }
        fixed_hessian_.resize(n, n);
        fixed_hessian_.setFromTriplets(triplets.begin(), triplets.end());
        fixed_hessian_.makeCompressed();
        const auto* inner = fixed_hessian_.innerIndexPtr();
        const auto* outer = fixed_hessian_.outerIndexPtr();
        slots_.resize(triplets.size());
        for (std::size_t k = 0; k < triplets.size(); ++k) {
            const Triplet& t = triplets[k];
            slots_[k] = static_cast<int>(std::lower_bound(inner + outer[t.col()], inner + outer[t.col() + 1], t.row()) - inner);
        }
        pattern_valid_ = true;
    }
    double* values = fixed_hessian_.valuePtr();
    std::fill(values, values + fixed_hessian_.nonZeros(), 0.0);
    changing_triplets_.clear();
    for (std::size_t f = 0; f < forms_.size(); ++f) {
        if (forms_[f]->changing_pattern())
            forms_[f]->add_hessian_triplets(changing_triplets_);
        else
            forms_[f]->add_hessian_values(values, slots_.data() + slot_start_[f]);
    }
    hessian_ = &fixed_hessian_;
    if (changing_triplets_.empty()) return;
    changing_hessian_.resize(n, n);
    changing_hessian_.setFromTriplets(changing_triplets_.begin(), changing_triplets_.end());  // summed in order
    sum_hessian_ = fixed_hessian_ + changing_hessian_;
    hessian_ = &sum_hessian_;
}

template <int dim>
const VecX& ProblemForm<dim>::slice(const VecX& x) const {
    in_ = x.segment(offset_, problem_.size());
    return in_;
}

template <int dim>
void ProblemForm<dim>::add_slice(const VecX& part, VecX& whole) const {
    whole.segment(offset_, problem_.size()) += part;
}

template <int dim>
double ProblemForm<dim>::value(const VecX& x) {
    return problem_.value(slice(x));
}

template <int dim>
double ProblemForm<dim>::add_gradient(const VecX& x, VecX& g) {
    const double e = problem_.value_gradient(slice(x), out_);
    add_slice(out_, g);
    return e;
}

template <int dim>
void ProblemForm<dim>::prepare_hessian(const VecX& x) {
    problem_.prepare_hessian(slice(x));
}

template <int dim>
double ProblemForm<dim>::add_gradient_hessian(const VecX& x, VecX& g) {
    const double e = problem_.value_gradient_hessian(slice(x), out_);
    add_slice(out_, g);
    return e;
}

template <int dim>
void ProblemForm<dim>::add_hessian_multiply(const VecX& d, VecX& out) const {
    problem_.hessian_multiply(slice(d), out_);
    add_slice(out_, out);
}

template <int dim>
void ProblemForm<dim>::add_hessian_diagonal(VecX& diagonal) const {
    problem_.hessian_diagonal(out_);
    add_slice(out_, diagonal);
}

template <int dim>
void ProblemForm<dim>::add_hessian_block_diagonal(VecX& blocks) const {
    problem_.hessian_block_diagonal(out_);
    blocks.segment(offset_ * dim, problem_.size() * dim) += out_;
}

template <int dim>
void ProblemForm<dim>::add_hessian_triplets(std::vector<Triplet>& triplets) const {
    problem_.add_hessian_triplets(triplets, offset_);
}

template <int dim>
double ProblemForm<dim>::max_step(const VecX& x, const VecX& d) {
    step_ = d.segment(offset_, problem_.size());
    return problem_.max_step(slice(x), step_);
}

template class Problem<2>;
template class Problem<3>;
template class ProblemForm<2>;
template class ProblemForm<3>;

}  // namespace pnet
