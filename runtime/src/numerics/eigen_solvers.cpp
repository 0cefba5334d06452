// The solvers of hybgen/rt/numerics/eigen_solvers.hpp: Spectra's and Eigen's, instantiated
// here once.

#include "hybgen/rt/numerics/eigen_solvers.hpp"

// See hybgen/rt/core/sparse.hpp: GCC 12's flow-sensitive warnings misfire inside Eigen and
// Spectra, whose solvers this file instantiates.
HYBGEN_EIGEN_WARNINGS_PUSH
#pragma GCC diagnostic ignored "-Wfree-nonheap-object"
#include <Spectra/GenEigsRealShiftSolver.h>
#include <Spectra/GenEigsSolver.h>
#include <Spectra/MatOp/SparseGenMatProd.h>
#include <Spectra/MatOp/SparseGenRealShiftSolve.h>
#include <Spectra/MatOp/SparseSymShiftSolve.h>
#include <Spectra/SymEigsShiftSolver.h>
#include <Eigen/Dense>
#include <Eigen/SparseLU>

namespace hybgen::rt {

namespace {

/// The converged pairs of a Spectra solver of complex eigenvalues.
template <class Solver>
void take_pairs(Solver& eigs, EigenPairs& out) {
  out.iterations = static_cast<long>(eigs.num_iterations());
  out.converged = eigs.info() == Spectra::CompInfo::Successful;
  if (!out.converged) return;
  const Eigen::VectorXcd ev = eigs.eigenvalues();
  out.values.assign(ev.data(), ev.data() + ev.size());
  out.vectors = eigs.eigenvectors();
}

}  // namespace

EigenPairs largest_eigenpairs(const CsrMatrix& P, Eigen::Index nev, Eigen::Index ncv,
                              const double* start, int max_restarts, double tol) {
  using Product = Spectra::SparseGenMatProd<double, Eigen::RowMajor, int>;
  Product prod(P);
  Spectra::GenEigsSolver<Product> eigs(prod, nev, ncv);
  eigs.init(start);
  eigs.compute(Spectra::SortRule::LargestMagn, max_restarts, tol, Spectra::SortRule::LargestMagn);
  EigenPairs out;
  take_pairs(eigs, out);
  return out;
}

EigenPairs eigenpairs_near(const CscMatrix& L, Eigen::Index nev, Eigen::Index ncv, double sigma,
                           int max_restarts, double tol) {
  using ShiftSolve = Spectra::SparseGenRealShiftSolve<double>;
  ShiftSolve shift(L);
  Spectra::GenEigsRealShiftSolver<ShiftSolve> eigs(shift, nev, ncv, sigma);
  eigs.init();
  eigs.compute(Spectra::SortRule::LargestMagn, max_restarts, tol, Spectra::SortRule::LargestMagn);
  EigenPairs out;
  take_pairs(eigs, out);
  return out;
}

SymmetricEigenPairs largest_symmetric_eigenpairs(const CscMatrix& S, Eigen::Index want,
                                                 double sigma, double tol,
                                                 Eigen::Index dense_below) {
  const Eigen::Index n = S.rows();
  SymmetricEigenPairs out;
  if (n < dense_below || n <= 2 * want + 1) {
    // Ascending from Eigen: the last `want`, reversed.
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es{Eigen::MatrixXd(S)};
    out.values.resize(want);
    out.vectors.resize(n, want);
    for (Eigen::Index q = 0; q < want; ++q) {
      out.values(q) = es.eigenvalues()(n - 1 - q);
      out.vectors.col(q) = es.eigenvectors().col(n - 1 - q);
    }
    out.converged = true;
    return out;
  }
  using ShiftSolve = Spectra::SparseSymShiftSolve<double>;
  ShiftSolve op(S);
  const Eigen::Index ncv = std::min<Eigen::Index>(n, std::max<Eigen::Index>(4 * want, 20));
  Spectra::SymEigsShiftSolver<ShiftSolve> eigs(op, want, ncv, sigma);
  const Eigen::VectorXd start = Eigen::VectorXd::Ones(n);
  eigs.init(start.data());
  // The largest 1/(λ − σ) in modulus are the λ nearest σ; returned by decreasing λ.
  eigs.compute(Spectra::SortRule::LargestMagn, 1000, tol, Spectra::SortRule::LargestAlge);
  out.converged = eigs.info() == Spectra::CompInfo::Successful;
  if (out.converged) {
    out.values = eigs.eigenvalues();
    out.vectors = eigs.eigenvectors();
  }
  return out;
}

std::optional<Eigen::VectorXd> sparse_lu_solve(const CscMatrix& A, const Eigen::VectorXd& b,
                                               std::string* error) {
  Eigen::SparseLU<CscMatrix, Eigen::COLAMDOrdering<int>> lu;
  lu.compute(A);
  if (lu.info() != Eigen::Success) {
    if (error) *error = lu.lastErrorMessage();
    return std::nullopt;
  }
  return Eigen::VectorXd(lu.solve(b));
}

}  // namespace hybgen::rt

HYBGEN_EIGEN_WARNINGS_POP
