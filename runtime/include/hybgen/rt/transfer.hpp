#pragma once
/// \file transfer.hpp
/// The transfer-operator method: the hybrid flow is autonomous, so the Frobenius–Perron
/// evolution over one step h is ONE fixed linear map u ↦ P u. It is assembled once as a
/// sparse matrix and the density is marched by sparse matrix–vector products.
///
/// State layout: index r = m·n_node + i (mode m, grid node i in C order), like `Solution`.
///
/// Interpolating (semi-Lagrangian) scheme, the default. The exact step is
///   u^{n+1}(y) = Σ_branches w_b · u^n_{m_b}(x_b),   w_b = exp(−∫div X)·Π 1/|J|,
/// over the feet (m_b, x_b) of the backward hybrid flow from (m, y) over time h — the same
/// tracer as the characteristics method (reversed resets, pre-image checks, support, events).
/// u^n between nodes is the multilinear interpolant Σ_k φ_k(x) u^n_k, so row (m, y) of P
/// holds w_b·φ_k(x_b). Multilinear weights are ≥ 0 and sum to 1 on a cell, so P ≥ 0 entrywise
/// (positivity and monotonicity: no over- or undershoots, unlike higher-order interpolants
/// without a limiter). Feet outside the grid box contribute nothing (no inflow from outside
/// the box: what flows in is unknown to a box-limited method); feet outside `in_support` have
/// no density; nodes outside `in_support` have an empty row. The error at fixed h is the
/// interpolation error, O(Δx²) per step, O(Δx²/h) over a fixed horizon; h enters only
/// through the number of interpolations (the trace is exact to the ODE tolerance).
///
/// Mass is never renormalised: `march` reports the discrete mass m(u) = Σ_r w_r u_r with the
/// trapezoid weights w (= dual-cell volumes) after every step, and the per-step loss
/// m(u^n) − m(u^{n+1}) (outflow through the faces plus the scheme's conservation error).
///
/// Conservative (Ulam) scheme: cell-to-cell mass transfer by the FORWARD hybrid flow
/// (forward.hpp). The cells are the dual cells of the nodes (half cells at the box faces;
/// their volumes are exactly the trapezoid weights). Cell i's mass is taken uniformly
/// distributed (Ulam's ansatz): K = samples_per_axis^N sample points on the midpoint tensor
/// pattern of the cell, each carrying the fraction 1/K, are pushed forward by h; a sample
/// lands in the cell of mode' containing its end point, or counts as outflow_i (it left the
/// box or the support), or as atom_i (it came to rest at a Zeno point within h: mass
/// concentrated on a point, which no density can hold). P_ji = fraction of cell i landing
/// in cell j, so Σ_j P_ji + outflow_i + atom_i = 1 (counts/K: exact up to one rounding), and
/// mass + outflow + atom = mass0 holds for the march to rounding. P acts on cell masses;
/// densities are masses / cell volumes. Ulam's ansatz smears each cell over its image: the
/// method is first order (more diffusive than interpolation) but conservative and ≥ 0.
/// Cost: K forward flows per cell (16 in 2-D with the default 4 per axis).
/// Sampling error: each fraction is quantised to k/K, an O(1/K) error that does not shrink
/// with Δx (tests/rt/test_invariant.cpp: the cycle's invariant density has L1 error 5.5e-2,
/// 1.4e-2, 3.2e-3 for K = 8, 32, 128 at 101 nodes, nearly the same at 51 … 401 nodes):
/// refine K together with the grid.
/// Zeno points: the cell of a Zeno point is re-spread uniformly every step and only its
/// samples with t_Z ≤ h drain into the atom; t_Z ~ √Δx there, so for small h the mass sits
/// in that cell as density and the atom lags (tests/rt/test_transfer.cpp: ZenoMassBecomesAnAtom).

// GCC 12's flow-sensitive warnings (null-dereference, use-after-free, maybe-uninitialized
// with AVX-512) misfire inside Eigen's and Spectra's headers after inlining, despite
// -isystem: silenced for those headers only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 12
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuse-after-free"
#endif
#include <Eigen/SparseCore>
#pragma GCC diagnostic pop

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/characteristics.hpp"
#include "hybgen/rt/forward.hpp"
#include "hybgen/rt/model.hpp"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace hybgen::rt {

