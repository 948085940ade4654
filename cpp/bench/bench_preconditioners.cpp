// The implicit MPM step's preconditioners against a library's algebraic multigrid (issue 55: "measure a
// library against the hand-written hierarchy"), on the constructed grid problem of
// pnet/solver/grid_model_problem.hpp: Jacobi, block Jacobi, the grid's Galerkin multigrid
// (solver/multigrid.hpp) and, where the build found hypre, its BoomerAMG (one V-cycle per
// application, systems AMG with the two velocity components as its functions), each inside the same
// PCG to the same relative tolerance from the same right-hand side. Prints one row per problem and
// preconditioner: the setup's and the solve's wall time (best of --repeats), the PCG iterations, and
// the solution's distance from Jacobi's. Asserts nothing.
//
//   bench_preconditioners [--cells 64,128,256] [--youngs 3.5e5,3.5e7,1e10] [--threads T] [--tol 1e-4]
//                         [--repeats 3]
//
// E = 3.5e5 Pa at dt = 1e-3 s is the shipped sand's stiffness-to-mass ratio at these grids (mass
// dominates: dt^2 E / (rho dx^2) from 1.4 to 23), 3.5e7 its stiff variant's, 1e10 far beyond both.
// hypre runs on one MPI rank without threads (Debian's build has no OpenMP); the others use --threads.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/solver/grid_model_problem.hpp"
#include "pnet/solver/multigrid.hpp"
#include "pnet/solver/pcg.hpp"

#ifdef PNET_HAVE_HYPRE
#include <HYPRE.h>
#include <HYPRE_parcsr_ls.h>
#include <mpi.h>
#endif

namespace pnet {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// A: the problem's matrix, applied by its sparse product; the preconditioner a function.
class MatrixObjective : public Objective {
public:
    MatrixObjective(const SparseMatrix& A, std::function<void(const VecX&, VecX&)> apply)
        : A_(A), apply_(std::move(apply)) {}
    Eigen::Index size() const override { return A_.rows(); }
    double value(const VecX&) override { return 0.0; }
    double value_gradient(const VecX&, VecX& g) override { return g.setZero(size()), 0.0; }
    void prepare_hessian(const VecX&) override {}
    void hessian_multiply(const VecX& d, VecX& out) const override { out.noalias() = A_ * d; }
    void hessian_diagonal(VecX& diagonal) const override { diagonal = A_.diagonal(); }
    bool has_preconditioner() const override { return static_cast<bool>(apply_); }
    void apply_preconditioner(const VecX& r, VecX& z) const override { apply_(r, z); }

private:
    const SparseMatrix& A_;
    std::function<void(const VecX&, VecX&)> apply_;
};

#ifdef PNET_HAVE_HYPRE
/// BoomerAMG as a preconditioner: one V-cycle from zero per application (tolerance 0, one iteration),
/// hypre's default coarsening (HMIS), interpolation (extended+i) and symmetric l1 Gauss-Seidel
/// smoothing (forward down, backward up), systems AMG over the interleaved velocity components.
class BoomerAmg {
public:
    BoomerAmg(const SparseMatrix& A, int functions) : n_(static_cast<HYPRE_BigInt>(A.rows())) {
        HYPRE_IJMatrixCreate(MPI_COMM_WORLD, 0, n_ - 1, 0, n_ - 1, &ij_);
        HYPRE_IJMatrixSetObjectType(ij_, HYPRE_PARCSR);
        std::vector<HYPRE_Int> sizes(static_cast<std::size_t>(n_));
        for (Eigen::Index j = 0; j < A.outerSize(); ++j)
            sizes[j] = static_cast<HYPRE_Int>(A.outerIndexPtr()[j + 1] - A.outerIndexPtr()[j]);
        HYPRE_IJMatrixSetRowSizes(ij_, sizes.data());
        HYPRE_IJMatrixInitialize(ij_);
        // A is symmetric, so its columns (Eigen stores them) are its rows.
        std::vector<HYPRE_BigInt> cols;
        std::vector<double> values;
        for (Eigen::Index j = 0; j < A.outerSize(); ++j) {
            cols.clear();
            values.clear();
            for (SparseMatrix::InnerIterator it(A, j); it; ++it) {
                cols.push_back(static_cast<HYPRE_BigInt>(it.row()));
                values.push_back(it.value());
            }
            HYPRE_Int count = static_cast<HYPRE_Int>(cols.size());
            HYPRE_BigInt row = static_cast<HYPRE_BigInt>(j);
            HYPRE_IJMatrixSetValues(ij_, 1, &count, &row, cols.data(), values.data());
        }
        HYPRE_IJMatrixAssemble(ij_);
        HYPRE_IJMatrixGetObject(ij_, reinterpret_cast<void**>(&A_));
        for (HYPRE_IJVector* v : {&b_ij_, &x_ij_}) {
            HYPRE_IJVectorCreate(MPI_COMM_WORLD, 0, n_ - 1, v);
            HYPRE_IJVectorSetObjectType(*v, HYPRE_PARCSR);
            HYPRE_IJVectorInitialize(*v);
            HYPRE_IJVectorAssemble(*v);
        }
        HYPRE_IJVectorGetObject(b_ij_, reinterpret_cast<void**>(&b_));
        HYPRE_IJVectorGetObject(x_ij_, reinterpret_cast<void**>(&x_));
        index_.resize(static_cast<std::size_t>(n_));
        for (HYPRE_BigInt i = 0; i < n_; ++i) index_[i] = i;
        HYPRE_BoomerAMGCreate(&amg_);
        HYPRE_BoomerAMGSetPrintLevel(amg_, 0);
        HYPRE_BoomerAMGSetMaxIter(amg_, 1);
        HYPRE_BoomerAMGSetTol(amg_, 0.0);
        HYPRE_BoomerAMGSetNumFunctions(amg_, functions);
        HYPRE_BoomerAMGSetStrongThreshold(amg_, 0.25);
        HYPRE_BoomerAMGSetRelaxType(amg_, 8);  // l1 symmetric Gauss-Seidel: a symmetric V-cycle for CG
        HYPRE_BoomerAMGSetup(amg_, A_, b_, x_);
    }
    ~BoomerAmg() {
        HYPRE_BoomerAMGDestroy(amg_);
        HYPRE_IJVectorDestroy(b_ij_);
        HYPRE_IJVectorDestroy(x_ij_);
        HYPRE_IJMatrixDestroy(ij_);
    }
    BoomerAmg(const BoomerAmg&) = delete;
    BoomerAmg& operator=(const BoomerAmg&) = delete;

