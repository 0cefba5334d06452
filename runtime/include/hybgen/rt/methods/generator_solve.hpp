#pragma once
/// \file generator_solve.hpp
/// The invariant density and the spectrum of the finite-volume generator (generator.hpp), and
/// their errors estimated from a second resolution: `scheme=fv` of the invariant method.
///
/// Null vector. The bordered system [[B, vol], [volᵀ, 0]] [u; σ] = [0; 1] (Eigen's SparseLU,
/// COLAMD ordering): B u = −σ·vol and Σ vol·u = 1. Summing the rows, σ = −1ᵀBu/Σvol is the
/// rate at which u's mass leaves the box over the box's volume: 0 (to rounding) when u is the
/// null vector of unit mass of an invariant set inside the box. When σ > 0 and μ₁ < 0 no
/// invariant set lies in the box, and the density is instead the eigenvector of the rightmost
/// eigenvalue μ₁ < 0 of L (quasi-stationary; `leak_rate` = −μ₁).
///
/// Spectrum. The eigenvalues μ of L = diag(1/vol)·B nearest a real shift s = −kFvShift·rate
/// (Spectra's GenEigsRealShiftSolver over a SparseLU of L − sI; a real shift on the real
/// matrix: no complex arithmetic; a complex shift would need a complex copy of L), sorted by
/// decreasing Re μ, except that μ = 0 of a closed system goes first when the ones before it
/// tie with it (kFvTie); reported as the transfer operator's λ = exp(μh), h the setting `step`
/// (else dt), so |λ₁| = e^{Re μ₁ h} = 1 to rounding for a closed system.
///
/// Errors. The grid's nodes are solved again on the grid of (n+1)/2 nodes per axis (every
/// coarse node is a fine one; n odd on every axis) and, when that is odd too, on (n+3)/4.
/// D = max over modes of Σ w|u_n − u_(n+1)/2| / Σ w|u_n| over the coarse nodes (trapezoid
/// weights w; nodes on a cut of the mode excluded: two-valued). For order p the fine error is
/// ≈ D/(2^p − 1), so D itself covers it with a margin of ≈ 7 for p = 3 and ≈ 3 for p = 2
/// (measured 6.8–7.2 for p = 3 in tests/validation/test_invariant_fv.cpp); for p = 5
/// `error_factor` is 1/4, keeping the margin near 8; for p = 1 the margin is ≈ 1 and
/// `error_factor` doubles it. `error` = factor·D; each eigenvalue's `error` is
/// factor·|λ(n) − λ((n+1)/2)| for the coarse eigenvalue nearest it, plus kFvRoundingUlps
/// units of rounding; the gap's, the decay
/// rate's and the leak rate's likewise, and a gap within its error of 0 claims no decay
/// (two_grid.hpp: the cycles' eigenvalues lie on the unit circle up to the scheme's damping,
/// which falls like n^{−p}). The observed order log2(D((n+3)/4 → (n+1)/2) / D) says whether
/// the estimate is in its asymptotic regime (`error_reliable`, two_grid.hpp's `order_near`).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/sparse.hpp"
#include "hybgen/rt/methods/generator.hpp"
#include "hybgen/rt/methods/two_grid.hpp"
#include "hybgen/rt/model.hpp"
#include "hybgen/rt/numerics/eigen_solvers.hpp"

