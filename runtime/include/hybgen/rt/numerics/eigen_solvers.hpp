#pragma once
/// \file eigen_solvers.hpp
/// The eigen-solvers and the sparse direct solve that the methods call, compiled once
/// (runtime/src/numerics/eigen_solvers.cpp, library hybgen::numerics) instead of in every
/// translation unit that instantiates a method for a model: Spectra's and Eigen's solvers are
/// the same code for every model, and were about a minute of compile time at -O3 in each of
/// the runtime's six dimension objects and in every test that instantiates the methods
/// (docs/hardening.md).

#include <complex>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "hybgen/rt/core/sparse.hpp"

namespace hybgen::rt {

/// Eigenpairs from a Krylov solver.
struct EigenPairs {
  /// The eigenvalues, in the solver's order (by decreasing modulus of what it iterates on:
  /// λ itself, or 1/(λ − σ) in shift-invert mode).
  std::vector<std::complex<double>> values;
  Eigen::MatrixXcd vectors;  ///< One column per eigenvalue (unit 2-norm, arbitrary phase).
  long iterations = 0;       ///< Restarts taken.
  bool converged = false;    ///< Whether every pair asked for met the tolerance.
};

/// The `nev` eigenvalues of largest modulus of P and their vectors: Spectra's implicitly
/// restarted Arnoldi (GenEigsSolver) with `ncv` Krylov vectors (nev + 2 ≤ ncv ≤ n), started
/// from `start` (P.rows() entries), at most `max_restarts` restarts, relative tolerance `tol`.
/// `values` and `vectors` are empty unless it converged.
EigenPairs largest_eigenpairs(const CsrMatrix& P, Eigen::Index nev, Eigen::Index ncv,
                              const double* start, int max_restarts, double tol);

/// The `nev` eigenvalues of L nearest the real shift σ and their vectors: Arnoldi on
/// (L − σI)⁻¹ (Spectra's GenEigsRealShiftSolver, a sparse LU of L − σI), `ncv` Krylov
/// vectors, at most `max_restarts` restarts, relative tolerance `tol`. Throws what Spectra
/// throws (std::invalid_argument for a singular L − σI).
EigenPairs eigenpairs_near(const CscMatrix& L, Eigen::Index nev, Eigen::Index ncv, double sigma,
                           int max_restarts, double tol);

/// The `want` algebraically largest eigenvalues of the symmetric S, in decreasing order, and
/// orthonormal eigenvectors (columns).
struct SymmetricEigenPairs {
  Eigen::VectorXd values;   ///< Decreasing.
  Eigen::MatrixXd vectors;  ///< One column per eigenvalue.
  bool converged = false;   ///< Whether the solver met its tolerance (the dense one always).
};

/// See SymmetricEigenPairs: a dense solver when S has fewer than `dense_below` rows or
/// `want` is not below half of them, else Lanczos in shift-invert mode about σ, which must
/// lie above every eigenvalue of S (the wanted ones, clustered near σ, map to the well
/// separated 1/(λ − σ)), started from the all-ones vector, at most 1000 restarts, relative
/// tolerance `tol`.
SymmetricEigenPairs largest_symmetric_eigenpairs(const CscMatrix& S, Eigen::Index want,
                                                 double sigma, double tol,
                                                 Eigen::Index dense_below);

/// The leading eigenpairs of a symmetric S solved over the connected components of its graph.
struct ComponentEigenPairs {
  /// Per component, its min(`want`, size) largest eigenvalues; all of them by decreasing
  /// value (ties: the earlier component first).
  std::vector<double> values;
  std::vector<std::size_t> component;  ///< The component of each value.
  /// Each value's eigenvector on its component's `members` (unit 2-norm; 0 elsewhere).
  std::vector<Eigen::VectorXd> vectors;
  std::vector<std::vector<std::size_t>> members;  ///< Per component, its rows of S, increasing.
  bool converged = true;  ///< Whether every component's solver met its tolerance.
};

/// ComponentEigenPairs of S: each connected component of S's graph (its nonzero entries)
/// solved on its own by largest_symmetric_eigenpairs (σ, tol, dense_below); a component whose
/// solver does not converge contributes nothing and clears `converged`. Where S is block
/// diagonal an eigenvalue is repeated across the blocks (pieces that never exchange mass), and
/// a Krylov solver started from one vector would find one vector of its eigenspace only.
ComponentEigenPairs largest_eigenpairs_by_component(const CscMatrix& S, Eigen::Index want,
                                                    double sigma, double tol,
                                                    Eigen::Index dense_below);

/// The solution of A x = b by a sparse LU (COLAMD ordering); std::nullopt when the
/// factorisation fails, with the factorisation's message in `error`.
std::optional<Eigen::VectorXd> sparse_lu_solve(const CscMatrix& A, const Eigen::VectorXd& b,
                                               std::string* error);

}  // namespace hybgen::rt
