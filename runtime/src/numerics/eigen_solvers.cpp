// The solvers of hybgen/rt/numerics/eigen_solvers.hpp: Spectra's and Eigen's, instantiated
// here once.

#include "hybgen/rt/numerics/eigen_solvers.hpp"

#include <algorithm>
#include <utility>
#include <vector>

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

/// Connected components of the graph of the symmetric sparse S: component index per row.
std::vector<std::size_t> components(const Eigen::SparseMatrix<double>& S, std::size_t* count) {
  const auto n = static_cast<std::size_t>(S.rows());
  std::vector<std::size_t> comp(n, n);
  std::vector<std::size_t> stack;
  std::size_t c = 0;
  for (std::size_t s = 0; s < n; ++s) {
    if (comp[s] != n) continue;
    comp[s] = c;
    stack.push_back(s);
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      for (Eigen::SparseMatrix<double>::InnerIterator e(S, static_cast<Eigen::Index>(i)); e; ++e) {
        const auto j = static_cast<std::size_t>(e.row());
        if (comp[j] == n && e.value() != 0.0) comp[j] = c, stack.push_back(j);
      }
    }
    ++c;
  }
  *count = c;
  return comp;
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

ComponentEigenPairs largest_eigenpairs_by_component(const CscMatrix& S, Eigen::Index want,
                                                    double sigma, double tol,
                                                    Eigen::Index dense_below) {
  const auto s = static_cast<std::size_t>(S.rows());
  std::size_t count = 0;
  const std::vector<std::size_t> comp = components(S, &count);
  ComponentEigenPairs out;
  out.members.resize(count);
  for (std::size_t i = 0; i < s; ++i) out.members[comp[i]].push_back(i);
  struct Pair {
    double value;
    std::size_t component;
    Eigen::VectorXd vector;
  };
  std::vector<Pair> pairs;
  std::vector<std::size_t> local(s, s);
  for (std::size_t c = 0; c < count; ++c) {
    const std::vector<std::size_t>& m = out.members[c];
    const auto size = static_cast<Eigen::Index>(m.size());
    for (std::size_t i = 0; i < m.size(); ++i) local[m[i]] = i;
    std::vector<Eigen::Triplet<double>> t;
    for (const std::size_t i : m)
      for (CscMatrix::InnerIterator e(S, static_cast<Eigen::Index>(i)); e; ++e)
        t.emplace_back(static_cast<int>(local[static_cast<std::size_t>(e.row())]),
                       static_cast<int>(local[i]), e.value());
    CscMatrix Sc(size, size);
    Sc.setFromTriplets(t.begin(), t.end());
    const Eigen::Index k = std::min<Eigen::Index>(want, size);
    const SymmetricEigenPairs e = largest_symmetric_eigenpairs(Sc, k, sigma, tol, dense_below);
    if (!e.converged) {
      out.converged = false;
      continue;
    }
    for (Eigen::Index q = 0; q < k; ++q) pairs.push_back({e.values(q), c, e.vectors.col(q)});
  }
  std::stable_sort(pairs.begin(), pairs.end(),
                   [](const Pair& a, const Pair& b) { return a.value > b.value; });
  for (Pair& p : pairs) {
    out.values.push_back(p.value);
    out.component.push_back(p.component);
    out.vectors.push_back(std::move(p.vector));
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
