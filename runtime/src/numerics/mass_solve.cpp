// The mass-matrix solve of hybgen/rt/numerics/mass_solve.hpp: Eigen's BiCGSTAB, instantiated
// here once.

#include "hybgen/rt/numerics/mass_solve.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

// See hybgen/rt/core/sparse.hpp: GCC 12's flow-sensitive warnings misfire inside Eigen.
HYBGEN_EIGEN_WARNINGS_PUSH
#pragma GCC diagnostic ignored "-Wfree-nonheap-object"
#include <Eigen/IterativeLinearSolvers>

namespace hybgen::rt {

struct MassSolve::Impl {
  CsrMatrix M;            ///< M with 1 on the diagonal of its empty rows.
  std::vector<double> c;  ///< The column sums of M: the mass of a unit value per node.
  double c_total = 0.0;   ///< Σ c.
  Eigen::BiCGSTAB<CsrMatrix, Eigen::DiagonalPreconditioner<double>> solver;
  mutable std::string error;
  mutable long iterations = 0;
};

MassSolve::MassSolve(const CsrMatrix& M, std::vector<double> column_mass)
    : impl_(std::make_unique<Impl>()) {
  if (M.rows() != M.cols() || column_mass.size() != static_cast<std::size_t>(M.cols()))
    throw std::invalid_argument("MassSolve: a square matrix and one column mass per column");
  impl_->M = M;
  impl_->c = std::move(column_mass);
  for (const double v : impl_->c) impl_->c_total += v;
  // An empty row (a node that holds no state of its mode) is the identity there: M plus a
  // diagonal of those rows, one sparse sum (inserting into a compressed matrix row by row
  // would move its entries once per row).
  CsrMatrix& A = impl_->M;
  std::vector<Eigen::Triplet<double>> ones;
  for (Eigen::Index r = 0; r < A.rows(); ++r)
    if (A.outerIndexPtr()[r] == A.outerIndexPtr()[r + 1]) ones.emplace_back(r, r, 1.0);
  if (!ones.empty()) {
    CsrMatrix D(A.rows(), A.cols());
    D.setFromTriplets(ones.begin(), ones.end());
    A = CsrMatrix(A + D);
  }
  impl_->solver.setTolerance(kMassSolveTol);
  impl_->solver.setMaxIterations(1000);
  impl_->solver.compute(A);
}

MassSolve::~MassSolve() = default;

bool MassSolve::solve(const double* x, double* u) const {
  const auto n = impl_->M.rows();
  const Eigen::Map<const Eigen::VectorXd> b(x, n);
  Eigen::Map<Eigen::VectorXd> v(u, n);
  const Eigen::VectorXd guess = v;
  v = impl_->solver.solveWithGuess(b, guess);
  impl_->iterations = static_cast<long>(impl_->solver.iterations());
  // BiCGSTAB's own estimate stops at the tolerance or where rounding stalls it; what the
  // budget needs is the true residual.
  const double rel = (b - impl_->M * v).norm() / std::max(b.norm(), 1e-300);
  if (rel <= 1e2 * kMassSolveTol) {
    // The mass exact: shift the nodes that carry mass by one constant.
    double mass = 0.0, target = 0.0;
    for (Eigen::Index r = 0; r < n; ++r) {
      mass += impl_->c[static_cast<std::size_t>(r)] * u[r];
      target += x[r];
    }
    if (impl_->c_total > 0.0) {
      const double shift = (target - mass) / impl_->c_total;
      for (Eigen::Index r = 0; r < n; ++r)
        if (impl_->c[static_cast<std::size_t>(r)] != 0.0) u[r] += shift;
    }
    impl_->error.clear();
    return true;
  }
  char msg[160];
  std::snprintf(msg, sizeof msg,
                "the mass-matrix solve stopped at a relative residual of %.3g after %ld "
                "iterations (wanted %.0e)",
                rel, impl_->iterations, 1e2 * kMassSolveTol);
  impl_->error = msg;
  return false;
}

const std::string& MassSolve::error() const {
  return impl_->error;
}

long MassSolve::iterations() const {
  return impl_->iterations;
}

}  // namespace hybgen::rt

HYBGEN_EIGEN_WARNINGS_POP
