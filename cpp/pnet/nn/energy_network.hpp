#pragma once
// The network N(F, F0, h) of a PlasticityNet energy and its derivatives in F,
// whatever the model's input representation (ModelMetadata::representation):
//
//   Raw:       the MLP takes x = [vec F, vec F0, h] (the paper's);
//   Principal: the MLP takes x = [vec G, Sigma0, h] with G = U^T F V and
//              F0 = U diag(Sigma0) V^T (polar_svd), frame-indifferent by
//              construction (python/plasticitynet/training/frames.py).
//
// A parametric energy's normalised material parameters u follow h in both
// (ModelMetadata::parameters); they are constants of the object.
//
// In both the differentiated inputs come first, so the fused kernel is the
// same; for Principal, with vec G = M vec F (M_(ij),(kl) = U_ki V_lj),
//   grad_F N = U (grad_G N) V^T,   Hess_F N = M^T (Hess_G N) M.
// U, V depend on F0 only, which is constant within an optimization: they, and
// the inputs Sigma0 and h, are computed once in set_reference().
#include <cstddef>
#include <vector>

#include "pnet/math/types.hpp"
#include "pnet/nn/fused_mlp.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet {

template <int dim>
class EnergyNetwork {
public:
    static constexpr int kM = dim * dim;

    /// Throws std::invalid_argument (naming `context`) unless the weights are
    /// those of a dim-D energy MLP in `representation` with a compiled kernel.
    /// `parameter_inputs`: a parametric energy's inputs u (the same for every row).
    EnergyNetwork(const MlpWeights& weights, EnergyRepresentation representation, bool has_hardening,
                  const std::string& context, std::vector<double> parameter_inputs = {});

    /// The reference state of n rows: F0 and the network's hardening input h
    /// (ignored without hardening; null: 0).
    void set_reference(const Mat<dim>* F0, const double* h, std::size_t n);
    std::size_t size() const { return size_; }

    /// N(F_r, F0_r, h_r) per row, and for Order >= Gradient its gradient in F
    /// (gradient[r kM + k], row-major vec), for Order::Hessian its Hessian
    /// (hessian[(r kM + k) kM + l], symmetric), in the MLP arithmetic of
    /// `precision` (the change of frame is double either way). Threaded like FusedMlp.
    void evaluate(const Mat<dim>* F, FusedMlp::Order order, double* value, double* gradient = nullptr,
                  double* hessian = nullptr, FusedMlp::Precision precision = FusedMlp::Precision::Double) const;

    /// change[r] = N(F_r, F0_r, h_r) - N(from_r, F0_r, h_r), accurate relative to the change
    /// (FusedMlp::difference), in the MLP arithmetic of `precision`.
    void difference(const Mat<dim>* F, const Mat<dim>* from, double* change,
                    FusedMlp::Precision precision = FusedMlp::Precision::Double) const;

    /// evaluate() and difference() on the listed rows only (`rows`: count ascending row indices;
    /// F and from are indexed by row, as above): the i-th listed row's results are at value[i],
    /// gradient[i kM], hessian[i kM kM] and change[i]. The same arithmetic as the whole batch's,
    /// so a row's result does not depend on which other rows are listed.
    void evaluate_rows(const int* rows, std::size_t count, const Mat<dim>* F, FusedMlp::Order order, double* value,
                       double* gradient = nullptr, double* hessian = nullptr,
                       FusedMlp::Precision precision = FusedMlp::Precision::Double) const;
    void difference_rows(const int* rows, std::size_t count, const Mat<dim>* F, const Mat<dim>* from,
                         double* change, FusedMlp::Precision precision = FusedMlp::Precision::Double) const;

    /// The MLP's input for one forward() row [vec F, vec F0, (h), (u)] of a model
    /// file (`parameters` entries u): what the loader checks forward() against.
    static void mlp_input(EnergyRepresentation representation, bool has_hardening, const double* forward_row,
                          double* mlp_row, int parameters = 0);

    EnergyRepresentation representation() const { return representation_; }
    const FusedMlp& mlp(FusedMlp::Precision precision = FusedMlp::Precision::Double) const {
        return precision == FusedMlp::Precision::Single ? mlp_single_ : mlp_;
    }

private:
    FusedMlp mlp_, mlp_single_;  // the same weights in double and in single precision
    EnergyRepresentation representation_;
    bool has_hardening_;
    std::vector<double> parameter_inputs_;
    int input_width_;
    std::size_t size_ = 0;
    std::vector<Mat<dim>> U_, V_;  // Principal: the frame of each row's F0
    mutable std::vector<double> inputs_, from_inputs_;  // the MLP's rows (the F slot set per evaluation)
    /// Writes the F slot of `rows` (inputs_ or from_inputs_, whose other slots are the reference's).
    void set_rows(const Mat<dim>* F, std::vector<double>& rows) const;
    /// Writes row p's F slot at x: G = U_p^T F V_p (Principal) or F itself.
    void write_F_slot(std::size_t p, const Mat<dim>& F, double* x) const;
    /// The MLP inputs of the listed rows (a copy of the reference's with F's slot), packed.
    void pack_rows(const int* rows, std::size_t count, const Mat<dim>* F, std::vector<double>& packed) const;
    /// The change of frame of the MLP's gradient and Hessian in G to F, for the listed rows (null: all).
    void to_frame_of_F(const int* rows, std::size_t count, FusedMlp::Order order, double* gradient,
                       double* hessian) const;
    mutable std::vector<double> packed_, packed_from_;  // evaluate_rows, difference_rows
};

}  // namespace pnet
