#pragma once
// Outcome of a plastic return mapping Z(Sigma, h), shared by every model.
#include "pnet/math/types.hpp"

namespace pnet {

/// Which branch of its return mapping a model took. The integer codes are part
/// of the file formats (test vectors, Python) and must not be renumbered.
enum class ReturnBranch : int {
    Elastic = 0,         // inside the elastic region: Z = Sigma
    Apex = 1,            // Drucker-Prager, tr(eps) > 0: stress-free, Z = 1
    Cone = 2,            // Drucker-Prager, projected onto the cone
    CompressionTip = 3,  // Cam-Clay, p > p0
    TensionTip = 4,      // Cam-Clay, p < -beta p0
    Ellipse = 5,         // Cam-Clay, projected onto the ellipse at fixed p
    Yield = 6,           // von Mises, projected along the volume-preserving path
};

inline const char* to_string(ReturnBranch branch) {
    switch (branch) {
        case ReturnBranch::Elastic: return "elastic";
        case ReturnBranch::Apex: return "apex";
        case ReturnBranch::Cone: return "cone";
        case ReturnBranch::CompressionTip: return "compression_tip";
        case ReturnBranch::TensionTip: return "tension_tip";
        case ReturnBranch::Ellipse: return "ellipse";
        case ReturnBranch::Yield: return "yield";
    }
    return "unknown";
}

/// Projected singular values and the updated hardening state. A model that
/// works in Hencky strain (Drucker-Prager) also gives log(Sigma) as it formed
/// it, so that the stress of the projected state needs no second log.
template <int dim>
struct ReturnResult {
    Vec<dim> Sigma;
    double hardening = 0.0;
    ReturnBranch branch = ReturnBranch::Elastic;
    bool strain_known = false;
    Vec<dim> strain = Vec<dim>::Zero();  // log(Sigma) where strain_known

    /// log(Sigma), the Hencky strain of the projected state.
    Vec<dim> hencky_strain() const { return strain_known ? strain : Vec<dim>(Sigma.array().log().matrix()); }
};

}  // namespace pnet
