#pragma once
/// \file particles.hpp
/// The particle method (`method=particles`): Monte-Carlo samples of the initial density,
/// pushed forward by the hybrid flow (forward.hpp), deposited onto the grid. It is the
/// definition-based baseline — the pushed-forward measure μ_t = (φ_t)_# (u0 dx), observed
/// through its integrals — and an independent check of the characteristics method.
///
/// Sampling: importance sampling. The proposal q is piecewise constant on the cells of a
/// tensor lattice covering the SAMPLING DOMAIN, the grid box widened by `margin`·width on
/// every side (mass starting outside the box flows in later: for the paper's ball 9 % of the
/// mass of u0 starts outside [0, 2] × [−2, 2], much of it on orbits through the box), per
/// mode: q_{m,c} ∝ max(|u0_m| at the 2ᴺ corners and the centre of cell c) + floor·mean, the
/// floor making q > 0 on the whole domain. With p(m, x) = (q_{m,c}/Q)/|c| the proposal density
/// and F the CDF of (m, c) in flat order, particle i inverts F at (i + U_i)/n (stratified
/// inversion: each particle draws from the slice [i/n, (i + 1)/n) of the proposal's mass),
/// then x uniform in c; its weight is w_i = u0_m(x)/(n p(m, x)). Particle i has density
/// n·p on its slice, so E[w_i f(m_i, x_i)] = ∫_slice u0 f and E[Σ_i w_i f] = Σ_m ∫_domain u0_m f:
/// every estimate is UNBIASED (up to the mass of u0 outside the sampling domain) whatever
/// the quality of q, which only sets the variance; stratification with equal slice
/// probabilities never increases it over i.i.d. draws from p (the variance estimates below
/// pair neighbouring strata instead of taking the i.i.d. formula, which overstates it), and it
/// makes consecutive particles neighbours in space, which keeps the deposit cache-friendly. Exact
/// rejection sampling would need a certified bound of u0/q; point values of a generated u0 cannot
/// certify one (a peak between the lattice points would bias rejection silently), while importance
/// weights stay exact. A weight is exactly 0 outside `M::in_support` (the characteristics method's
/// convention); such particles are not traced.
///
/// Many dimensions: a lattice of at most `proposal_cells` cells has fewer than
/// kMinLatticeCells cells per axis from 7-D on (4 in 10-D), each far wider than the density's
/// features: the weights then vary by orders of magnitude and the estimates, though unbiased,
/// are noise (measured on models/gl3.model: mass 4.4e-4 ± 7.4e-4 against 0.21 with 20000
/// particles). There the proposal is a PRODUCT of 1-D profiles instead: per mode, the point
/// x* of largest u0 found by coordinate ascent (two sweeps of kProfileCells points per axis
/// from the grid box's centre), and along each axis the profile p_a(t) = u0(x* with x_a = t),
/// piecewise constant on kProfileCells cells (the largest of its ends and middle) plus the
/// floor; modes are drawn in proportion to Π_a ∫p_a / u0(x*)^{N−1}, the mass of a density
/// of product form. For such a density the weights are constant; for any other the floor
/// keeps q > 0 and the estimates unbiased.
///
/// Randomness: particle i draws from its own SplitMix64 stream seeded by (seed, i), so the
/// particles — and, with the integer accumulation below, every output bit — do not depend
/// on the number of threads or the schedule, nor on the number of ranks: with a backend of
/// R ranks (core/backend.hpp) each pushes its block of the indices, and the integer sums
/// and max|w| are reduced across ranks exactly.
///
/// Deposit: cloud-in-cell. A particle of weight w at y in the grid box adds w·λ_j(y) to the 2ᴺ
/// corner nodes j of its grid cell (multilinear weights, Σ_j λ_j = 1); node sums are divided
/// by the node's dual-cell volume V_j = Π_a (h_a, or h_a/2 at the ends), so the result is a
/// density and its trapezoid mass Σ_j V_j u_j equals the particle mass in the box. All sums
/// are in 64-bit fixed point (w ↦ round(w·S), S = 2^⌊61 − log2(n max|w|)⌋, so no sum of ≤ n
/// weights overflows; the corner parts of one particle sum exactly to its rounded weight):
/// integer addition is associative, so the results are independent of the summation order;
/// the rounding is ≤ 2⁻⁶²·n·max|w| per term.
///
/// Budget per output time t_k (box = the grid box, closed, with the tolerance of
/// characteristics' in_box): mass0 = Σ w·[x_i(0) ∈ box], mass_k = Σ w·[x_i(t_k) ∈ box],
/// atom_k = Σ w·[the particle has come to rest at a Zeno point in the box by t_k], outflow_k =
/// Σ w·([x_i(0) ∈ box] − [x_i(t_k) ∈ box] − [atom]) (net outflow through the faces, as in
/// characteristics.hpp; a particle that left the support, or came to rest outside the box,
/// counts as outside). Hence mass + outflow + atom = mass0 exactly in integers, to rounding in
/// doubles. mass_error[k] = 2σ̂ of mass_k, σ̂² the collapsed-strata variance of the stratified
/// sample (Σ over neighbouring pairs of particles of the squared difference of their
/// contributions: an overestimate by the neighbours' differences of mean only; the i.i.d.
/// formula was 5–300× the true error); atom_error and each trap's absorbed_error alike.
///
/// Failures (a trajectory hitting the event cap without the Zeno signature, or a numerical
/// failure) are reported for the particle with the smallest index, with its start and the
/// place; the other results are then partial.
///
/// Size: the proposal and its sampling, the counter-based streams, the deposit on the grid or
/// on the marginals, and the integer bookkeeping that keeps mass + outflow + atom exact, over
/// threads and ranks: one method whose parts share the sample's life.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/core/ode.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/methods/forward.hpp"
#include "hybgen/rt/methods/impacts.hpp"
#include "hybgen/rt/methods/observables.hpp"
#include "hybgen/rt/model.hpp"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace hybgen::rt {

/// Options of the particle method.
struct ParticleOptions {
  std::size_t particles = 1000000;  ///< Number of samples n.
  std::uint64_t seed = 1;           ///< Seed of the particle streams.
  ForwardOptions forward{};         ///< The forward flow (tolerances, event cap, Zeno).
  double margin = 1.0;              ///< Sampling domain: the box widened by margin·width per side.
  std::size_t proposal_cells = std::size_t{1} << 20;  ///< Cap on proposal cells (per mode).
  double proposal_floor = 1e-3;  ///< Floor of q relative to its mean cell value (> 0).
  /// Per-thread deposit arrays (no atomics) while threads × (times × modes × nodes) × 8 bytes
  /// stay below this; above it one shared array with atomic adds.
  std::size_t private_deposit_bytes = std::size_t{256} << 20;
  Progress* progress = nullptr;  ///< Advanced once per particle pushed when set.
  /// Advanced once per particle drawn in the first pass (the weights' largest, for the fixed
  /// point), when set: at 10¹⁰ particles that pass alone takes minutes.
  Progress* draw_progress = nullptr;
  /// The ranks sharing the particles (null: this process alone); the result is on rank 0.
  const Backend* backend = nullptr;
  /// Keep the 2-D marginals of every pair of axes and the moments instead of the density on
  /// every node (`density=marginals`): for grids too large to hold.
  bool marginals = false;
};