/// Which transfer operator to assemble.
enum class TransferScheme {
  interpolate,   ///< Backward feet + multilinear interpolation (semi-Lagrangian), default.
  conservative,  ///< Ulam: cell-to-cell mass transfer by the forward flow (exact budget).
};

/// Options of `assemble_transfer`.
struct TransferOptions {
  double step = 0.05;                                   ///< Step h of the operator (> 0).
  TransferScheme scheme = TransferScheme::interpolate;  ///< Scheme.
  int samples_per_axis = 4;        ///< Conservative: sample points per axis and cell (K = this^N).
  CharacteristicsOptions trace{};  ///< Interpolating: the backward traces' options.
  /// Conservative: the forward flows' options. zeno_time = 1: a Zeno accumulation is
  /// declared as soon as the gap signature holds and t_Z ≤ h (the physical criterion for
  /// mass reaching the Zeno point within the step), not only deep inside the cascade.
  ForwardOptions forward{.ode = {}, .max_events = 1000, .zeno_time = 1.0, .zeno_ratio = 0.999};
  Progress* progress = nullptr;  ///< Advanced once per assembled row when set.
};

/// Compressed sparse row matrix with int32 column indices and row pointers: each mat-vec
/// streams 8 + 4 bytes per nonzero and 4 per row (int64 indices would add a third).
using CsrMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

/// One step of the hybrid Frobenius–Perron evolution as a sparse matrix.
template <std::size_t N>
struct TransferOperator {
  TensorGrid<N> grid{};                                 ///< The grid.
  std::size_t n_mode = 0;                               ///< Number of modes.
  std::size_t n_node = 0;                               ///< Nodes per mode.
  double step = 0.0;                                    ///< Step h.
  TransferScheme scheme = TransferScheme::interpolate;  ///< Scheme.
  /// Interpolating: u^{n+1} = P u^n on node densities. Conservative: M^{n+1} = P M^n on
  /// cell masses M_r = weight_r·u_r; P_jr = fraction of cell r's mass that lands in cell j.
  CsrMatrix P;
  std::vector<double> weight;   ///< Trapezoid weight (= dual-cell volume) of every index r.
  std::vector<double> outflow;  ///< Conservative: fraction of cell r leaving box/support.
  /// Conservative: fraction of cell r that reaches a Zeno point within h (an atom).
  std::vector<double> atom;
  /// First failure (smallest index r), if any. Conservative scheme: the forward flow's
  /// status mapped in (status.tau is then the FORWARD time of the failure).
  TraceFailure<N> failure{};
  std::string failure_message;  ///< One-line description of `failure` (exit code 3), or "".
  double seconds = 0.0;         ///< Wall time of the assembly.

  /// Length of the state vector, n_mode·n_node.
  std::size_t size() const { return n_mode * n_node; }
  /// Whether the assembly succeeded everywhere.
  bool ok() const { return failure.ok(); }
};

/// Result of `march`: densities at the output times and the mass budget.
template <std::size_t N>
struct TransferRun {
  Solution<N> solution;  ///< Densities, layout [time][mode][node] (like `solve_grid`).
  /// Budget per output time: mass = Σ w u; interpolating scheme: outflow = cumulative loss
  /// mass0 − mass (faces + conservation error), atom = 0; conservative: exact cumulative
  /// outflow and atom, mass + outflow + atom = mass0 up to rounding.
  MassBudget budget;
  std::vector<double> step_mass;     ///< Mass after n steps, n = 0..n_steps.
  std::vector<double> step_outflow;  ///< Per step: loss (interpolating) / outflow (conservative).
  std::vector<double> step_atom;     ///< Per step: atom gained (conservative), else 0.
  long n_steps = 0;                  ///< Steps taken.
  double seconds = 0.0;              ///< Wall time of the march.
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

/// The multilinear hat functions at x: flat node indices and weights of the 2^N corners of
/// the cell containing x; false if x is outside the box (beyond 1e-12 of a side, rounding).
template <std::size_t N>
bool hat_weights(const TensorGrid<N>& grid, const double* x,
                 std::array<std::size_t, (std::size_t{1} << N)>& idx,
                 std::array<double, (std::size_t{1} << N)>& wt) {
  std::array<std::size_t, N> base{};
  std::array<double, N> t{};
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    const double cells = static_cast<double>(ax.n - 1);
    const double s = (x[a] - ax.min) / (ax.max - ax.min) * cells;
    if (!(s >= -1e-12 * cells && s <= cells * (1.0 + 1e-12))) return false;
    const double f = std::clamp(std::floor(s), 0.0, cells - 1.0);
    base[a] = static_cast<std::size_t>(f);
    t[a] = std::clamp(s - f, 0.0, 1.0);
  }
  constexpr std::size_t C = std::size_t{1} << N;
  for (std::size_t c = 0; c < C; ++c) {
    std::size_t flat = 0;
    double w = 1.0;
    for (std::size_t a = 0; a < N; ++a) {
      const std::size_t bit = (c >> (N - 1 - a)) & 1U;
      flat = flat * static_cast<std::size_t>(grid.axes[a].n) + base[a] + bit;
      w *= bit ? t[a] : 1.0 - t[a];
    }
    idx[c] = flat;
    wt[c] = w;
  }
  return true;
}

