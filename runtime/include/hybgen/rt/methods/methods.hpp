#pragma once
/// \file methods.hpp
/// The solver methods of `hybgen run` behind one interface: each takes the grid, the output
/// times and the parameters and returns a `MethodResult` — densities on the grid nodes at
/// the output times, the mass budget, and the method's own summary fields — which the runner
/// writes out the same way whatever the method (docs/design.md run contract). Each row of the
/// methods table (method_table.hpp) has its solve function in `solvers`, with one signature;
/// `solve_method` dispatches through it.
///
///  - characteristics: exact backward characteristics per node (characteristics.hpp); the
///    budget by adaptive cubature of the same characteristics (budget.hpp);
///  - transfer: one step h as a sparse matrix on node masses, marched by mat-vecs
///    (transfer.hpp); scheme `hat` (default) or `cell`, both conserving mass column by column;
///  - invariant: the leading eigenvector of the transfer operator and the next eigenvalues
///    (invariant.hpp); one frame, `invariant`, instead of the time series; with scheme=fv the
///    null vector and the spectrum of the finite-volume generator instead, with their
///    estimated errors (generator.hpp, generator_solve.hpp);
///  - particles: Monte-Carlo samples of u0 pushed forward and deposited (particles.hpp);
///  - escape: an open system's escape rate −ln λ₁/h and its conditionally invariant density,
///    the leading eigenpair of the transfer operator (invariant.hpp) on the grid and on the
///    halved grid for the error (escape.hpp); one frame, `escape`;
///  - almost_invariant: K almost-invariant sets of a closed system and their invariance
///    ratios (almost_invariant.hpp), on the grid and on the halved grid for their errors; one
///    frame, the invariant density, and the sets as `set_label`;
///  - coherent: K coherent pairs between t = 0 and t_end (coherent.hpp) from the transport over
///    the interval, on the grid and on the halved grid for their errors; two frames (the
///    initial density and the transported one), the pairs' sets at both as `set_label`.
///
/// Invariants of a successful result: solution.n_time == frame_names.size() (or, for the
/// particles with density=marginals, an empty solution and marginals with one block per
/// frame and mode); for the time
/// methods frame_times == times and budget.{mass, outflow, atom} have one entry per time (none
/// with budget=off) with mass + outflow + atom = mass0: for characteristics within the
/// terms' estimated errors, each measured on its own (budget.hpp; a run whose budget does not
/// close warns); counted per sample for particles and per column for the transfer operator.

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/method_table.hpp"
#include "hybgen/rt/methods/almost_invariant.hpp"
#include "hybgen/rt/methods/budget.hpp"
#include "hybgen/rt/methods/budget/cell_averages.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/coherent.hpp"
#include "hybgen/rt/methods/escape.hpp"
#include "hybgen/rt/methods/mass_budget.hpp"
#include "hybgen/rt/methods/observables.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "hybgen/rt/model.hpp"
#include "hybgen/rt/setting_rules.hpp"
#include "hybgen/rt/settings.hpp"

#include "hybgen/rt/methods/generator_march.hpp"
#include "hybgen/rt/methods/generator_solve.hpp"
#include "hybgen/rt/methods/invariant.hpp"
#include "hybgen/rt/methods/transfer.hpp"
#include "hybgen/rt/methods/two_grid.hpp"

namespace hybgen::rt {

/// budget=fast: the relative tolerance it uses at least.
inline constexpr double kFastBudgetTol = 1e-2;
/// budget=fast: the point cap of each of its cubatures.
inline constexpr std::size_t kFastBudgetPoints = 20000;
/// The budget closes when |defect| ≤ kDefectFactor·(its estimated error) + kDefectFloor·mass0:
/// the estimates are ≈ 2σ estimates, not bounds (budget.hpp), and the sum of three of them
/// (the drop mass0 − mass, the outflow, the atom)
/// exceeds its own defect now and then on a budget that is right (pendulum at a wall: 1.1×);
/// twice the sum is ≈ 4σ. kDefectFloor covers rounding.
inline constexpr double kDefectFactor = 2.0;
inline constexpr double kDefectFloor = 1e-12;  ///< See kDefectFactor.

/// The settings every method reads (from the run configuration).
struct MethodSettings {
  /// The run's settings (settings.hpp: method, tol, max_events, budget, budget_tol, step,
  /// scheme, samples, eigenvalues, particles, seed). The mass budget of characteristics
  /// (`solve_by_characteristics`): fast (the default: to max(budget_tol, kFastBudgetTol)
  /// with at most kFastBudgetPoints per integral, about the cost of the solve on the shipped
  /// models), full (to budget_tol), off (none: summary.json's mass, outflow and atom are
  /// empty).
  Settings settings;
  bool quiet = false;  ///< No progress output.
  /// characteristics: per guard, the pre-flight's seeds for enumerating pre-images
  /// (CharacteristicsOptions::preimage_seeds); null or empty: every reset is injective.
  const std::vector<std::vector<double>>* preimage_seeds = nullptr;
  /// The ranks sharing the work (core/backend.hpp); null: this process alone. Every rank
  /// calls the method; with several ranks each keeps its block of every frame
  /// (Solution::distributed), and the budget and summary are the same on every rank.
  const Backend* backend = nullptr;

