#pragma once
/// \file generator_march.hpp
/// The finite-volume generator (generator.hpp) stepped in time: `scheme=fv` of the transfer
/// method (docs/methods.md, "transfer"). Where the invariant method takes the generator's null
/// vector, this integrates the cell masses w = vol·u of
///
///   dw/dt = B u = B diag(1/vol) w
///
/// from the cell averages of u0 to the output times, by the three-stage strong-stability-
/// preserving Runge–Kutta method of Shu and Osher (third order in time):
///
///   w⁽¹⁾ = wⁿ + h A wⁿ,  w⁽²⁾ = ¾ wⁿ + ¼ (w⁽¹⁾ + h A w⁽¹⁾),  wⁿ⁺¹ = ⅓ wⁿ + ⅔ (w⁽²⁾ + h A w⁽²⁾),
///
/// i.e. wⁿ⁺¹ = wⁿ + h (⅙ A wⁿ + ⅙ A w⁽¹⁾ + ⅔ A w⁽²⁾), A = B diag(1/vol).
///
/// Invariants. Every flux of B leaves one cell and enters another, a reset's target or the
/// box's outside, so 1ᵀA w = −oᵀw with o = −1ᵀA the rate at which each cell's mass leaves the
/// box. The step therefore changes the mass by exactly −h (⅙ oᵀwⁿ + ⅙ oᵀw⁽¹⁾ + ⅔ oᵀw⁽²⁾),
/// which is booked as outflow: mass + outflow = mass0 to rounding, checked every step
/// (`budget_defect`). No J, no divergence and no inverse reset is used, so no mass is created
/// at a reset whatever |J| (the fluxes do the work of 1/|J|); there is no atom: mass that a
/// Zeno point would absorb stays in the cells around it.
///
/// Step. h = T/⌈T/h_max⌉ for each output interval T (the outputs are hit exactly), h_max =
/// kFvCfl · min over cells of vol/out_rate (FvOperator::out_rate: the volume leaving a cell
/// per unit time through its downwind faces): in 1-D ν = |X| h/Δx ≤ kFvCfl, and in N-D
/// Σ_d |X_d| h/Δx_d ≤ kFvCfl, within the stability region of this Runge–Kutta method for the
/// upwind reconstructions of order 1–5 (the third-order one is stable to ν ≈ 1.6, the
/// fifth-order one to ν ≈ 1.4). Cuts
/// within Δx/4 of a dual face move that face (make_fv_axis), so no cell is thinner than Δx/4
/// except next to a box face or another cut. A max step (the setting `step` when positive
/// and smaller) caps h.
///
/// Accuracy. Order p (5 by default) along each axis for products of 1-D flows, with the
/// third-order stencils next to walls (generator.hpp); where X_d varies across a face the
/// flux keeps the product rule's transverse term. Fine structure that the flow keeps
/// steepening, as the ball's annulus wound into stripes by its shear, is damped by every
/// grid scheme: order 2.4 there at t = 10 (tests/validation/test_transient_closed_forms.cpp).
/// The time step's error is O(h³) with h ≤ kFvCfl·Δx/|X|, below the space error on the
/// models measured (step 0.0004 against 0.00125 changes the ball's error in its fourth
/// digit). The density jumps exactly at guards and reset images. The upwind reconstruction is
/// linear and unlimited: it conserves mass but not positivity, and undershoots near steep fronts
/// (reported as `min_value`).
///
/// Node values at the output times: fv_node_values (generator.hpp), nodes on a cut averaged;
/// at t = 0, u0 at the nodes (transfer.hpp's initial_vector).

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/core/sparse.hpp"
#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/methods/generator.hpp"
#include "hybgen/rt/methods/transfer.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// The Courant number of the time-stepped generator (see the file comment).
inline constexpr double kFvCfl = 0.8;
/// Cuts closer than this many node spacings to a dual face move it (make_fv_axis).
inline constexpr double kFvMarchSnap = 0.25;
/// A march whose Σ|w| grows past this factor of its start is unstable (a numerical failure).
inline constexpr double kFvGrowthLimit = 10.0;
/// Relative mass-budget defect per step beyond which the march fails (rounding is ~1e-16·cells).
inline constexpr double kFvStepBudgetTol = 1e-10;

/// Options of `fv_march`.
struct FvMarchOptions {
  int order = 5;          ///< Reconstruction order (1–5).
  double max_step = 0.0;  ///< Cap of the time step h (0: kFvCfl alone).
};

