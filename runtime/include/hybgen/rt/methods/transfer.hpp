#pragma once
/// \file transfer.hpp
/// The transfer-operator method: the hybrid flow is autonomous, so the Frobenius–Perron
/// evolution over one step h is ONE fixed linear map u ↦ P u. It is assembled once as a
/// sparse matrix and the density is marched by sparse matrix–vector products.
///
/// State layout: index r = m·n_node + i (mode m, grid node i in C order), like `Solution`.
///
/// The scheme moves MASS, column by column: the mass of a node is the mass of its dual cell
/// (half cells at the box faces; their volumes are exactly the trapezoid weights w), taken
/// uniformly distributed over the cell (Ulam's ansatz) and represented by K =
/// samples_per_axis^N sample points on the midpoint tensor pattern of the cell, each
/// carrying the fraction 1/K (of the cell's part inside the support and the mode's region).
/// Every sample is pushed
/// FORWARD by h with the hybrid flow (forward.hpp: event location, resets, Zeno detection) and
/// its fraction is booked where it ends:
///   * in the box and the support, in mode m': deposited on nodes of mode m' that lie in the
///     support and in the closure of mode m''s region (`where`, `in_mode_region`; without it the
///     smoothing of the deposit would carry a mode's mass across its switching surface, where
///     that mode's guard never fires again: measured on models/filippov.model,
///     tests/validation/test_moments.cpp) —
///       on the hat functions φ_j (`hat`), by their exact integrals over the image of the
///         sample's sub-cell (`deposit`), renormalised over the nodes that may hold the mass
///         (the fraction never goes to a node that holds no state);
///   * outside the box or the support: outflow_i;
///   * at a Zeno point within h (mass concentrated on a point, which no density holds): atom_i.
/// P_ji = fraction of cell i's mass deposited on node j, so, for every column i,
///     Σ_j P_ji + outflow_i + atom_i = 1          (hat weights sum to 1; counts/K)
/// up to one rounding per entry, all entries ≥ 0. P acts on node masses M_r = w_r·u_r;
/// densities are masses / weights. Consequences, by construction and checked at assembly
/// (`column_defect`) and at every step of `march` (`budget_defect`): the scheme never
/// creates mass, whatever |J| at a reset, however many pre-images a point has (no inverse
/// of a reset is used: only the forward flow), and for constant resets; densities stay ≥ 0;
/// the spectral radius of P is ≤ max_i Σ_j P_ji ≤ 1, so `invariant`'s leading eigenvalue is
/// ≤ 1 (= 1 for a closed system), up to the eigen-solver's tolerance.
///
/// (A backward, interpolating scheme — row y of P = the multilinear interpolation weights at
/// the foot of y's backward characteristic, times 1/|J| — was the default until 2026-11: its
/// stencil mixes nodes on both sides of a reset's image, whose densities differ by the
/// factor 1/|J|, and so created mass at every reset with |J| ≠ 1: the bouncing ball with
/// e = 0.8 on 301² went from mass 2.6 to 3·10¹⁴ by t = 10. Rows cannot be made conservative
/// without knowing where the mass goes, which is what the columns above are built from.)
///
/// Accuracy. For a smooth density away from guards the scheme is consistent; per step it adds
/// the smoothing of the uniform-cell source convolved with the hat deposit,
/// (Δx²/8)·∂²u per axis (the identity map gives u_j ← (u_{j−1} + 6u_j + u_{j+1})/8), so the
/// error is O(Δx²) per step and O(Δx²/h) over a fixed horizon; the deposit is continuous in
/// the end point, so it does not quantise to 1/K. (Ulam's scheme, `cell` — all of a sample's
/// fraction on the node whose dual cell holds its end point — quantised every fraction to
/// k/K, an O(1/K) error that does not shrink with Δx: 13–15 % on the sawtooth's invariant
/// density at every grid from 101 to 1601 nodes with K = 4, the node values zig-zagging. It
/// was withdrawn in 2026-11; hat deposits without quantising and scheme=fv converges at order
/// 3.) A map that expands by more than samples_per_axis per
/// step leaves gaps between the images of one cell's samples (`hat` then under-resolves).
/// Cost: K forward flows per node (default K = 16 in 1-D and 2-D, 27 in 3-D, 2^N above).
/// Zeno points: the cell of a Zeno point is re-spread uniformly every step and only its
/// samples with t_Z ≤ h drain into the atom; t_Z ~ √Δx there, so for small h the mass sits
/// in that cell as density and the atom lags (tests/rt/test_transfer.cpp: ZenoMassBecomesAnAtom).
/// Size: the hat deposit, the sampling of each cell by the forward flow, the
/// CSR assembly and the per-column outflow and atom bookkeeping that keep the mass exact.
///
/// `galerkin` (a transient scheme for method=transfer): the density is its hat expansion
/// u = Σ_k u_k φ_k, moved EXACTLY by the flow and projected back on the hats (a conservative
/// Lagrange–Galerkin step). The unknowns are the values u_k; a step is
///     x = P u,  M u' = x,   P_ik = ∫ ψ_i(T x) φ_k(x) dx,   M_ik = ∫ ψ_i φ_k,
/// ψ_i the hats of the nodes that may hold the mass renormalised to a partition of unity (the
/// hat deposit above). Column k of P and M comes from (2·samples)^N points over the support of
/// φ_k, each carrying φ_k times its sub-cell's volume: its sub-cell moved to where the flow
/// ends for P, where it starts for M (so that the identity map gives P = M). Then
/// Σ_i P_ik + outflow_k + atom_k = Σ_i M_ik = c_k, the mass of a unit value at node k, and the
/// mass Σ_k c_k u_k = Σ_i x_i is carried exactly (MassSolve makes the solve exact in it).
/// u' is the L2 projection of the moved density: the projection's error is not piled up step
/// after step as hat's smoothing is (u' differs from the moved u by a part orthogonal to the
/// hats, of which the next step keeps O(h)), so the error does not grow like 1/step. The
/// projection is not monotone: next to a jump the values overshoot (the paper's ball at 257²:
/// min −0.14 against max 1.2) — the price of second order (docs/methods.md, "transfer").
/// Measured with a prototype on the paper's ball (docs/study/lagrange-galerkin/).

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/core/ode.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/core/sparse.hpp"
#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/methods/forward.hpp"
#include "hybgen/rt/model.hpp"
#include "hybgen/rt/numerics/mass_solve.hpp"
#include "hybgen/rt/settings.hpp"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace hybgen::rt {

/// Which transfer operator to assemble (see the file comment): one kind since Ulam's `cell`
/// was withdrawn (settings.hpp, kWithdrawnCell).
enum class TransferScheme {
  hat,       ///< Forward samples deposited on the hat functions of their end points.
  galerkin,  ///< The density's hat expansion moved exactly and projected back (see above).
};

/// The scheme's name in settings and outputs ("hat", "galerkin").
inline const char* scheme_name(TransferScheme s) {
  return s == TransferScheme::galerkin ? "galerkin" : "hat";
}

/// The scheme named `name` (`auto`: hat, the transfer operator's default); throws
/// std::invalid_argument for any other name.
inline TransferScheme parse_scheme(const std::string& name) {
  if (name == "hat" || name == "auto") return TransferScheme::hat;
  if (name == "galerkin") return TransferScheme::galerkin;
  if (name == "cell") throw std::invalid_argument(std::string("scheme=") + kWithdrawnCell);
  if (name == "fv")
    throw std::invalid_argument(
        "scheme=fv is the finite-volume generator (methods/generator.hpp), not a sampled "
        "transfer operator: method=transfer and invariant take it, escape does not; use "
        "scheme=hat");
  throw std::invalid_argument("unknown transfer scheme '" + name + "' (hat, galerkin)");
}