  /// Set a number setting; throws std::invalid_argument when the table refuses it.
  MethodSettings& set(std::string_view name, double x) {
    SettingValue v;
    v.number = x, v.has_number = true;
    settings.assign(name, v);
    return *this;
  }
  /// Set a word setting; throws std::invalid_argument when the table refuses it.
  MethodSettings& set(std::string_view name, std::string_view word) {
    SettingValue v;
    v.word = std::string(word);
    settings.assign(name, v);
    return *this;
  }
};

/// What a method produced.
template <std::size_t N>
struct MethodResult {
  Solution<N> solution;                  ///< Densities, layout [frame][mode][node].
  std::vector<std::string> frame_names;  ///< Output file stem per frame (u_0000, …).
  std::vector<double> frame_times;       ///< Time per frame (empty for `invariant`).
  MassBudget budget;                     ///< Per frame time (empty for `invariant`).
  /// particles with density=marginals: the pairs and moments (then `solution` is empty).
  Marginals marginals;
  std::vector<double> atom_error;  ///< Estimated |error| of budget.atom (may be empty).
  /// How the observables' errors are estimated (observables.hpp), and from what: the same
  /// answer on the halved and quartered grids (`coarse`) of a scheme of order `order`, or
  /// the samples' own expectations (`sampled_observables`, particles; or, computed by the
  /// method too, the cell averages' cubature of f u: budget/cell_averages.hpp).
  ObservableErrorKind observable_errors = ObservableErrorKind::none;
  std::vector<CoarseAnswer<N>> coarse;                ///< See observable_errors.
  int order = 1;                                      ///< See observable_errors.
  std::vector<ObservableSeries> sampled_observables;  ///< See observable_errors.
  /// Whether `solution` holds cell averages (characteristics, values=cells).
  bool cell_averages = false;
  /// almost_invariant: the set (1 … K, 0: none) of every (mode, node), [mode][node];
  /// coherent: the same at each of its two frames, [frame][mode][node]; empty for the other
  /// methods.
  std::vector<std::int32_t> set_label;
  nlohmann::json summary = nlohmann::json::object();  ///< Method fields for summary.json.
  std::vector<std::string> warnings;                  ///< Printed, not fatal.
  std::string failure;    ///< Non-empty: a numerical failure (exit 3), what/where/when.
  double solve_s = 0.0;   ///< Seconds solving (assembly + march for transfer).
  double budget_s = 0.0;  ///< Seconds on the mass budget (characteristics only).
  /// Whether the method succeeded.
  bool ok() const { return failure.empty(); }
};

namespace detail {

using MethodClock = std::chrono::steady_clock;

inline double seconds_since(MethodClock::time_point t0) {
  return std::chrono::duration<double>(MethodClock::now() - t0).count();
}

inline std::string frame_name(std::size_t k) {
  char b[32];
  std::snprintf(b, sizeof b, "u_%04zu", k);
  return b;
}

/// Frame names u_0000.. and times for a time series.
template <std::size_t N>
void set_time_frames(MethodResult<N>& r, std::span<const double> times) {
  r.frame_times.assign(times.begin(), times.end());
  r.frame_names.clear();
  for (std::size_t k = 0; k < times.size(); ++k) r.frame_names.push_back(frame_name(k));
}

/// The ODE tolerances of `s` (rtol = tol, atol = tol/100) and its event cap into `o`, a
/// CharacteristicsOptions or ForwardOptions: the one place every method takes them from.
template <class Options>
void set_ode_settings(const MethodSettings& s, Options& o) {
  const double tol = s.settings.real<"tol">();
  o.ode.rtol = tol;
  o.ode.atol = tol * 1e-2;
  o.max_events = static_cast<int>(s.settings.integer<"max_events">());
}

inline CharacteristicsOptions trace_options(const MethodSettings& s) {
  CharacteristicsOptions opt;
  set_ode_settings(s, opt);
  opt.preimage_seeds = s.preimage_seeds;
  opt.backend = s.backend;
  return opt;
}

/// The transfer operator's options from the settings; throws std::invalid_argument where
/// the settings' own rule refuses the scheme (setting_rules.hpp, galerkin_scheme_rule: the
/// front door says so before anything runs; this is for the library's callers).
inline TransferOptions transfer_options(const MethodSettings& s, double dt) {
  TransferOptions o;
  const double step = s.settings.real<"step">();
  o.step = step > 0 ? step : dt;
  o.scheme = parse_scheme(s.settings.word<"scheme">());
  if (const std::string why = galerkin_scheme_rule(s.settings, s.backend ? s.backend->ranks() : 1);
      !why.empty())
    throw std::invalid_argument(why);
  o.samples_per_axis = static_cast<int>(s.settings.integer<"samples">());
  set_ode_settings(s, o.forward);
  o.backend = s.backend;
  return o;
}

/// The operator's part of summary.json: scheme, step, samples, size, conservation, time.
template <std::size_t N>
nlohmann::json operator_summary(const TransferOptions& o, const TransferOperator<N>& op) {
  return {{"scheme", scheme_name(o.scheme)},
          {"step", o.step},
          {"samples_per_axis", op.samples_per_axis},
          {"column_defect", op.column_defect},
          {"rows", op.size()},
          {"nonzeros", op.nonzeros()},
          {"matrix_bytes_per_rank", op.matrix_bytes()},
          {"ghost_entries", op.ghost_entries()},
          {"assembly_seconds", op.seconds}};
}

/// Whether the assembly failed; if so, r carries the failure and the time spent.
template <std::size_t N>
bool assembly_failed(const TransferOperator<N>& op, MethodResult<N>& r,
                     MethodClock::time_point t0) {
  if (op.ok()) return false;
  r.failure = "(assembling the transfer operator) " + op.failure_message;
  r.solve_s = seconds_since(t0);
  return true;
}

/// Assemble the transfer operator of M with a progress bar (titled `what`) over its rows.
template <HybridModel M>
TransferOperator<state_dim_v<M>> assemble(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                                          TransferOptions o, bool quiet,
                                          const char* what = "transfer operator: assembly") {
  // Each rank assembles its block of the columns: rank 0's bar counts its own share.
  const Backend& backend = o.backend ? *o.backend : serial_backend();
  Progress progress(what, backend.block(grid.size() * static_cast<std::size_t>(M::n_mode)).size(),
                    quiet);
  o.progress = &progress;
  return assemble_transfer<M>(grid, par, o);
}

/// The one frame of a method that answers with one density ([mode][node], n_mode × n_point
/// entries): `density` as frame `method.frame`.
template <std::size_t N>
void set_density_frame(MethodResult<N>& r, std::size_t n_mode, std::size_t n_point,
                       std::vector<double> density, const MethodSpec& method) {
  r.solution.n_time = 1;
  r.solution.n_mode = n_mode;
  r.solution.n_point = n_point;
  r.solution.u = std::move(density);
  r.frame_names = {std::string(method.frame)};
}

/// The one frame of a method that answers with the leading eigenvector of `op` (invariant,
/// escape): `inv`'s density as frame `method.frame`, distributed as the operator is.
template <std::size_t N>
void set_eigenvector_frame(MethodResult<N>& r, const TransferOperator<N>& op,
                           const InvariantResult& inv, const MethodSpec& method) {
  set_density_frame(r, op.n_mode, op.n_node, inv.density, method);
  if (op.distributed) r.solution.distributed = true, r.solution.owned = inv.owned;
}

/// A coarser grid's one-frame answer (an eigenvector, [mode][node]) for the observables'
/// errors (observables.hpp); nothing when it is empty (not computed, or distributed).
template <std::size_t N>
void keep_coarse_frame(MethodResult<N>& r, const TensorGrid<N>& grid, std::vector<double> u,
                       std::size_t n_mode) {
  if (u.size() != n_mode * grid.size()) return;
  Solution<N> c;
  c.n_time = 1, c.n_mode = n_mode, c.n_point = grid.size(), c.u = std::move(u);
  r.coarse.push_back({grid, std::move(c)});
}

/// The eigenvalues of `inv` as summary.json lists them: re, im, abs.
inline nlohmann::json eigenvalues_json(const InvariantResult& inv) {
  nlohmann::json eig = nlohmann::json::array();
  for (const auto& l : inv.eigenvalues)
    eig.push_back({{"re", l.real()}, {"im", l.imag()}, {"abs", std::abs(l)}});
  return eig;
}

/// Per-mode values (one per mode of M, in its order) as summary.json's object by mode name.
template <HybridModel M>
nlohmann::json by_mode(const std::vector<double>& values) {
  nlohmann::json modes = nlohmann::json::object();
  for (std::size_t m = 0; m < static_cast<std::size_t>(M::n_mode) && m < values.size(); ++m)
    modes[M::mode_names[m]] = values[m];
  return modes;
}

/// A number, or null when it is not finite (no estimate).
inline nlohmann::json number_or_null(double x) {
  return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json();
}

/// The spectrum's members of the invariant block of summary.json, every one with its error
/// (two_grid.hpp; null: no estimate): `eigenvalues` (re, im, abs, error), `spectral_gap`,
/// `decay_rate`, `leak_rate`, and the decisions `decays` and `leaks`.
inline void add_spectrum_json(nlohmann::json& j, std::span<const std::complex<double>> lambda,
                              const SpectrumErrors& e) {
  nlohmann::json eig = nlohmann::json::array();
  for (std::size_t k = 0; k < lambda.size(); ++k)
    eig.push_back(
        {{"re", lambda[k].real()},
         {"im", lambda[k].imag()},
         {"abs", std::abs(lambda[k])},
         {"error", number_or_null(k < e.lambda_error.size() ? e.lambda_error[k] : std::nan(""))}});
  j["eigenvalues"] = eig;
  j["spectral_gap"] = e.gap;
  j["spectral_gap_error"] = number_or_null(e.gap_error);
  j["decay_rate"] = e.decay_rate;
  j["decay_rate_error"] = number_or_null(e.decay_rate_error);
  j["leak_rate"] = e.leak_rate;
  j["leak_rate_error"] = number_or_null(e.leak_rate_error);
  j["decays"] = e.decays ? nlohmann::json(*e.decays) : nlohmann::json();
  j["leaks"] = e.leaks ? nlohmann::json(*e.leaks) : nlohmann::json();
}

/// A density's largest value over its largest value on a coarser grid (NaN if that is not
/// positive): ≈ 1 for a bounded density, ≈ 2^c for a measure concentrated on a set of
/// codimension c that the grid resolves to its spacing (a cycle in the plane: 2).
inline double max_growth(std::span<const double> fine, std::span<const double> coarse) {
  if (fine.empty() || coarse.empty()) return std::numeric_limits<double>::quiet_NaN();
  const double a = *std::max_element(fine.begin(), fine.end());
  const double b = *std::max_element(coarse.begin(), coarse.end());
  return b > 0.0 ? a / b : std::numeric_limits<double>::quiet_NaN();
}

/// The growth of the maximum, at each of two halvings, beyond which an invariant density is
/// taken for a measure concentrated below the grid's spacing: √2, a peak growing at least
/// like h^(−1/2) (the width of a cycle smeared by a first-order scheme's diffusion).
inline constexpr double kConcentratedGrowth = 1.4142;

/// The density's error members of the invariant block (two_grid.hpp; null: no estimate).
inline void add_density_error_json(nlohmann::json& j, double error,
                                   const std::vector<double>& mode_errors, double observed_order,
                                   std::optional<bool> reliable,
                                   const std::vector<int>& coarse_nodes) {
  j["error"] = number_or_null(error);
  j["mode_errors"] = nlohmann::json::array();
  for (const double e : mode_errors) j["mode_errors"].push_back(number_or_null(e));
  j["observed_order"] = number_or_null(observed_order);
  j["error_reliable"] = reliable ? nlohmann::json(*reliable) : nlohmann::json();
  j["coarse_grid"] = coarse_nodes;
}

/// An invariant density that is not unique (λ₂ within the errors of λ₁: two_grid.hpp,
/// `leading_eigenvalue_repeats`; the fv generator: μ₂ ties with μ₁): the grids' solvers need
/// not pick the same one, so their difference is no error estimate. The density's error, its
/// modes' and `reliable` are withdrawn, and a warning says why, in `notes` and `warnings`.
inline void withdraw_not_unique_error(std::complex<double> l1, std::complex<double> l2, double step,
                                      double& error, std::vector<double>& mode_errors,
                                      std::optional<bool>& reliable,
                                      std::vector<std::string>& notes,
                                      std::vector<std::string>& warnings) {
  error = std::numeric_limits<double>::quiet_NaN();
  for (double& e : mode_errors) e = error;
  reliable = false;
  char b[700];
  std::snprintf(b, sizeof b,
                "lambda2 = %.12g%+.3gi is within the errors of lambda1 = %.12g: the invariant "
                "density is not unique (the system has several invariant sets, or the "
                "transfer operator over step = %g is the identity to within the eigen-solver's "
                "tolerance: raise step), and the frame is one of them, the solver's choice; no "
                "error is estimated",
                l2.real(), l2.imag(), l1.real(), step);
  notes.push_back(b);
  warnings.push_back(b);
}

/// What a spectrum's decisions tell the user (two_grid.hpp): no decay, mass that leaves.
inline void spectrum_warnings(const SpectrumErrors& e, std::vector<std::string>& warnings) {
  if (e.leaks == true)
    warnings.push_back(
        "mass leaves the box: lambda1 is below 1 by more than its error (leak rate " +
        std::to_string(e.leak_rate) + " +/- " + std::to_string(e.leak_rate_error) +
        " per unit time), so no density in the box is invariant; the frame is the "
        "conditionally invariant density. method=escape reports the escape rate with its "
        "error");
}

/// The cell averages' point cap per traced point of their first pass (each dual cell's
/// Gauss nodes and its halves'): budget=fast refines to 4 times that work, full to 16 times.
inline constexpr std::size_t kCellWorkFast = 4, kCellWorkFull = 16;
/// The largest memory the cell averages may take (their per-root and per-leaf sums).
inline constexpr double kCellAverageBytes = 4.0 * (1 << 30);

/// Characteristics' last stage (the setting `values`): with values=cells, or values=auto where
/// the nodes' trapezoid sums under-resolve the density (core/solution.hpp,
/// under_resolved_frame), r.solution's node values become the dual cells' averages
/// (budget/cell_averages.hpp), to the budget's tolerance; summary.json's `values` block says
/// which and why, with the averages' estimated relative L1 error per frame.
template <HybridModel M>
void cell_average_stage(const TensorGrid<state_dim_v<M>>& grid, std::span<const double> times,
                        const double* par, const CharacteristicsOptions& opt,
                        const MethodSettings& s, MethodResult<state_dim_v<M>>& r) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::string& want = s.settings.word<"values">();
  const Backend& backend = s.backend ? *s.backend : serial_backend();
  const std::size_t K = times.size(), Mn = static_cast<std::size_t>(M::n_mode);
  nlohmann::json& j = r.summary[summary_key::values];
  j = {{"kind", "nodes"}, {"setting", want}};
  if (want == "nodes") return;
  std::string why = "values=cells asks for them";
  std::vector<double> sums(K, 0.0);
  for (std::size_t k = 0; k < K; ++k)
    sums[k] = observable_sums<M>(grid, r.solution, k, 1, par, backend).back();
  if (want == "auto") {
    const std::size_t k = under_resolved_frame(r.budget, sums);
    if (k == K) return;
    char b[200];
    std::snprintf(b, sizeof b,
                  "the nodes under-resolve the density (values=auto): at t = %g their trapezoid "
                  "sum is %.4g but the mass is %.4g",
                  times[k], sums[k], r.budget.mass[k]);
    why = b;
  }
  const auto refuse = [&](const std::string& what) {
    j["reason"] = what;
    r.warnings.push_back("cell averages: " + what + "; the grid holds the node values");
  };
  for (std::size_t a = 0; a < N; ++a)
    if (grid.axes[a].n < 2) return refuse("an axis with one node has no dual cells");
  const bool full = s.settings.word<"budget">() == "full";
  AdaptiveOptions aopt;
  aopt.rel_tol = full ? s.settings.real<"budget_tol">()
                      : std::max(s.settings.real<"budget_tol">(), kFastBudgetTol);
  // The mass per frame: the budget's, or without a budget the nodes' trapezoid sums.
  const std::vector<double>& mass = r.budget.mass.size() == K ? r.budget.mass : sums;
  double scale = r.budget.mass0;
  for (const double m : mass) scale = std::max(scale, m);
  // Each dual cell in 1, then 2, then 4 parts per axis, until the cells' masses agree with the
  // budget's (budget/cell_averages.hpp: what the first pass can miss).
  CellAverages<N> ca;
  std::vector<double> gap(K, 0.0);
  double secs = 0.0;
  int parts_used = 1;
  bool agrees = true;
  for (int parts = 1; parts <= 4; parts *= 2) {
    const double split = std::pow(static_cast<double>(parts), static_cast<double>(N));
    const double pass = 3.0 * std::pow(kCellAverageOrder, static_cast<double>(N)) * split *
                        static_cast<double>(grid.size());  // the rule's nodes, split once
    // 5 sums per slot (masses and observables), for each root and about twice as many leaves.
    const auto slots =
        static_cast<double>(K * (Mn + static_cast<std::size_t>(observable_count<M>())));
    const double bytes = 8.0 * 5.0 * slots * 3.0 * split * static_cast<double>(grid.size());
    if (bytes > kCellAverageBytes) {
      if (parts > 1) break;
      char b[200];
      std::snprintf(b, sizeof b, "they would take about %.1f GiB (the cap is %.0f)",
                    bytes / (1 << 30), kCellAverageBytes / (1 << 30));
      return refuse(b);
    }
    parts_used = parts;
    aopt.root_parts = parts;
    aopt.max_points = static_cast<std::size_t>(pass) * (full ? kCellWorkFull : kCellWorkFast);
    const auto t0 = MethodClock::now();
    if (!s.quiet)
      std::printf(
          "cell averages (%s): %zu dual cells in %d part(s) per axis, at least %.0f "
          "points\n",
          want == "auto" ? "the nodes under-resolve the density" : "values=cells", grid.size(),
          parts, pass);
    TraceFailure<N> failure;
    ca = cell_averages<M>(grid, times, par, opt, aopt, scale, r.solution, failure);
    secs += seconds_since(t0);
    if (!failure.ok()) {
      r.solve_s += secs;
      r.failure = "(cell averages) " + describe<M>(failure);
      return;
    }
    if (r.budget.mass.size() != K) break;
    agrees = true;
    for (std::size_t k = 0; k < K; ++k) {
      gap[k] = std::fabs(ca.mass[k] - r.budget.mass[k]);
      agrees = agrees && gap[k] <= 2.0 * (ca.l1_error[k] + r.budget.mass_error[k]);
    }
    if (agrees) break;
  }
  r.solve_s += secs;
  for (std::size_t k = 0; k < K; ++k) ca.l1_error[k] = std::max(ca.l1_error[k], gap[k]);
  if (observable_count<M>() > 0) {
    r.sampled_observables = std::move(ca.observables);
    r.observable_errors = ObservableErrorKind::cells;
  }
  std::vector<double> rel(K, 0.0);
  for (std::size_t k = 0; k < K; ++k)
    rel[k] = mass[k] > 0.0 ? ca.l1_error[k] / mass[k] : ca.l1_error[k];
  const Block own = r.solution.owned;
  const bool distributed = r.solution.distributed;
  r.solution.u = std::move(ca.averages.u);
  r.solution.distributed = false;
  if (distributed) r.solution.keep_only(own);
  r.cell_averages = true;
  j = {{"kind", "cells"},
       {"setting", want},
       {"reason", why},
       {"rel_tol", aopt.rel_tol},
       {"points", ca.points},
       {"cells", ca.cells},
       {"parts", parts_used},
       {"converged", ca.converged},
       {"error", rel},
       {"error_note",
        "per frame, the estimated L1 error of the cell averages (the sum over the dual cells of "
        "|C|·|average − exact average|) over the mass in the box"},
       {"seconds", secs}};
  if (!ca.converged) {
    char b[400];
    std::snprintf(b, sizeof b,
                  "the cell averages reached their point cap (%zu points) before their tolerance "
                  "%.1e: their estimated relative L1 error is up to %.2g (summary.json "
                  "values.error)%s",
                  ca.points, aopt.rel_tol, *std::max_element(rel.begin(), rel.end()),
                  full ? "" : "; --set budget=full refines them further");
    r.warnings.push_back(b);
  }
  if (!agrees) {
    const auto k = static_cast<std::size_t>(std::max_element(gap.begin(), gap.end()) - gap.begin());
    char b[400];
    std::snprintf(b, sizeof b,
                  "the cell averages miss mass that the budget measures: at t = %g they hold "
                  "%.6g against %.6g +/- %.2g; their error estimate (summary.json values.error) "
                  "includes the gap",
                  times[k], ca.mass[k], r.budget.mass[k], r.budget.mass_error[k]);
    r.warnings.push_back(b);
  }
}

}  // namespace detail