/// Rows assembled by one thread: row ids and their (column, value) runs, columns sorted.
struct RowBlock {
  std::vector<std::int64_t> rows;   // row ids, in the order processed
  std::vector<std::int64_t> begin;  // start of each row's run in cols/vals
  std::vector<int> cols;
  std::vector<double> vals;
};

/// Sort a row's entries by column and merge duplicates (several feet in one cell), dropping
/// exact zeros (a foot on a grid line gives zero weights to half the corners).
inline void sort_merge(std::vector<std::pair<int, double>>& e) {
  std::sort(e.begin(), e.end(),
            [](const std::pair<int, double>& a, const std::pair<int, double>& b) {
              return a.first < b.first;
            });
  std::size_t o = 0;
  for (std::size_t k = 0; k < e.size(); ++k) {
    if (o > 0 && e[o - 1].first == e[k].first)
      e[o - 1].second += e[k].second;
    else
      e[o++] = e[k];
  }
  e.resize(o);
  std::erase_if(e, [](const std::pair<int, double>& p) { return p.second == 0.0; });
}

/// Build the CSR matrix from per-thread row blocks (each row in exactly one block; rows in
/// no block are empty). Row pointers by a prefix sum of the counts, then every block copies
/// its runs into place in parallel.
inline void build_csr(CsrMatrix& P, std::int64_t R, std::vector<RowBlock>& blocks) {
  std::vector<std::int64_t> count(static_cast<std::size_t>(R) + 1, 0);
  for (const RowBlock& b : blocks)
    for (std::size_t k = 0; k < b.rows.size(); ++k) {
      const std::int64_t end =
          k + 1 < b.rows.size() ? b.begin[k + 1] : static_cast<std::int64_t>(b.cols.size());
      count[static_cast<std::size_t>(b.rows[k]) + 1] = end - b.begin[k];
    }
  for (std::size_t r = 0; r < static_cast<std::size_t>(R); ++r) count[r + 1] += count[r];
  const std::int64_t nnz = count[static_cast<std::size_t>(R)];
  if (nnz > std::numeric_limits<int>::max())
    throw std::length_error("transfer: more than 2^31 nonzeros (int32 CSR indices)");
  P.resize(static_cast<Eigen::Index>(R), static_cast<Eigen::Index>(R));
  P.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int* outer = P.outerIndexPtr();
  int* inner = P.innerIndexPtr();
  double* val = P.valuePtr();
  for (std::size_t r = 0; r <= static_cast<std::size_t>(R); ++r)
    outer[r] = static_cast<int>(count[r]);
  const auto nb = static_cast<std::int64_t>(blocks.size());
#pragma omp parallel for schedule(static, 1)
  for (std::int64_t bi = 0; bi < nb; ++bi) {
    const RowBlock& b = blocks[static_cast<std::size_t>(bi)];
    for (std::size_t k = 0; k < b.rows.size(); ++k) {
      const std::int64_t end =
          k + 1 < b.rows.size() ? b.begin[k + 1] : static_cast<std::int64_t>(b.cols.size());
      std::int64_t dst = count[static_cast<std::size_t>(b.rows[k])];
      for (std::int64_t s = b.begin[k]; s < end; ++s, ++dst) {
        inner[dst] = b.cols[static_cast<std::size_t>(s)];
        val[dst] = b.vals[static_cast<std::size_t>(s)];
      }
    }
  }
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
  return op;
}