/// What `fv_march` produced.
template <std::size_t N>
struct FvMarchRun {
  Solution<N> solution;  ///< Node densities, layout [time][mode][node].
  /// Per output time: mass Σ w, outflow counted per stage; atom 0.
  MassBudget budget;
  double step = 0.0;              ///< The largest time step taken.
  long n_steps = 0;               ///< Steps taken.
  std::size_t unknowns = 0;       ///< Cells.
  std::size_t nonzeros = 0;       ///< Entries of B.
  double min_value = 0.0;         ///< The smallest node density of every frame (undershoot).
  double budget_defect = 0.0;     ///< max over steps |Δmass + Δoutflow| / mass0.
  double assembly_seconds = 0.0;  ///< Building the generator and u0's cell averages.
  double seconds = 0.0;           ///< Marching.
  std::string failure;            ///< Non-empty: a numerical failure (exit 3), where and when.
  /// Whether the march succeeded.
  bool ok() const { return failure.empty(); }
};

namespace detail {

/// The cell averages of u0 in op's cells, (Gauss–Legendre, 2 points per axis, points outside
/// the support counted as 0), per mode in op's order.
template <HybridModel M>
std::vector<double> fv_initial_averages(const FvOperator<state_dim_v<M>>& op, const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  const double g = 0.5 / std::sqrt(3.0);
  std::vector<double> u(op.size(), 0.0);
  for (int m = 0; m < op.n_mode; ++m) {
    const auto& ax = op.axes[static_cast<std::size_t>(m)];
    std::array<std::size_t, N> dims{};
    std::size_t cells = 1;
    for (std::size_t a = 0; a < N; ++a)
      dims[a] = static_cast<std::size_t>(ax[a].cells()), cells *= dims[a];
    const std::size_t base = op.offset[static_cast<std::size_t>(m)];
    const auto total = static_cast<std::int64_t>(cells);
#pragma omp parallel for schedule(static)
    for (std::int64_t c = 0; c < total; ++c) {
      std::array<int, N> k{};
      auto rem = static_cast<std::size_t>(c);
      for (std::size_t a = N; a-- > 0;) k[a] = static_cast<int>(rem % dims[a]), rem /= dims[a];
      double sum = 0.0;
      std::array<double, N> x{};
      for (std::size_t corner = 0; corner < (std::size_t{1} << N); ++corner) {
        for (std::size_t a = 0; a < N; ++a)
          x[a] = ax[a].centre(k[a]) + ((corner >> a) & 1 ? g : -g) * ax[a].width(k[a]);
        if (M::in_support(x.data(), par)) sum += M::initial_density(m, x.data(), par);
      }
      u[base + static_cast<std::size_t>(c)] = sum / static_cast<double>(std::size_t{1} << N);
    }
  }
  return u;
}

}  // namespace detail