/// The characteristics method and its adaptive mass budget (`dt` unused).
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_characteristics(const TensorGrid<state_dim_v<M>>& grid,
                                                      std::span<const double> times, double,
                                                      const double* par, const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  detail::set_time_frames(r, times);
  r.observable_errors = ObservableErrorKind::quadrature;  // exact node values
  CharacteristicsOptions opt = detail::trace_options(s);
  const auto t0 = detail::MethodClock::now();
  {
    const Backend& backend = s.backend ? *s.backend : serial_backend();
    Progress progress("characteristics",
                      backend.block(grid.size() * static_cast<std::size_t>(M::n_mode)).size(),
                      s.quiet);
    opt.progress = &progress;
    r.solution = solve_grid<M>(grid, times, par, opt);
  }
  opt.progress = nullptr;
  r.solve_s = detail::seconds_since(t0);
  if (!r.solution.ok()) {
    r.failure = describe<M>(r.solution.failure);
    return r;
  }
  const std::string& budget_kind = s.settings.word<"budget">();
  const double budget_tol = s.settings.real<"budget_tol">();
  if (budget_kind == "off") {
    r.summary[summary_key::budget] = {{"kind", "off"}};
    detail::cell_average_stage<M>(grid, times, par, opt, s, r);
    return r;
  }
  // The mass budget integrates u(t) adaptively (characteristics at the cubature nodes): a
  // grid rule cannot integrate the unbounded, striped density near a Zeno point.
  const auto t1 = detail::MethodClock::now();
  AdaptiveOptions aopt;
  aopt.rel_tol = budget_tol;
  if (budget_kind == "fast") {
    aopt.rel_tol = std::max(budget_tol, kFastBudgetTol);
    aopt.max_points = kFastBudgetPoints;
  }
  AdaptiveBudgetInfo info;
  const BudgetResult<N> budget =
      adaptive_mass_budget<M>(grid, times, par, opt, aopt, &info, &r.solution);
  r.budget_s = detail::seconds_since(t1);
  if (!budget.ok()) {
    r.failure =
        "(mass budget) " + (budget.message.empty() ? describe<M>(budget.failure) : budget.message);
    return r;
  }
  r.budget = budget.budget;
  const bool converged = info.volume.converged && info.surface.converged && info.atom.converged &&
                         info.reset.converged;
  if (!converged) {
    char b[400];
    std::snprintf(b, sizeof b,
                  "the mass budget reached %s before its tolerance %.1e; "
                  "the error estimates in summary.json say how far it got",
                  budget_bounds_reached(info).c_str(), aopt.rel_tol);
    r.warnings.push_back(b);
  }
  const MassBudget& mb = r.budget;
  r.atom_error = mb.atom_error;
  // The budget's own check: every term is measured on its own, so what none accounts for
  // (the defect) must lie within the terms' estimated errors.
  const std::vector<double> defect = budget_defect(mb), bar = budget_defect_error(mb);
  double worst = 0.0, worst_ratio = 0.0;
  std::size_t worst_k = 0;
  for (std::size_t k = 0; k < defect.size(); ++k) {
    worst = std::max(worst, std::fabs(defect[k]));
    const double ratio =
        std::fabs(defect[k]) / (kDefectFactor * bar[k] + kDefectFloor * std::fabs(mb.mass0));
    if (ratio > worst_ratio) worst_ratio = ratio, worst_k = k;
  }
  // The defect is the sum of the terms' errors, and nothing says which term holds it. Where
  // the budget does not close, some term missed mass (a thin strip between the cubature's
  // first samples: docs/hardening.md, the differential campaign): each term's bar at that time
  // is widened by |defect|. Where it closes, each bar is still at least |defect|: a defect
  // inside the sum of the bars may lie in a term whose own bar is narrow (the differential
  // campaign's model 2430 at t = 1.5: the box mass 0.0157 ± 0.0048 against 0.0400 by Monte
  // Carlo, the defect 0.024 inside twice the sum of the bars, 0.031, which the outflow's
  // dominated; a strip of density 49 thinner than the grid's spacing that no cubature node
  // saw).
  std::vector<double> widened(defect.size(), 0.0);
  // Without guards there is no Zeno point: the atom is 0 by construction, and so is its bar.
  std::vector<std::vector<double>*> bars = {&r.budget.mass_error, &r.budget.outflow_error};
  if (M::n_guard > 0) bars.push_back(&r.budget.atom_error);
  // The defect's own bar is the one measured, before the widening (every output agrees:
  // summary.json, run.nc, the report, the figures and the run's printout).
  r.budget.defect_error = bar;
  for (std::vector<double>& a : r.budget.absorbed_error) bars.push_back(&a);
  for (std::size_t k = 0; k < defect.size(); ++k) {
    const double d = std::fabs(defect[k]);
    const bool closes = d <= kDefectFactor * bar[k] + kDefectFloor * std::fabs(mb.mass0);
    if (!closes) widened[k] = d;
    for (std::vector<double>* e : bars)
      if (k < e->size()) (*e)[k] = closes ? std::max((*e)[k], d) : (*e)[k] + d;
  }
  r.atom_error = mb.atom_error;
  if (worst_ratio > 1.0) {
    char b[640];
    std::snprintf(b, sizeof b,
                  "the mass budget does not close: at t = %g, mass0 - mass - outflow - atom = "
                  "%.3e, %.1fx twice its estimated error %.2e. Mass no term measures: mass "
                  "from outside the grid box that a reset carries into it, mass from outside "
                  "the box at a Zeno point, or an error the estimates missed; the error bars of "
                  "%s are widened by |defect| there. A box that holds the "
                  "initial density closes it; else try --set budget_tol=%.0e",
                  times[worst_k], defect[worst_k], worst_ratio, bar[worst_k],
                  M::n_guard > 0 ? "mass, outflow and atom" : "mass and outflow",
                  aopt.rel_tol / 10);
    r.warnings.push_back(b);
  }
  r.summary[summary_key::budget] = {{"kind", budget_kind},
                                    {"rel_tol", aopt.rel_tol},
                                    {"volume_points", info.volume.points},
                                    {"check_points", info.volume.check_points},
                                    {"face_points", info.surface.points},
                                    {"atom_points", info.atom.points},
                                    {"impact_points", info.impact_points},
                                    {"impact_seconds", info.impact_seconds},
                                    {"converged", converged},
                                    {"time_capped", info.surface.time_capped},
                                    {"defect", defect},
                                    {"defect_error", bar},
                                    {"closes", worst_ratio <= 1.0},
                                    {"widened_by", widened},
                                    {"mass_error", mb.mass_error},
                                    {"outflow_error", mb.outflow_error},
                                    {"reset_outflow", mb.reset_outflow},
                                    {"seconds", r.budget_s}};
  detail::cell_average_stage<M>(grid, times, par, opt, s, r);
  return r;
}