/// Default sample points per axis and cell in N dimensions: 4 up to 2-D, 3 in 3-D, 2 above
/// (K = 16, 27, 2^N forward flows per node). `galerkin` twice as many up to 3-D: each point
/// weighs its sub-cell by φ_k at its middle, a midpoint rule for the product of φ_k with the
/// moved hats whose relative error (δ/Δx)² does not fall with the grid (the paper's ball at
/// 257², t = 10: 1.41e-2 with 4, 1.16e-2 with 8; docs/methods.md, "transfer").
constexpr int default_samples_per_axis(std::size_t n, TransferScheme scheme = TransferScheme::hat) {
  const int hat = n <= 2 ? 4 : (n == 3 ? 3 : 2);
  return scheme == TransferScheme::galerkin && n <= 3 ? 2 * hat : hat;
}

/// Options of `assemble_transfer`.
struct TransferOptions {
  double step = 0.05;                           ///< Step h of the operator (> 0).
  TransferScheme scheme = TransferScheme::hat;  ///< Scheme.
  /// Sample points per axis and cell (K = this^N); 0: `default_samples_per_axis(N)`.
  int samples_per_axis = 0;
  /// The forward flows' options. zeno_time = 1: a Zeno accumulation is declared as soon as
  /// the gap signature holds and t_Z ≤ h (the physical criterion for mass reaching the Zeno
  /// point within the step), not only deep inside the cascade.
  ForwardOptions forward{.ode = {}, .max_events = 1000, .zeno_time = 1.0, .zeno_ratio = 0.999};
  Progress* progress = nullptr;  ///< Advanced once per assembled column when set.
  /// The ranks sharing the operator (null: this process alone). With several, each assembles
  /// the columns of its block and the matrix is the backend's (`DistributedMatrix`, PETSc),
  /// its rows distributed by the same blocks.
  const Backend* backend = nullptr;
};

/// Largest |Σ_j P_ji + outflow_i + atom_i − 1| over the columns that the assembly accepts:
/// a few roundings per entry. A larger defect is a failure of the assembly (never exit 0).
inline constexpr double kColumnTol = 1e-12;

/// Largest |mass_{n+1} + outflow_n + atom_n − mass_n| / mass_0 per step that `march` accepts
/// on up to 10⁶ unknowns; the rounding of the step's sums grows like √R to R (measured
/// 2.4e-14, 5e-14, 1.8e-13 at R = 10⁵, 10⁶, 10⁷), so the tolerance is this times R/10⁶ above.
inline constexpr double kStepBudgetTol = 1e-12;

/// Most sample points per cell (samples_per_axis^N) `assemble_transfer` accepts.
inline constexpr std::size_t kMaxSamplesPerCell = std::size_t{1} << 20;

/// One step of the hybrid Frobenius–Perron evolution as a sparse matrix acting on node masses.
template <std::size_t N>
struct TransferOperator {
  TensorGrid<N> grid{};                         ///< The grid.
  std::size_t n_mode = 0;                       ///< Number of modes.
  std::size_t n_node = 0;                       ///< Nodes per mode.
  double step = 0.0;                            ///< Step h.
  TransferScheme scheme = TransferScheme::hat;  ///< Scheme.
  int samples_per_axis = 0;                     ///< Sample points per axis and cell used.
  /// M^{n+1} = P M^n on node masses M_r = weight_r·u_r; P_jr = fraction of cell r's mass that
  /// lands on node j. Empty when `distributed` holds the matrix. `galerkin`: x = P u, the
  /// moments of the moved density from the node values.
  CsrMatrix P;
  /// `galerkin`: the mass matrix M (x = M u; see the file comment) and its solve; empty
  /// otherwise.
  CsrMatrix mass;
  std::shared_ptr<const MassSolve> mass_solve;  ///< `galerkin`: u = M⁻¹ x; null otherwise.
  /// `galerkin`: per column k, c_k = Σ_i M_ik, the mass of a unit value at node k, which its
  /// entries, outflow and atom sum to; empty otherwise (fractions: they sum to 1).
  std::vector<double> column_mass;
  /// The matrix over several ranks (a backend with several); null: `P` is the matrix.
  std::shared_ptr<DistributedMatrix> distributed;
  const Backend* backend = nullptr;  ///< The ranks of `distributed` (null: this process).
  /// The state indices this rank assembled, owns as rows and holds as vector entries;
  /// outflow, atom and weight are valid there ([0, size()) in one process).
  Block owned{};
  std::vector<double> weight;  ///< Trapezoid weight (= dual-cell volume) of every index r.
  /// Fraction of cell r leaving the box or the support (`galerkin`: the mass per unit value).
  std::vector<double> outflow;
  /// Fraction of cell r that reaches a Zeno point within h (`galerkin`: per unit value).
  std::vector<double> atom;
  /// Per guard g, whether it absorbs (model.hpp, `absorbs`); n_guard entries.
  std::vector<char> absorbing;
  /// absorbed[r·n_guard + g]: the fraction of cell r that guard g absorbs within h (a part of
  /// outflow_r); valid where outflow is. Empty without absorbing guards.
  std::vector<double> absorbed;
  /// impacts[r·n_guard + g]: the firings of guard g within h per unit mass of cell r (its
  /// samples' mean count, an absorption included; methods/impacts.hpp); valid where outflow
  /// is. Empty without guards.
  std::vector<double> impacts;
  /// Per guard g, whether a sample came to rest at a Zeno point on g within h (its impacts
  /// are then infinite once mass reaches the atom); all ranks agree.
  std::vector<char> zeno_guard;
  /// max_r |Σ_j P_jr + outflow_r + atom_r − 1| (≤ kColumnTol, or the assembly failed);
  /// `galerkin`: relative to column_mass_r.
  double column_defect = 0.0;
  /// First failure (smallest index r), if any; status.tau is the FORWARD time of the failure.
  TraceFailure<N> failure{};
  std::string failure_message;  ///< One-line description of `failure` (exit code 3), or "".
  double seconds = 0.0;         ///< Wall time of the assembly.

  /// Length of the state vector, n_mode·n_node.
  std::size_t size() const { return n_mode * n_node; }
  /// Non-zeros of the whole matrix.
  std::size_t nonzeros() const {
    return distributed ? distributed->nonzeros() : static_cast<std::size_t>(P.nonZeros());
  }
  /// Vector entries the ranks receive from each other per mat-vec (0 in one process;
  /// collective when distributed).
  std::size_t ghost_entries() const {
    if (!distributed || !backend) return 0;
    return static_cast<std::size_t>(
        backend->sum(static_cast<std::int64_t>(distributed->ghost_entries())));
  }
  /// Bytes of the matrix on the rank holding most (collective when distributed): values,
  /// indices and row pointers (and PETSc's communication plan).
  std::size_t matrix_bytes() const {
    if (distributed && backend)
      return static_cast<std::size_t>(
          backend->max(static_cast<double>(distributed->local_bytes())));
    return static_cast<std::size_t>(P.nonZeros()) * (sizeof(double) + sizeof(int)) +
           static_cast<std::size_t>(P.rows() + 1) * sizeof(int);
  }
  /// Whether the assembly succeeded everywhere.
  bool ok() const { return failure.ok() && failure_message.empty(); }
};