/// A counter-based random stream: SplitMix64 (Steele, Lea, Flood 2014) started at a state
/// derived from (seed, index) by two SplitMix64 finalisations.
class ParticleRng {
 public:
  /// The stream of particle `index` under `seed`.
  ParticleRng(std::uint64_t seed, std::uint64_t index) {
    std::uint64_t s = seed;
    std::uint64_t t = index ^ next_of(s);
    state_ = next_of(t);
  }
  /// Next 64 random bits.
  std::uint64_t next() { return next_of(state_); }
  /// Uniform in [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

 private:
  static std::uint64_t next_of(std::uint64_t& state) {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  std::uint64_t state_ = 0;
};

/// One sample of the initial density: mode, state and importance weight (Σ over all samples
/// estimates the mass of u0 in the sampling domain).
template <std::size_t N>
struct ParticleSample {
  int mode = 0;               ///< Mode.
  std::array<double, N> x{};  ///< State at t = 0.
  double weight = 0.0;        ///< u0(x)/(n·p(mode, x)); 0 outside the support.
};

/// Fewest lattice cells per axis the proposal uses; below, the product proposal (file doc).
inline constexpr std::size_t kMinLatticeCells = 8;
/// Cells per axis of the product proposal's profiles.
inline constexpr std::size_t kProfileCells = 1024;

/// The importance-sampling proposal of the file doc and the draw of particle i.
template <HybridModel M>
class ParticleSampler {
 public:
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  using State = std::array<double, N>;              ///< A state.

  /// The proposal for the box of `grid` widened by opt.margin (throws std::invalid_argument
  /// for a grid axis with fewer than 2 nodes or an empty extent).
  ParticleSampler(const TensorGrid<N>& grid, const double* par, const ParticleOptions& opt)
      : par_(par), n_(opt.particles), seed_(opt.seed) {
    if (!(opt.margin >= 0.0) || !(opt.proposal_floor > 0.0))
      throw std::invalid_argument("particles: margin must be >= 0 and proposal_floor > 0");
    double cells = 1.0;
    for (std::size_t a = 0; a < N; ++a) {
      const GridAxis& ax = grid.axes[a];
      if (ax.n < 2 || !(ax.max > ax.min))
        throw std::invalid_argument("particles: every grid axis needs >= 2 nodes and max > min");
      const double w = ax.max - ax.min;
      lo_[a] = ax.min - opt.margin * w;
      hi_[a] = ax.max + opt.margin * w;
      cells_[a] = std::max<std::size_t>(
          1, static_cast<std::size_t>(std::lround((ax.n - 1) * (1.0 + 2.0 * opt.margin))));
      cells *= static_cast<double>(cells_[a]);
    }
    const double cap = static_cast<double>(std::max<std::size_t>(opt.proposal_cells, 1));
    if (cells > cap) {
      const double f = std::pow(cap / cells, 1.0 / static_cast<double>(N));
      for (std::size_t a = 0; a < N; ++a)
        cells_[a] = std::max<std::size_t>(
            1, static_cast<std::size_t>(std::floor(static_cast<double>(cells_[a]) * f)));
    }
    product_ = *std::min_element(cells_.begin(), cells_.end()) < kMinLatticeCells;
    if (product_) {
      build_product(opt.proposal_floor);
      return;
    }
    ncell_ = 1;
    vol_ = 1.0;
    for (std::size_t a = 0; a < N; ++a) {
      h_[a] = (hi_[a] - lo_[a]) / static_cast<double>(cells_[a]);
      ncell_ *= cells_[a];
      vol_ *= h_[a];
    }
    build(opt.proposal_floor);
  }

  /// Whether the proposal is the product of profiles (many dimensions; file doc).
  bool product() const { return product_; }

  /// Particle i (deterministic in (seed, i)).
  ParticleSample<N> draw(std::size_t i) const {
    if (product_) return draw_product(i);
    ParticleRng rng(seed_, i);
    ParticleSample<N> s;
    // Stratified inversion: particle i inverts the CDF at (i + U)/n.
    const double target =
        std::min((static_cast<double>(i) + rng.uniform()) / static_cast<double>(n_), 1.0) *
        cdf_.back();
    auto it = std::upper_bound(cdf_.begin(), cdf_.end(), target);
    std::size_t idx = static_cast<std::size_t>(it - cdf_.begin());
    if (idx >= cdf_.size()) idx = cdf_.size() - 1;
    while (q_[idx] == 0.0 && idx > 0) --idx;  // (never with a positive floor)
    s.mode = static_cast<int>(idx / ncell_);
    std::size_t c = idx % ncell_;
    for (std::size_t a = N; a-- > 0;) {
      const std::size_t ca = c % cells_[a];
      c /= cells_[a];
      s.x[a] = lo_[a] + (static_cast<double>(ca) + rng.uniform()) * h_[a];
    }
    if (!M::in_support(s.x.data(), par_)) return s;
    const double u0 = M::initial_density(s.mode, s.x.data(), par_);
    s.weight = u0 * cdf_.back() * vol_ / (static_cast<double>(n_) * q_[idx]);
    return s;
  }

  /// Number of particles n.
  std::size_t size() const { return n_; }
  /// Lower corner of the sampling domain.
  const State& lo() const { return lo_; }
  /// Upper corner of the sampling domain.
  const State& hi() const { return hi_; }
  /// Proposal cells per axis.
  const std::array<std::size_t, N>& cells() const { return cells_; }