/// The interpolating operator (see the file comment). Rows in parallel, dynamic schedule
/// (traces differ in cost: a reset costs an event location), per-thread row blocks.
template <HybridModel M>
TransferOperator<state_dim_v<M>> assemble_interpolating(const TensorGrid<state_dim_v<M>>& grid,
                                                        const double* par,
                                                        const TransferOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  constexpr std::size_t C = std::size_t{1} << N;
  using State = std::array<double, N>;
  TransferOperator<N> op =
      empty_operator<N>(grid, M::n_mode, opt.step, TransferScheme::interpolate);
  const auto R = static_cast<std::int64_t>(op.size());
  const auto nn = static_cast<std::int64_t>(op.n_node);
  int threads = 1;
#ifdef _OPENMP
  threads = omp_get_max_threads();
#endif
  std::vector<RowBlock> blocks(static_cast<std::size_t>(threads));
  std::atomic<std::int64_t> first_fail{R};
#pragma omp parallel num_threads(threads)
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    RowBlock& blk = blocks[static_cast<std::size_t>(tid)];
    blk.cols.reserve(static_cast<std::size_t>(R / threads) * C + 64);
    blk.vals.reserve(static_cast<std::size_t>(R / threads) * C + 64);
    Tracer<M> tracer(par, first_step_h(opt.trace, opt.step));
    std::vector<std::pair<int, double>> row;
    std::array<std::size_t, C> idx{};
    std::array<double, C> wt{};
    auto sink = [&](int mf, const State& x, double w) {
      if (!M::in_support(x.data(), par)) return;
      if (!hat_weights<N>(grid, x.data(), idx, wt)) return;
      const auto off = static_cast<std::size_t>(mf) * static_cast<std::size_t>(nn);
      for (std::size_t c = 0; c < C; ++c)
        if (wt[c] != 0.0) row.emplace_back(static_cast<int>(off + idx[c]), w * wt[c]);
    };
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t r = 0; r < R; ++r) {
      if (opt.progress) opt.progress->advance();
      if (r > first_fail.load(std::memory_order_relaxed)) continue;
      const auto m = static_cast<int>(r / nn);
      const auto i = static_cast<std::size_t>(r % nn);
      const State y = grid.node(i);
      if (!M::in_support(y.data(), par)) continue;
      row.clear();
      const TraceStatus<N> st = tracer.trace_feet(y, m, opt.step, sink);
      if (!st.ok()) {
#pragma omp critical(hybgen_rt_transfer_failure)
        {
          if (r < first_fail.load()) {
            first_fail.store(r);
            op.failure = TraceFailure<N>{st, m, i, y};
          }
        }
        continue;
      }
      sort_merge(row);
      if (row.empty()) continue;
      blk.rows.push_back(r);
      blk.begin.push_back(static_cast<std::int64_t>(blk.cols.size()));
      for (const auto& [c, v] : row) {
        blk.cols.push_back(c);
        blk.vals.push_back(v);
      }
    }
  }
  build_csr(op.P, R, blocks);
  return op;
}