/// Result of `march`: densities at the output times and the mass budget.
template <std::size_t N>
struct TransferRun {
  Solution<N> solution;  ///< Densities, layout [time][mode][node] (like `solve_grid`).
  /// Budget per output time: mass = Σ w u, the cumulative outflow and atom counted per
  /// column; mass + outflow + atom = mass0 up to rounding (budget_defect).
  MassBudget budget;
  std::vector<double> step_mass;     ///< Mass after n steps, n = 0..n_steps.
  std::vector<double> step_outflow;  ///< Per step: the outflow.
  std::vector<double> step_atom;     ///< Per step: the atom gained.
  /// max_n |mass_{n+1} + outflow_n + atom_n − mass_n| / mass_0 over the steps.
  double budget_defect = 0.0;
  long n_steps = 0;      ///< Steps taken.
  double seconds = 0.0;  ///< Wall time of the march.
  /// Non-empty: a step broke the budget beyond kStepBudgetTol (the step and the amount).
  std::string failure;
  /// Whether every step kept the budget.
  bool ok() const { return failure.empty(); }
};

namespace detail {

/// Trapezoid weight of every state index (repeated per mode).
template <std::size_t N>
std::vector<double> trapezoid_weights(const TensorGrid<N>& grid, std::size_t n_mode) {
  std::array<AxisRule, N> rules;
  for (std::size_t a = 0; a < N; ++a) rules[a] = trapezoid_rule(grid.axes[a]);
  const std::size_t n = grid.size();
  std::vector<double> w(n * n_mode);
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t rem = i;
    double wi = 1.0;
    for (std::size_t a = N; a-- > 0;) {
      const std::size_t na = rules[a].weights.size();
      wi *= rules[a].weights[rem % na];
      rem /= na;
    }
    for (std::size_t m = 0; m < n_mode; ++m) w[m * n + i] = wi;
  }
  return w;
}

/// Options with the ODE's first trial step = h unless set: every trace spans exactly h, and
/// guessing the first step (Hairer's hinit, two extra f-evaluations and norms) costs more
/// than an occasional rejected trial (measured: assembly at 1025² 0.80 s → 0.34 s, entries
/// equal to 2.4e-13).
template <class Options>
Options first_step_h(Options o, double h) {
  if (!(o.ode.h_init > 0.0)) o.ode.h_init = h;
  return o;
}

/// Throws std::invalid_argument unless the step is finite and > 0.
inline void validate_transfer(double step) {
  if (!(step > 0.0) || !std::isfinite(step))
    throw std::invalid_argument("transfer: the step must be finite and > 0");
}

/// Throws unless every axis has ≥ 2 nodes and positive length, and the unknowns fit int32.
template <std::size_t N>
void validate_grid(const TensorGrid<N>& grid, std::size_t n_mode) {
  for (const GridAxis& a : grid.axes)
    if (a.n < 2 || !(a.max > a.min))
      throw std::invalid_argument("transfer: every grid axis needs n >= 2 and max > min");
  if (grid.size() * n_mode > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::length_error("transfer: more than 2^31 unknowns (int32 CSR indices)");
}

/// An operator without entries: its grid, modes, step, scheme and quadrature weights.
template <std::size_t N>
TransferOperator<N> empty_operator(const TensorGrid<N>& grid, int n_mode, double step,
                                   TransferScheme scheme) {
  TransferOperator<N> op;
  op.grid = grid;
  op.n_mode = static_cast<std::size_t>(n_mode);
  op.n_node = grid.size();
  op.step = step;
  op.scheme = scheme;
  op.weight = trapezoid_weights(grid, op.n_mode);
  op.owned = {0, op.size()};
  return op;
}

/// With `regions`, per state index r = m·n_node + i: whether node i is inside `M::in_support`
/// and inside the closure of mode m's region (`in_mode_region`); without, per node i: whether
/// it is inside `M::in_support`.
template <HybridModel M>
std::vector<char> node_support(const TensorGrid<state_dim_v<M>>& grid, const double* par,
                               bool regions) {
  const std::size_t nn = grid.size();
  std::vector<char> in(nn * static_cast<std::size_t>(regions ? M::n_mode : 1));
  const auto n = static_cast<std::int64_t>(in.size());
#pragma omp parallel for schedule(static)
  for (std::int64_t r = 0; r < n; ++r) {
    const auto ru = static_cast<std::size_t>(r);
    const auto y = grid.node(ru % nn);
    const int m = static_cast<int>(ru / nn);
    in[ru] = M::in_support(y.data(), par) && (!regions || in_mode_region<M>(m, y.data(), par));
  }
  return in;
}

/// Weights of the hat functions of one axis on the interval [c − δ/2, c + δ/2] ∩ [min, max]:
/// w_j = (1/|I|)∫_I φ_j (exact, by the antiderivative of the hat), appended as (node, w);
/// Σ w_j = 1 (the hats are a partition of unity on the axis). δ = 0 gives the point values.
inline void axis_box_weights(const GridAxis& ax, double dx, double c, double delta,
                             std::vector<std::pair<int, double>>& out) {
  out.clear();
  const double lo = std::max(ax.min, c - 0.5 * delta), hi = std::min(ax.max, c + 0.5 * delta);
  const double last = static_cast<double>(ax.n - 1);
  if (!(hi - lo > 1e-8 * dx)) {  // a point: the hat values at c
    const double s = std::clamp((c - ax.min) / dx, 0.0, last);
    const double f = std::min(std::floor(s), last - 1.0);
    const double t = s - f;
    if (1.0 - t > 0.0) out.emplace_back(static_cast<int>(f), 1.0 - t);
    if (t > 0.0) out.emplace_back(static_cast<int>(f) + 1, t);
    return;
  }
  // Antiderivative of the hat of node j in units of dx: Φ(σ), σ = (y − x_j)/dx.
  auto Phi = [](double sg) {
    if (sg <= -1.0) return 0.0;
    if (sg <= 0.0) return 0.5 * (sg + 1.0) * (sg + 1.0);
    if (sg <= 1.0) return 1.0 - 0.5 * (1.0 - sg) * (1.0 - sg);
    return 1.0;
  };
  const double slo = (lo - ax.min) / dx, shi = (hi - ax.min) / dx;
  const auto j0 = static_cast<int>(std::clamp(std::floor(slo), 0.0, last));
  const auto j1 = static_cast<int>(std::clamp(std::ceil(shi), 0.0, last));
  double total = 0.0;
  for (int j = j0; j <= j1; ++j) {
    const double w = Phi(shi - j) - Phi(slo - j);
    if (w > 0.0) {
      out.emplace_back(j, w);
      total += w;
    }
  }
  for (auto& [j, w] : out) w /= total;
}

/// Where a sample's fraction goes when its forward flow ended at x inside the box and the
/// support: (flat node, weight) pairs with weights summing to 1, appended to `out`; false if
/// no node can take it. `hat`: the sample stands for its sub-cell of the source cell (width
/// `delta` per axis), moved rigidly to x, and is deposited on the hats by their exact
/// integrals over that box (per axis: axis_box_weights; a tensor product), renormalised over
/// the nodes inside the support; false when all of them are outside it.
/// (Depositing a POINT on the hats — cloud-in-cell — is not enough: the column is then a
/// K-point midpoint rule of the kinked integrand φ_j(T x), whose error O(1/K²) does not shrink
/// with Δx and, for a nearly uniform flow, repeats every step; the box deposit is exact for
/// a translation. Measured on the cycle of tests/rt/test_invariant.cpp: L1 error of the
/// invariant density 1.0e-2, 7.7e-3, 7.3e-3, 6.1e-3 at 51 … 401 nodes with points.)
template <std::size_t N>
bool deposit(const TensorGrid<N>& grid, const std::array<double, N>& dx,
             const std::array<double, N>& delta, const char* in_support,
             const std::array<double, N>& x, std::vector<std::pair<std::size_t, double>>& out) {
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    const double s = (x[a] - ax.min) / dx[a];
    if (!(s >= -1e-12 * (ax.n - 1) && s <= (ax.n - 1) * (1.0 + 1e-12))) return false;
  }
  thread_local std::array<std::vector<std::pair<int, double>>, N> w;
  std::size_t combos = 1;
  for (std::size_t a = 0; a < N; ++a) {
    axis_box_weights(grid.axes[a], dx[a], x[a], delta[a], w[a]);
    combos *= w[a].size();
  }
  const std::size_t before = out.size();
  double total = 0.0;
  for (std::size_t c = 0; c < combos; ++c) {
    std::size_t rem = c, flat = 0;
    double wt = 1.0;
    std::array<std::size_t, N> pick{};
    for (std::size_t a = N; a-- > 0;) {
      pick[a] = rem % w[a].size();
      rem /= w[a].size();
    }
    for (std::size_t a = 0; a < N; ++a) {
      flat = flat * static_cast<std::size_t>(grid.axes[a].n) +
             static_cast<std::size_t>(w[a][pick[a]].first);
      wt *= w[a][pick[a]].second;
    }
    if (in_support[flat] && wt > 0.0) {
      out.emplace_back(flat, wt);
      total += wt;
    }
  }
  if (!(total > 0.0)) {
    out.resize(before);
    return false;
  }
  for (std::size_t k = before; k < out.size(); ++k) out[k].second /= total;
  return true;
}