    void apply(const VecX& r, VecX& z) const {
        HYPRE_IJVectorSetValues(b_ij_, static_cast<HYPRE_Int>(n_), index_.data(), r.data());
        HYPRE_ParVectorSetConstantValues(x_, 0.0);
        HYPRE_BoomerAMGSolve(amg_, A_, b_, x_);
        z.resize(r.size());
        HYPRE_IJVectorGetValues(x_ij_, static_cast<HYPRE_Int>(n_), index_.data(), z.data());
    }

private:
    HYPRE_BigInt n_;
    HYPRE_IJMatrix ij_;
    HYPRE_ParCSRMatrix A_;
    HYPRE_IJVector b_ij_, x_ij_;
    HYPRE_ParVector b_, x_;
    HYPRE_Solver amg_;
    std::vector<HYPRE_BigInt> index_;
};
#endif

std::vector<double> parse_list(const std::string& text, const char* flag) {
    std::vector<double> out;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        try {
            out.push_back(std::stod(item));
        } catch (const std::exception&) {
            throw std::invalid_argument(std::string(flag) + ": '" + item + "' is not a number");
        }
    }
    if (out.empty()) throw std::invalid_argument(std::string(flag) + ": an empty list");
    return out;
}

struct Row {
    std::string name;
    int threads = 1, iterations = 0, levels = 0;
    double setup = 0.0, solve = 0.0, difference = 0.0;
    bool converged = false;
};

}  // namespace
}  // namespace pnet