namespace detail {

/// The errors of a transfer run per output time (two_grid.hpp), into the transfer summary
/// `t`: the same scheme (same step and samples; for fv the same order) marched on the halved
/// grid and on the quartered one by `solve_on(grid, title)`, which returns an empty Solution
/// when it fails. At each time and for each mode m, D_k is the relative L1 difference of the
/// mode's density from the halved grid's and D'_k the halved grid's from the quartered one's;
/// the observed order p_k = log2(D'_k/D_k) and the mode's estimate f(p_k)·D_k, the frame's
/// E_k the largest over modes (each mode with its own order: a mode fed through a reset can
/// converge at another rate than the rest, or not at all), with
/// f(p) = max(error_factor(order), m/(2^p − 1)), p clamped to ≥ 1/4 (the margin 2 of a
/// first-order scheme, 1 — a margin of 2^p − 1 — of order 2 or 3, and the Richardson factor
/// of a slower one: 2.4 at p = 1/2); m = 1 up to order 3. Above, error_factor is below 1 and
/// the Richardson term alone has no margin where the coarse grids' order overstates the fine
/// grid's, as it does before the asymptotic range (measured: fv at order 5 on the ball's
/// annulus, ratios 0.87–0.95 with m = 1; near the ball's origin, first order, p = 1.85 from
/// 33², 65², 129²). Roache's grid convergence index multiplies the Richardson estimate by a
/// safety factor of 3 outside the asymptotic range; here m = clamp(2p − 1, 1, 3): 3 for an
/// observed order of 2 and more, none at p ≤ 1, where 1/(2^p − 1) is already wide (4.1 at
/// p = 0.3). The initial frame is u0 at the nodes: 0. A
/// frame where some mode's p_k is below 1/4 or missing is flagged unreliable. Over several
/// processes nothing is estimated (the frames are distributed).
template <std::size_t N, class SolveOn>
void add_transfer_errors(nlohmann::json& t, MethodResult<N>& r, const TensorGrid<N>& grid,
                         std::span<const double> times, int order, const MethodSettings& s,
                         SolveOn&& solve_on) {
  const Solution<N>& sol = r.solution;
  r.observable_errors = ObservableErrorKind::coarse;
  r.order = order;
  if (sol.distributed || (s.backend && s.backend->ranks() > 1)) {
    t["errors"] = nullptr;
    t["error_note"] = "no error estimate over several processes";
    return;
  }
  const auto t0 = MethodClock::now();
  const TensorGrid<N> half = halved_grid(grid), quarter = halved_grid(half);
  Solution<N> c = solve_on(half, "transfer: halved grid");
  Solution<N> q = solve_on(quarter, "transfer: quartered grid");
  const auto frame = [](const Solution<N>& u, std::size_t k) {
    return std::span<const double>(u.u.data() + u.index(k, 0, 0), u.n_mode * u.n_point);
  };
  const std::span<const char> none;
  const int n_mode = static_cast<int>(sol.n_mode);
  nlohmann::json errors = nlohmann::json::array(), orders = nlohmann::json::array(),
                 reliable = nlohmann::json::array();
  bool all_reliable = true;
  for (std::size_t k = 0; k < times.size(); ++k) {
    if (times[k] == 0.0) {
      errors.push_back(0.0), orders.push_back(nullptr), reliable.push_back(true);
      continue;
    }
    if (c.n_time != times.size()) {
      errors.push_back(nullptr), orders.push_back(nullptr), reliable.push_back(nullptr);
      all_reliable = false;
      continue;
    }
    // Per mode: its own difference, observed order and factor (a mode fed through a reset
    // can converge at another rate than the rest, or not at all).
    std::vector<double> dm, d2m;
    coarse_difference(grid, frame(sol, k), none, half, frame(c, k), none, n_mode, &dm);
    if (q.n_time == times.size())
      coarse_difference(half, frame(c, k), none, quarter, frame(q, k), none, n_mode, &d2m);
    double estimate = 0.0, p = std::numeric_limits<double>::quiet_NaN(), worst_d = -1.0;
    bool ok = true;
    for (int m = 0; m < n_mode; ++m) {
      const double D = dm[static_cast<std::size_t>(m)];
      if (!std::isfinite(D)) continue;  // no mass in this mode on the fine grid
      const double D2 =
          d2m.empty() ? std::numeric_limits<double>::quiet_NaN() : d2m[static_cast<std::size_t>(m)];
      const double pm =
          D > 0.0 && D2 > 0.0 ? std::log2(D2 / D) : std::numeric_limits<double>::quiet_NaN();
      const double margin = order > 3 ? std::clamp(2.0 * pm - 1.0, 1.0, 3.0) : 1.0;
      const double factor = std::isfinite(pm)
                                ? std::max(error_factor(order), margin / richardson_divisor(pm))
                                : error_factor(1);
      ok = ok && std::isfinite(pm) && pm >= 0.25;
      estimate = std::max(estimate, factor * D);
      if (D > worst_d) worst_d = D, p = pm;  // the order reported: the largest difference's
    }
    all_reliable = all_reliable && ok;
    errors.push_back(number_or_null(estimate));
    orders.push_back(number_or_null(p));
    reliable.push_back(ok);
  }
  std::vector<int> coarse_nodes;
  for (const GridAxis& a : half.axes) coarse_nodes.push_back(a.n);
  t["errors"] = errors;
  t["observed_orders"] = orders;
  t["errors_reliable"] = reliable;
  t["error"] = errors.empty() ? nlohmann::json() : errors.back();
  t["error_reliable"] = all_reliable;
  t["coarse_grid"] = coarse_nodes;
  t["error_seconds"] = seconds_since(t0);
  // The observables' errors take the same coarse answers (observables.hpp).
  r.coarse.push_back({half, std::move(c)});
  r.coarse.push_back({quarter, std::move(q)});
  t["error_note"] =
      "errors: per output time, the estimated relative L1 error of the density, the largest "
      "over modes of f(p) times the mode's difference from the same scheme on the grid of "
      "coarse_grid nodes, p the mode's order observed against the grid halved again and "
      "f(p) = max(f0, m/(2^max(p, 1/4) - 1)), f0 = 2 at order 1, 1 at orders 2-3, 8/2^order "
      "above, m = clamp(2p - 1, 1, 3) above order 3, else 1 (docs/methods.md, \"transfer\"); "
      "unreliable where some mode's p is below 1/4 or unknown; observed_orders gives the "
      "order of the mode with the largest difference";
}

/// The errors of the absorbed masses of a transfer run (`mb.absorbed`), from the same scheme's
/// on the halved and quartered grids (`coarse`, in that order; either may be missing): per
/// guard and frame, with D = |A_h − A_2h| and D' = |A_2h − A_4h|, f(p)·D with f(p) =
/// max(3, 1/(2^p − 1)), p = log2(D'/D) clamped to ≥ 1/4 (3 D at p ≥ 0.42, up to 5.3 D); 3 D
/// without the quartered grid. The factor 3 is Roache's safety factor for grids outside the
/// asymptotic range: an absorbed mass is the mass a front has carried across the guard, which
/// hat's smearing does not converge to regularly on usual grids (the shuttle of
/// tests/validation/test_absorbing.cpp at t = 1.25: errors −1.1e-3, +2.7e-4, +4.5e-4, +3.3e-4
/// on 31, 61, 121, 241 nodes; 2 D would be 0.78 of the last). Nothing without the halved grid
/// (errors stay empty: null in summary.json).
inline void add_absorbed_errors(MassBudget& mb, const std::vector<MassBudget>& coarse) {
  mb.absorbed_error.assign(mb.absorbed.size(), {});
  if (coarse.empty()) return;
  for (std::size_t g = 0; g < mb.absorbed.size(); ++g) {
    const std::vector<double>& a = mb.absorbed[g];
    if (a.empty() || g >= coarse[0].absorbed.size() || coarse[0].absorbed[g].size() != a.size())
      continue;
    const std::vector<double>& a2 = coarse[0].absorbed[g];
    const bool third = coarse.size() > 1 && g < coarse[1].absorbed.size() &&
                       coarse[1].absorbed[g].size() == a.size();
    for (std::size_t k = 0; k < a.size(); ++k) {
      const double D = std::fabs(a[k] - a2[k]);
      double factor = 3.0;
      if (third && D > 0.0) {
        const double D2 = std::fabs(a2[k] - coarse[1].absorbed[g][k]);
        if (D2 > 0.0) factor = std::max(factor, 1.0 / richardson_divisor(std::log2(D2 / D)));
      }
      mb.absorbed_error[g].push_back(factor * D);
    }
  }
}

}  // namespace detail

/// scheme=fv of the transfer method: the finite-volume generator stepped in time
/// (generator_march.hpp) on the grid, in one process, on guards that are coordinate planes;
/// the errors per output time from the same march on the halved and quartered grids
/// (detail::add_transfer_errors, order fv_order). `step`, when positive, caps the time step.
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_transfer_fv(const TensorGrid<state_dim_v<M>>& grid,
                                                  std::span<const double> times, const double* par,
                                                  const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  detail::set_time_frames(r, times);
  if (s.backend && s.backend->ranks() > 1)
    throw std::invalid_argument(
        "scheme=fv runs in one process: run without MPI, or use scheme=hat over several");
  const std::vector<FvGuardPlane> planes = fv_guard_planes<M>(grid, par);  // throws: a guard
  FvMarchOptions fo;
  fo.order = static_cast<int>(s.settings.integer<"fv_order">());
  fo.max_step = s.settings.real<"step">();
  const auto t0 = detail::MethodClock::now();
  FvMarchRun<N> run;
  {
    Progress progress("transfer (fv): march", times.size(), s.quiet);
    run = fv_march<M>(grid, par, planes, times, fo, &progress);
  }
  r.solve_s = detail::seconds_since(t0);
  if (!run.ok()) {
    r.failure = "(scheme=fv) " + run.failure;
    return r;
  }
  r.solution = std::move(run.solution);
  r.budget = std::move(run.budget);
  nlohmann::json t = {
      {"scheme", "fv"},
      {"order", fo.order},
      {"rows", run.unknowns},
      {"nonzeros", run.nonzeros},
      {"step", run.step},
      {"cfl", kFvCfl},
      {"steps", run.n_steps},
      {"time_integrator", "SSP Runge-Kutta 3 (Shu-Osher)"},
      {"assembly_seconds", run.assembly_seconds},
      {"march_seconds", run.seconds},
      {"budget_defect", run.budget_defect},
      {"min_value", run.min_value},
      {"note",
       "the finite-volume generator stepped in time (docs/methods.md, \"transfer\"): outflow "
       "is counted per stage, mass + outflow = initial mass to budget_defect; no atom (mass a "
       "Zeno point absorbs stays in the cells around it)"}};
  double top = 0.0;
  for (const double u : r.solution.u) top = std::max(top, u);
  if (run.min_value < -kFvNegativeTolerance * top) {
    char b[300];
    std::snprintf(b, sizeof b,
                  "scheme=fv undershoots: the smallest density is %.3g against a largest of %.3g "
                  "(the unlimited order-%d reconstruction near a steep front); refine the "
                  "grid, or --set fv_order=1 for a positive, first-order march",
                  run.min_value, top, fo.order);
    r.warnings.push_back(b);
  }
  detail::add_transfer_errors(t, r, grid, times, fo.order, s,
                              [&](const TensorGrid<N>& g, const char*) {
                                // The same planes: they are the model's within the same box,
                                // whatever the grid.
                                FvMarchRun<N> c = fv_march<M>(g, par, planes, times, fo, nullptr);
                                return c.ok() ? std::move(c.solution) : Solution<N>{};
                              });
  r.summary[summary_key::transfer] = t;
  return r;
}