/// Conservation, column by column: Σ_j P_jr + outflow_r + atom_r = 1 (`galerkin`:
/// column_mass_r, to kColumnTol relative) and P_jr ≥ 0. It holds by construction (fractions
/// of the samples in the support, deposit weights summing to 1).
/// `each(f)` calls f(row, column, value) for every entry this rank assembled (all of its
/// owned columns' entries). Sets op.column_defect (the largest over all ranks), and
/// op.failure_message (naming the node, from the rank that owns it) when the defect exceeds
/// kColumnTol or an entry is negative or not finite: such an operator is never marched.
template <HybridModel M, class ForEach>
void check_columns(TransferOperator<state_dim_v<M>>& op, const Backend& b, ForEach&& each) {
  const Block own = op.owned;
  const std::size_t R = op.size();
  std::vector<double> col(own.size());
  for (std::size_t r = own.begin; r < own.end; ++r) col[r - own.begin] = op.outflow[r] + op.atom[r];
  std::size_t negative = R;  // the column of a negative or non-finite entry, if any
  each([&](std::size_t, std::size_t c, double v) {
    col[c - own.begin] += v;
    if (!(v >= 0.0) || !std::isfinite(v)) negative = c;
  });
  double defect = 0.0;
  std::size_t worst = own.begin;
  // What column r sums to: 1, or the mass of a unit value at its node (`galerkin`).
  const auto want = [&op](std::size_t r) {
    return op.column_mass.empty() ? 1.0 : op.column_mass[r];
  };
  for (std::size_t r = own.begin; r < own.end; ++r) {
    const double d = std::fabs(col[r - own.begin] - want(r)) / (want(r) > 0.0 ? want(r) : 1.0);
    if (!(d <= defect)) {
      defect = std::isfinite(d) ? d : std::numeric_limits<double>::infinity();
      worst = r;
    }
  }
  op.column_defect = b.max(defect);
  const auto none = static_cast<std::int64_t>(R);
  const std::int64_t mine = negative == R ? none : static_cast<std::int64_t>(negative);
  const std::int64_t first_negative = b.min(mine);
  if (first_negative == none && op.column_defect <= kColumnTol) return;
  const bool owner_here =
      first_negative != none ? mine == first_negative : defect == op.column_defect;
  const std::int64_t owner = b.min(owner_here ? std::int64_t{b.rank()} : b.ranks());
  std::string message;
  if (b.rank() == owner) {
    if (negative != R) worst = negative;
    std::ostringstream os;
    os.precision(17);
    os << "the transfer operator does not conserve mass: the column of node ";
    write_state<M>(os, op.grid.node(worst % op.n_node));
    os << " in mode '" << mode_name<M>(static_cast<int>(worst / op.n_node))
       << "' sums, with its outflow and atom, to " << col[worst - own.begin] << " instead of "
       << want(worst) << " (tolerance " << kColumnTol << " relative), or has a negative entry";
    message = os.str();
  }
  op.failure_message = b.broadcast(message, static_cast<int>(owner));
}

/// `check_columns` of the CSR matrix `op.P` (one process).
template <HybridModel M>
void check_columns(TransferOperator<state_dim_v<M>>& op) {
  check_columns<M>(op, serial_backend(), [&op](auto&& f) {
    const int* outer = op.P.outerIndexPtr();
    const int* inner = op.P.innerIndexPtr();
    const double* val = op.P.valuePtr();
    for (std::size_t r = 0; r < static_cast<std::size_t>(op.P.rows()); ++r)
      for (int k = outer[r]; k < outer[r + 1]; ++k)
        f(r, static_cast<std::size_t>(inner[k]), val[k]);
  });
}

/// Entries per chunk of an assembling thread's list (1 MiB of OperatorEntry).
inline constexpr std::size_t kEntryChunk = std::size_t{1} << 16;