namespace hybgen::rt {

/// The shift of the eigen-solver, as a fraction of the model's rate (FvOperator::rate).
inline constexpr double kFvShift = 1e-2;
/// A density below −this × its maximum is oscillating, not rounding (scheme=auto's test,
/// methods.hpp `solve_by_invariant_fv`).
inline constexpr double kFvNegativeTolerance = 1e-6;
/// Rates within this × the model's rate of each other are a tie (rounding and the scheme's
/// damping of a cycle, not a decay): the leak test and λ₁'s choice.
inline constexpr double kFvTie = 1e-8;
/// The eigenvalues' error floor in units of rounding: λ = exp(μh) from a shift-invert solve.
inline constexpr double kFvRoundingUlps = 16.0;
/// Fewest nodes per axis of a grid the error estimate solves on.
inline constexpr int kFvMinNodes = 5;

/// One grid's solution.
struct FvGridSolution {
  std::vector<double> density;           ///< Node densities [mode][node], unit mass.
  std::vector<char> on_jump;             ///< Per (mode, node): on a cut of the mode.
  std::vector<std::complex<double>> mu;  ///< Eigenvalues of L, by decreasing Re μ.
  double sigma = 0.0;                    ///< The bordered system's multiplier.
  double residual = 0.0;         ///< ‖B u + σ vol‖₁ / (rate · Σ vol|u|) of the returned u.
  std::size_t unknowns = 0;      ///< Cells.
  std::size_t nonzeros = 0;      ///< Entries of B.
  double rate = 0.0;             ///< FvOperator::rate.
  bool leaks = false;            ///< Mass leaves the box: u is μ₁'s eigenvector.
  bool eigen_converged = false;  ///< Whether Spectra met its tolerance.
  long iterations = 0;           ///< Arnoldi restarts.
  std::string failure;           ///< Non-empty: what failed.
};

/// Options of `fv_invariant`.
struct FvOptions {
  int order = 5;       ///< Reconstruction order p.
  int n_eigen = 6;     ///< Eigenvalues reported.
  double step = 1.0;   ///< h of λ = e^{μh}.
  double tol = 1e-10;  ///< Spectra's tolerance.
};

/// The density on the grid, the spectrum, and their estimated errors (see the file comment).
struct FvInvariantResult {
  FvGridSolution fine;                       ///< On the run's grid.
  std::vector<std::complex<double>> lambda;  ///< e^{μh}, n_eigen of them.
  std::vector<int> coarse_nodes;             ///< Nodes per axis of the coarse grid (or empty).
  double error = std::numeric_limits<double>::quiet_NaN();  ///< Density, relative L1.
  std::vector<double> mode_errors;  ///< Per mode (NaN: a mode without mass).
  double observed_order = std::numeric_limits<double>::quiet_NaN();  ///< From three grids.
  std::optional<bool> error_reliable;  ///< observed_order near the order (two_grid.hpp).
  SpectrumErrors spectrum;             ///< The rates of λ and their errors (two_grid.hpp).
  double seconds_fine = 0.0, seconds_coarse = 0.0;  ///< Wall time per part.
  std::vector<std::string> notes;                   ///< What the summary should say.
  /// The densities on the halved and quartered grids (detail::fv_half_grid; empty where not
  /// solved), for the observables' errors (observables.hpp).
  std::vector<double> coarse_density, quarter_density;
};

namespace detail {

/// The bordered system's solution (see the file comment): u, and σ as its last entry; empty,
/// with `failure` set, when the LU finds it singular.
template <std::size_t N>
std::optional<Eigen::VectorXd> fv_bordered_solve(const FvOperator<N>& op, std::string& failure) {
  using SpMat = Eigen::SparseMatrix<double>;
  const auto n = static_cast<Eigen::Index>(op.size());
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(static_cast<std::size_t>(op.B.nonZeros()) + 2 * op.size());
  for (Eigen::Index c = 0; c < op.B.outerSize(); ++c)
    for (SpMat::InnerIterator it(op.B, c); it; ++it) t.emplace_back(it.row(), it.col(), it.value());
  for (Eigen::Index r = 0; r < n; ++r) {
    t.emplace_back(r, n, op.vol[static_cast<std::size_t>(r)]);
    t.emplace_back(n, r, op.vol[static_cast<std::size_t>(r)]);
  }
  SpMat A(n + 1, n + 1);
  A.setFromTriplets(t.begin(), t.end());
  A.makeCompressed();
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n + 1);
  rhs[n] = 1.0;
  std::string lu_error;
  std::optional<Eigen::VectorXd> solved = sparse_lu_solve(A, rhs, &lu_error);
  if (!solved)
    failure = "the bordered generator is singular (" + lu_error +
              "): the null space has several dimensions (a region the flow never leaves, "
              "or a rest point on a face?)";
  return solved;
}

}  // namespace detail