/// The transfer-operator method: assemble once, march to the output times, and estimate
/// the error of every frame (detail::add_transfer_errors).
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_transfer(const TensorGrid<state_dim_v<M>>& grid,
                                               std::span<const double> times, double dt,
                                               const double* par, const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  if (s.settings.word<"scheme">() == "fv") return solve_by_transfer_fv<M>(grid, times, par, s);
  MethodResult<N> r;
  detail::set_time_frames(r, times);
  const TransferOptions o = detail::transfer_options(s, dt);
  for (const double t : times) (void)steps_to(t, o.step);  // throws: not a multiple of h
  const auto t0 = detail::MethodClock::now();
  const TransferOperator<N> op = detail::assemble<M>(grid, par, o, s.quiet);
  if (detail::assembly_failed(op, r, t0)) return r;
  const std::vector<double> u0 = initial_vector<M>(grid, par);
  Progress progress("transfer operator: march",
                    static_cast<std::size_t>(times.empty() ? 0 : steps_to(times.back(), o.step)),
                    s.quiet);
  TransferRun<N> run = march(op, u0, times, &progress);
  progress.finish();
  r.solve_s = detail::seconds_since(t0);
  if (!run.ok()) {
    r.failure = "(marching the transfer operator) " + run.failure;
    return r;
  }
  r.solution = std::move(run.solution);
  r.budget = std::move(run.budget);
  nlohmann::json t = detail::operator_summary(o, op);
  t["steps"] = run.n_steps;
  t["march_seconds"] = run.seconds;
  t["budget_defect"] = run.budget_defect;
  t["note"] =
      "outflow and atom are counted per column of the operator (where the forward flow of each "
      "cell's samples ends); mass + outflow + atom = initial mass to budget_defect";
  // hat is first order at best; galerkin, the L2 projection of the moved density, second
  // (docs/methods.md, "transfer").
  const int order = o.scheme == TransferScheme::galerkin ? 2 : 1;
  if (o.scheme == TransferScheme::galerkin) {
    double low = 0.0, top = 0.0;
    for (const double u : r.solution.u) low = std::min(low, u), top = std::max(top, u);
    t["min_value"] = low;
    if (low < -kFvNegativeTolerance * top) {
      char b[300];
      std::snprintf(b, sizeof b,
                    "scheme=galerkin undershoots: the smallest density is %.3g against a largest "
                    "of %.3g (the L2 projection overshoots next to a jump); scheme=hat stays "
                    "non-negative",
                    low, top);
      r.warnings.push_back(b);
    }
  }
  std::vector<MassBudget> coarse_budgets;  // the halved grid's, then the quartered one's
  detail::add_transfer_errors(
      t, r, grid, times, order, s, [&](const TensorGrid<N>& g, const char* title) {
        const TransferOperator<N> cop = detail::assemble<M>(g, par, o, s.quiet, title);
        if (!cop.ok()) return Solution<N>{};
        TransferRun<N> crun = march(cop, initial_vector<M>(g, par), times, nullptr);
        if (!crun.ok()) return Solution<N>{};
        coarse_budgets.push_back(std::move(crun.budget));
        return std::move(crun.solution);
      });
  detail::add_absorbed_errors(r.budget, coarse_budgets);
  r.summary[summary_key::transfer] = t;
  return r;
}

/// Most state dimensions in which scheme=auto of the invariant method takes the
/// finite-volume generator (see detail::fv_unavailable).
inline constexpr std::size_t kFvAutoMaxDim = 2;