/// The R × R matrix of the per-thread entry lists `trip` (chunks of (row, column, value),
/// one entry per row and column), freeing each chunk as it goes.
inline CsrMatrix csr_by_rows(std::vector<std::vector<std::vector<OperatorEntry>>>& trip,
                             std::size_t R) {
  using Triplet = OperatorEntry;
  CsrMatrix A;
  // CSR by target rows: count, prefix sum, scatter (serial: O(nnz) moves), then sort each
  // row's columns (parallel; rows are short).
  std::vector<int> outer(R + 1, 0);
  std::size_t nnz = 0;
  for (const auto& chunks : trip)
    for (const auto& c : chunks) {
      nnz += c.size();
      for (const Triplet& e : c) ++outer[static_cast<std::size_t>(e.row) + 1];
    }
  if (nnz > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::length_error("transfer: more than 2^31 nonzeros (int32 CSR indices)");
  for (std::size_t r = 0; r < R; ++r) outer[r + 1] += outer[r];
  A.resize(static_cast<Eigen::Index>(R), static_cast<Eigen::Index>(R));
  A.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int* po = A.outerIndexPtr();
  int* pi = A.innerIndexPtr();
  double* pv = A.valuePtr();
  std::copy(outer.begin(), outer.end(), po);
  std::vector<int> fill(outer.begin(), outer.end() - 1);
  for (auto& chunks : trip)
    for (auto& c : chunks) {
      for (const Triplet& e : c) {
        const auto dst = static_cast<std::size_t>(fill[static_cast<std::size_t>(e.row)]++);
        pi[dst] = e.col;
        pv[dst] = e.value;
      }
      std::vector<Triplet>().swap(c);  // free as we go: the triplets are ~1.3× the matrix
    }
#pragma omp parallel
  {
    std::vector<std::pair<int, double>> row;
#pragma omp for schedule(static)
    for (std::int64_t r = 0; r < static_cast<std::int64_t>(R); ++r) {
      const int b = po[r], e = po[r + 1];
      row.clear();
      for (int k = b; k < e; ++k) row.emplace_back(pi[k], pv[k]);
      std::sort(row.begin(), row.end());
      for (int k = b; k < e; ++k) {
        pi[k] = row[static_cast<std::size_t>(k - b)].first;
        pv[k] = row[static_cast<std::size_t>(k - b)].second;
      }
    }
  }
  return A;
}

/// The operator (see the file comment). Source cells (columns) in parallel,
/// dynamic schedule, per-thread (target, source, fraction) triplets, then CSR by rows.
template <HybridModel M>
TransferOperator<state_dim_v<M>> assemble_forward(const TensorGrid<state_dim_v<M>>& grid,
                                                  const double* par, const TransferOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  using State = std::array<double, N>;
  TransferOperator<N> op = empty_operator<N>(grid, M::n_mode, opt.step, opt.scheme);
  const auto R = static_cast<std::int64_t>(op.size());
  const auto nn = static_cast<std::int64_t>(op.n_node);
  const Backend& backend = opt.backend ? *opt.backend : serial_backend();
  op.owned = backend.block(op.size());
  op.outflow.assign(static_cast<std::size_t>(R), 0.0);
  op.atom.assign(static_cast<std::size_t>(R), 0.0);
  const auto G = static_cast<std::size_t>(M::n_guard);
  op.absorbing.assign(G, 0);
  for (std::size_t g = 0; g < G; ++g) op.absorbing[g] = absorbs(detail::guard_info<M>(g)) ? 1 : 0;
  const bool any_absorbing =
      std::any_of(op.absorbing.begin(), op.absorbing.end(), [](char c) { return c != 0; });
  if (any_absorbing) op.absorbed.assign(static_cast<std::size_t>(R) * G, 0.0);
  op.impacts.assign(static_cast<std::size_t>(R) * G, 0.0);
  op.zeno_guard.assign(G, 0);
  const std::array<double, 1> step_time{opt.step};
  const int Ka =
      opt.samples_per_axis > 0 ? opt.samples_per_axis : default_samples_per_axis(N, opt.scheme);
  op.samples_per_axis = Ka;
  // `galerkin` samples the support of node k's hat, two cells per axis (one at a box face):
  // K is then the most points a column takes.
  const bool galerkin = opt.scheme == TransferScheme::galerkin;
  if (galerkin && backend.ranks() > 1)
    throw std::invalid_argument("transfer: scheme=galerkin runs in one process");
  const std::size_t per_axis = static_cast<std::size_t>(Ka) * (galerkin ? 2 : 1);
  std::size_t K = 1;
  for (std::size_t a = 0; a < N; ++a) {
    K *= per_axis;
    if (K > kMaxSamplesPerCell)
      throw std::invalid_argument("transfer: samples_per_axis^N = " + std::to_string(Ka) + "^" +
                                  std::to_string(N) + " exceeds " +
                                  std::to_string(kMaxSamplesPerCell) + " samples per cell");
  }
  std::array<double, N> dx{};
  for (std::size_t a = 0; a < N; ++a)
    dx[a] = (grid.axes[a].max - grid.axes[a].min) / static_cast<double>(grid.axes[a].n - 1);
  const std::vector<char> in_region = node_support<M>(grid, par, true);    // per (mode, node)
  const std::vector<char> in_support = node_support<M>(grid, par, false);  // per node
  using Triplet = OperatorEntry;  // (target row, source column, fraction)
  int threads = 1;
#ifdef _OPENMP
  threads = omp_get_max_threads();
#endif
  // Per thread, its entries in chunks of kEntryChunk, each reserved once: no vector grows by
  // copying itself (a doubling vector briefly holds 1.5 to 2 times its entries), and each
  // chunk is freed as soon as it has been moved into the matrix. `mtrip`: the mass matrix's
  // (`galerkin`).
  std::vector<std::vector<std::vector<Triplet>>> trip(static_cast<std::size_t>(threads)),
      mtrip(static_cast<std::size_t>(threads));
  if (galerkin) op.column_mass.assign(static_cast<std::size_t>(R), 0.0);
  std::atomic<std::int64_t> first_fail{R};
#pragma omp parallel num_threads(threads)
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    auto emit_to = [](std::vector<std::vector<Triplet>>& chunks, const Triplet& e) {
      if (chunks.empty() || chunks.back().size() == kEntryChunk) {
        chunks.emplace_back();
        chunks.back().reserve(kEntryChunk);
      }
      chunks.back().push_back(e);
    };
    std::vector<std::vector<Triplet>>& chunks = trip[static_cast<std::size_t>(tid)];
    std::vector<std::vector<Triplet>>& mchunks = mtrip[static_cast<std::size_t>(tid)];
    ForwardFlow<M> flow(par, first_step_h(opt.forward, opt.step));
    std::vector<std::pair<std::size_t, double>> dest;  // (state index, weight of one sample)
    dest.reserve(K * (std::size_t{1} << N));
    std::vector<std::pair<std::size_t, double>> mdest;      // the mass matrix's (`galerkin`)
    std::vector<ForwardResult<N>> end(K);                   // where each sample's flow ended
    std::vector<char> valid(K);                             // … in the support, status ok
    std::vector<char> flowed(K);                            // whether the sample was in the support
    std::vector<double> weight(K);                          // what each sample carries (see below)
    std::vector<double> n_absorbed(any_absorbing ? G : 0);  // per guard, in one cell
    std::vector<double> n_fired(G);                         // per guard, in one cell
    std::vector<char> zeno_guard(G, 0);                     // this thread's
#pragma omp for schedule(dynamic, 64)
    for (auto r = static_cast<std::int64_t>(op.owned.begin);
         r < static_cast<std::int64_t>(op.owned.end); ++r) {
      if (opt.progress) opt.progress->advance();
      if (r > first_fail.load(std::memory_order_relaxed)) continue;
      const auto m = static_cast<int>(r / nn);
      const auto i = static_cast<std::size_t>(r % nn);
      // The dual cell of node i, [y − Δ/2, y + Δ/2] ∩ box, in Ka sub-cells per axis; with
      // `galerkin` the support of its hat, [y − Δ, y + Δ] ∩ box, in Ka per cell.
      const State y = grid.node(i);
      State lo{}, hi{}, delta{};
      std::array<std::size_t, N> count{};  // sub-cells per axis
      std::size_t Kr = 1;                  // … in all
      for (std::size_t a = 0; a < N; ++a) {
        const double reach = galerkin ? dx[a] : 0.5 * dx[a];
        lo[a] = std::max(grid.axes[a].min, y[a] - reach);
        hi[a] = std::min(grid.axes[a].max, y[a] + reach);
        count[a] = galerkin ? static_cast<std::size_t>(Ka) *
                                  static_cast<std::size_t>(std::lround((hi[a] - lo[a]) / dx[a]))
                            : static_cast<std::size_t>(Ka);
        delta[a] = (hi[a] - lo[a]) / static_cast<double>(count[a]);  // a sample's sub-cell
        Kr *= count[a];
      }
      dest.clear();
      std::fill(n_absorbed.begin(), n_absorbed.end(), 0.0);
      std::fill(n_fired.begin(), n_fired.end(), 0.0);
      double n_out = 0.0, n_atom = 0.0;
      std::size_t n_void = 0;
      bool failed = false;
      auto sample = [&](std::size_t q) {
        State x0{};
        std::size_t rem = q;
        for (std::size_t a = N; a-- > 0;) {
          const auto j = static_cast<double>(rem % count[a]);
          rem /= count[a];
          x0[a] = lo[a] + (j + 0.5) * (hi[a] - lo[a]) / static_cast<double>(count[a]);
        }
        return x0;
      };
      // The cell's mass of mode m lives on cell ∩ support ∩ the mode's region; where no sample
      // lies in the region (a node that took mass by the deposit's support-only fallback),
      // on cell ∩ support, so that such mass moves on instead of being booked as outflow.
      bool use_region = false;
      for (std::size_t q = 0; q < Kr && !use_region; ++q) {
        const State x0 = sample(q);
        use_region = M::in_support(x0.data(), par) && in_mode_region<M>(m, x0.data(), par);
      }
      // What a sample carries: with `hat` 1 (the fractions are taken over the samples in the
      // support below), with `galerkin` φ_i at its point times its sub-cell's volume, and its
      // sub-cell where it starts is deposited on the hats as the mass matrix's column.
      mdest.clear();
      double column_mass = 0.0;
      const std::size_t mo_here = static_cast<std::size_t>(m) * static_cast<std::size_t>(nn);
      // Pass 1: the forward flow of every sample (kept: pass 2 reads its neighbours).
      for (std::size_t q = 0; q < Kr && !failed; ++q) {
        const State x0 = sample(q);
        valid[q] = 0;
        flowed[q] = 0;
        weight[q] = 1.0;
        if (!M::in_support(x0.data(), par) ||
            (use_region && !in_mode_region<M>(m, x0.data(), par))) {
          ++n_void;  // no state there
          continue;
        }
        if (galerkin) {
          double v = 1.0;
          for (std::size_t a = 0; a < N; ++a)
            v *= std::max(0.0, 1.0 - std::fabs(x0[a] - y[a]) / dx[a]) * delta[a];
          const std::size_t before = mdest.size();
          if (!(v > 0.0) || !(deposit<N>(grid, dx, delta, in_region.data() + mo_here, x0, mdest) ||
                              deposit<N>(grid, dx, delta, in_support.data(), x0, mdest))) {
            ++n_void;  // no node of its mode holds it: no state of this column there
            continue;
          }
          for (std::size_t k = before; k < mdest.size(); ++k) {
            mdest[k].first += mo_here;
            mdest[k].second *= v;
          }
          weight[q] = v;
          column_mass += v;
        }
        const double wq = weight[q];
        end[q] = flow.run(
            m, x0, std::span<const double>(step_time), [](std::size_t, int, const State&) {},
            [&](double, int g, const State&, const State&) {
              n_fired[static_cast<std::size_t>(g)] += wq;
            });
        flowed[q] = 1;
        const ForwardResult<N>& res = end[q];
        if (res.status == ForwardStatus::absorbed)
          n_fired[static_cast<std::size_t>(res.guard)] += wq;
        if (res.status == ForwardStatus::zeno && res.guard >= 0 && res.t_stop > 0.0)
          zeno_guard[static_cast<std::size_t>(res.guard)] = 1;
        valid[q] = res.status == ForwardStatus::ok && M::in_support(res.x.data(), par) ? 1 : 0;
        if (res.status == ForwardStatus::event_cap || res.status == ForwardStatus::failed) {
          failed = true;
#pragma omp critical(hybgen_rt_transfer_failure)
          {
            if (r < first_fail.load()) {
              first_fail.store(r);
              TraceStatus<N> st;
              st.error = res.error != TraceError::none ? res.error : TraceError::event_cap;
              st.mode = res.mode;
              st.guard = res.guard;
              st.tau = res.t_stop;
              st.state = res.x;
              st.events = res.events;
              op.failure = TraceFailure<N>{st, m, i, x0};
              op.failure_message = describe<M>(res, m, x0);
            }
          }
        }
      }
      // Pass 2: book every sample (see the file comment). `hat` deposits the IMAGE of the
      // sample's sub-cell: its width along each axis b is estimated from the images of the
      // neighbouring samples, w_b = (Σ_a D_a[b]²)^{1/2} with D_a the image of one sub-cell step
      // along axis a (central difference, one-sided at the cell's edge or where a neighbour
      // ended elsewhere: another mode, outside, or farther than 4 cells); it matches the
      // second moments of the image of an affine map exactly (in 1-D the images then tile
      // without gaps or overlaps; for a smooth map up to O(δ²)).
      for (std::size_t q = 0; q < Kr && !failed; ++q) {
        if (!flowed[q]) continue;  // a void sample (counted in pass 1; end[q] is stale)
        const ForwardResult<N>& res = end[q];
        if (res.status == ForwardStatus::zeno) {
          n_atom += weight[q];
          continue;
        }
        if (res.status != ForwardStatus::ok) {
          n_out += weight[q];
          if (res.status == ForwardStatus::absorbed)
            n_absorbed[static_cast<std::size_t>(res.guard)] += weight[q];
          continue;
        }
        State width = delta;
        if (Ka > 1) {
          std::array<std::array<double, N>, N> D{};
          std::size_t stride = 1;
          for (std::size_t a = N; a-- > 0;) {
            const std::size_t digit = (q / stride) % count[a];
            auto near = [&](std::size_t nb) {
              if (!valid[nb] || end[nb].mode != res.mode) return false;
              for (std::size_t b = 0; b < N; ++b)
                if (!(std::fabs(end[nb].x[b] - res.x[b]) <= 4.0 * dx[b] + 4.0 * delta[b]))
                  return false;
              return true;
            };
            const bool up = digit + 1 < count[a] && near(q + stride);
            const bool down = digit > 0 && near(q - stride);
            for (std::size_t b = 0; b < N; ++b) {
              if (up && down)
                D[a][b] = 0.5 * (end[q + stride].x[b] - end[q - stride].x[b]);
              else if (up)
                D[a][b] = end[q + stride].x[b] - res.x[b];
              else if (down)
                D[a][b] = res.x[b] - end[q - stride].x[b];
              else
                D[a][b] = a == b ? delta[a] : 0.0;
            }
            stride *= count[a];
          }
          for (std::size_t b = 0; b < N; ++b) {
            double w2 = 0.0;
            for (std::size_t a = 0; a < N; ++a) w2 += D[a][b] * D[a][b];
            width[b] = std::min(std::sqrt(w2), 8.0 * dx[b]);
          }
        }
        const std::size_t before = dest.size();
        // On the nodes of the end mode inside the support and the mode's region; where none
        // of the stencil is (a region thinner than a cell), on those inside the support.
        const std::size_t mo = static_cast<std::size_t>(res.mode) * static_cast<std::size_t>(nn);
        if (valid[q] && (deposit<N>(grid, dx, width, in_region.data() + mo, res.x, dest) ||
                         deposit<N>(grid, dx, width, in_support.data(), res.x, dest))) {
          for (std::size_t k = before; k < dest.size(); ++k) {
            dest[k].first += mo;
            dest[k].second *= weight[q];
          }
        } else {
          n_out += weight[q];
        }
      }
      if (failed) continue;
      // `hat`: fractions over the samples in the support (all K but near a support boundary
      // that is not a box face); a cell with none keeps no mass: all of it counts as outflow.
      // `galerkin`: the samples' weights as they are; the column sums to column_mass.
      const std::size_t k_in = Kr - n_void;
      const double inv = galerkin ? 1.0 : (k_in > 0 ? 1.0 / static_cast<double>(k_in) : 0.0);
      const auto ru = static_cast<std::size_t>(r);
      op.outflow[ru] = galerkin || k_in > 0 ? n_out * inv : 1.0;
      op.atom[ru] = n_atom * inv;
      for (std::size_t g = 0; g < n_absorbed.size(); ++g)
        op.absorbed[ru * G + g] = n_absorbed[g] * inv;
      for (std::size_t g = 0; g < G; ++g) op.impacts[ru * G + g] = n_fired[g] * inv;
      // The summed entries of one column, (row, weight) pairs in any order.
      const auto emit_column = [&](std::vector<std::pair<std::size_t, double>>& d,
                                   std::vector<std::vector<Triplet>>& to) {
        std::sort(d.begin(), d.end());
        for (std::size_t k = 0; k < d.size();) {
          double w = 0.0;
          std::size_t e = k;
          for (; e < d.size() && d[e].first == d[k].first; ++e) w += d[e].second;
          emit_to(to, Triplet{static_cast<std::int32_t>(d[k].first), static_cast<std::int32_t>(r),
                              w * inv});
          k = e;
        }
      };
      emit_column(dest, chunks);
      if (galerkin) {
        emit_column(mdest, mchunks);
        op.column_mass[ru] = column_mass;
      }
    }
#pragma omp critical(hybgen_rt_transfer_zeno)
    for (std::size_t g = 0; g < G; ++g)
      op.zeno_guard[g] = static_cast<char>(op.zeno_guard[g] | zeno_guard[g]);
  }
  if (backend.ranks() > 1 && G > 0) {
    std::vector<double> z(op.zeno_guard.begin(), op.zeno_guard.end());
    backend.max(std::span<double>(z));
    for (std::size_t g = 0; g < G; ++g) op.zeno_guard[g] = z[g] > 0.0 ? 1 : 0;
  }
  // The failure of the smallest state index over all ranks, then the columns' mass check.
  agree_first_failure(backend, first_fail.load(), op.failure, R, &op.failure_message);
  if (op.failure_message.empty())
    check_columns<M>(op, backend, [&trip](auto&& f) {
      for (const auto& chunks : trip)
        for (const auto& c : chunks)
          for (const Triplet& e : c)
            f(static_cast<std::size_t>(e.row), static_cast<std::size_t>(e.col), e.value);
    });
  if (backend.ranks() > 1) {
    // The owned columns' entries, every thread's chunks as they are (moved, not copied),
    // handed to the backend's distributed matrix.
    if (!op.failure_message.empty()) return op;  // agreed on every rank: none builds one
    OperatorEntries part;
    part.size = op.size();
    part.owned = op.owned;
    for (auto& chunks : trip)
      for (auto& c : chunks) part.lists.push_back(std::move(c));
    trip.clear();
    op.backend = &backend;
    op.distributed = backend.matrix(std::move(part));
    if (!op.distributed)
      throw std::logic_error("transfer: a backend of several ranks without distributed matrices");
    return op;
  }
  op.P = csr_by_rows(trip, static_cast<std::size_t>(R));
  if (galerkin) {
    op.mass = csr_by_rows(mtrip, static_cast<std::size_t>(R));
    op.mass_solve = std::make_shared<const MassSolve>(op.mass, op.column_mass);
  }
  return op;
}