/// Solve the generator of M on `grid` (see the file comment).
template <HybridModel M>
FvGridSolution fv_solve_grid(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                             const std::vector<FvGuardPlane>& planes, const FvOptions& o) {
  using SpMat = Eigen::SparseMatrix<double>;
  const FvOperator<state_dim_v<M>> op = assemble_fv_generator<M>(grid, par, planes, o.order);
  FvGridSolution s;
  const auto n = static_cast<Eigen::Index>(op.size());
  s.unknowns = op.size();
  s.nonzeros = static_cast<std::size_t>(op.B.nonZeros());
  s.rate = op.rate > 0.0 ? op.rate : 1.0;
  const std::optional<Eigen::VectorXd> solved = detail::fv_bordered_solve(op, s.failure);
  if (!solved) return s;
  const Eigen::VectorXd& sol = *solved;
  std::vector<double> u(sol.data(), sol.data() + n);
  s.sigma = sol[n];
  // Spectrum of L near the shift.
  SpMat L = op.B;
  for (Eigen::Index c = 0; c < L.outerSize(); ++c)
    for (SpMat::InnerIterator it(L, c); it; ++it)
      it.valueRef() /= op.vol[static_cast<std::size_t>(it.row())];
  const Eigen::Index nev = std::min<Eigen::Index>(std::max(o.n_eigen + 2, 8), n - 2);
  if (nev >= 1) {
    const Eigen::Index ncv = std::min<Eigen::Index>(n, std::max<Eigen::Index>(2 * nev + 1, 30));
    try {
      const EigenPairs eigs = eigenpairs_near(L, nev, ncv, -kFvShift * s.rate, 1000, o.tol);
      s.iterations = eigs.iterations;
      if (eigs.converged) {
        s.eigen_converged = true;
        const Eigen::Map<const Eigen::VectorXcd> ev(eigs.values.data(),
                                                    static_cast<Eigen::Index>(eigs.values.size()));
        std::vector<Eigen::Index> order(static_cast<std::size_t>(ev.size()));
        for (Eigen::Index k = 0; k < ev.size(); ++k) order[static_cast<std::size_t>(k)] = k;
        std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) {
          const std::complex<double> x = ev[a], y = ev[b];
          if (x.real() != y.real()) return x.real() > y.real();
          if (std::fabs(x.imag()) != std::fabs(y.imag()))
            return std::fabs(x.imag()) < std::fabs(y.imag());
          return x.imag() > y.imag();
        });
        // λ₁ is the invariant density's. At order 5 a cycle's eigenvalues lie on the unit
        // circle to ~1e-10 either side (Re μ of either sign), and the sort by Re μ alone may
        // put one of them before μ = 0: the real eigenvalue nearest 0 goes first when every
        // one before it is within kFvTie·rate of its real part (a tie, not a growing mode).
        const double tie = kFvTie * s.rate;
        auto first = order.end();
        for (auto it = order.begin(); it != order.end(); ++it) {
          const std::complex<double> m = ev[*it];
          if (std::fabs(m.imag()) <= tie && std::fabs(m.real()) <= tie &&
              (first == order.end() || std::abs(m) < std::abs(ev[*first])))
            first = it;
        }
        if (first != order.end() && std::all_of(order.begin(), first, [&](Eigen::Index k) {
              return ev[k].real() <= ev[*first].real() + tie;
            }))
          std::rotate(order.begin(), first, first + 1);
        for (const Eigen::Index k : order) s.mu.push_back(ev[k]);
        // Mass leaves the box: the density is μ₁'s eigenvector (real: rotate its phase).
        s.leaks = s.sigma > tie && s.mu.front().real() < -tie;
        if (s.leaks) {
          const Eigen::MatrixXcd& V = eigs.vectors;
          const Eigen::Index k = order.front();
          Eigen::Index big = 0;
          for (Eigen::Index r = 1; r < n; ++r)
            if (std::abs(V(r, k)) > std::abs(V(big, k))) big = r;
          const std::complex<double> ph = std::conj(V(big, k)) / std::abs(V(big, k));
          double mass = 0.0;
          for (Eigen::Index r = 0; r < n; ++r) {
            u[static_cast<std::size_t>(r)] = (V(r, k) * ph).real();
            mass += op.vol[static_cast<std::size_t>(r)] * u[static_cast<std::size_t>(r)];
          }
          for (double& x : u) x /= mass;
        }
      }
    } catch (const std::exception& e) {
      s.failure = std::string("the eigen-solver failed: ") + e.what();
    }
  }
  // Residual of the returned u: B u + σ·vol for the bordered solution, B u − μ₁·vol·u for the
  // eigenvector.
  {
    const Eigen::Map<const Eigen::VectorXd> uv(u.data(), n);
    const Eigen::VectorXd Bu = op.B * uv;
    double num = 0.0, den = 0.0;
    const double mu1 = s.leaks ? s.mu.front().real() : 0.0;
    for (Eigen::Index r = 0; r < n; ++r) {
      const double v = op.vol[static_cast<std::size_t>(r)];
      num += std::fabs(Bu[r] + (s.leaks ? -mu1 * v * uv[r] : s.sigma * v));
      den += v * std::fabs(uv[r]);
    }
    s.residual = num / (s.rate * std::max(den, 1e-300));
  }
  s.density = fv_node_values(op, grid, u, &s.on_jump);
  return s;
}

