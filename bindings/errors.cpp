// C++ exceptions as Python exceptions with the same message:
//   missing scene, model or checkpoint file   -> FileNotFoundError
//   a model file no MANIFEST pins (untrusted) -> plasticitynet_sim.UntrustedModelError (a ValueError)
//   bad input (std::invalid_argument)         -> ValueError (pybind11's own translation)
//   a blow-up or failed solve                 -> plasticitynet_sim.SimulationError (a RuntimeError)
//   anything else (std::runtime_error)        -> RuntimeError
#include "common.hpp"
#include "pnet/mpm/integrator.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet::bindings {

void define_errors(py::module_& m) {
    static py::exception<UntrustedModelError> untrusted(m, "UntrustedModelError", PyExc_ValueError);
    untrusted.doc() =
        "A model file that no MANIFEST beside it pins by sha256. Model files are code to LibTorch: pass "
        "trusted=True (trust_models=True for a simulation) only for files whose origin you trust.";
    static py::exception<SimulationError> simulation_error(m, "SimulationError", PyExc_RuntimeError);
    simulation_error.doc() =
        "A simulation step failed (a blow-up, a NaN, a Newton solve that could not descend); the message names "
        "the step. The simulation keeps the state of its last completed step.";
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const SceneFileNotFound& e) {
            PyErr_SetString(PyExc_FileNotFoundError, e.what());
        } catch (const FileNotFoundError& e) {
            PyErr_SetString(PyExc_FileNotFoundError, e.what());
        } catch (const UntrustedModelError& e) {
            untrusted(e.what());
        } catch (const SimulationError& e) {
            simulation_error(e.what());
        }
    });
}

}  // namespace pnet::bindings