/// The reductions fused into one step.
struct StepSums {
  double mass = 0.0;     ///< Σ y (node masses after the step).
  double outflow = 0.0;  ///< Σ outflow_r x_r (the mass leaving the box or the support).
  double atom = 0.0;     ///< Σ atom_r x_r (the mass reaching a Zeno point).
};

/// Below this many rows a step runs on one thread: a fork/join costs microseconds, and on an
/// oversubscribed machine a spinning barrier can cost milliseconds — more than the step.
inline constexpr std::int64_t kParallelRows = 32768;

/// y = P x with the budget's reductions fused, OpenMP static schedule over rows (the same
/// partition every step, so each thread streams the same slice of the CSR arrays and of y).
inline StepSums csr_step(const CsrMatrix& P, const double* x, double* y, const double* outflow,
                         const double* atom) {
  const int* outer = P.outerIndexPtr();
  const int* inner = P.innerIndexPtr();
  const double* val = P.valuePtr();
  const auto R = static_cast<std::int64_t>(P.rows());
  double sm = 0.0, so = 0.0, sa = 0.0;
#pragma omp parallel for schedule(static) reduction(+ : sm, so, sa) if (R > kParallelRows)
  for (std::int64_t r = 0; r < R; ++r) {
    double s = 0.0;
    for (int k = outer[r]; k < outer[r + 1]; ++k) s += val[k] * x[inner[k]];
    y[r] = s;
    sm += s;
    so += outflow[r] * x[r];
    sa += atom[r] * x[r];
  }
  return {sm, so, sa};
}

}  // namespace detail