namespace detail {

/// The grid with (n+1)/2 nodes per axis on the same box, if every n is odd and the result has
/// kFvMinNodes nodes or more.
template <std::size_t N>
std::optional<TensorGrid<N>> fv_half_grid(const TensorGrid<N>& g) {
  for (std::size_t a = 0; a < N; ++a)
    if (g.axes[a].n % 2 == 0 || (g.axes[a].n + 1) / 2 < kFvMinNodes) return std::nullopt;
  return halved_grid(g);
}

}  // namespace detail

/// A density whose positive part u⁺ has a residual ‖B u⁺‖₁ / (rate · Σ vol·u⁺) below this is
/// itself a null vector: u mixes the densities of disjoint invariant sets (the null space has
/// several dimensions; tests/validation/models/two_sawtooths.model), rather than oscillating.
inline constexpr double kFvSplitTolerance = 1e-8;

/// Why a density that oscillates is not kept: `where` it oscillated (empty for the run's grid,
/// else ending in a space), its minimum `lo` and maximum `hi`.
inline std::string fv_oscillation_reason(const std::string& where, double lo, double hi) {
  char b[400];
  std::snprintf(b, sizeof b,
                "the finite-volume generator's density oscillated (min %.3g against max %.3g), "
                "as it does where the density has features below the grid spacing (a measure "
                "concentrated near an attracting cycle); hat keeps it non-negative",
                lo, hi);
  return where + b;
}