int main(int argc, char** argv) {
    using namespace pnet;
#ifdef PNET_HAVE_HYPRE
    MPI_Init(&argc, &argv);
    HYPRE_Init();
#endif
    std::vector<double> cells_list = {64, 128, 256}, youngs_list = {3.5e5, 3.5e7, 1e10};
    int threads = 2, repeats = 3;
    double tolerance = 1e-4;
    try {
        for (int i = 1; i < argc; ++i) {
            const std::string arg = argv[i];
            auto value = [&]() -> std::string {
                if (i + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
                return argv[++i];
            };
            if (arg == "--cells")
                cells_list = parse_list(value(), "--cells");
            else if (arg == "--youngs")
                youngs_list = parse_list(value(), "--youngs");
            else if (arg == "--threads")
                threads = std::stoi(value());
            else if (arg == "--tol")
                tolerance = std::stod(value());
            else if (arg == "--repeats")
                repeats = std::max(1, std::stoi(value()));
            else if (arg == "--help" || arg == "-h") {
                std::printf(
                    "bench_preconditioners [--cells 64,128,256] [--youngs 3.5e5,3.5e7,1e10] [--threads T] "
                    "[--tol 1e-4] [--repeats 3]\n");
                return 0;
            } else
                throw std::invalid_argument("unknown argument '" + arg + "' (--help lists them)");
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_preconditioners: %s\n", e.what());
        return 2;
    }
#ifdef PNET_HAVE_HYPRE
    const bool have_hypre = true;
#else
    const bool have_hypre = false;
#endif
    std::printf("PCG to a relative residual of %.0e, the best of %d repeats; %s\n\n", tolerance, repeats,
                have_hypre ? "hypre BoomerAMG on one rank" : "built without hypre (no BoomerAMG rows)");
    std::printf(
        "| cells | E (Pa) | dt^2 E / (rho dx^2) | unknowns | preconditioner | threads | levels | setup ms | "
        "PCG iterations | solve ms | setup + solve ms | vs Jacobi's solution |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const double cells_value : cells_list) {
        const int cells = static_cast<int>(cells_value);
        for (const double youngs : youngs_list) {
            const GridModelProblem problem(cells, youngs);
            const double ratio = 1e-6 * youngs / (1000.0 / (cells * double(cells)));
            VecX b(problem.A.rows());
            for (Eigen::Index i = 0; i < b.size(); ++i) b[i] = std::sin(0.37 * double(i)) * problem.free[i];
            VecX reference;
            std::vector<Row> rows;
            auto measure = [&](const std::string& name, int row_threads,
                               const std::function<std::function<void(const VecX&, VecX&)>(Row&)>& setup,
                               const std::function<Preconditioner(const Objective&)>& preconditioner) {
                Row row{name, row_threads};
                omp_set_num_threads(row_threads);
                row.setup = row.solve = 1e30;
                for (int r = 0; r < repeats; ++r) {
                    auto start = std::chrono::steady_clock::now();
                    std::function<void(const VecX&, VecX&)> apply = setup(row);
                    row.setup = std::min(row.setup, seconds_since(start));
                    const MatrixObjective objective(problem.A, apply);
                    VecX x;
                    start = std::chrono::steady_clock::now();
                    const PcgResult result = solve_pcg(objective, b, preconditioner(objective), x, tolerance, 100000);
                    row.solve = std::min(row.solve, seconds_since(start));
                    row.iterations = result.iterations;
                    row.converged = result.converged;
                    if (reference.size() == 0) reference = x;
                    row.difference = (x - reference).norm() / reference.norm();
                }
                rows.push_back(row);
            };
            const auto jacobi = [&](const Objective&) { return Preconditioner::jacobi(problem.A.diagonal()); };
            const auto own = [&](const Objective& objective) { return Preconditioner::of(objective); };
            measure(
                "Jacobi", threads, [](Row&) { return std::function<void(const VecX&, VecX&)>(); }, jacobi);
            VecX blocks(problem.A.rows() * 2);  // the nodes' 2 x 2 diagonal blocks, row-major
            for (Eigen::Index k = 0; k < problem.A.rows() / 2; ++k)
                for (int a = 0; a < 2; ++a)
                    for (int c = 0; c < 2; ++c) blocks[4 * k + 2 * a + c] = problem.A.coeff(2 * k + a, 2 * k + c);
            measure(
                "block Jacobi (2 x 2)", threads, [](Row&) { return std::function<void(const VecX&, VecX&)>(); },
                [&](const Objective&) { return Preconditioner::block_jacobi(blocks, 2); });
            for (const int t : {1, threads}) {
                if (t == threads && threads == 1) break;
                auto multigrid = std::make_shared<GridMultigrid>();
                measure(
                    "grid multigrid (Galerkin, hand-written)", t,
                    [&, multigrid](Row& row) {
                        *multigrid = GridMultigrid();
                        multigrid->set_grid(problem.dim, problem.coordinates, problem.free);
                        multigrid->set_operator(problem.A, true);
                        row.levels = multigrid->levels();
                        return std::function<void(const VecX&, VecX&)>(
                            [multigrid](const VecX& r, VecX& z) { multigrid->apply(r, z); });
                    },
                    own);
            }
#ifdef PNET_HAVE_HYPRE
            {
                std::shared_ptr<BoomerAmg> amg;
                measure(
                    "BoomerAMG (hypre)", 1,
                    [&](Row&) {
                        amg.reset();
                        amg = std::make_shared<BoomerAmg>(problem.A, 2);
                        std::shared_ptr<BoomerAmg> held = amg;
                        return std::function<void(const VecX&, VecX&)>(
                            [held](const VecX& r, VecX& z) { held->apply(r, z); });
                    },
                    own);
            }
#endif
            for (const Row& row : rows)
                std::printf("| %d | %.2g | %.3g | %ld | %s | %d | %s | %.2f | %d%s | %.2f | %.2f | %.1e |\n", cells,
                            youngs, ratio, static_cast<long>(problem.A.rows()), row.name.c_str(), row.threads,
                            row.levels ? std::to_string(row.levels).c_str() : "-", 1e3 * row.setup, row.iterations,
                            row.converged ? "" : " (not converged)", 1e3 * row.solve, 1e3 * (row.setup + row.solve),
                            row.difference);
            std::fflush(stdout);
        }
    }
#ifdef PNET_HAVE_HYPRE
    HYPRE_Finalize();
    MPI_Finalize();
#endif
    return 0;
}