/// Assemble the transfer operator of one step `opt.step` on `grid` (parameters `par`).
/// Throws std::invalid_argument on a bad step, grid or sample count. A failed forward flow is
/// reported in `failure` and `failure_message` (the smallest state index: mode, start point,
/// guard, forward time), a broken column in `failure_message`; the matrix must then not be
/// used.
template <HybridModel M>
TransferOperator<state_dim_v<M>> assemble_transfer(const TensorGrid<state_dim_v<M>>& grid,
                                                   const double* par, const TransferOptions& opt) {
  detail::validate_transfer(opt.step);
  detail::validate_grid(grid, static_cast<std::size_t>(M::n_mode));
  const auto t0 = std::chrono::steady_clock::now();
  if (opt.samples_per_axis < 0)
    throw std::invalid_argument("transfer: samples_per_axis must be >= 1 (0: the default)");
  TransferOperator<state_dim_v<M>> op = detail::assemble_forward<M>(grid, par, opt);
  if (!op.ok() && op.failure_message.empty()) op.failure_message = describe<M>(op.failure);
  op.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return op;
}

/// The initial density on the grid nodes, layout [mode][node]; 0 outside `in_support`.
template <HybridModel M>
std::vector<double> initial_vector(const TensorGrid<state_dim_v<M>>& grid, const double* par) {
  const std::size_t n = grid.size();
  const auto nm = static_cast<std::size_t>(M::n_mode);
  std::vector<double> u(n * nm, 0.0);
  const auto total = static_cast<std::int64_t>(n * nm);
#pragma omp parallel for schedule(static)
  for (std::int64_t r = 0; r < total; ++r) {
    const auto i = static_cast<std::size_t>(r) % n;
    const auto m = static_cast<int>(static_cast<std::size_t>(r) / n);
    const auto y = grid.node(i);
    if (M::in_support(y.data(), par))
      u[static_cast<std::size_t>(r)] = M::initial_density(m, y.data(), par);
  }
  return u;
}

/// Number of steps h to reach t: t/h must be an integer to 1e-9 relative, else throws.
inline long steps_to(double t, double h) {
  const double s = t / h;
  const double k = std::round(s);
  if (!std::isfinite(s) || s < 0.0 || std::fabs(s - k) > 1e-9 * std::max(1.0, s))
    throw std::invalid_argument("transfer: output time " + std::to_string(t) +
                                " is not a multiple of the step " + std::to_string(h));
  return static_cast<long>(k);
}

/// March the node densities `u0` (layout [mode][node], see `initial_vector`) with the
/// operator to the sorted output `times` (each an integer multiple of op.step, to 1e-9
/// relative; throws std::invalid_argument otherwise, or if the assembly failed). Never
/// renormalises. After every step the budget mass_{n+1} + outflow_n + atom_n = mass_n is
/// checked: a defect beyond kStepBudgetTol·mass0 stops the march with `failure` naming the
/// step, its time and the node that gained most (a numerical failure, exit 3). `progress`,
/// if set, is advanced once per step. A distributed operator is marched by every rank on
/// its owned entries (one collective mat-vec and one sum of the three budget terms per
/// step); each rank's `solution` keeps its own entries of every frame (distributed: nothing
/// is gathered). `galerkin`: x = M u0 are the moments, each step x ← P u, u = M⁻¹ x; a
/// solve that fails stops the march with `failure`.
template <std::size_t N>
TransferRun<N> march(const TransferOperator<N>& op, std::span<const double> u0,
                     std::span<const double> times, Progress* progress = nullptr) {
  detail::validate_times(times);
  if (!op.ok()) throw std::invalid_argument("transfer: the operator failed: " + op.failure_message);
  const std::size_t R = op.size();
  if (u0.size() != R) throw std::invalid_argument("transfer: initial vector has the wrong size");
  const auto t0 = std::chrono::steady_clock::now();
  const Backend& b = op.distributed && op.backend ? *op.backend : serial_backend();
  const Block own = op.distributed ? op.owned : Block{0, R};
  const std::size_t L = own.size();
  std::vector<long> at(times.size());
  for (std::size_t k = 0; k < times.size(); ++k) at[k] = steps_to(times[k], op.step);
  TransferRun<N> run;
  run.n_steps = at.empty() ? 0 : at.back();
  Solution<N>& sol = run.solution;
  sol.n_time = times.size();
  sol.n_mode = op.n_mode;
  sol.n_point = op.n_node;
  if (op.distributed) sol.distributed = true, sol.owned = own;
  sol.u.assign(sol.n_time * L, 0.0);
  // x: the owned node masses weight·u (`galerkin`: the moments M u, and u the values).
  // (`galerkin` runs in one process: assemble_forward refuses it over several ranks.)
  const bool galerkin = op.mass_solve != nullptr;
  std::vector<double> x(L), y(L), u(galerkin ? L : 0);
  const double* w = op.weight.data() + own.begin;
  const double* outflow = op.outflow.data() + own.begin;
  const double* atom = op.atom.data() + own.begin;
  double mass0 = 0.0;
  const auto Li = static_cast<std::int64_t>(L);
  if (galerkin) {
    std::copy(u0.begin(), u0.end(), u.begin());
    Eigen::Map<Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(L)) =
        op.mass * Eigen::Map<const Eigen::VectorXd>(u.data(), static_cast<Eigen::Index>(L));
  }