/// March M's generator on `grid`, cut at `planes` (fv_guard_planes), from u0 to the sorted
/// output `times` (≥ 0; throws std::invalid_argument otherwise). A step that breaks the budget
/// beyond kFvStepBudgetTol, a non-finite value or Σ|w| growing past kFvGrowthLimit × its start
/// ends the march with `failure`. `progress`, if set, is advanced once per output interval.
template <HybridModel M>
FvMarchRun<state_dim_v<M>> fv_march(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                                    const std::vector<FvGuardPlane>& planes,
                                    std::span<const double> times, const FvMarchOptions& opt,
                                    Progress* progress = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  for (std::size_t k = 0; k < times.size(); ++k)
    if (!(times[k] >= 0.0) || (k > 0 && !(times[k] >= times[k - 1])))
      throw std::invalid_argument("scheme=fv: output times must be sorted and non-negative");
  const auto t0 = std::chrono::steady_clock::now();
  const auto since = [](auto t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  };
  FvMarchRun<N> run;
  const FvOperator<N> op = assemble_fv_generator<M>(grid, par, planes, opt.order, kFvMarchSnap);
  const auto n = static_cast<Eigen::Index>(op.size());
  run.unknowns = op.size();
  run.nonzeros = static_cast<std::size_t>(op.B.nonZeros());
  // A = B diag(1/vol) in row-major order (Eigen parallelises its products with OpenMP).
  Eigen::VectorXd inv_vol(n);
  for (Eigen::Index i = 0; i < n; ++i) inv_vol[i] = 1.0 / op.vol[static_cast<std::size_t>(i)];
  const Eigen::SparseMatrix<double, Eigen::RowMajor> A = op.B * inv_vol.asDiagonal();
  const Eigen::VectorXd out = -(Eigen::RowVectorXd::Ones(n) * A).transpose();
  double h_max = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < op.size(); ++i)
    if (op.out_rate[i] > 0.0) h_max = std::min(h_max, kFvCfl * op.vol[i] / op.out_rate[i]);
  if (opt.max_step > 0.0) h_max = std::min(h_max, opt.max_step);
  const std::vector<double> avg = detail::fv_initial_averages<M>(op, par);
  Eigen::VectorXd w(n);
  for (Eigen::Index i = 0; i < n; ++i)
    w[i] = op.vol[static_cast<std::size_t>(i)] * avg[static_cast<std::size_t>(i)];
  run.assembly_seconds = since(t0);
  const auto t1 = std::chrono::steady_clock::now();

  Solution<N>& sol = run.solution;
  sol.n_time = times.size();
  sol.n_mode = static_cast<std::size_t>(M::n_mode);
  sol.n_point = grid.size();
  sol.u.reserve(sol.n_time * sol.n_mode * sol.n_point);
  MassBudget& mb = run.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = w.sum();
  const double scale = std::max(std::fabs(mb.mass0), std::numeric_limits<double>::min());
  const double l1_0 = std::max(w.lpNorm<1>(), std::numeric_limits<double>::min());
  double t = 0.0, outflow = 0.0;
  run.min_value = std::numeric_limits<double>::infinity();
  Eigen::VectorXd w1(n), w2(n), a0(n), a1(n), a2(n);
  for (std::size_t k = 0; k < times.size() && run.ok(); ++k) {
    const double T = times[k] - t;
    const long steps =
        T > 0.0 ? std::max(1L, static_cast<long>(std::ceil(T / h_max * (1.0 - 1e-12)))) : 0;
    const double h = steps > 0 ? T / static_cast<double>(steps) : 0.0;
    run.step = std::max(run.step, h);
    for (long s = 0; s < steps; ++s) {
      const double mass = w.sum();
      a0.noalias() = A * w;
      w1 = w + h * a0;
      a1.noalias() = A * w1;
      w2 = 0.75 * w + 0.25 * (w1 + h * a1);
      a2.noalias() = A * w2;
      const double lost = h * (out.dot(w) / 6.0 + out.dot(w1) / 6.0 + 2.0 * out.dot(w2) / 3.0);
      w = w / 3.0 + (2.0 / 3.0) * (w2 + h * a2);
      outflow += lost;
      ++run.n_steps;
      const double after = w.sum(), l1 = w.lpNorm<1>();
      const double defect = std::fabs(after + lost - mass) / scale;
      run.budget_defect = std::max(run.budget_defect, std::isfinite(defect) ? defect : HUGE_VAL);
      const double at = t + h * static_cast<double>(s + 1);
      if (!std::isfinite(l1) || l1 > kFvGrowthLimit * l1_0 ||
          !(defect <= kFvStepBudgetTol * std::max(1.0, static_cast<double>(n) / 1e6))) {
        std::ostringstream os;
        os.precision(6);
        os << "the time-stepped generator failed at step " << run.n_steps << " (t = " << at
           << ", step " << h << "): ";
        if (!std::isfinite(l1) || l1 > kFvGrowthLimit * l1_0)
          os << "sum |mass| grew to " << l1 / l1_0 << " times its start (unstable)";
        else
          os << "mass + outflow changed by " << defect << " of the initial mass";
        run.failure = os.str();
        break;
      }
    }
    if (!run.ok()) break;
    t = times[k];
    std::vector<double> cell_u(op.size());
    for (std::size_t i = 0; i < op.size(); ++i)
      cell_u[i] = w[static_cast<Eigen::Index>(i)] / op.vol[i];
    // At t = 0 the frame is u0 at the nodes, as the user wrote it (as the other schemes give
    // it): not its reconstruction from the cell averages, which differs by O(Δx³) and by the
    // mean of two one-sided values at a node on a jump.
    const std::vector<double> nodes =
        times[k] == 0.0 ? initial_vector<M>(grid, par) : fv_node_values(op, grid, cell_u, nullptr);
    for (const double v : nodes) run.min_value = std::min(run.min_value, v);
    sol.u.insert(sol.u.end(), nodes.begin(), nodes.end());
    mb.mass.push_back(w.sum());
    mb.outflow.push_back(outflow);
    mb.atom.push_back(0.0);
    if (progress) progress->advance();
  }
  if (!run.ok()) sol.n_time = sol.u.size() / std::max<std::size_t>(1, sol.n_mode * sol.n_point);
  run.seconds = since(t1);
  return run;
}

}  // namespace hybgen::rt