namespace detail {

/// Why scheme=auto of the invariant method cannot take the finite-volume generator on this
/// model and run, or "" when it can: it runs in one process, in 1-D or 2-D, on guards that
/// are coordinate planes (generator_geometry.hpp, `fv_guard_planes`, whose planes go to
/// `planes`). In 3-D its sparse LU and shift-invert Arnoldi cost far more than hat: the shipped
/// models/chaplygin.model (21³ nodes) took 38.7 s by fv, whose density then oscillated and was
/// dropped for hat's 1.4 s (2026-12-01); scheme=fv still asks for it there.
template <HybridModel M>
std::string fv_unavailable(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                           const MethodSettings& s, std::vector<FvGuardPlane>& planes) {
  if (s.backend && s.backend->ranks() > 1) return "the generator runs in one process";
  if constexpr (kFvAutoMaxDim < state_dim_v<M>)
    return "the generator's direct solve is taken by scheme=auto in 1-D and 2-D only (in " +
           std::to_string(state_dim_v<M>) +
           "-D it costs tens of times hat's; --set scheme=fv asks for it)";
  try {
    planes = fv_guard_planes<M>(grid, par);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

}  // namespace detail

/// scheme=fv of the invariant method: the finite-volume generator's null vector on the grid's
/// nodes, its eigenvalues as the transfer operator's over `step` (else dt), and their errors
/// from the grid of (n+1)/2 nodes per axis (generator_solve.hpp). The same summary keys as the
/// transfer operator's spectrum, and `error`, `order`, `coarse_grid`, per eigenvalue `error`
/// and μ, `decays`. With `oscillates` (scheme=auto), a density that oscillates (below
/// −kFvNegativeTolerance × its maximum) is not returned: `*oscillates` says why. `planes`:
/// the guards' planes when the caller found them (else found here).
/// (Not inlined into solve_by_invariant: GCC 12 then misreads the sampled path's vectors,
/// -Wfree-nonheap-object in invariant.hpp.)
template <HybridModel M>
[[gnu::noinline]] MethodResult<state_dim_v<M>> solve_by_invariant_fv(
    const TensorGrid<state_dim_v<M>>& grid, double dt, const double* par, const MethodSettings& s,
    std::string* oscillates = nullptr, const std::vector<FvGuardPlane>* planes = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  FvOptions o;
  o.order = static_cast<int>(s.settings.integer<"fv_order">());
  o.n_eigen = std::max(2, static_cast<int>(s.settings.integer<"eigenvalues">()));
  const double step = s.settings.real<"step">();
  o.step = step > 0 ? step : dt;
  const auto t0 = detail::MethodClock::now();
  // Throws: a guard it cannot cut (without `planes`, found by scheme=auto already).
  const FvInvariantResult inv =
      planes ? fv_invariant<M>(grid, par, o, *planes) : fv_invariant<M>(grid, par, o);
  // μ₂ ties with μ₁ (within kFvTie·rate, as the generator's own choice of λ₁): the null space
  // is not one-dimensional, the invariant density not unique, and the grids' solvers need not
  // pick the same one (tests/validation/models/two_sawtooths.model: λ₂ = 1 − 3e-16, and the
  // two grids' densities 0.42 apart, reported as the density's error). The frame is then a
  // vector of that null space, possibly of both signs: not an oscillation.
  const bool unique =
      inv.fine.mu.size() < 2 || std::abs(inv.fine.mu[1] - inv.fine.mu[0]) > kFvTie * inv.fine.rate;
  // A density with features below the grid spacing (a measure concentrated near an attracting
  // cycle) makes the high-order reconstruction oscillate: scheme=auto drops it for hat, and
  // scheme=fv by name keeps it with a warning (below).
  double low = std::numeric_limits<double>::infinity(), high = -low;
  for (const double u : inv.fine.density) low = std::min(low, u), high = std::max(high, u);
  const bool oscillating = unique && inv.fine.failure.empty() && low < -kFvNegativeTolerance * high;
  if (oscillates && oscillating) {
    *oscillates = fv_oscillation_reason("", low, high);
    return r;
  }
  r.solve_s = detail::seconds_since(t0);
  if (!inv.fine.failure.empty()) {
    r.failure = "(the finite-volume generator) " + inv.fine.failure;
    return r;
  }
  r.solution.n_time = 1;
  r.solution.n_mode = static_cast<std::size_t>(M::n_mode);
  r.solution.n_point = grid.size();
  r.solution.u = inv.fine.density;
  r.frame_names = {std::string(method_spec(Method::invariant).frame)};
  r.observable_errors = ObservableErrorKind::coarse, r.order = o.order;
  if (const auto half = detail::fv_half_grid(grid)) {
    detail::keep_coarse_frame(r, *half, inv.coarse_density, r.solution.n_mode);
    if (const auto quarter = detail::fv_half_grid(*half); quarter && r.coarse.size() == 1)
      detail::keep_coarse_frame(r, *quarter, inv.quarter_density, r.solution.n_mode);
  }
  nlohmann::json j = {{"scheme", "fv"},
                      {"step", o.step},
                      {"order", o.order},
                      {"rows", inv.fine.unknowns},
                      {"nonzeros", inv.fine.nonzeros},
                      {"file", "invariant.npy"},
                      {"min_value", low},
                      {"residual", inv.fine.residual},
                      {"sigma", inv.fine.sigma},
                      {"solver", "bordered SparseLU; shift-invert Arnoldi (Spectra)"},
                      {"iterations", inv.fine.iterations},
                      {"converged", inv.fine.eigen_converged},
                      {"assembly_seconds", inv.seconds_fine},
                      {"error_seconds", inv.seconds_coarse}};
  detail::add_spectrum_json(j, inv.lambda, inv.spectrum);
  for (std::size_t k = 0; k < inv.lambda.size(); ++k) {
    j["eigenvalues"][k]["mu_re"] = inv.fine.mu[k].real();
    j["eigenvalues"][k]["mu_im"] = inv.fine.mu[k].imag();
  }
  std::vector<std::string> notes = inv.notes;
  double error = inv.error;
  std::vector<double> mode_errors = inv.mode_errors;
  std::optional<bool> reliable = inv.error_reliable;
  if (!unique)
    detail::withdraw_not_unique_error(inv.lambda[0], inv.lambda[1], o.step, error, mode_errors,
                                      reliable, notes, r.warnings);
  detail::add_density_error_json(j, error, mode_errors, inv.observed_order, reliable,
                                 inv.coarse_nodes);
  j["unique"] = unique;
  std::string note =
      "error: estimated relative L1 error of the density (max over modes; nodes on a cut "
      "excluded), the difference from the grid of coarse_grid nodes" +
      std::string(o.order <= 1 ? " times 2" : "") +
      "; each eigenvalue's error likewise (docs/methods.md, \"invariant\")";
  for (const std::string& n : notes) note += ". " + n;
  j["note"] = note;
  // scheme=fv asked for by name keeps what it found, but never silently: a density that
  // oscillates (what scheme=auto leaves to hat) and growing modes (Re μ > 0, which the
  // generator of a transfer operator has none of: the high-order reconstruction is not
  // positive and, on such a density, not stable either; models/sir.model gave |λ| = 1.0187 and
  // a density from −1.2e5 to 3.4e5) say so.
  j["oscillates"] = oscillating;
  if (oscillating) {
    char b[400];
    std::snprintf(b, sizeof b,
                  "the finite-volume generator's density oscillates (min %.3g against max %.3g): "
                  "it has features below the grid spacing (a measure concentrated near an "
                  "attracting cycle): its values are not a density, nor need its eigenvalues "
                  "be the model's; scheme=hat keeps it non-negative",
                  low, high);
    r.warnings.push_back(b);
  }
  double top = 0.0;
  int growing = 0;
  for (std::size_t k = 0; k < inv.lambda.size(); ++k)
    if (inv.fine.mu[k].real() > kFvTie * inv.fine.rate)
      ++growing, top = std::max(top, std::abs(inv.lambda[k]));
  j["growing_modes"] = growing;
  if (growing > 0) {
    char b[400];
    std::snprintf(b, sizeof b,
                  "the finite-volume generator has %d growing mode(s) (|lambda| up to %.6g > 1), "
                  "which a transfer operator cannot have: the scheme is unstable on this model "
                  "and grid, and its spectrum is not the model's; scheme=hat",
                  growing, top);
    r.warnings.push_back(b);
  }
  detail::spectrum_warnings(inv.spectrum, r.warnings);
  if (inv.fine.leaks && inv.spectrum.leaks != true)
    r.warnings.push_back(
        "mass leaves the box: the density is the quasi-stationary one (the "
        "eigenvector of the rightmost eigenvalue), decaying at leak_rate");
  if (!inv.fine.eigen_converged)
    r.warnings.push_back(
        "the eigen-solver (shift-invert Arnoldi) did not converge: "
        "invariant.eigenvalues holds what it found");
  r.summary[summary_key::invariant] = j;
  return r;
}

/// The invariant density (leading eigenvector of the transfer operator) and the spectrum:
/// one frame (`times` unused; the operator's step is `step`, else `dt`). scheme=fv:
/// `solve_by_invariant_fv`.
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_invariant(const TensorGrid<state_dim_v<M>>& grid,
                                                std::span<const double>, double dt,
                                                const double* par, const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::string& scheme = s.settings.word<"scheme">();
  if (scheme == "fv") return solve_by_invariant_fv<M>(grid, dt, par, s);
  // scheme=auto: the generator where it applies, else hat, saying why.
  std::string fallback;
  if (scheme == "auto") {
    std::vector<FvGuardPlane> planes;
    fallback = detail::fv_unavailable<M>(grid, par, s, planes);
    if (fallback.empty()) {
      FvOptions probe;
      probe.order = static_cast<int>(s.settings.integer<"fv_order">());
      fallback = fv_probe_oscillation<M>(grid, par, planes, probe);
    }
    if (fallback.empty()) {
      MethodResult<N> fv = solve_by_invariant_fv<M>(grid, dt, par, s, &fallback, &planes);
      if (fallback.empty()) return fv;
    }
  }
  MethodResult<N> r;
  if (!fallback.empty())
    r.warnings.push_back(
        "scheme=auto used hat, first order, not the finite-volume generator (order " +
        std::to_string(s.settings.integer<"fv_order">()) + "): " + fallback);
  const TransferOptions o = detail::transfer_options(s, dt);
  const auto t0 = detail::MethodClock::now();
  const TransferOperator<N> op = detail::assemble<M>(grid, par, o, s.quiet);
  if (detail::assembly_failed(op, r, t0)) return r;
  InvariantOptions io;
  io.n_eigen = std::max(2, static_cast<int>(s.settings.integer<"eigenvalues">()));
  const InvariantResult inv = invariant_density(op, io);
  // The errors (two_grid.hpp): the same scheme on the halved grid, and halved again for the
  // observed order; the density's difference needs every node in this process.
  const TensorGrid<N> half = halved_grid(grid), quarter = halved_grid(half);
  const auto coarse_solve = [&](const TensorGrid<N>& g, const char* title) {
    const TransferOperator<N> cop = detail::assemble<M>(g, par, o, s.quiet, title);
    if (!cop.ok()) return InvariantResult{};
    return invariant_density(cop, io);
  };
  const auto t1 = detail::MethodClock::now();
  const InvariantResult c = coarse_solve(half, "transfer operator: assembly (halved grid)");
  const InvariantResult q =
      op.distributed ? InvariantResult{}
                     : coarse_solve(quarter, "transfer operator: assembly (quartered grid)");
  const double error_s = detail::seconds_since(t1);
  r.solve_s = detail::seconds_since(t0);
  detail::set_eigenvector_frame(r, op, inv, method_spec(Method::invariant));
  constexpr int kOrder = 1;  // the sampled schemes are first order at best (docs/methods.md)
  r.observable_errors = ObservableErrorKind::coarse, r.order = kOrder;
  if (!op.distributed) {
    detail::keep_coarse_frame(r, half, c.density, op.n_mode);
    if (r.coarse.size() == 1) detail::keep_coarse_frame(r, quarter, q.density, op.n_mode);
  }
  const double factor = error_factor(kOrder);
  const SpectrumErrors spec =
      spectrum_errors(inv.eigenvalues, c.eigenvalues, o.step, factor, io.tol);
  double error = std::numeric_limits<double>::quiet_NaN(), observed = error;
  std::vector<double> mode_errors;
  std::optional<bool> reliable;
  std::vector<std::string> notes;
  if (op.distributed) {
    notes.push_back(
        "no error estimate of the density over several ranks (the eigenvalues' "
        "errors are estimated)");
  } else if (!c.density.empty()) {
    const int n_mode = static_cast<int>(op.n_mode);
    const std::span<const char> none;
    const double D =
        coarse_difference(grid, std::span<const double>(inv.density), none, half,
                          std::span<const double>(c.density), none, n_mode, &mode_errors);
    error = factor * D;
    for (double& e : mode_errors) e *= factor;
    if (!q.density.empty()) {
      const double D2 =
          coarse_difference(half, std::span<const double>(c.density), none, quarter,
                            std::span<const double>(q.density), none, n_mode, nullptr);
      if (D > 0.0 && D2 > 0.0)
        observed = std::log2(D2 / D), reliable = order_near(observed, kOrder);
    }
    if (reliable == false)
      notes.push_back("the observed order of convergence is " + std::to_string(observed) +
                      ", not near 1: the error estimate is unreliable (the scheme's error does "
                      "not fall like the grid spacing here); scheme=fv converges at order 3 "
                      "where it applies");
  }
  // λ₂ within the errors of λ₁: the invariant density is not unique, and the two grids'
  // solvers need not return the same one, so their difference is no error estimate (the
  // sawtooth with step=1e-300, an operator equal to the identity: the solver's start vector,
  // 17 % off the closed form, with an "error" of 9e-13).
  const bool unique = !leading_eigenvalue_repeats(inv.eigenvalues, spec.lambda_error, io.tol);
  if (!unique)
    detail::withdraw_not_unique_error(inv.eigenvalues[0], inv.eigenvalues[1], o.step, error,
                                      mode_errors, reliable, notes, r.warnings);
  if (spec.decays == false && unique)
    notes.push_back(
        "the spectral gap is within its estimated error of 0: no decay is claimed "
        "(the scheme's numerical diffusion moves a cycle's eigenvalues inside the "
        "unit circle)");
  // A measure concentrated below the grid's spacing (an attracting cycle): the maximum grows
  // as the grid is refined, and the values are cell masses that converge as a measure only.
  const double g1 = detail::max_growth(inv.density, c.density);
  const double g2 = detail::max_growth(c.density, q.density);
  const bool concentrated = g1 >= detail::kConcentratedGrowth && g2 >= detail::kConcentratedGrowth;
  if (concentrated) {
    char b[700];
    std::snprintf(b, sizeof b,
                  "the invariant density's maximum grows %.2fx from the halved grid to this one "
                  "(%.2fx from the quartered to the halved): the invariant measure is "
                  "concentrated below the grid's spacing (an attracting cycle carries a measure "
                  "on a curve), and the values are the dual cells' masses over their volumes. "
                  "They converge as a measure (cell masses, the means of observables: observe "
                  "NAME = f, with their errors), not pointwise or in L1, so the density's L1 "
                  "error estimate does not apply",
                  g1, g2);
    notes.push_back(b);
    r.warnings.push_back(b);
  }
  std::vector<int> coarse_nodes;
  for (const GridAxis& a : half.axes) coarse_nodes.push_back(a.n);
  nlohmann::json j = detail::operator_summary(o, op);
  j["file"] = r.frame_names.front() + ".npy";
  detail::add_spectrum_json(j, inv.eigenvalues, spec);
  detail::add_density_error_json(j, error, mode_errors, observed, reliable, coarse_nodes);
  j["unique"] = unique;
  j["order"] = kOrder;
  j["max_growth"] = {detail::number_or_null(g2), detail::number_or_null(g1)};
  j["concentrated"] = concentrated;
  j["error_seconds"] = error_s;
  j["min_value"] = inv.min_value;
  j["residual"] = inv.residual;
  j["solver"] = inv.method;
  j["iterations"] = inv.iterations;
  j["converged"] = inv.converged;
  std::string note =
      "error: estimated relative L1 error of the density (max over modes), twice the "
      "difference from the grid of coarse_grid nodes; each eigenvalue's error likewise "
      "(docs/methods.md, \"invariant\")";
  for (const std::string& n : notes) note += ". " + n;
  j["note"] = note;
  r.summary[summary_key::invariant] = j;
  detail::spectrum_warnings(spec, r.warnings);
  if (!inv.converged)
    r.warnings.push_back("the eigen-solver (" + inv.method +
                         ") did not meet its tolerance; see invariant.residual in summary.json");
  return r;
}

/// The escape rate of an open system and its conditionally invariant density (escape.hpp):
/// the leading eigenpair of the transfer operator on the grid, and λ₁ on the halved grid for
/// the rate's error; one frame (`times` unused; the operator's step is `step`, else `dt`). A
/// closed system (λ₁ within its error of 1) is told so in a warning.
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_escape(const TensorGrid<state_dim_v<M>>& grid,
                                             std::span<const double>, double dt, const double* par,
                                             const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  const TransferOptions o = detail::transfer_options(s, dt);
  const auto t0 = detail::MethodClock::now();
  const TransferOperator<N> op = detail::assemble<M>(grid, par, o, s.quiet);
  if (detail::assembly_failed(op, r, t0)) return r;
  InvariantOptions io;
  io.n_eigen = std::max(2, static_cast<int>(s.settings.integer<"eigenvalues">()));
  const InvariantResult inv = invariant_density(op, io);
  // The halved grid's operator, for its λ₁ only (freed at the end of the block).
  InvariantResult coarse;
  std::size_t coarse_rows = 0;
  {
    const TransferOperator<N> op2h = detail::assemble<M>(
        halved_grid(grid), par, o, s.quiet, "transfer operator: assembly (halved grid)");
    if (detail::assembly_failed(op2h, r, t0)) return r;
    coarse = invariant_density(op2h, io);
    coarse_rows = op2h.size();
  }
  r.solve_s = detail::seconds_since(t0);
  const double lam1 = inv.eigenvalues.front().real();
  const double lam1_2h = coarse.eigenvalues.front().real();
  if (!(lam1 > 0.0) || !(lam1_2h > 0.0)) {
    char b[512];
    std::snprintf(b, sizeof b,
                  "(escape) the transfer operator's leading eigenvalue is %g (%g on the halved "
                  "grid): every sample leaves the box within finitely many steps of %g, so no "
                  "density is conditionally invariant and the escape rate is infinite",
                  lam1, lam1_2h, o.step);
    r.failure = b;
    return r;
  }
  const EscapeRate e = escape_rate(inv, coarse, o.step, io.tol);
  detail::set_eigenvector_frame(r, op, inv, method_spec(Method::escape));
  r.observable_errors = ObservableErrorKind::coarse, r.order = 1;
  if (!op.distributed) detail::keep_coarse_frame(r, halved_grid(grid), coarse.density, op.n_mode);
  nlohmann::json j = detail::operator_summary(o, op);
  j["file"] = r.frame_names.front() + ".npy";
  j["rate"] = e.rate;
  j["rate_error"] = e.rate_error;
  j["lambda1"] = e.lambda1;
  j["closed"] = e.closed;
  j["coarse_rate"] = e.coarse_rate;
  j["coarse_lambda1"] = e.coarse_lambda1;
  j["coarse_rows"] = coarse_rows;
  j["solver_error"] = e.solver_error;
  j["eigenvalues"] = detail::eigenvalues_json(inv);
  j["min_value"] = inv.min_value;
  j["residual"] = inv.residual;
  j["solver"] = inv.method;
  j["iterations"] = inv.iterations;
  j["converged"] = inv.converged && coarse.converged;
  j["note"] =
      "rate = -ln(lambda1)/step per unit time; rate_error = 2 |rate - coarse_rate| (the grid "
      "with (n+1)/2 nodes per axis) + the eigen-solver's tolerance/step (escape.hpp)";
  r.summary[summary_key::escape] = j;
  if (e.closed) {
    char b[512];
    std::snprintf(b, sizeof b,
                  "the system is closed: lambda1 = %.12g is within its error of 1 (escape rate "
                  "%.3g +/- %.2g per unit time), so nothing escapes and the density is invariant, "
                  "not conditionally invariant; use method=invariant",
                  e.lambda1, e.rate, e.rate_error);
    r.warnings.push_back(b);
  }
  if (!inv.converged || !coarse.converged)
    r.warnings.push_back("the eigen-solver (" + inv.method +
                         ") did not meet its tolerance; see escape.residual in summary.json");
  return r;
}

namespace detail {

/// For each set of the labels `fine` (on `grid`, sets 1 … K, [mode][node]), the set of the
/// labels `coarse` (on `half`, sets 1 … Kc) that holds the most of its mass `mu` at the coarse
/// nodes nearest its nodes, or −1: the same region on the two grids. Greedy by overlap (K is
/// small).
template <std::size_t N>
std::vector<int> match_sets(const TensorGrid<N>& grid, std::span<const std::int32_t> fine,
                            std::size_t K, std::span<const double> mu, const TensorGrid<N>& half,
                            std::span<const std::int32_t> coarse, std::size_t Kc,
                            std::size_t n_mode) {
  const std::size_t n = grid.size();
  std::vector<double> overlap(K * Kc, 0.0);
  for (std::size_t m = 0; m < n_mode; ++m)
    for (std::size_t i = 0; i < n; ++i) {
      const std::int32_t a = fine[m * n + i];
      if (a == 0) continue;
      const std::int32_t b = coarse[m * half.size() + half.nearest(grid.node(i))];
      if (b > 0)
        overlap[static_cast<std::size_t>(a - 1) * Kc + static_cast<std::size_t>(b - 1)] +=
            mu[m * n + i];
    }
  std::vector<int> match(K, -1);
  std::vector<char> taken(Kc, 0);
  for (std::size_t round = 0; round < K; ++round) {
    double best = 0.0;
    std::size_t ba = K, bb = Kc;
    for (std::size_t a = 0; a < K; ++a)
      for (std::size_t b = 0; b < Kc; ++b)
        if (match[a] < 0 && !taken[b] && overlap[a * Kc + b] > best)
          best = overlap[a * Kc + b], ba = a, bb = b;
    if (ba == K) break;
    match[ba] = static_cast<int>(bb), taken[bb] = 1;
  }
  return match;
}

}  // namespace detail

/// Almost-invariant sets of a closed system (almost_invariant.hpp): the transfer operator's
/// invariant masses, K sets from the reversibilised chain, their masses and invariance ratios;
/// the same on the halved grid, each set matched to the coarse set that holds most of its mass,
/// for the errors (twice the difference, as the escape rate's: first order). One frame, the
/// invariant density; the sets as `set_label`.
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_almost_invariant(const TensorGrid<state_dim_v<M>>& grid,
                                                       std::span<const double>, double dt,
                                                       const double* par, const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  const TransferOptions o = detail::transfer_options(s, dt);
  const auto t0 = detail::MethodClock::now();
  const int K = static_cast<int>(s.settings.integer<"sets">());
  InvariantOptions io;
  io.n_eigen = std::max(2, static_cast<int>(s.settings.integer<"eigenvalues">()));
  struct Answer {
    InvariantResult inv;
    std::vector<double> mu;  // invariant node masses
    AlmostInvariantSets sets;
    nlohmann::json op_summary;  // the operator's part of summary.json
  };
  // The sets on grid g, or a failure in r.
  const auto solve_on = [&](const TensorGrid<N>& g, const char* title) -> std::optional<Answer> {
    const TransferOperator<N> op = detail::assemble<M>(g, par, o, s.quiet, title);
    if (detail::assembly_failed(op, r, t0)) return std::nullopt;
    Answer a;
    a.op_summary = detail::operator_summary(o, op);
    a.inv = invariant_density(op, io);
    const double lam1 = a.inv.eigenvalues.front().real();
    if (!(lam1 > 1.0 - kOpenSystem)) {
      char b[600];
      std::snprintf(b, sizeof b,
                    "(almost_invariant) the transfer operator's leading eigenvalue is %.12g on "
                    "%zu nodes: the system loses mass (through the box's faces or a trap), so it "
                    "has no invariant density whose sets to split; method=escape gives its "
                    "escape rate and conditionally invariant density",
                    lam1, g.size());
      r.failure = b;
      return std::nullopt;
    }
    // μ = |v| of unit mass: where λ = 1 is repeated (invariant pieces that never exchange
    // mass) the solver's eigenvector is any combination of the pieces' measures, signs mixed;
    // for a Markov P and P v = v, P|v| ≥ |P v| = |v| with equal sums, so |v| is invariant too.
    a.mu.resize(op.size());
    double total = 0.0;
    for (std::size_t i = 0; i < op.size(); ++i)
      total += a.mu[i] = op.weight[i] * std::fabs(a.inv.density[i]);
    for (std::size_t i = 0; i < op.size(); ++i) {
      a.mu[i] /= total;
      a.inv.density[i] = a.mu[i] / op.weight[i];
    }
    try {
      a.sets = almost_invariant_sets(op.P, a.mu, K, op.n_mode, io.tol);
    } catch (const std::invalid_argument& e) {
      r.failure = std::string("(almost_invariant) ") + e.what() + " (on " +
                  std::to_string(g.size()) + " nodes per mode)";
      return std::nullopt;
    }
    return a;
  };
  std::optional<Answer> fine = solve_on(grid, "transfer operator: assembly");
  if (!fine) return r;
  const TensorGrid<N> half = halved_grid(grid);
  std::optional<Answer> coarse = solve_on(half, "transfer operator: assembly (halved grid)");
  if (!coarse) return r;
  r.solve_s = detail::seconds_since(t0);
  const std::size_t n_mode = static_cast<std::size_t>(M::n_mode);
  detail::set_density_frame(r, n_mode, grid.size(), fine->inv.density,
                            method_spec(Method::almost_invariant));
  r.observable_errors = ObservableErrorKind::coarse, r.order = 1;
  detail::keep_coarse_frame(r, half, coarse->inv.density, n_mode);
  r.set_label = fine->sets.label;
  const std::vector<int> match =
      detail::match_sets(grid, fine->sets.label, fine->sets.sets.size(), fine->mu, half,
                         coarse->sets.label, coarse->sets.sets.size(), n_mode);
  const double step = o.step;
  // Several pieces of the support that never exchange mass: the invariant density is any
  // mixture of theirs, so the sets' masses are the solver's choice (their ratios are not).
  const bool unique = fine->sets.invariant_pieces <= 1 && coarse->sets.invariant_pieces <= 1;
  nlohmann::json sets = nlohmann::json::array();
  double ratio_sum = 0.0;
  bool all_matched = true;
  for (std::size_t q = 0; q < fine->sets.sets.size(); ++q) {
    const AlmostInvariantSet& a = fine->sets.sets[q];
    ratio_sum += a.ratio;
    nlohmann::json j;
    j["set"] = q + 1;
    j["mass"] = a.mass;
    j["ratio"] = a.ratio;
    // −ln ρ / h: the rate at which invariant mass leaves the set, per unit time.
    j["exit_rate"] =
        a.ratio > 0.0 ? -std::log(a.ratio) / step : std::numeric_limits<double>::infinity();
    j["nodes"] = a.nodes;
    j["mode_mass"] = detail::by_mode<M>(a.mode_mass);
    if (match[q] >= 0) {
      const AlmostInvariantSet& c = coarse->sets.sets[static_cast<std::size_t>(match[q])];
      if (unique)
        j["mass_error"] = kAlmostInvariantErrorFactor * std::fabs(a.mass - c.mass) + io.tol;
      else
        j["mass_error"] = nullptr;
      j["ratio_error"] = kAlmostInvariantErrorFactor * std::fabs(a.ratio - c.ratio) + io.tol;
      j["coarse_set"] = match[q] + 1;
    } else {
      all_matched = false;
      j["mass_error"] = nullptr;
      j["ratio_error"] = nullptr;
      j["coarse_set"] = nullptr;
    }
    sets.push_back(j);
  }
  nlohmann::json j = fine->op_summary;
  j["file"] = r.frame_names.front() + ".npy";
  j["step"] = step;
  j["sets"] = sets;
  j["ratio_sum"] = ratio_sum;
  j["bound"] = fine->sets.bound;
  j["eigenvalues"] = fine->sets.eigenvalues;
  j["unassigned_mass"] = fine->sets.unassigned;
  j["components"] = fine->sets.components;
  j["invariant_pieces"] = fine->sets.invariant_pieces;
  j["unique"] = unique;
  j["lambda1"] = fine->inv.eigenvalues.front().real();
  j["coarse_ratios"] = [&] {
    nlohmann::json c = nlohmann::json::array();
    for (const AlmostInvariantSet& a : coarse->sets.sets) c.push_back(a.ratio);
    return c;
  }();
  std::vector<int> coarse_nodes;
  for (const GridAxis& ax : half.axes) coarse_nodes.push_back(ax.n);
  j["coarse_grid"] = coarse_nodes;
  j["seba_iterations"] = fine->sets.seba_iterations;
  j["converged"] = fine->sets.converged && coarse->sets.converged && fine->inv.converged;
  j["note"] =
      "ratio: the probability that invariant mass in the set is in it one step later, "
      "mu(A & P^-1 A)/mu(A); exit_rate = -ln(ratio)/step; errors: twice the difference from "
      "the set of the grid of coarse_grid nodes that holds most of its mass; bound: the sum of "
      "the reversibilised chain's K leading eigenvalues, which the sum of the ratios of any K "
      "disjoint sets cannot exceed (docs/methods.md, \"almost_invariant\")";
  r.summary[summary_key::almost_invariant] = j;
  if (!unique)
    r.warnings.push_back(
        "the support falls into " + std::to_string(fine->sets.invariant_pieces) +
        " pieces that never exchange mass (each invariant): the invariant density is any "
        "mixture of theirs, so the sets' masses are not determined (no mass_error); their "
        "ratios are");
  if (!all_matched)
    r.warnings.push_back(
        "a set has no counterpart on the halved grid (the sets change with the grid): its "
        "errors are not estimated; refine the grid");
  if (!fine->sets.converged || !coarse->sets.converged)
    r.warnings.push_back("the eigen-solver of the sets did not meet its tolerance");
  return r;
}

/// Finite-time coherent pairs (coherent.hpp) between t = 0 and t_end = times.back() (the
/// runner passes the two ends: MethodSpec::ends_only). The transport F over the interval is the
/// transfer operator of ONE step of length t_end (transfer.hpp: each sample pushed by the hybrid
/// flow over the whole interval; composing shorter steps would add the deposit's smoothing at
/// each), applied to the initial node masses p = w·u0; the pairs come from F and p. The same on
/// the halved grid gives their errors: twice the difference from the coarse pair whose initial
/// set holds most of the pair's initial mass (first order, as the almost-invariant sets'). Two
/// frames, the initial density and the transported one, with their errors from the halved and
/// quartered grids (add_transfer_errors); the labels at both times as `set_label`,
/// [frame][mode][node].
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_coherent(const TensorGrid<state_dim_v<M>>& grid,
                                               std::span<const double> times, double dt,
                                               const double* par, const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  if (times.size() != 2 || !(times.back() > 0.0))
    throw std::invalid_argument("coherent: the times are 0 and t_end > 0");
  const double t_end = times.back();
  detail::set_time_frames(r, times);
  TransferOptions o = detail::transfer_options(s, dt);
  o.step = t_end;
  const int K = static_cast<int>(s.settings.integer<"sets">());
  const double tol = InvariantOptions{}.tol;
  const std::size_t n_mode = static_cast<std::size_t>(M::n_mode);
  const auto t0 = detail::MethodClock::now();
  struct Answer {
    TransferRun<N> run;
    std::vector<double> p;  // initial node masses
    CoherentSets sets;
    bool has_pairs = false;     // whether `sets` holds the pairs (else `why` says why not)
    nlohmann::json op_summary;  // the operator's part of summary.json
  };
  // The transport on grid g and (with `pairs`) its pairs; nothing where the transport failed.
  // Why either failed: `why`.
  const auto solve_on = [&](const TensorGrid<N>& g, const char* title, std::string& why,
                            bool pairs = true) -> std::optional<Answer> {
    const TransferOperator<N> op = detail::assemble<M>(g, par, o, s.quiet, title);
    if (!op.ok()) {
      why = "(assembling the transfer operator over [0, t_end]) " + op.failure_message;
      return std::nullopt;
    }
    Answer a;
    a.op_summary = detail::operator_summary(o, op);
    const std::vector<double> u0 = initial_vector<M>(g, par);
    a.run = march(op, u0, times, nullptr);
    if (!a.run.ok()) {
      why = "(transporting the initial density) " + a.run.failure;
      return std::nullopt;
    }
    if (!pairs) return a;
    a.p.resize(op.size());
    for (std::size_t i = 0; i < op.size(); ++i) a.p[i] = op.weight[i] * u0[i];
    try {
      a.sets = coherent_sets(op.P, a.p, K, op.n_mode, tol);
      a.has_pairs = true;
    } catch (const std::invalid_argument& e) {
      why = std::string("(coherent) ") + e.what() + " (on " + std::to_string(g.size()) +
            " nodes per mode)";
    }
    return a;
  };
  std::string why;
  std::optional<Answer> fine = solve_on(grid, "transport over [0, t_end]: assembly", why);
  if (!fine || !fine->has_pairs) {
    r.failure = why;
    r.solve_s = detail::seconds_since(t0);
    return r;
  }
  const TensorGrid<N> half = halved_grid(grid);
  std::string coarse_why;
  std::optional<Answer> coarse =
      solve_on(half, "transport over [0, t_end]: assembly (halved grid)", coarse_why);
  r.solution = std::move(fine->run.solution);
  r.budget = std::move(fine->run.budget);
  r.set_label = fine->sets.initial_label;
  r.set_label.insert(r.set_label.end(), fine->sets.final_label.begin(),
                     fine->sets.final_label.end());
  nlohmann::json j = fine->op_summary;
  j["t_end"] = t_end;
  j["budget_defect"] = fine->run.budget_defect;
  // The frames' errors from the halved grid's transport (computed above) and the quartered one's.
  detail::add_transfer_errors(j, r, grid, times, 1, s, [&](const TensorGrid<N>& g, const char*) {
    if (g.size() == half.size() && coarse) return std::move(coarse->run.solution);
    if (g.size() == half.size()) return Solution<N>{};
    std::string ignored;
    std::optional<Answer> q =
        solve_on(g, "transport over [0, t_end]: assembly (quartered grid)", ignored, false);
    return q ? std::move(q->run.solution) : Solution<N>{};
  });
  r.solve_s = detail::seconds_since(t0);
  if (coarse && !coarse->has_pairs) coarse.reset();  // its transport has served the errors
  const std::vector<int> match =
      coarse
          ? detail::match_sets(grid, fine->sets.initial_label, fine->sets.sets.size(), fine->p,
                               half, coarse->sets.initial_label, coarse->sets.sets.size(), n_mode)
          : std::vector<int>(fine->sets.sets.size(), -1);
  nlohmann::json sets = nlohmann::json::array();
  bool all_matched = true;
  for (std::size_t q = 0; q < fine->sets.sets.size(); ++q) {
    const CoherentPair& a = fine->sets.sets[q];
    nlohmann::json e;
    e["set"] = q + 1;
    e["initial_mass"] = a.initial_mass;
    e["final_mass"] = a.final_mass;
    e["carried"] = a.carried;
    e["forward"] = a.forward;
    e["backward"] = a.backward;
    e["initial_nodes"] = a.initial_nodes;
    e["final_nodes"] = a.final_nodes;
    e["initial_mode_mass"] = detail::by_mode<M>(a.initial_mode_mass);
    e["final_mode_mass"] = detail::by_mode<M>(a.final_mode_mass);
    const CoherentPair* c =
        match[q] >= 0 ? &coarse->sets.sets[static_cast<std::size_t>(match[q])] : nullptr;
    all_matched = all_matched && c != nullptr;
    const auto error = [&](double fine_value, double coarse_value) {
      return c ? nlohmann::json(kAlmostInvariantErrorFactor * std::fabs(fine_value - coarse_value) +
                                tol)
               : nlohmann::json();
    };
    e["initial_mass_error"] = error(a.initial_mass, c ? c->initial_mass : 0.0);
    e["final_mass_error"] = error(a.final_mass, c ? c->final_mass : 0.0);
    e["carried_error"] = error(a.carried, c ? c->carried : 0.0);
    e["forward_error"] = error(a.forward, c ? c->forward : 0.0);
    e["backward_error"] = error(a.backward, c ? c->backward : 0.0);
    e["coarse_set"] = c ? nlohmann::json(match[q] + 1) : nlohmann::json();
    sets.push_back(e);
  }
  j["sets"] = sets;
  j["singular_values"] = fine->sets.singular_values;
  j["bound"] = fine->sets.bound;
  j["coherence_sum"] = fine->sets.coherence_sum;
  j["coarse_coherence_sum"] =
      coarse ? nlohmann::json(coarse->sets.coherence_sum) : nlohmann::json();
  j["components"] = fine->sets.components;
  j["seba_iterations"] = fine->sets.seba_iterations;
  j["converged"] = fine->sets.converged && (!coarse || coarse->sets.converged);
  std::vector<int> coarse_nodes;
  for (const GridAxis& ax : half.axes) coarse_nodes.push_back(ax.n);
  j["coarse_grid"] = coarse_nodes;
  j["note"] =
      "pair k: set A at t = 0 (run.nc set_label at the first time) and B at t_end (at the last); "
      "carried: the initial density's mass in A that is in B at t_end; forward = carried / "
      "initial_mass, the probability that mass in A ends in B; backward = carried / final_mass, "
      "the probability that mass in B came from A; errors: twice the difference from the pair "
      "of the grid of coarse_grid nodes whose initial set holds most of the pair's initial "
      "mass; bound: the sum of the normalised transport's K leading singular values, which "
      "coherence_sum = sum of sqrt(forward*backward) cannot exceed (docs/methods.md, "
      "\"coherent\")";
  r.summary[summary_key::coherent] = j;
  if (!coarse)
    r.warnings.push_back("the pairs on the halved grid failed " + coarse_why +
                         ": the pairs' errors are not estimated; refine the grid");
  else if (!all_matched)
    r.warnings.push_back(
        "a pair has no counterpart on the halved grid (the pairs change with the grid): its "
        "errors are not estimated; refine the grid");
  if (!fine->sets.converged || (coarse && !coarse->sets.converged))
    r.warnings.push_back("the eigen-solver of the pairs did not meet its tolerance");
  return r;
}

/// The particle method (`dt` unused).
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_by_particles(const TensorGrid<state_dim_v<M>>& grid,
                                                std::span<const double> times, double,
                                                const double* par, const MethodSettings& s) {
  constexpr std::size_t N = state_dim_v<M>;
  MethodResult<N> r;
  detail::set_time_frames(r, times);
  ParticleOptions po;
  po.particles = static_cast<std::size_t>(s.settings.integer<"particles">());
  po.seed = static_cast<std::uint64_t>(s.settings.integer<"seed">());
  detail::set_ode_settings(s, po.forward);
  po.backend = s.backend;
  po.marginals = s.settings.word<"density">() == "marginals";
  const auto t0 = detail::MethodClock::now();
  // Each rank advances its own block: rank 0's bar counts its own share.
  const Backend& backend = s.backend ? *s.backend : serial_backend();
  const std::size_t mine = particle_block(po.particles, backend).size();
  Progress drawing("particles: drawing", mine, s.quiet), progress("particles", mine, s.quiet);
  po.draw_progress = &drawing;
  po.progress = &progress;
  ParticleRun<N> run = solve_particles<M>(grid, times, par, po);
  progress.finish();
  r.solve_s = detail::seconds_since(t0);
  if (!run.ok()) {
    r.failure = describe<M>(run.failure);
    return r;
  }
  r.solution = std::move(run.solution);
  r.marginals = std::move(run.marginals);
  r.observable_errors = ObservableErrorKind::samples;
  r.sampled_observables = std::move(run.observables);
  r.budget = std::move(run.budget);
  r.atom_error = run.atom_error;
  r.summary[summary_key::particles] = {
      {"particles", run.particles},
      {"traced", run.traced},
      {"seed", po.seed},
      {"sampled_mass", run.sampled_mass},
      {"note", "mass_error and atom_error are 2-sigma Monte-Carlo estimates"}};
  r.summary[summary_key::mass_error] = r.budget.mass_error;
  return r;
}

/// A method's solve function: the grid, the output times, the output interval dt, the
/// parameters and the settings to a result.
template <HybridModel M>
using SolveFunction = MethodResult<state_dim_v<M>> (*)(const TensorGrid<state_dim_v<M>>&,
                                                       std::span<const double>, double,
                                                       const double*, const MethodSettings&);

/// The solve function of each row of the methods table (method_table.hpp), in its order.
template <HybridModel M>
inline constexpr std::array<SolveFunction<M>, kMethods.size()> solvers = {
    &solve_by_characteristics<M>,   // Method::characteristics
    &solve_by_transfer<M>,          // Method::transfer
    &solve_by_invariant<M>,         // Method::invariant
    &solve_by_particles<M>,         // Method::particles
    &solve_by_escape<M>,            // Method::escape
    &solve_by_almost_invariant<M>,  // Method::almost_invariant
    &solve_by_coherent<M>,          // Method::coherent
};

/// Dispatch on the setting `method` through the methods table; throws std::invalid_argument
/// for an unknown method.
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_method(const TensorGrid<state_dim_v<M>>& grid,
                                          std::span<const double> times, double dt,
                                          const double* par, const MethodSettings& s) {
  const MethodSpec& method = method_named(s.settings.word<"method">());
  MethodResult<state_dim_v<M>> r =
      solvers<M>[static_cast<std::size_t>(method.id)](grid, times, dt, par, s);
  // Over several ranks every frame stays distributed (each method keeps its blocks; this
  // holds the contract for any method that does not).
  const Backend& backend = s.backend ? *s.backend : serial_backend();
  if (backend.ranks() > 1 && r.marginals.empty() && !r.solution.distributed &&
      r.solution.n_time > 0)
    r.solution.keep_only(backend.block(grid.size() * static_cast<std::size_t>(M::n_mode)));
  return r;
}

}  // namespace hybgen::rt