#pragma omp parallel for schedule(static) reduction(+ : mass0) if (Li > detail::kParallelRows)
  for (std::int64_t r = 0; r < Li; ++r) {
    const auto ru = static_cast<std::size_t>(r);
    if (!galerkin) x[ru] = w[ru] * u0[own.begin + ru];
    y[ru] = 0.0;
    mass0 += x[ru];
  }
  mass0 = b.sum(mass0);
  // What the operator acts on: the masses, or the values (`galerkin`).
  const std::vector<double>& src = galerkin ? u : x;
  run.step_mass.reserve(static_cast<std::size_t>(run.n_steps) + 1);
  run.step_mass.push_back(mass0);
  std::size_t k = 0;
  double out_cum = 0.0, atom_cum = 0.0;
  MassBudget& mb = run.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = mass0;
  // The absorbing guards' shares, Σ_r absorbed_rg x_r per step, cumulated (with the outflow).
  const std::size_t G = op.absorbed.empty() ? 0 : op.absorbing.size();
  std::vector<double> absorbed_cum(G, 0.0), absorbed_step(G, 0.0);
  if (G > 0) mb.absorbed.assign(G, {});
  // The impacts per guard, Σ_r impacts_rg x_r per step, cumulated (methods/impacts.hpp);
  // infinite, on a guard with Zeno samples, from the first frame whose atom exceeds the
  // budget's rounding tolerance (`tol`: a node at rest carries no measurable mass).
  const std::size_t GI = op.impacts.empty() ? 0 : op.zeno_guard.size();
  std::vector<double> impacts_cum(GI, 0.0), impacts_step(GI, 0.0);
  // One step's per-guard totals of a column table (`table`[r·n + g] per unit mass in column
  // r, n = step.size(): op.absorbed, op.impacts) applied to the marched masses x (`galerkin`:
  // per unit value, to the values u), summed over the ranks, and added to `cum`.
  const auto per_guard = [&](const std::vector<double>& table, std::vector<double>& step,
                             std::vector<double>& cum) {
    const std::size_t n = step.size();
    std::fill(step.begin(), step.end(), 0.0);
    const double* t = table.data() + own.begin * n;
    for (std::size_t r = 0; r < L; ++r)
      for (std::size_t g = 0; g < n; ++g) step[g] += t[r * n + g] * src[r];
    if (op.distributed) b.sum(std::span<double>(step));
    for (std::size_t g = 0; g < n; ++g) cum[g] += step[g];
  };
  mb.impacts.assign(GI, {});
  mb.impacts_infinite_from.assign(GI, times.size());
  const double scale = std::max(std::fabs(mass0), std::numeric_limits<double>::min());
  const double tol = kStepBudgetTol * std::max(1.0, static_cast<double>(R) / 1e6);
  auto emit = [&](long n) {
    for (; k < times.size() && at[k] == n; ++k) {
      double* dst = sol.u.data() + k * L;
#pragma omp parallel for schedule(static) if (Li > detail::kParallelRows)
      for (std::int64_t r = 0; r < Li; ++r) {
        const auto ru = static_cast<std::size_t>(r);
        dst[ru] = galerkin ? u[ru] : x[ru] / w[ru];
      }
      mb.mass.push_back(run.step_mass.back());
      mb.outflow.push_back(out_cum);
      mb.atom.push_back(atom_cum);
      for (std::size_t g = 0; g < G; ++g)
        if (op.absorbing[g]) mb.absorbed[g].push_back(absorbed_cum[g]);
      for (std::size_t g = 0; g < GI; ++g) {
        mb.impacts[g].push_back(impacts_cum[g]);
        if (op.zeno_guard[g] && atom_cum > tol * scale)
          mb.impacts_infinite_from[g] = std::min(mb.impacts_infinite_from[g], k);
      }
    }
  };
  emit(0);
  for (long n = 0; n < run.n_steps; ++n) {
    detail::StepSums s;
    if (op.distributed) {
      op.distributed->multiply(src, y);
      double sm = 0.0, so = 0.0, sa = 0.0;
#pragma omp parallel for schedule(static) reduction(+ : sm, so, sa) if (Li > detail::kParallelRows)
      for (std::int64_t r = 0; r < Li; ++r) {
        const auto ru = static_cast<std::size_t>(r);
        sm += y[ru];
        so += outflow[ru] * src[ru];
        sa += atom[ru] * src[ru];
      }
      std::array<double, 3> sums{sm, so, sa};
      b.sum(std::span<double>(sums));
      s = {sums[0], sums[1], sums[2]};
    } else {
      s = detail::csr_step(op.P, src.data(), y.data(), outflow, atom);
    }
    const double defect = std::fabs(s.mass + s.outflow + s.atom - run.step_mass.back()) / scale;
    run.budget_defect = std::max(run.budget_defect, std::isnan(defect) ? HUGE_VAL : defect);
    if (!(defect <= tol)) {
      // The node whose mass grew most names the place (over every rank's entries).
      std::size_t worst = 0;
      double gain = -HUGE_VAL;
      for (std::size_t r = 0; r < L; ++r)
        if (!(y[r] - x[r] <= gain)) gain = y[r] - x[r], worst = r;
      const double top = b.max(gain);
      const auto node =
          static_cast<std::size_t>(b.min(gain == top ? static_cast<std::int64_t>(own.begin + worst)
                                                     : static_cast<std::int64_t>(R)));
      std::ostringstream os;
      os.precision(6);
      os << "the transfer operator broke the mass budget at step " << n + 1
         << " (t = " << static_cast<double>(n + 1) * op.step
         << "): mass + outflow + atom changed by " << defect << " of the initial mass (tolerance "
         << tol << "); the largest gain is at node " << node % op.n_node << " of mode "
         << node / op.n_node;
      run.failure = os.str();
      break;
    }
    if (G > 0) per_guard(op.absorbed, absorbed_step, absorbed_cum);
    if (GI > 0) per_guard(op.impacts, impacts_step, impacts_cum);
    std::swap(x, y);
    if (galerkin && !op.mass_solve->solve(x.data(), u.data())) {
      run.failure = "at step " + std::to_string(n + 1) + ": " + op.mass_solve->error();
      break;
    }
    out_cum += s.outflow;
    atom_cum += s.atom;
    run.step_outflow.push_back(s.outflow);
    run.step_atom.push_back(s.atom);
    run.step_mass.push_back(s.mass);
    emit(n + 1);
    if (progress) progress->advance();
  }
  run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return run;
}

}  // namespace hybgen::rt