namespace detail {

/// The minimum and maximum of the node values of the cell averages `u` of `op` on `grid` when
/// they oscillate: the minimum is below −kFvNegativeTolerance × the maximum and the positive
/// part u⁺ is not a null vector of B (kFvSplitTolerance); else nothing.
template <std::size_t N>
std::optional<std::pair<double, double>> fv_oscillation(const FvOperator<N>& op,
                                                        const TensorGrid<N>& grid,
                                                        const std::vector<double>& u) {
  const std::vector<double> nodes = fv_node_values(op, grid, u, nullptr);
  const auto [lo, hi] = std::minmax_element(nodes.begin(), nodes.end());
  if (lo == nodes.end() || !(*lo < -kFvNegativeTolerance * *hi)) return std::nullopt;
  const auto n = static_cast<Eigen::Index>(op.size());
  const Eigen::VectorXd plus = Eigen::Map<const Eigen::VectorXd>(u.data(), n).cwiseMax(0.0);
  const Eigen::VectorXd Bplus = op.B * plus;
  double den = 0.0;
  for (Eigen::Index r = 0; r < n; ++r) den += op.vol[static_cast<std::size_t>(r)] * plus[r];
  const double rate = op.rate > 0.0 ? op.rate : 1.0;
  if (Bplus.lpNorm<1>() <= kFvSplitTolerance * rate * den) return std::nullopt;
  return std::pair{*lo, *hi};
}

}  // namespace detail

/// Why scheme=auto should not solve the generator on `grid`, judged on the probe grid of
/// (n+3)/4 nodes per axis, or "" when it should (or the probe does not apply). The probe costs one
/// bordered LU on about 4^−N of the unknowns and no eigen-solve, where the run's grid costs the LU,
/// a shift-invert Arnoldi (most of the time) and the coarse grids: on the shipped 2-D models whose
/// invariant measure concentrates on an attracting cycle or point (models/integrate_and_fire.model,
/// 129 × 167), the full solve took 8.7 s before its density was found to oscillate and dropped for
/// hat's 1.3 s.
///
/// The density oscillates when a node value is below −kFvNegativeTolerance × the maximum and
/// its positive part is not a null vector (kFvSplitTolerance). A density resolved on the run's
/// grid but not on the probe's is then left to hat, which is first order but non-negative and
/// carries its own error estimate; `--set scheme=fv` still solves it on the run's grid. In 1-D
/// (where every solve is cheap) and where (n+3)/4 is below kFvMinNodes on an axis the
/// probe does not apply: the run's grid decides (methods.hpp, `solve_by_invariant_fv`).
template <HybridModel M>
std::string fv_probe_oscillation(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                                 const std::vector<FvGuardPlane>& planes, const FvOptions& o) {
  constexpr std::size_t N = state_dim_v<M>;
  if constexpr (N < 2) return "";
  TensorGrid<N> probe = grid;
  std::string shape;
  for (GridAxis& a : probe.axes) {
    a.n = (a.n + 3) / 4;
    if (a.n < kFvMinNodes) return "";
    shape += (shape.empty() ? "" : " x ") + std::to_string(a.n);
  }
  const FvOperator<N> op = assemble_fv_generator<M>(probe, par, planes, o.order);
  std::string failure;
  const std::optional<Eigen::VectorXd> solved = detail::fv_bordered_solve(op, failure);
  if (!solved) return "";  // the run's grid reports it
  const std::vector<double> u(solved->data(), solved->data() + solved->size() - 1);
  const auto range = detail::fv_oscillation(op, probe, u);
  if (!range) return "";
  return fv_oscillation_reason("on the probe grid of " + shape + " nodes ", range->first,
                               range->second) +
         " (--set scheme=fv solves it on the run's grid)";
}

