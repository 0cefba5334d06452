#pragma once
/// \file invariant.hpp
/// Invariant densities and the leading spectrum of a transfer operator (transfer.hpp).
///
/// P is entrywise ≥ 0, so (Perron–Frobenius) its spectral radius ρ is an eigenvalue with a
/// non-negative eigenvector: the invariant density (up to the mass the box leaks per step:
/// P v = ρ v with ρ < 1 when mass leaves, ρ = 1 for a Markov operator). The next
/// eigenvalues by magnitude say how fast other densities settle: a component along the
/// eigenvector of λ₂ decays relative to the invariant one like |λ₂/λ₁|ⁿ after n steps,
/// i.e. at the rate −log|λ₂/λ₁|/h per unit time; the spectral gap is 1 − |λ₂/λ₁|. (The
/// ratio, not |λ₂| alone, so that the leak −log|λ₁|/h — reported separately — is not
/// mistaken for mixing; for λ₁ = 1 both readings agree.)
///
/// Eigen-solver: Spectra's implicitly restarted Arnoldi (GenEigsSolver with
/// SparseGenMatProd over the CSR matrix), selection and sorting by largest magnitude,
/// tolerance `tol` on the Ritz values (Spectra's test: ‖residual‖ ≤ tol·max(|λ|, ε^{2/3})),
/// deterministic start vector (all ones). If Spectra does not converge within `max_restarts`
/// (or `force_power`), the fallback is power iteration on the leading eigenvector alone:
/// v ← P v / Σ|P v| until ‖v_{k+1} − v_k‖₁ ≤ power_tol·‖v_k‖₁; its λ₁ is Σ|P v|/Σ|v| at
/// the end and |λ₂/λ₁| is estimated by the contraction ratio of successive differences
/// (‖v_{k+1} − v_k‖₁/‖v_k − v_{k−1}‖₁ → |λ₂/λ₁|), so the fallback reports λ₂ by modulus only
/// (a real number) and no further eigenvalues.
///
/// Caveat (measured, tests/rt/test_invariant.cpp): Arnoldi's converged Ritz values are
/// eigenvalues, but not necessarily the LARGEST ones when many eigenvalues cluster near the
/// unit circle (transport without mixing: a cycle's e^{2πikh/T}(1 − O(Δx²))). Then raise
/// `search` and ncv until λ₂ stops changing; λ₁ and the invariant density are robust. The
/// defaults (12 eigenvalues in a 60-vector basis, reporting n_eigen of them) resolve the
/// cycle of the test at 51 … 401 nodes, where 4 in 20 or 6 in 30 do not. Memory: ncv
/// vectors of the operator's size (60 × 8 MB at 1025²).

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/sparse.hpp"
#include "hybgen/rt/methods/transfer.hpp"
#include "hybgen/rt/numerics/eigen_solvers.hpp"