 private:
  void build(double floor) {
    const std::size_t nm = static_cast<std::size_t>(M::n_mode);
    // |u0| on the lattice nodes ((cells+1) per axis) and at the cell centres.
    std::array<std::size_t, N> nn{};
    std::size_t nodes = 1;
    for (std::size_t a = 0; a < N; ++a) {
      nn[a] = cells_[a] + 1;
      nodes *= nn[a];
    }
    auto u0abs = [this](int m, const State& x) {
      if (!M::in_support(x.data(), par_)) return 0.0;
      const double v = std::fabs(M::initial_density(m, x.data(), par_));
      return std::isfinite(v) ? v : 0.0;
    };
    q_.assign(nm * ncell_, 0.0);
    std::vector<double> nodal(nodes);
    for (std::size_t m = 0; m < nm; ++m) {
      for (std::size_t j = 0; j < nodes; ++j) {
        State x;
        std::size_t r = j;
        for (std::size_t a = N; a-- > 0;) {
          x[a] = lo_[a] + static_cast<double>(r % nn[a]) * h_[a];
          r /= nn[a];
        }
        nodal[j] = u0abs(static_cast<int>(m), x);
      }
      for (std::size_t c = 0; c < ncell_; ++c) {
        std::array<std::size_t, N> ci{};
        std::size_t r = c;
        State xc;
        for (std::size_t a = N; a-- > 0;) {
          ci[a] = r % cells_[a];
          r /= cells_[a];
          xc[a] = lo_[a] + (static_cast<double>(ci[a]) + 0.5) * h_[a];
        }
        double v = u0abs(static_cast<int>(m), xc);
        for (std::size_t corner = 0; corner < (std::size_t{1} << N); ++corner) {
          std::size_t j = 0;
          for (std::size_t a = 0; a < N; ++a) j = j * nn[a] + ci[a] + ((corner >> a) & 1U);
          v = std::max(v, nodal[j]);
        }
        q_[m * ncell_ + c] = v;
      }
    }
    double total = 0.0;
    for (double v : q_) total += v;
    const double add = total > 0.0 ? floor * total / static_cast<double>(q_.size()) : 1.0;
    cdf_.resize(q_.size());
    double acc = 0.0;
    for (std::size_t i = 0; i < q_.size(); ++i) {
      q_[i] += add;
      acc += q_[i];
      cdf_[i] = acc;
    }
  }

  /// Particle i from the product proposal: the mode by inversion at (i + U)/n (stratified),
  /// then each axis by inversion of its profile's CDF.
  ParticleSample<N> draw_product(std::size_t i) const {
    ParticleRng rng(seed_, i);
    ParticleSample<N> s;
    const double u =
        std::min((static_cast<double>(i) + rng.uniform()) / static_cast<double>(n_), 1.0) *
        mode_cdf_.back();
    s.mode = static_cast<int>(std::min<std::size_t>(
        static_cast<std::size_t>(std::upper_bound(mode_cdf_.begin(), mode_cdf_.end(), u) -
                                 mode_cdf_.begin()),
        mode_cdf_.size() - 1));
    const auto m = static_cast<std::size_t>(s.mode);
    double q = mode_p_[m];  // the proposal density at x: π_m Π_a p_a(x_a)/Z_a
    for (std::size_t a = 0; a < N; ++a) {
      const std::vector<double>& cdf = profile_cdf_[m * N + a];
      const double v = rng.uniform() * cdf.back();
      const auto c = std::min<std::size_t>(
          static_cast<std::size_t>(std::upper_bound(cdf.begin(), cdf.end(), v) - cdf.begin()),
          kProfileCells - 1);
      const double h = (hi_[a] - lo_[a]) / static_cast<double>(kProfileCells);
      s.x[a] = lo_[a] + (static_cast<double>(c) + rng.uniform()) * h;
      q *= profile_[m * N + a][c] / (cdf.back() * h);
    }
    if (!M::in_support(s.x.data(), par_)) return s;
    const double u0 = M::initial_density(s.mode, s.x.data(), par_);
    s.weight = u0 / (static_cast<double>(n_) * q);
    return s;
  }

  /// The product proposal (file doc).
  void build_product(double floor) {
    const std::size_t nm = static_cast<std::size_t>(M::n_mode);
    profile_.assign(nm * N, std::vector<double>(kProfileCells, 0.0));
    profile_cdf_.assign(nm * N, std::vector<double>(kProfileCells, 0.0));
    mode_p_.assign(nm, 0.0);
    mode_cdf_.assign(nm, 0.0);
    auto u0abs = [this](int m, const State& x) {
      if (!M::in_support(x.data(), par_)) return 0.0;
      const double v = std::fabs(M::initial_density(m, x.data(), par_));
      return std::isfinite(v) ? v : 0.0;
    };
    std::vector<double> mass(nm, 0.0);
    for (std::size_t m = 0; m < nm; ++m) {
      const auto mi = static_cast<int>(m);
      // x*: coordinate ascent from the box's centre (the sampling domain's centre).
      State x;
      for (std::size_t a = 0; a < N; ++a) x[a] = 0.5 * (lo_[a] + hi_[a]);
      double best = u0abs(mi, x);
      for (int sweep = 0; sweep < 2; ++sweep)
        for (std::size_t a = 0; a < N; ++a) {
          State y = x;
          for (std::size_t c = 0; c <= kProfileCells; ++c) {
            y[a] = lo_[a] +
                   (hi_[a] - lo_[a]) * static_cast<double>(c) / static_cast<double>(kProfileCells);
            const double v = u0abs(mi, y);
            if (v > best) best = v, x[a] = y[a];
          }
        }
      double log_z = 0.0;
      for (std::size_t a = 0; a < N; ++a) {
        std::vector<double>& p = profile_[m * N + a];
        const double h = (hi_[a] - lo_[a]) / static_cast<double>(kProfileCells);
        State y = x;
        double total = 0.0;
        for (std::size_t c = 0; c < kProfileCells; ++c) {
          double v = 0.0;
          for (const double f : {0.0, 0.5, 1.0}) {
            y[a] = lo_[a] + (static_cast<double>(c) + f) * h;
            v = std::max(v, u0abs(mi, y));
          }
          p[c] = v;
          total += v;
        }
        const double add = total > 0.0 ? floor * total / static_cast<double>(kProfileCells) : 1.0;
        double acc = 0.0;
        for (std::size_t c = 0; c < kProfileCells; ++c) {
          p[c] += add;
          acc += p[c];
          profile_cdf_[m * N + a][c] = acc;
        }
        log_z += std::log(acc * h);
      }
      // The mass of a product-form density with these profiles: Π_a Z_a / u0(x*)^{N−1}.
      mass[m] = best > 0.0 ? std::exp(log_z - static_cast<double>(N - 1) * std::log(best)) : 0.0;
    }
    double total = 0.0;
    for (const double v : mass) total += v;
    double acc = 0.0;
    for (std::size_t m = 0; m < nm; ++m) {
      const double w =
          total > 0.0 ? std::max(mass[m], floor * total / static_cast<double>(nm)) : 1.0;
      acc += w;
      mode_cdf_[m] = acc;
    }
    for (std::size_t m = 0; m < nm; ++m)
      mode_p_[m] = (mode_cdf_[m] - (m ? mode_cdf_[m - 1] : 0.0)) / mode_cdf_.back();
  }