/// The conservative (Ulam) operator (see the file comment). Source cells in parallel
/// (dynamic schedule), per-thread (target, source, count) triplets, then CSR by rows.
template <HybridModel M>
TransferOperator<state_dim_v<M>> assemble_conservative(const TensorGrid<state_dim_v<M>>& grid,
                                                       const double* par,
                                                       const TransferOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  using State = std::array<double, N>;
  TransferOperator<N> op =
      empty_operator<N>(grid, M::n_mode, opt.step, TransferScheme::conservative);
  const auto R = static_cast<std::int64_t>(op.size());
  const auto nn = static_cast<std::int64_t>(op.n_node);
  op.outflow.assign(static_cast<std::size_t>(R), 0.0);
  op.atom.assign(static_cast<std::size_t>(R), 0.0);
  const int Ka = opt.samples_per_axis;
  std::size_t K = 1;
  for (std::size_t a = 0; a < N; ++a) K *= static_cast<std::size_t>(Ka);
  std::array<double, N> dx{};
  for (std::size_t a = 0; a < N; ++a)
    dx[a] = (grid.axes[a].max - grid.axes[a].min) / static_cast<double>(grid.axes[a].n - 1);
  struct Triplet {
    int row, col;
    double frac;  // count / (samples in the support)
  };
  int threads = 1;
#ifdef _OPENMP
  threads = omp_get_max_threads();
#endif
  std::vector<std::vector<Triplet>> trip(static_cast<std::size_t>(threads));
  std::atomic<std::int64_t> first_fail{R};
#pragma omp parallel num_threads(threads)
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    std::vector<Triplet>& out = trip[static_cast<std::size_t>(tid)];
    ForwardFlow<M> flow(par, first_step_h(opt.forward, opt.step));
    std::vector<int> dest;
    dest.reserve(K);
#pragma omp for schedule(dynamic, 64)
    for (std::int64_t r = 0; r < R; ++r) {
      if (opt.progress) opt.progress->advance();
      if (r > first_fail.load(std::memory_order_relaxed)) continue;
      const auto m = static_cast<int>(r / nn);
      const auto i = static_cast<std::size_t>(r % nn);
      // The dual cell of node i: [y − Δ/2, y + Δ/2] ∩ box.
      const State y = grid.node(i);
      State lo{}, hi{};
      for (std::size_t a = 0; a < N; ++a) {
        lo[a] = std::max(grid.axes[a].min, y[a] - 0.5 * dx[a]);
        hi[a] = std::min(grid.axes[a].max, y[a] + 0.5 * dx[a]);
      }
      dest.clear();
      std::size_t n_out = 0, n_atom = 0, n_void = 0;
      bool failed = false;
      for (std::size_t q = 0; q < K && !failed; ++q) {
        State x0{};
        std::size_t rem = q;
        for (std::size_t a = N; a-- > 0;) {
          const auto j = static_cast<double>(rem % static_cast<std::size_t>(Ka));
          rem /= static_cast<std::size_t>(Ka);
          x0[a] = lo[a] + (j + 0.5) * (hi[a] - lo[a]) / static_cast<double>(Ka);
        }
        if (!M::in_support(x0.data(), par)) {
          ++n_void;  // no state there: the cell's mass lives on cell ∩ support
          continue;
        }
        const ForwardResult<N> res = flow.run(m, x0, opt.step);
        switch (res.status) {
          case ForwardStatus::ok: {
            // The cell containing the end point: the nearest node.
            std::size_t flat = 0;
            bool inside = true;
            for (std::size_t a = 0; a < N; ++a) {
              const GridAxis& ax = grid.axes[a];
              const double s = (res.x[a] - ax.min) / dx[a];
              if (!(s >= -0.5 && s <= static_cast<double>(ax.n - 1) + 0.5)) {
                inside = false;
                break;
              }
              const auto j = static_cast<std::size_t>(
                  std::clamp(std::floor(s + 0.5), 0.0, static_cast<double>(ax.n - 1)));
              flat = flat * static_cast<std::size_t>(ax.n) + j;
            }
            if (inside && M::in_support(res.x.data(), par))
              dest.push_back(static_cast<int>(
                  static_cast<std::size_t>(res.mode) * static_cast<std::size_t>(nn) + flat));
            else
              ++n_out;
            break;
          }
          case ForwardStatus::left_support:
            ++n_out;
            break;
          case ForwardStatus::zeno:
            ++n_atom;
            break;
          case ForwardStatus::event_cap:
          case ForwardStatus::failed: {
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
            break;
          }
        }
      }
      if (failed) continue;
      // Fractions over the samples in the support (all K but near a support boundary that
      // is not a box face); a cell with none keeps no mass: all of it counts as outflow.
      const std::size_t k_in = K - n_void;
      const double inv = k_in > 0 ? 1.0 / static_cast<double>(k_in) : 0.0;
      op.outflow[static_cast<std::size_t>(r)] = k_in > 0 ? static_cast<double>(n_out) * inv : 1.0;
      op.atom[static_cast<std::size_t>(r)] = static_cast<double>(n_atom) * inv;
      std::sort(dest.begin(), dest.end());
      for (std::size_t k = 0; k < dest.size();) {
        std::size_t e = k;
        while (e < dest.size() && dest[e] == dest[k]) ++e;
        out.push_back(Triplet{dest[k], static_cast<int>(r), static_cast<double>(e - k) * inv});
        k = e;
      }
    }
  }
  // CSR by target rows: count, prefix sum, scatter (serial: O(nnz) moves), then sort each
  // row's columns (parallel; rows are short).
  std::vector<int> outer(static_cast<std::size_t>(R) + 1, 0);
  std::size_t nnz = 0;
  for (const auto& t : trip) {
    nnz += t.size();
    for (const Triplet& e : t) ++outer[static_cast<std::size_t>(e.row) + 1];
  }
  if (nnz > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::length_error("transfer: more than 2^31 nonzeros (int32 CSR indices)");
  for (std::size_t r = 0; r < static_cast<std::size_t>(R); ++r) outer[r + 1] += outer[r];
  op.P.resize(static_cast<Eigen::Index>(R), static_cast<Eigen::Index>(R));
  op.P.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int* po = op.P.outerIndexPtr();
  int* pi = op.P.innerIndexPtr();
  double* pv = op.P.valuePtr();
  std::copy(outer.begin(), outer.end(), po);
  std::vector<int> fill(outer.begin(), outer.end() - 1);
  for (const auto& t : trip)
    for (const Triplet& e : t) {
      const auto dst = static_cast<std::size_t>(fill[static_cast<std::size_t>(e.row)]++);
      pi[dst] = e.col;
      pv[dst] = e.frac;
    }
#pragma omp parallel
  {
    std::vector<std::pair<int, double>> row;
#pragma omp for schedule(static)
    for (std::int64_t r = 0; r < R; ++r) {
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
  return op;
}

/// The reductions fused into one step.
struct StepSums {
  double mass = 0.0;   ///< Σ w y (or Σ y).
  double leak1 = 0.0;  ///< Σ leak1 x.
  double leak2 = 0.0;  ///< Σ leak2 x.
};

/// Below this many rows a step runs on one thread: a fork/join costs microseconds, and on an
/// oversubscribed machine a spinning barrier can cost milliseconds — more than the step.
inline constexpr std::int64_t kParallelRows = 32768;

/// y = P x with fused reductions, OpenMP static schedule over rows (the same partition every
/// step, so each thread streams the same slice of the CSR arrays and of y). With w: returns
/// Σ w_r y_r (interpolating mass). Without (w null): Σ y_r (conservative: cell masses) and
/// Σ leak1_r x_r, Σ leak2_r x_r (the mass leaving through the columns' outflow and atom).
inline StepSums csr_step(const CsrMatrix& P, const double* x, double* y, const double* w,
                         const double* leak1, const double* leak2) {
  const int* outer = P.outerIndexPtr();
  const int* inner = P.innerIndexPtr();
  const double* val = P.valuePtr();
  const auto R = static_cast<std::int64_t>(P.rows());
  double sm = 0.0, s1 = 0.0, s2 = 0.0;
  if (w != nullptr) {
#pragma omp parallel for schedule(static) reduction(+ : sm) if (R > kParallelRows)
    for (std::int64_t r = 0; r < R; ++r) {
      double s = 0.0;
      for (int k = outer[r]; k < outer[r + 1]; ++k) s += val[k] * x[inner[k]];
      y[r] = s;
      sm += w[r] * s;
    }
  } else {
#pragma omp parallel for schedule(static) reduction(+ : sm, s1, s2) if (R > kParallelRows)
    for (std::int64_t r = 0; r < R; ++r) {
      double s = 0.0;
      for (int k = outer[r]; k < outer[r + 1]; ++k) s += val[k] * x[inner[k]];
      y[r] = s;
      sm += s;
      s1 += leak1[r] * x[r];
      s2 += leak2[r] * x[r];
    }
  }
  return {sm, s1, s2};
}

}  // namespace detail

/// Assemble the transfer operator of one step `opt.step` on `grid` (parameters `par`).
/// Throws std::invalid_argument on a bad step or grid. A failed trace is reported in
/// `failure` (the smallest state index; `describe<M>(op.failure)` names mode, point, guard,
/// backward time); the matrix is then incomplete and must not be used.
template <HybridModel M>
TransferOperator<state_dim_v<M>> assemble_transfer(const TensorGrid<state_dim_v<M>>& grid,
                                                   const double* par, const TransferOptions& opt) {
  detail::validate_transfer(opt.step);
  detail::validate_grid(grid, static_cast<std::size_t>(M::n_mode));
  const auto t0 = std::chrono::steady_clock::now();
  TransferOperator<state_dim_v<M>> op;
  if (opt.scheme == TransferScheme::interpolate) {
    op = detail::assemble_interpolating<M>(grid, par, opt);
  } else {
    if (opt.samples_per_axis < 1)
      throw std::invalid_argument("transfer: samples_per_axis must be >= 1");
    op = detail::assemble_conservative<M>(grid, par, opt);
  }
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
/// renormalises. `progress`, if set, is advanced once per step.
template <std::size_t N>
TransferRun<N> march(const TransferOperator<N>& op, std::span<const double> u0,
                     std::span<const double> times, Progress* progress = nullptr) {
  detail::validate_times(times);
  if (!op.ok()) throw std::invalid_argument("transfer: the operator failed: " + op.failure_message);
  const std::size_t R = op.size();
  if (u0.size() != R) throw std::invalid_argument("transfer: initial vector has the wrong size");
  const auto t0 = std::chrono::steady_clock::now();
  const bool cons = op.scheme == TransferScheme::conservative;
  std::vector<long> at(times.size());
  for (std::size_t k = 0; k < times.size(); ++k) at[k] = steps_to(times[k], op.step);
  TransferRun<N> run;
  run.n_steps = at.empty() ? 0 : at.back();
  Solution<N>& sol = run.solution;
  sol.n_time = times.size();
  sol.n_mode = op.n_mode;
  sol.n_point = op.n_node;
  sol.u.assign(sol.n_time * R, 0.0);
  // x: densities (interpolating) or cell masses weight·u (conservative).
  std::vector<double> x(R), y(R);
  const double* w = op.weight.data();
  double mass0 = 0.0;
  const auto Ri = static_cast<std::int64_t>(R);
#pragma omp parallel for schedule(static) reduction(+ : mass0) if (Ri > detail::kParallelRows)
  for (std::int64_t r = 0; r < Ri; ++r) {
    const auto ru = static_cast<std::size_t>(r);
    x[ru] = cons ? w[ru] * u0[ru] : u0[ru];
    y[ru] = 0.0;
    mass0 += w[ru] * u0[ru];
  }
  run.step_mass.reserve(static_cast<std::size_t>(run.n_steps) + 1);
  run.step_mass.push_back(mass0);
  std::size_t k = 0;
  double out_cum = 0.0, atom_cum = 0.0;
  MassBudget& mb = run.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = mass0;
  auto emit = [&](long n) {
    for (; k < times.size() && at[k] == n; ++k) {
      double* dst = sol.u.data() + k * R;
#pragma omp parallel for schedule(static) if (Ri > detail::kParallelRows)
      for (std::int64_t r = 0; r < Ri; ++r) {
        const auto ru = static_cast<std::size_t>(r);
        dst[ru] = cons ? x[ru] / w[ru] : x[ru];
      }
      const double m = run.step_mass.back();
      mb.mass.push_back(m);
      mb.outflow.push_back(cons ? out_cum : mass0 - m);
      mb.atom.push_back(cons ? atom_cum : 0.0);
    }
  };
  emit(0);
  for (long n = 0; n < run.n_steps; ++n) {
    const detail::StepSums s =
        cons
            ? detail::csr_step(op.P, x.data(), y.data(), nullptr, op.outflow.data(), op.atom.data())
            : detail::csr_step(op.P, x.data(), y.data(), w, nullptr, nullptr);
    std::swap(x, y);
    if (cons) {
      out_cum += s.leak1;
      atom_cum += s.leak2;
      run.step_outflow.push_back(s.leak1);
      run.step_atom.push_back(s.leak2);
    } else {
      run.step_outflow.push_back(run.step_mass.back() - s.mass);
      run.step_atom.push_back(0.0);
    }
    run.step_mass.push_back(s.mass);
    emit(n + 1);
    if (progress) progress->advance();
  }
  run.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return run;
}

}  // namespace hybgen::rt