namespace hybgen::rt {

/// Options of `invariant_density`.
struct InvariantOptions {
  int n_eigen = 4;  ///< Eigenvalues reported, the leading one included (≥ 2).
  /// Eigenvalues computed (≥ n_eigen): a wider search than reported, because Arnoldi may
  /// miss the largest of a cluster near the unit circle (see the file comment).
  int search = 12;
  int ncv = 0;               ///< Arnoldi basis size; 0: min(5·search, n), at least 2·search + 1.
  double tol = 1e-10;        ///< Spectra's relative tolerance on the Ritz values.
  int max_restarts = 1000;   ///< Spectra's restart limit.
  bool force_power = false;  ///< Skip Spectra (tests of the fallback).
  long power_max_iter = 100000;  ///< Power-iteration limit (each one a mat-vec).
  double power_tol = 1e-12;      ///< Power-iteration stop: relative L1 change per step.
};

/// An invariant density and the leading spectrum.
struct InvariantResult {
  /// Leading eigenvector as node densities, layout [mode][node], sign fixed so that its
  /// discrete mass Σ w u is positive and normalised to 1 (never clipped: see min_value).
  /// A distributed operator: this rank's entries `owned` of it.
  std::vector<double> density;
  Block owned{};           ///< The entries of `density` (every entry in one process).
  double min_value = 0.0;  ///< Smallest entry of `density` (≥ 0 up to the solver tolerance).
  /// Eigenvalues by decreasing magnitude, eigenvalues[0] = λ₁ (real, ≥ 0).
  std::vector<std::complex<double>> eigenvalues;
  double gap = 0.0;         ///< 1 − |λ₂/λ₁|.
  double decay_rate = 0.0;  ///< −log|λ₂/λ₁| / h: settling rate per unit time.
  double leak_rate = 0.0;   ///< −log λ₁ / h: mass lost per unit time by the invariant shape.
  double residual = 0.0;  ///< ‖P v − λ₁ v‖₁ / ‖v‖₁ of the returned vector (in P's variable).
  std::string method;      ///< "spectra" or "power".
  long iterations = 0;     ///< Arnoldi restarts or power iterations.
  bool converged = false;  ///< Whether the chosen method met its tolerance.
};

namespace detail {

/// y = P x (OpenMP, static schedule; serial below kParallelRows rows).
inline void csr_matvec(const CsrMatrix& P, const double* x, double* y) {
  const int* outer = P.outerIndexPtr();
  const int* inner = P.innerIndexPtr();
  const double* val = P.valuePtr();
  const auto R = static_cast<std::int64_t>(P.rows());
#pragma omp parallel for schedule(static) if (R > kParallelRows)
  for (std::int64_t r = 0; r < R; ++r) {
    double s = 0.0;
    for (int k = outer[r]; k < outer[r + 1]; ++k) s += val[k] * x[inner[k]];
    y[r] = s;
  }
}

/// Σ |v_r|.
inline double l1(const std::vector<double>& v) {
  double s = 0.0;
  for (const double x : v) s += std::fabs(x);
  return s;
}

}  // namespace detail

/// The invariant density of `op` (the leading eigenvector of P, as densities of unit mass)
/// and its leading eigenvalues (see the file comment for methods and tolerances). A
/// distributed operator (transfer.hpp, `distributed`) is solved by its backend's
/// eigen-solver (SLEPc's Krylov–Schur, runtime/src/mpi/petsc_matrix.cpp) with the same
/// selection of the Perron root, the same power-iteration fallback and the same
/// normalisation, on every rank's owned entries; each rank keeps its own entries of the
/// density (`owned`).
// GCC 12 at -O3 reports -Wfree-nonheap-object on the vector of Ritz values below in some
// translation units (runner_dim.cpp with N = 2, once generator_solve.hpp shares it): a false
// positive of its inlining, silenced for this function only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wfree-nonheap-object"
template <std::size_t N>
InvariantResult invariant_density(const TransferOperator<N>& op, const InvariantOptions& opt = {}) {
  const auto n = static_cast<Eigen::Index>(op.size());
  if (opt.n_eigen < 2) throw std::invalid_argument("invariant: n_eigen must be >= 2");
  if (n < 4) throw std::invalid_argument("invariant: the operator is too small");
  const Backend& b = op.distributed && op.backend ? *op.backend : serial_backend();
  const Block own = op.distributed ? op.owned : Block{0, op.size()};
  const std::size_t L = own.size();
  // y = P x on the owned entries; Σ over every rank's entries.
  auto apply = [&](const double* x, double* y) {
    if (op.distributed)
      op.distributed->multiply(std::span<const double>(x, L), std::span<double>(y, L));
    else
      detail::csr_matvec(op.P, x, y);
  };
  auto l1 = [&](const std::vector<double>& v) { return b.sum(detail::l1(v)); };
  InvariantResult res;
  std::vector<double> v(L, 0.0);
  double lam1 = 0.0, lam2_abs = std::numeric_limits<double>::quiet_NaN();
  bool have = false;
  // The eigenvalues with the Perron root first, n_eigen of them.
  auto take = [&](const std::vector<std::complex<double>>& ev, int lead) {
    res.eigenvalues.push_back(ev[static_cast<std::size_t>(lead)]);
    for (std::size_t j = 0; j < ev.size(); ++j)
      if (static_cast<int>(j) != lead) res.eigenvalues.push_back(ev[j]);
    if (res.eigenvalues.size() > static_cast<std::size_t>(opt.n_eigen))
      res.eigenvalues.resize(static_cast<std::size_t>(opt.n_eigen));
    lam1 = res.eigenvalues[0].real();
    lam2_abs = res.eigenvalues.size() > 1 ? std::abs(res.eigenvalues[1]) : 0.0;
  };
  if (!opt.force_power && op.distributed) {
    EigenRequest req;
    req.n_eigen = std::min<int>(std::max(opt.n_eigen, opt.search), static_cast<int>(n) - 2);
    req.ncv = opt.ncv;
    req.tol = opt.tol;
    req.max_iterations = opt.max_restarts;
    EigenAnswer a = op.distributed->eigen(req);
    res.iterations = a.iterations;
    if (a.lead >= 0 && a.vector.size() == L) {
      v = std::move(a.vector);
      take(a.eigenvalues, a.lead);
      res.method = a.solver;
      res.converged = a.converged;
      have = true;
    }
  } else if (!opt.force_power) {
    const Eigen::Index nev = std::min<Eigen::Index>(std::max(opt.n_eigen, opt.search), n - 2);
    const Eigen::Index ncv = std::min<Eigen::Index>(
        n, opt.ncv > 0 ? opt.ncv : std::max<Eigen::Index>(2 * nev + 1, 5 * nev));
    const Eigen::VectorXd start = Eigen::VectorXd::Ones(n);
    const EigenPairs eigs =
        largest_eigenpairs(op.P, nev, ncv, start.data(), opt.max_restarts, opt.tol);
    res.iterations = eigs.iterations;
    if (eigs.converged) {
      const std::vector<std::complex<double>>& ev = eigs.values;
      const int lead = perron_index(ev);
      if (lead >= 0) {
        const Eigen::MatrixXcd& vecs = eigs.vectors;
        // A real eigenvalue's eigenvector up to a complex phase: rotate its largest entry real.
        Eigen::Index big = 0;
        for (Eigen::Index r = 1; r < n; ++r)
          if (std::abs(vecs(r, lead)) > std::abs(vecs(big, lead))) big = r;
        const std::complex<double> phase = std::conj(vecs(big, lead)) / std::abs(vecs(big, lead));
        for (Eigen::Index r = 0; r < n; ++r)
          v[static_cast<std::size_t>(r)] = (vecs(r, lead) * phase).real();
        take(ev, lead);
        res.method = "spectra";
        res.converged = true;
        have = true;
      }
    }
  }
  if (!have) {
    // Power iteration from the all-ones vector, normalised in L1 every step.
    res.method = "power";
    res.eigenvalues.clear();
    std::vector<double> y(v.size());
    std::fill(v.begin(), v.end(), 1.0 / static_cast<double>(n));
    double prev_diff = 0.0, ratio = std::numeric_limits<double>::quiet_NaN();
    long it = 0;
    for (; it < opt.power_max_iter; ++it) {
      apply(v.data(), y.data());
      const double norm = l1(y);
      if (!(norm > 0.0)) break;  // nilpotent: everything leaves
      lam1 = norm;               // Σ|P v| / Σ|v| with Σ|v| = 1
      double diff = 0.0;
      for (std::size_t r = 0; r < y.size(); ++r) {
        y[r] /= norm;
        diff += std::fabs(y[r] - v[r]);
      }
      diff = b.sum(diff);
      v.swap(y);
      if (prev_diff > 0.0) ratio = diff / prev_diff;
      prev_diff = diff;
      if (diff <= opt.power_tol) {
        res.converged = true;
        ++it;
        break;
      }
    }
    res.iterations = it;
    lam2_abs = std::isfinite(ratio) ? ratio * lam1 : std::numeric_limits<double>::quiet_NaN();
    res.eigenvalues.emplace_back(lam1, 0.0);
    res.eigenvalues.emplace_back(lam2_abs, 0.0);
  }
  // Residual in P's variable, then sign and mass normalisation.
  {
    std::vector<double> y(v.size());
    apply(v.data(), y.data());
    double num = 0.0;
    for (std::size_t r = 0; r < y.size(); ++r) num += std::fabs(y[r] - lam1 * v[r]);
    res.residual = b.sum(num) / std::max(l1(v), 1e-300);
  }
  // P's variable → densities: the operator acts on node masses.
  std::vector<double> density(L);
  double mass = 0.0;
  for (std::size_t r = 0; r < L; ++r) {
    density[r] = v[r] / op.weight[own.begin + r];
    mass += op.weight[own.begin + r] * density[r];
  }
  mass = b.sum(mass);
  if (mass == 0.0) mass = 1.0;
  double low = std::numeric_limits<double>::infinity();
  for (double& u : density) {
    u /= mass;
    low = std::min(low, u);
  }
  res.min_value = -b.max(-low);
  res.density = std::move(density);
  res.owned = own;
  const double ratio = lam1 > 0.0 ? lam2_abs / lam1 : std::numeric_limits<double>::quiet_NaN();
  res.gap = 1.0 - ratio;
  res.decay_rate = -std::log(ratio) / op.step;
  res.leak_rate = -std::log(lam1) / op.step;
  return res;
}

#pragma GCC diagnostic pop

}  // namespace hybgen::rt
