#pragma once
/// \file mass_solve.hpp
/// The Galerkin transfer scheme's solve (methods/transfer.hpp, scheme=galerkin): the node
/// values u of the moments x = M u, M the scheme's mass matrix, compiled once
/// (runtime/src/numerics/mass_solve.cpp, library hybgen::numerics). M is a mass matrix:
/// M_ik = ∫ ψ_i φ_k with hats φ and the partition of unity ψ, close to symmetric and
/// positive definite, its condition number about 3^N on a tensor grid in N dimensions: a
/// Krylov solver with the diagonal as preconditioner converges in tens of iterations whatever
/// the grid, where a direct factorisation would fill in (3-D and above).

#include <memory>
#include <string>
#include <vector>

#include "hybgen/rt/core/sparse.hpp"

namespace hybgen::rt {

/// u = M⁻¹ x by BiCGSTAB with M's diagonal as preconditioner (Eigen), relative residual
/// kMassSolveTol, then shifted by a constant on the nodes that carry mass so that the mass
/// is exact: cᵀu = 1ᵀx, c the mass of a unit value per node (the column sums of M, which
/// the assembly computes and checks: TransferOperator::column_mass). The scheme's mass is
/// Σ_k c_k u_k, whose budget transfer.hpp checks each step to 1e-12 of the initial mass
/// (kStepBudgetTol); the residual alone would leave 1ᵀ(x − M u), up to √rows times its norm.
/// A row of M without entries (a node no sample of its mode reaches) is solved as u = x there.
class MassSolve {
 public:
  /// Relative residual ‖x − M u‖/‖x‖ the solve asks for (it fails above 100 times this).
  static constexpr double kMassSolveTol = 1e-13;
  /// Set up the solver for M (square), `column_mass` its column sums (M.cols() of them).
  MassSolve(const CsrMatrix& M, std::vector<double> column_mass);
  ~MassSolve();
  MassSolve(const MassSolve&) = delete;             ///< Not copied: it holds the solver.
  MassSolve& operator=(const MassSolve&) = delete;  ///< Not copied.
  /// u = M⁻¹ x, both of M.rows() entries, `u` holding the first guess; false when the
  /// solver did not reach its tolerance (`error` says how far it got).
  bool solve(const double* x, double* u) const;
  /// Why the last solve failed, or "".
  const std::string& error() const;
  /// Iterations of the last solve.
  long iterations() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hybgen::rt