  const double* par_;
  std::size_t n_ = 0;
  std::uint64_t seed_ = 1;
  State lo_{}, hi_{}, h_{};
  std::array<std::size_t, N> cells_{};
  std::size_t ncell_ = 1;
  double vol_ = 1.0;
  std::vector<double> q_, cdf_;
  bool product_ = false;                          // the product proposal (many dimensions)
  std::vector<std::vector<double>> profile_;      // [mode·N + axis][cell]: p_a + floor
  std::vector<std::vector<double>> profile_cdf_;  // … their running sums
  std::vector<double> mode_p_, mode_cdf_;         // mode probabilities and their CDF
};

/// What a particle is at an output time.
enum class ParticleFate {
  state,            ///< Flowing (or ended ok): x is its state at t_k (inside the box or not).
  outside_support,  ///< Left the support before t_k (x: its first state outside).
  zeno,             ///< At rest at the Zeno accumulation state x since t_Z ≤ t_k.
  absorbed,         ///< Absorbed by a guard (model.hpp, absorbs) before t_k, at x.
};

/// The first failed particle (event cap without the Zeno signature, or a numerical failure).
template <std::size_t N>
struct ParticleFailure {
  std::size_t index = 0;          ///< Particle index.
  int start_mode = -1;            ///< Mode at t = 0.
  std::array<double, N> start{};  ///< State at t = 0.
  ForwardResult<N> result{};      ///< How and where its trajectory failed.
  /// Whether nothing failed.
  bool ok() const {
    return result.status != ForwardStatus::event_cap && result.status != ForwardStatus::failed;
  }
};

/// Result of `solve_particles`.
template <std::size_t N>
struct ParticleRun {
  Solution<N> solution;            ///< Deposited density, layout [time][mode][node].
  MassBudget budget;               ///< Particle budget of the grid box (file doc).
  ParticleFailure<N> failure{};    ///< First failed particle, if any.
  std::size_t particles = 0;       ///< Particles drawn.
  std::size_t traced = 0;          ///< Particles with a nonzero weight (traced).
  double sampled_mass = 0.0;       ///< Σ w: estimate of Σ_m ∫ u0_m over the sampling domain.
  std::vector<double> atom_error;  ///< 2σ̂ of budget.atom[k] (as budget.mass_error for mass).
  Marginals marginals;             ///< With opt.marginals: the pairs and moments (solution empty).
  /// The expectations of M's observables over the samples in the box per output time, and
  /// twice their standard errors (observables.hpp); on rank 0.
  std::vector<ObservableSeries> observables;
  /// Whether every trajectory succeeded.
  bool ok() const { return failure.ok(); }
};

namespace detail {

/// Push one particle through `times`: visit(k, ParticleFate, int mode, const State& x, int
/// guard) for every k (in order) unless the trajectory fails; `guard` is the absorbing guard
/// for ParticleFate::absorbed, else −1; on_reset(double t, int g, const State& before, const
/// State& after) at every reset (ForwardFlow::run). Returns its result.
template <HybridModel M, class Visit, class OnReset>
ForwardResult<state_dim_v<M>> push_one(ForwardFlow<M>& flow,
                                       const ParticleSample<state_dim_v<M>>& s,
                                       std::span<const double> times, Visit& visit,
                                       OnReset&& on_reset) {
  std::size_t delivered = 0;
  auto on_output = [&](std::size_t k, int mode, const std::array<double, state_dim_v<M>>& x) {
    delivered = k + 1;
    visit(k, ParticleFate::state, mode, x, -1);
  };
  const ForwardResult<state_dim_v<M>> r =
      flow.run(s.mode, s.x, times, on_output, std::forward<OnReset>(on_reset));
  if (r.status == ForwardStatus::event_cap || r.status == ForwardStatus::failed) return r;
  const ParticleFate fate = r.status == ForwardStatus::zeno       ? ParticleFate::zeno
                            : r.status == ForwardStatus::absorbed ? ParticleFate::absorbed
                            : r.status == ForwardStatus::left_support
                                ? ParticleFate::outside_support
                                : ParticleFate::state;
  const int guard = fate == ParticleFate::absorbed ? r.guard : -1;
  for (std::size_t k = delivered; k < times.size(); ++k) visit(k, fate, r.mode, r.x, guard);
  return r;
}

/// As above, without a reset callback.
template <HybridModel M, class Visit>
ForwardResult<state_dim_v<M>> push_one(ForwardFlow<M>& flow,
                                       const ParticleSample<state_dim_v<M>>& s,
                                       std::span<const double> times, Visit& visit) {
  return push_one<M>(flow, s, times, visit,
                     [](double, int, const std::array<double, state_dim_v<M>>&,
                        const std::array<double, state_dim_v<M>>&) {});
}

}  // namespace detail

/// Draw every particle of `sampler` and push it through the sorted output times (OpenMP,
/// dynamic schedule): visit(std::size_t i, const ParticleSample<N>&, std::size_t k,
/// ParticleFate, int mode, const State& x) for every traced particle i and output time k —
/// concurrently from several threads (the visitor must be thread-safe; distinct i never
/// share a call). Particles of zero weight are not visited. Returns the first failure.
template <HybridModel M, class Visit>
ParticleFailure<state_dim_v<M>> push_particles(const ParticleSampler<M>& sampler,
                                               std::span<const double> times, const double* par,
                                               const ForwardOptions& opt, Visit&& visit) {
  constexpr std::size_t N = state_dim_v<M>;
  detail::validate_times(times);
  ParticleFailure<N> failure;
  const auto n = static_cast<long long>(sampler.size());
  std::atomic<long long> first_fail{n};
  if (times.empty()) return failure;
#pragma omp parallel
  {
    ForwardFlow<M> flow(par, opt);
#pragma omp for schedule(dynamic, 64)
    for (long long ii = 0; ii < n; ++ii) {
      if (ii > first_fail.load(std::memory_order_relaxed)) continue;
      const auto i = static_cast<std::size_t>(ii);
      const ParticleSample<N> s = sampler.draw(i);
      if (s.weight == 0.0) continue;
      auto v = [&](std::size_t k, ParticleFate f, int mode, const std::array<double, N>& x, int) {
        visit(i, s, k, f, mode, x);
      };
      const ForwardResult<N> r = detail::push_one<M>(flow, s, times, v);
      if (r.status == ForwardStatus::event_cap || r.status == ForwardStatus::failed) {
#pragma omp critical(hybgen_rt_particles_failure)
        {
          if (ii < first_fail.load()) {
            first_fail.store(ii);
            failure = ParticleFailure<N>{i, s.mode, s.x, r};
          }
        }
      }
    }
  }
  return failure;
}

/// Particles per chunk for n particles: the unit of work of a thread, and of the moments'
/// deterministic sums (a function of n alone, so every partition sums the same chunks).
inline std::size_t particle_chunk(std::size_t n) {
  return std::max<std::size_t>(1024, (n + 1023) / 1024);
}

/// The particle indices a rank pushes: its block of whole chunks (particle_chunk) of the n.
inline Block particle_block(std::size_t n, const Backend& backend) {
  const std::size_t chunk = particle_chunk(n);
  const Block chunks = backend.block((n + chunk - 1) / chunk);
  return {std::min(chunks.begin * chunk, n), std::min(chunks.end * chunk, n)};
}

/// The particle method on `grid` (file doc): density per output time and mode at the grid
/// nodes (or, with opt.marginals, the 2-D marginals of every pair of axes and the moments:
/// nothing of the grid's size), the particle mass budget of the grid box, and the first
/// failure.
///
/// The particles are processed in chunks (`particle_chunk`); a rank owns a block of whole
/// chunks. The moments are sums of doubles, formed per chunk in index order and then over
/// the chunks in chunk order on rank 0: the same bits for any number of threads or ranks,
/// as the integer deposit is.
template <HybridModel M>
ParticleRun<state_dim_v<M>> solve_particles(const TensorGrid<state_dim_v<M>>& grid,
                                            std::span<const double> times, const double* par,
                                            const ParticleOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  using State = std::array<double, N>;
  detail::validate_times(times);
  const ParticleSampler<M> sampler(grid, par, opt);
  const std::size_t K = times.size();
  const std::size_t nm = static_cast<std::size_t>(M::n_mode);
  const auto n = static_cast<long long>(opt.particles);
  const Backend& backend = opt.backend ? *opt.backend : serial_backend();
  const std::size_t chunk = particle_chunk(opt.particles);
  const std::size_t n_chunk = (opt.particles + chunk - 1) / chunk;
  const Block chunks = backend.block(n_chunk);  // particle_block's chunks
  const Block pushed = particle_block(opt.particles, backend);
  const auto first = static_cast<long long>(pushed.begin);
  const auto last = static_cast<long long>(pushed.end);
  ParticleRun<N> run;
  run.particles = opt.particles;
  MassBudget& mb = run.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass.assign(K, 0.0);
  mb.outflow.assign(K, 0.0);
  mb.atom.assign(K, 0.0);
  mb.mass_error.assign(K, 0.0);
  run.atom_error.assign(K, 0.0);

  // What is deposited: every node (the density), or every pair of axes (the marginals).
  const std::size_t nodes = opt.marginals ? 0 : grid.size();
  Marginals& mg = run.marginals;
  if (opt.marginals) {
    for (std::size_t a = 0; a < N; ++a)
      for (std::size_t b = a + 1; b < N; ++b) {
        mg.pairs.push_back({a, b});
        mg.offset.push_back(mg.block);
        mg.block +=
            static_cast<std::size_t>(grid.axes[a].n) * static_cast<std::size_t>(grid.axes[b].n);
      }
    if (mg.pairs.empty()) throw std::invalid_argument("particles: marginals need two axes or more");
  } else {
    run.solution.n_time = K;
    run.solution.n_mode = nm;
    run.solution.n_point = nodes;
  }
  const std::size_t per_frame_mode = opt.marginals ? mg.block : nodes;

  // Pass 1: the fixed-point scales from max|w| (a max: independent of the order).
  double wmax = 0.0;
  long long traced = 0;
#pragma omp parallel for reduction(max : wmax) reduction(+ : traced) schedule(static)
  for (long long i = first; i < last; ++i) {
    if (opt.draw_progress) opt.draw_progress->advance();
    const double w = std::fabs(sampler.draw(static_cast<std::size_t>(i)).weight);
    if (!std::isfinite(w)) continue;
    wmax = std::max(wmax, w);
    if (w > 0.0) ++traced;
  }
  if (opt.draw_progress) opt.draw_progress->finish();
  if (opt.progress) opt.progress->restart();  // its times from here: the pushes alone
  wmax = backend.max(wmax);
  run.traced = static_cast<std::size_t>(backend.sum(std::int64_t{traced}));
  const double nd = static_cast<double>(std::max<long long>(n, 1));
  const double scale = wmax > 0.0 ? std::ldexp(1.0, 61 - std::ilogb(nd * wmax)) : 1.0;
  const double scale2 = wmax > 0.0 ? std::ldexp(1.0, 61 - std::ilogb(nd * wmax * wmax)) : 1.0;

  // Grid geometry.
  std::array<double, N> lo{}, hi{}, h{}, tol{};
  std::array<std::size_t, N> stride{};
  std::size_t st = 1;
  for (std::size_t a = N; a-- > 0;) {
    const GridAxis& ax = grid.axes[a];
    lo[a] = ax.min;
    hi[a] = ax.max;
    h[a] = (ax.max - ax.min) / static_cast<double>(ax.n - 1);
    tol[a] = 1e-12 * (ax.max - ax.min);
    stride[a] = st;
    st *= static_cast<std::size_t>(ax.n);
  }
  auto in_box = [&](const State& x) {
    for (std::size_t a = 0; a < N; ++a)
      if (!(x[a] >= lo[a] - tol[a] && x[a] <= hi[a] + tol[a])) return false;
    return true;
  };
  std::vector<std::int64_t> acc(K * nm * per_frame_mode, 0);
#ifdef _OPENMP
  const auto threads = static_cast<std::size_t>(std::max(omp_get_max_threads(), 1));
#else
  const std::size_t threads = 1;
#endif
  const bool private_acc = threads * acc.size() * sizeof(std::int64_t) <= opt.private_deposit_bytes;
  // Budget accumulators: [0] mass, [1] atom, [2] outflow, [3] the box's and [4] the atom's
  // collapsed-strata sum (below), then per guard g [5 + 2g] Σ W and [6 + 2g] the collapsed-
  // strata sum of the particles it absorbed (absorbing guards), then per guard g [5 + 2G + 2g]
  // Σ W·(firings of g) and [6 + 2G + 2g] their collapsed-strata sum (the impacts,
  // methods/impacts.hpp).
  //
  // Collapsed strata: particle i draws from its own slice of the proposal (stratified), so
  // the sum T = Σ zᵢ (zᵢ = wᵢ·[particle i counts]) has variance Σ σᵢ², which the i.i.d.
  // formula Σ zᵢ² − T²/n overstates by every stratum's mean against the global one (measured:
  // 5–300× the true error of the mass on tests/validation/models/leap_out.model). Neighbouring
  // particles (2j, 2j + 1) of a chunk form a pair; E[(z_a − z_b)²] = σ_a² + σ_b² +
  // (μ_a − μ_b)², so Σ_pairs (z_a − z_b)² overestimates Var T by the neighbours' differences
  // of mean only (a chunk's last particle left alone adds z_a²). Each pair's square is added
  // in fixed point at scale2/4 (|z_a − z_b| ≤ 2 max|w|, n/2 pairs: the sum stays below 2⁶¹).
  const std::size_t G = static_cast<std::size_t>(M::n_guard);
  const std::size_t z_stride = 2 + 2 * G;  // per frame: box, atom, absorbed, impacts per guard
  // A particle fires at most max_events times (beyond, its flow fails), so its impacts are
  // summed at scale/C and their pairs' squares at scale2/(4C²), C = 2^⌈log₂(max_events + 1)⌉:
  // the same bounds below 2⁶¹ hold for any count.
  const double pair_scale = 0.25 * scale2;
  const double impact_c =
      std::ldexp(1.0, std::ilogb(static_cast<double>(std::max(opt.forward.max_events, 1))) + 1);
  const double impact_scale = scale / impact_c;
  const double impact_pair_scale = pair_scale / (impact_c * impact_c);
  const std::size_t n_sums = (5 + 4 * G) * K;
  std::vector<double> zeno_time(G, HUGE_VAL);  // per guard, the earliest Zeno time seen
  std::vector<std::int64_t> sums(n_sums, 0);
  std::int64_t mass0 = 0, sampled = 0;
  std::atomic<long long> first_fail{n};
  ParticleFailure<N> failure;
  bool non_finite_weight = false;
  // Moments (marginals only): per chunk and frame, Σ w, Σ w x_a, Σ w x_a x_b (a ≤ b).
  constexpr std::size_t S = 1 + N + N * (N + 1) / 2;
  const std::size_t moment_size = opt.marginals ? K * S : 0;
  std::vector<double> moments(chunks.size() * moment_size, 0.0);
  // Observables (observables.hpp): per chunk and frame, over the samples in the box, Σ w and
  // per observable Σ w f; and the collapsed-strata sums of the chunk's pairs of neighbouring
  // particles (2j, 2j + 1): with B and A the pair's differences of w·[in box] and of
  // w f·[in box], Σ B², then per observable Σ A B and Σ A². Like the moments, summed in chunk
  // order. `y` holds the current particle's w·[in box] and w f·[in box] per frame, `held` the
  // pair's first.
  const int n_obs = observable_count<M>();
  const auto n_obs_u = static_cast<std::size_t>(n_obs);
  const std::size_t obs_stride = 2 + 3 * n_obs_u, y_stride = 1 + n_obs_u;
  const std::size_t obs_size = n_obs > 0 ? K * obs_stride : 0;
  std::vector<double> obs_sums(chunks.size() * obs_size, 0.0);
  // Add the pair (a, b) (b null: a stratum left alone, paired with nothing) to the row `o`.
  const auto add_pair = [&](double* o, const double* a, const double* b) {
    for (std::size_t k = 0; k < K; ++k, o += obs_stride, a += y_stride) {
      const double wb = b ? b[k * y_stride] : 0.0, B = a[0] - wb;
      o[0] += a[0] + wb, o[1] += B * B;
      for (std::size_t j = 0; j < n_obs_u; ++j) {
        const double fb = b ? b[k * y_stride + 1 + j] : 0.0, A = a[1 + j] - fb;
        o[2 + 3 * j] += a[1 + j] + fb, o[3 + 3 * j] += A * B, o[4 + 3 * j] += A * A;
      }
    }
  };

  if (K > 0) {
#pragma omp parallel
    {
      ForwardFlow<M> flow(par, opt.forward);
      std::vector<double> y(obs_size > 0 ? K * y_stride : 0), held(y.size());
      std::vector<double> z(K * z_stride, 0.0), z_held(z.size());
      std::vector<std::int64_t> local(n_sums, 0);
      std::vector<std::int64_t> mine(private_acc ? acc.size() : 0, 0);
      std::int64_t local_mass0 = 0, local_sampled = 0;
      bool local_bad = false;
      auto add = [&](std::size_t at, std::int64_t part) {
        if (part == 0) return;
        if (private_acc)
          mine[at] += part;
        else
          std::atomic_ref<std::int64_t>(acc[at]).fetch_add(part, std::memory_order_relaxed);
      };
#pragma omp for schedule(dynamic, 1)
      for (std::size_t c = chunks.begin; c < chunks.end; ++c) {
        double* mom = moments.data() + (c - chunks.begin) * moment_size;
        double* obs = obs_sums.data() + (c - chunks.begin) * obs_size;
        const auto c_begin = static_cast<long long>(c * chunk);
        const auto c_end = static_cast<long long>(std::min((c + 1) * chunk, opt.particles));
        // The budget's pair (a, b) (b null: a particle left alone) into the collapsed-strata
        // sums of `local`.
        const auto add_budget_pair = [&](const double* a, const double* b) {
          for (std::size_t k = 0; k < K; ++k)
            for (std::size_t q = 0; q < z_stride; ++q) {
              const double d = a[k * z_stride + q] - (b ? b[k * z_stride + q] : 0.0);
              if (d == 0.0) continue;
              if (q >= 2 + G) {  // impacts: a count, at a smaller scale (above)
                const std::size_t at = (6 + 2 * G + 2 * (q - 2 - G)) * K + k;
                local[at] += std::llround(d * d * impact_pair_scale);
                continue;
              }
              const std::size_t at = (q < 2 ? 3 + q : 6 + 2 * (q - 2)) * K + k;
              local[at] += std::llround(d * d * pair_scale);
            }
        };
        // The particle before ii is complete: hold it (the pair's first) or add the pair.
        const auto pair_step = [&](long long done) {
          if ((done - c_begin) % 2 == 0) {
            held.swap(y);
            z_held.swap(z);
          } else {
            if (obs_size > 0) add_pair(obs, held.data(), y.data());
            add_budget_pair(z_held.data(), z.data());
          }
          std::fill(y.begin(), y.end(), 0.0);
          std::fill(z.begin(), z.end(), 0.0);
        };
        for (auto ii = c_begin; ii < c_end; ++ii) {
          if (ii > c_begin) pair_step(ii - 1);
          if (opt.progress) opt.progress->advance();
          if (ii > first_fail.load(std::memory_order_relaxed)) continue;
          const auto i = static_cast<std::size_t>(ii);
          const ParticleSample<N> s = sampler.draw(i);
          if (s.weight == 0.0) continue;
          if (!std::isfinite(s.weight)) {
            local_bad = true;
            continue;
          }
          const std::int64_t W = std::llround(s.weight * scale);
          const std::int64_t W_imp = std::llround(s.weight * impact_scale);
          const bool b0 = in_box(s.x);
          local_sampled += W;
          if (b0) local_mass0 += W;
          auto visit = [&](std::size_t k, ParticleFate fate, int mode, const State& x, int guard) {
            const bool inside = in_box(x);
            std::int64_t* L = local.data();
            double* zk = z.data() + k * z_stride;
            if (fate == ParticleFate::absorbed) {  // its mass left: counted per guard too
              const auto g = static_cast<std::size_t>(guard);
              L[(5 + 2 * g) * K + k] += W;
              zk[2 + g] = s.weight;
              L[(5 + 2 * G + 2 * g) * K + k] += W_imp;  // and its last impact
              zk[2 + G + g] += s.weight;
            }
            if (fate == ParticleFate::zeno && inside) {
              L[K + k] += W;
              zk[1] = s.weight;
              L[2 * K + k] += (b0 ? W : 0) - W;
              return;
            }
            if (fate != ParticleFate::state || !inside) {
              L[2 * K + k] += b0 ? W : 0;
              return;
            }
            L[k] += W;
            zk[0] = s.weight;
            L[2 * K + k] += (b0 ? W : 0) - W;
            if (obs_size > 0) {
              double* yk = y.data() + k * y_stride;
              yk[0] = s.weight;
              for (int j = 0; j < n_obs; ++j)
                yk[1 + j] = s.weight * observable_value<M>(j, mode, x.data(), par);
            }
            // Cloud-in-cell weights along every axis: the cell and the offset in it.
            std::array<std::size_t, N> base{};
            std::array<double, N> f{};
            for (std::size_t a = 0; a < N; ++a) {
              const double sa =
                  std::clamp((x[a] - lo[a]) / h[a], 0.0, static_cast<double>(grid.axes[a].n - 1));
              const auto ia = std::min(static_cast<std::size_t>(sa),
                                       static_cast<std::size_t>(grid.axes[a].n - 2));
              base[a] = ia;
              f[a] = sa - static_cast<double>(ia);
            }
            const std::size_t off = (k * nm + static_cast<std::size_t>(mode)) * per_frame_mode;
            if (opt.marginals) {
              // The 4 corners of the particle's cell in each pair's plane; the moments.
              for (std::size_t p = 0; p < mg.pairs.size(); ++p) {
                const std::size_t a = mg.pairs[p][0], b = mg.pairs[p][1];
                const auto nb = static_cast<std::size_t>(grid.axes[b].n);
                std::int64_t rest = W;
                for (std::size_t corner = 0; corner < 4; ++corner) {
                  const bool ua = (corner & 1U) != 0, ub = (corner & 2U) != 0;
                  const double lam = (ua ? f[a] : 1.0 - f[a]) * (ub ? f[b] : 1.0 - f[b]);
                  const std::int64_t part =
                      corner == 3 ? rest : std::llround(s.weight * lam * scale);
                  rest -= part;
                  add(off + mg.offset[p] + (base[a] + (ua ? 1 : 0)) * nb + base[b] + (ub ? 1 : 0),
                      part);
                }
              }
              double* m = mom + k * S;
              m[0] += s.weight;
              std::size_t q = 1 + N;
              for (std::size_t a = 0; a < N; ++a) {
                m[1 + a] += s.weight * x[a];
                for (std::size_t b = a; b < N; ++b) m[q++] += s.weight * x[a] * x[b];
              }
              return;
            }
            // Cloud-in-cell onto the 2ᴺ corner nodes of the particle's grid cell.
            std::int64_t rest = W;
            constexpr std::size_t corners = std::size_t{1} << N;
            for (std::size_t corner = 0; corner < corners; ++corner) {
              double lam = 1.0;
              std::size_t node = 0;
              for (std::size_t a = 0; a < N; ++a) {
                const bool up = ((corner >> a) & 1U) != 0;
                lam *= up ? f[a] : 1.0 - f[a];
                node += (base[a] + (up ? 1 : 0)) * stride[a];
              }
              const std::int64_t part =
                  corner + 1 == corners ? rest : std::llround(s.weight * lam * scale);
              rest -= part;
              add(off + node, part);
            }
          };
          // Every firing counts from the first frame at or after it (right-continuous).
          auto on_reset = [&](double t, int g, const State&, const State&) {
            const auto gu = static_cast<std::size_t>(g);
            for (std::size_t k = K; k-- > 0 && times[k] >= t;) {
              local[(5 + 2 * G + 2 * gu) * K + k] += W_imp;
              z[k * z_stride + 2 + G + gu] += s.weight;
            }
          };
          const ForwardResult<N> r = detail::push_one<M>(flow, s, times, visit, on_reset);
          if (r.status == ForwardStatus::zeno && r.guard >= 0 && r.t_stop > 0.0) {
#pragma omp critical(hybgen_rt_particles_zeno)
            {
              double& zt = zeno_time[static_cast<std::size_t>(r.guard)];
              zt = std::min(zt, r.t_stop);
            }
          }
          if (r.status == ForwardStatus::event_cap || r.status == ForwardStatus::failed) {
#pragma omp critical(hybgen_rt_particles_failure)
            {
              if (ii < first_fail.load()) {
                first_fail.store(ii);
                failure = ParticleFailure<N>{i, s.mode, s.x, r};
              }
            }
          }
        }
        if (c_end > c_begin) {
          pair_step(c_end - 1);
          if ((c_end - c_begin) % 2 == 1) {  // left alone
            if (obs_size > 0) add_pair(obs, held.data(), nullptr);
            add_budget_pair(z_held.data(), nullptr);
          }
        }
      }
#pragma omp critical(hybgen_rt_particles_sums)
      {
        for (std::size_t j = 0; j < local.size(); ++j) sums[j] += local[j];
        for (std::size_t j = 0; j < mine.size(); ++j) acc[j] += mine[j];
        mass0 += local_mass0;
        sampled += local_sampled;
        non_finite_weight = non_finite_weight || local_bad;
      }
    }
  }
  // Across ranks: integer sums (exact, so the same bits for any number of ranks), the
  // marginals' deposit onto rank 0 (the density's: each rank its block, below), the chunks'
  // moments onto rank 0 in chunk order, and the failure of the smallest index.
  backend.sum(std::span<std::int64_t>(sums));
  if (opt.marginals) backend.sum_to_root(std::span<std::int64_t>(acc));
  if (obs_size > 0) {
    // E = Σ w f / Σ w. Its variance by the delta method on the collapsed strata: the pairs'
    // differences of z = w f − E w, Σ (A − E B)² = Σ A² − 2E Σ AB + E² Σ B², over (Σ w)².
    // Each pair's E (z_a − z_b)² is the two strata's variances plus their means' squared
    // difference, so this overestimates the stratified sampling's variance, by the means'
    // differences between neighbouring strata only (the i.i.d. formula's Σ w² f² − … counts
    // every stratum's mean against the global one: 20-300× wider on the thermostat and ball).
    const std::vector<double> all = backend.gather(obs_sums);
    std::vector<double> total(obs_size, 0.0);
    if (backend.root())
      for (std::size_t c = 0; c < n_chunk; ++c)
        for (std::size_t j = 0; j < obs_size; ++j) total[j] += all[c * obs_size + j];
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (int j = 0; j < n_obs; ++j) {
      ObservableSeries series{observable_name<M>(j), {}, {}};
      for (std::size_t k = 0; k < K; ++k) {
        const double* o = total.data() + k * obs_stride;
        const auto ju = static_cast<std::size_t>(j);
        if (!(o[0] > 0.0)) {
          series.values.push_back(nan), series.errors.push_back(nan);
          continue;
        }
        const double e = o[2 + 3 * ju] / o[0];
        const double var = (o[4 + 3 * ju] - 2.0 * e * o[3 + 3 * ju] + e * e * o[1]) / (o[0] * o[0]);
        series.values.push_back(e);
        series.errors.push_back(2.0 * std::sqrt(std::max(var, 0.0)));
      }
      run.observables.push_back(std::move(series));
    }
  }
  mass0 = backend.sum(mass0);
  sampled = backend.sum(sampled);
  if (backend.any(non_finite_weight))
    throw std::runtime_error("particles: non-finite initial density");
  agree_first_failure(backend, first_fail.load(), failure, n);
  run.failure = failure;
  const double inv = 1.0 / scale;
  // The dual-cell length of node i on axis a: its trapezoid weight (h, or h/2 at the ends).
  std::array<std::vector<double>, N> dual_length;
  for (std::size_t a = 0; a < N; ++a) dual_length[a] = trapezoid_rule(grid.axes[a]).weights;
  auto dual = [&](std::size_t a, std::size_t ia) { return dual_length[a][ia]; };
  if (opt.marginals) {
    // Pair sums over dual areas: marginal densities.
    mg.values.assign(acc.size(), 0.0);
    for (std::size_t km = 0; km < K * nm; ++km)
      for (std::size_t p = 0; p < mg.pairs.size(); ++p) {
        const std::size_t a = mg.pairs[p][0], b = mg.pairs[p][1];
        const auto na = static_cast<std::size_t>(grid.axes[a].n);
        const auto nb = static_cast<std::size_t>(grid.axes[b].n);
        for (std::size_t ia = 0; ia < na; ++ia)
          for (std::size_t ib = 0; ib < nb; ++ib) {
            const std::size_t at = km * mg.block + mg.offset[p] + ia * nb + ib;
            mg.values[at] = static_cast<double>(acc[at]) * inv / (dual(a, ia) * dual(b, ib));
          }
      }
    const std::vector<double> all = backend.gather(moments);
    mg.mass.assign(K, 0.0);
    mg.mean.assign(K * N, 0.0);
    mg.covariance.assign(K * N * N, 0.0);
    if (backend.root()) {
      std::vector<double> total(K * S, 0.0);
      for (std::size_t c = 0; c < n_chunk; ++c)
        for (std::size_t j = 0; j < K * S; ++j) total[j] += all[c * K * S + j];
      for (std::size_t k = 0; k < K; ++k) {
        const double* m = total.data() + k * S;
        mg.mass[k] = m[0];
        if (!(m[0] > 0.0)) continue;
        for (std::size_t a = 0; a < N; ++a) mg.mean[k * N + a] = m[1 + a] / m[0];
        std::size_t q = 1 + N;
        for (std::size_t a = 0; a < N; ++a)
          for (std::size_t b = a; b < N; ++b, ++q) {
            const double c = m[q] / m[0] - mg.mean[k * N + a] * mg.mean[k * N + b];
            mg.covariance[(k * N + a) * N + b] = c;
            mg.covariance[(k * N + b) * N + a] = c;
          }
      }
    }
  } else {
    // Densities: node sums over dual-cell volumes. Over several ranks each sums its block of
    // every frame's (mode, node) pairs from every rank's deposit and keeps it.
    Solution<N>& sol = run.solution;
    const std::size_t F = nm * nodes;
    const Block own = backend.ranks() > 1 ? backend.block(F) : Block{0, F};
    if (backend.ranks() > 1) sol.distributed = true, sol.owned = own;
    sol.u.assign(K * own.size(), 0.0);
    std::vector<double> dual_volume(own.size());
    for (std::size_t j = own.begin; j < own.end; ++j) {
      double V = 1.0;
      std::size_t r = j % nodes;
      for (std::size_t a = N; a-- > 0;) {
        const auto na = static_cast<std::size_t>(grid.axes[a].n);
        V *= dual(a, r % na);
        r /= na;
      }
      dual_volume[j - own.begin] = V;
    }
    for (std::size_t k = 0; k < K; ++k) {
      const std::span<const std::int64_t> frame(acc.data() + k * F, F);
      std::vector<std::int64_t> mine;
      if (backend.ranks() > 1) mine = backend.sum_to_blocks(frame);
      const std::int64_t* count = backend.ranks() > 1 ? mine.data() : frame.data();
      for (std::size_t j = 0; j < own.size(); ++j)
        sol.u[k * own.size() + j] = static_cast<double>(count[j]) * inv / dual_volume[j];
    }
  }
  mb.mass0 = static_cast<double>(mass0) * inv;
  run.sampled_mass = static_cast<double>(sampled) * inv;
  for (std::size_t k = 0; k < K; ++k) {
    mb.mass[k] = static_cast<double>(sums[k]) * inv;
    mb.atom[k] = static_cast<double>(sums[K + k]) * inv;
    mb.outflow[k] = static_cast<double>(sums[2 * K + k]) * inv;
    mb.mass_error[k] = 2.0 * std::sqrt(static_cast<double>(sums[3 * K + k]) / pair_scale);
    run.atom_error[k] = 2.0 * std::sqrt(static_cast<double>(sums[4 * K + k]) / pair_scale);
  }
  // The mass each absorbing guard took, with 2σ̂ as for the mass in the box, but at least as
  // wide as at one particle in n (a count of 0 has σ̂ = 0, which would claim the mass exact:
  // a trap the first of 200000 particles reaches only later than t took 2.6e-11 by then).
  mb.absorbed.assign(G, {});
  mb.absorbed_error.assign(G, {});
  const double one_in_n = 2.0 * std::fabs(run.sampled_mass) / nd;
  for (std::size_t g = 0; g < G; ++g) {
    if (!absorbs(detail::guard_info<M>(g))) continue;
    for (std::size_t k = 0; k < K; ++k) {
      const std::size_t at = (5 + 2 * g) * K + k;
      const double var = static_cast<double>(sums[at + K]) / pair_scale;
      mb.absorbed[g].push_back(static_cast<double>(sums[at]) * inv);
      mb.absorbed_error[g].push_back(std::max(2.0 * std::sqrt(var), one_in_n));
    }
  }
  // The impacts on every guard (methods/impacts.hpp), with 2σ̂ as for the absorbed mass;
  // infinite from the earliest Zeno time (t_Z > 0) any rank saw on the guard.
  for (double& zt : zeno_time) zt = -zt;
  backend.max(std::span<double>(zeno_time));
  for (double& zt : zeno_time) zt = -zt;
  mb.impacts_infinite_from = impacts_infinite_from(times, zeno_time);
  mb.impacts.assign(G, {});
  mb.impacts_error.assign(G, {});
  for (std::size_t g = 0; g < G; ++g)
    for (std::size_t k = 0; k < K; ++k) {
      const std::size_t at = (5 + 2 * G + 2 * g) * K + k;
      const double var = static_cast<double>(sums[at + K]) / impact_pair_scale;
      mb.impacts[g].push_back(static_cast<double>(sums[at]) / impact_scale);
      mb.impacts_error[g].push_back(std::max(2.0 * std::sqrt(var), one_in_n));
    }
  return run;
}

/// One-line description of a failed particle for an error message (exit code 3).
template <HybridModel M>
std::string describe(const ParticleFailure<state_dim_v<M>>& f) {
  std::ostringstream os;
  os << "particle " << f.index << ": " << describe<M>(f.result, f.start_mode, f.start);
  return os.str();
}

}  // namespace hybgen::rt
