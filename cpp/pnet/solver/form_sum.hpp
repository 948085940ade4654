#pragma once
// Forms summed as one (form.hpp): a group whose terms are added together before the problem
// adds them to the others, such as contact (the barrier and the friction of the same pairs).
#include <algorithm>
#include <vector>

#include "pnet/solver/form.hpp"

namespace pnet {

class FormSum final : public Form {
public:
    /// The forms, summed in this order (not owned).
    void set_forms(std::vector<Form*> forms) { forms_ = std::move(forms); }
    bool empty() const { return forms_.empty(); }

    double value(const VecX& x) override {
        double e = 0.0;
        for (Form* f : forms_) e += f->value(x);
        return e;
    }
    double add_gradient(const VecX& x, VecX& g) override {
        double e = 0.0;
        for (Form* f : forms_) e += f->add_gradient(x, g);
        return e;
    }
    void prepare_hessian(const VecX& x) override {
        for (Form* f : forms_) f->prepare_hessian(x);
    }
    double add_gradient_hessian(const VecX& x, VecX& g) override {
        double e = 0.0;
        for (Form* f : forms_) e += f->add_gradient_hessian(x, g);
        return e;
    }
    void add_hessian_multiply(const VecX& d, VecX& out) const override {
        for (const Form* f : forms_) f->add_hessian_multiply(d, out);
    }
    void add_hessian_diagonal(VecX& diagonal) const override {
        for (const Form* f : forms_) f->add_hessian_diagonal(diagonal);
    }
    void add_hessian_block_diagonal(VecX& blocks) const override {
        for (const Form* f : forms_) f->add_hessian_block_diagonal(blocks);
    }
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override {
        for (const Form* f : forms_) f->add_hessian_triplets(triplets);
    }
    bool symmetric_hessian() const override {
        return std::all_of(forms_.begin(), forms_.end(), [](const Form* f) { return f->symmetric_hessian(); });
    }
    bool changing_pattern() const override {
        return std::any_of(forms_.begin(), forms_.end(), [](const Form* f) { return f->changing_pattern(); });
    }
    double max_step(const VecX& x, const VecX& d) override {
        double t = 1.0;
        for (Form* f : forms_) t = std::min(t, f->max_step(x, d));
        return t;
    }

private:
    std::vector<Form*> forms_;
};

}  // namespace pnet