/// The invariant density of M by the finite-volume generator on `grid`, cut at `planes`
/// (fv_guard_planes of the same grid), its spectrum as the transfer operator's over `o.step`,
/// and their errors from the coarser grids (see the file comment).
template <HybridModel M>
FvInvariantResult fv_invariant(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                               const FvOptions& o, const std::vector<FvGuardPlane>& planes) {
  constexpr std::size_t N = state_dim_v<M>;
  using Clock = std::chrono::steady_clock;
  FvInvariantResult r;
  const auto t0 = Clock::now();
  r.fine = fv_solve_grid<M>(grid, par, planes, o);
  r.seconds_fine = std::chrono::duration<double>(Clock::now() - t0).count();
  if (!r.fine.failure.empty()) return r;
  const double h = o.step, factor = error_factor(o.order);
  // λ = exp(μh) is known to a few units of rounding: the eigenvalues' error floor.
  const double floor = kFvRoundingUlps * std::numeric_limits<double>::epsilon();
  const std::size_t ne =
      std::min<std::size_t>(static_cast<std::size_t>(o.n_eigen), r.fine.mu.size());
  for (std::size_t k = 0; k < ne; ++k) r.lambda.push_back(std::exp(r.fine.mu[k] * h));
  r.spectrum = spectrum_errors(r.lambda, {}, h, factor);  // the rates; errors below
  const auto t1 = Clock::now();
  const std::optional<TensorGrid<N>> half = detail::fv_half_grid(grid);
  if (!half) {
    r.notes.push_back(
        "no error estimate: it needs an odd number of nodes on every axis, at least " +
        std::to_string(2 * kFvMinNodes - 1) + " (the coarse grid's nodes are every other node)");
    return r;
  }
  for (std::size_t a = 0; a < N; ++a) r.coarse_nodes.push_back(half->axes[a].n);
  const FvGridSolution c = fv_solve_grid<M>(*half, par, planes, o);
  if (!c.failure.empty()) {
    r.notes.push_back("no error estimate: on the coarse grid " + c.failure);
    return r;
  }
  const auto difference = [](const TensorGrid<N>& f, const FvGridSolution& fs,
                             const TensorGrid<N>& cg, const FvGridSolution& cs,
                             std::vector<double>* per_mode) {
    return coarse_difference(f, std::span<const double>(fs.density),
                             std::span<const char>(fs.on_jump), cg,
                             std::span<const double>(cs.density), std::span<const char>(cs.on_jump),
                             M::n_mode, per_mode);
  };
  const double D = difference(grid, r.fine, *half, c, &r.mode_errors);
  r.coarse_density = c.density;
  r.error = factor * D;
  for (double& e : r.mode_errors) e *= factor;
  std::vector<std::complex<double>> coarse_lambda;
  for (const std::complex<double> m : c.mu) coarse_lambda.push_back(std::exp(m * h));
  r.spectrum = spectrum_errors(r.lambda, coarse_lambda, h, factor, floor);
  if (r.spectrum.decays == false)
    r.notes.push_back(
        "the spectral gap is within its estimated error of 0: no decay is claimed (the "
        "eigenvalues after the first lie on the unit circle up to the scheme's damping, "
        "which falls like n^-p: a cycle, not mixing)");
  // A third grid for the observed order.
  if (const std::optional<TensorGrid<N>> quarter = detail::fv_half_grid(*half)) {
    const FvGridSolution q = fv_solve_grid<M>(*quarter, par, planes, o);
    if (q.failure.empty()) {
      const double D2 = difference(*half, c, *quarter, q, nullptr);
      if (D > 0.0 && D2 > 0.0) r.observed_order = std::log2(D2 / D);
      r.quarter_density = q.density;
    }
  }
  if (std::isfinite(r.observed_order)) r.error_reliable = order_near(r.observed_order, o.order);
  if (r.error_reliable == false)
    r.notes.push_back("the observed order of convergence is " + std::to_string(r.observed_order) +
                      ", not near " + std::to_string(o.order) +
                      ": the grids are not in the asymptotic regime (or the density is not "
                      "smooth between cuts), and the error estimate is unreliable");
  r.seconds_coarse = std::chrono::duration<double>(Clock::now() - t1).count();
  return r;
}

/// fv_invariant on the planes of M's guards in the box; throws std::invalid_argument for a
/// guard it cannot cut (fv_guard_planes).
template <HybridModel M>
FvInvariantResult fv_invariant(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                               const FvOptions& o) {
  return fv_invariant<M>(grid, par, o, fv_guard_planes<M>(grid, par));
}

}  // namespace hybgen::rt
