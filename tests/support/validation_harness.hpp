#pragma once
/// \file validation_harness.hpp
/// The reference side of the shipped-model validations (tests/validation/test_shipped_*.cpp):
/// a model re-derived by hand (a `Hand` class written in the test) is matched against the
/// generated kernel, and its RK4 push-forward of a Gauss–Legendre quadrature of u0 against the
/// characteristics solution in weak form (∫φu per mode for φ = 1, x_a, x_a x_b).
///
/// A hand model H provides `static constexpr int n_mode`, `static constexpr std::array<HandGuard,
/// G> guards`, `par()` (the parameters in the model's order) and, for a state x of the model's
/// dimension, `flow(m, x)`, `divergence(m, x)`, `surface(g, x)`, `gradient(g, x)`, `reset(g, x)`,
/// `reset_inverse(g, x)`, `reset_jacobian(g, x)` (row-major), `hybrid_jacobian(g, x)`,
/// `in_support(x)` and `initial(m, x)`. On the reference side only the Gauss–Legendre nodes
/// (rt::gauss_legendre_rule) come from hybgen; the generated kernel M is only on the tested side.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "hybgen/rt/methods/characteristics.hpp"

namespace hybgen::testing::validation {

/// A guard of the hand model: source and target mode, direction (+1 increasing, −1 decreasing).
struct HandGuard {
  int from;  ///< source mode
  int to;    ///< target mode
  int dir;   ///< firing direction of s_g
};

/// |a − b| ≤ tol·max(1, |b|): relative, with an absolute floor for values near 0.
inline ::testing::AssertionResult close(double a, double b, double tol = 1e-12) {
  if (std::fabs(a - b) <= tol * std::max(1.0, std::fabs(b))) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "kernel " << a << " vs hand " << b;
}

// ---------------------------------------------------------------------------------------------
// The weak-form reference: the hand model's RK4 push-forward of a quadrature of u0.

/// One classical RK4 step of mode m of the hand model.
template <class H, std::size_t N>
std::array<double, N> rk4(const H& hand, int m, const std::array<double, N>& y, double dt) {
  using State = std::array<double, N>;
  State k1 = hand.flow(m, y), tmp{};
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + 0.5 * dt * k1[a];
  const State k2 = hand.flow(m, tmp);
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + 0.5 * dt * k2[a];
  const State k3 = hand.flow(m, tmp);
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + dt * k3[a];
  const State k4 = hand.flow(m, tmp);
  State out{};
  for (std::size_t a = 0; a < N; ++a)
    out[a] = y[a] + dt / 6.0 * (k1[a] + 2.0 * k2[a] + 2.0 * k3[a] + k4[a]);
  return out;
}

/// Pushes (m, x) forward over time t by RK4 steps of at most dt; a guard of mode m whose s_g
/// changes sign in its direction over a (sub)step fires at the crossing located by bisection on
/// the step, the hand reset is applied (at the last bisection point before the crossing, so
/// that a flow turning straight back into the surface meets it again) and the step goes on in
/// the target mode. `resets` counts the resets; `clock` is the time at (m, x) and advances by
/// t, `last` gets the time of the latest reset.
template <class H, std::size_t N>
void push(const H& hand, int& m, std::array<double, N>& x, double t, double dt, int& resets,
          double& clock, double& last) {
  const auto steps = std::max<long>(1, std::lround(std::ceil(t / dt - 1e-9)));
  const double h = t / static_cast<double>(steps);
  for (long n = 0; n < steps; ++n) {
    double left = h;
    for (int hop = 0; hop < 64 && left > 0.0; ++hop) {
      const std::array<double, N> y = rk4(hand, m, x, left);
      int fired = -1;
      double tau = left, before = 0.0;
      for (std::size_t g = 0; g < H::guards.size(); ++g) {
        const auto& gd = H::guards[g];
        if (gd.from != m) continue;
        const int gi = static_cast<int>(g);
        const double s0 = hand.surface(gi, x), s1 = hand.surface(gi, y);
        if (!(gd.dir > 0 ? (s0 < 0.0 && s1 >= 0.0) : (s0 > 0.0 && s1 <= 0.0))) continue;
        double a = 0.0, b = left;
        for (int it = 0; it < 60; ++it) {
          const double c = 0.5 * (a + b);
          const double sc = hand.surface(gi, rk4(hand, m, x, c));
          (gd.dir > 0 ? sc < 0.0 : sc > 0.0) ? a = c : b = c;
        }
        if (b < tau) tau = b, before = a, fired = gi;
      }
      if (fired < 0) {
        x = y;
        left = 0.0;
      } else {
        x = hand.reset(fired, rk4(hand, m, x, before));
        m = H::guards[static_cast<std::size_t>(fired)].to;
        ++resets;
        last = std::max(last, clock + (h - left) + tau);
        left -= tau;
      }
    }
    clock += h;
  }
}

/// A weighted initial state: ∫ψ u0 ≈ Σ w·ψ(mode, x).
template <std::size_t N>
struct Sample {
  std::array<double, N> x;  ///< position
  int mode;                 ///< mode
  double w;                 ///< quadrature weight times u0
};

/// The number of test functions 1, x_a, x_a x_b (a ≤ b) in dimension N.
template <std::size_t N>
constexpr std::size_t kPhi = 1 + N + N*(N + 1) / 2;

/// The test functions at x.
template <std::size_t N>
std::array<double, kPhi<N>> phis(const std::array<double, N>& x) {
  std::array<double, kPhi<N>> r{};
  std::size_t k = 0;
  r[k++] = 1.0;
  for (std::size_t a = 0; a < N; ++a) r[k++] = x[a];
  for (std::size_t a = 0; a < N; ++a)
    for (std::size_t b = a; b < N; ++b) r[k++] = x[a] * x[b];
  return r;
}

/// The name of test function q, from the state names of the generated model M.
template <class M>
std::string phi_name(std::size_t q) {
  constexpr auto N = static_cast<std::size_t>(M::n_state);
  if (q == 0) return "1";
  if (q <= N) return M::state_names[q - 1];
  std::size_t k = N + 1;
  for (std::size_t a = 0; a < N; ++a)
    for (std::size_t b = a; b < N; ++b, ++k)
      if (k == q) return std::string(M::state_names[a]) + "*" + M::state_names[b];
  return "?";
}

/// ∫φ_k u_m over the box [lo, hi] per output time: [time][mode][k].
template <std::size_t N>
using Moments = std::vector<std::vector<std::array<double, kPhi<N>>>>;

/// Whether x lies in the box [lo, hi].
template <std::size_t N>
bool in_box(const std::array<double, N>& x, const std::array<double, N>& lo,
            const std::array<double, N>& hi) {
  for (std::size_t a = 0; a < N; ++a)
    if (!(x[a] >= lo[a] && x[a] <= hi[a])) return false;
  return true;
}

/// The reference moments at `times` (ascending, > 0); `crossed` gets the share of the box mass
/// at the last time that has crossed at least one reset, `last` the time of the latest reset.
template <class H, std::size_t N>
Moments<N> reference(const H& hand, const std::vector<Sample<N>>& samples,
                     const std::vector<double>& times, double dt, const std::array<double, N>& lo,
                     const std::array<double, N>& hi, double& crossed, double& last) {
  constexpr std::size_t P = kPhi<N>;
  Moments<N> mom(times.size(), std::vector<std::array<double, P>>(H::n_mode));
  double in_last = 0.0, crossed_last = 0.0, last_all = 0.0;
#pragma omp parallel
  {
    Moments<N> local(times.size(), std::vector<std::array<double, P>>(H::n_mode));
    double li = 0.0, lc = 0.0, ll = 0.0;
#pragma omp for schedule(dynamic, 64)
    for (std::size_t j = 0; j < samples.size(); ++j) {
      std::array<double, N> x = samples[j].x;
      int m = samples[j].mode, resets = 0;
      double clock = 0.0;
      for (std::size_t k = 0; k < times.size(); ++k) {
        push(hand, m, x, times[k] - clock, dt, resets, clock, ll);
        if (!in_box(x, lo, hi)) continue;
        const auto p = phis(x);
        for (std::size_t q = 0; q < P; ++q)
          local[k][static_cast<std::size_t>(m)][q] += samples[j].w * p[q];
        if (k + 1 == times.size()) {
          li += samples[j].w;
          if (resets > 0) lc += samples[j].w;
        }
      }
    }
#pragma omp critical(test_shipped_reference)
    {
      for (std::size_t k = 0; k < times.size(); ++k)
        for (std::size_t m = 0; m < mom[k].size(); ++m)
          for (std::size_t q = 0; q < P; ++q) mom[k][m][q] += local[k][m][q];
      in_last += li;
      crossed_last += lc;
      last_all = std::max(last_all, ll);
    }
  }
  crossed = crossed_last / in_last;
  last = last_all;
  return mom;
}

/// The same moments of the characteristics solution of the generated model M at `times`, by
/// the midpoint rule on `cells` equal cells per axis of the box [lo, hi], refined where u jumps:
/// a cell whose midpoint value differs from a face neighbour's by more than `jump`·max u (any
/// mode, any time) is integrated instead by the midpoint rule on `sub`^N sub-cells (none if
/// `sub` ≤ 1). (Where the density jumps across a surface the plain rule errs by O(Δx).)
template <class M, std::size_t N>
Moments<N> characteristics(const std::vector<double>& times, const double* par,
                           const std::array<double, N>& lo, const std::array<double, N>& hi,
                           int cells, int sub, double jump) {
  static_assert(static_cast<std::size_t>(M::n_state) == N);
  using State = std::array<double, N>;
  constexpr std::size_t P = kPhi<N>;
  const auto nc = static_cast<std::size_t>(cells);
  std::size_t count = 1;
  State h{};
  for (std::size_t a = 0; a < N; ++a) count *= nc, h[a] = (hi[a] - lo[a]) / cells;
  auto index_of = [nc](std::size_t idx) {
    std::array<std::size_t, N> c{};
    for (std::size_t a = N; a-- > 0;) c[a] = idx % nc, idx /= nc;
    return c;
  };
  std::vector<State> pts(count);
  for (std::size_t idx = 0; idx < count; ++idx) {
    const auto c = index_of(idx);
    for (std::size_t a = 0; a < N; ++a)
      pts[idx][a] = lo[a] + (static_cast<double>(c[a]) + 0.5) * h[a];
  }
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const auto sol = rt::evaluate<M>(pts, times, par, co);
  EXPECT_TRUE(sol.ok()) << rt::describe<M>(sol.failure);
  const auto nm = static_cast<std::size_t>(M::n_mode);
  // Flag the cells on either side of a jump.
  std::vector<char> flag(count, 0);
  for (std::size_t k = 0; k < times.size() && sub > 1; ++k) {
    double umax = 0.0;
    for (std::size_t m = 0; m < nm; ++m)
      for (std::size_t i = 0; i < count; ++i) umax = std::max(umax, sol.at(k, m, i));
    for (std::size_t i = 0; i < count; ++i) {
      const auto c = index_of(i);
      std::size_t stride = 1;
      for (std::size_t a = N; a-- > 0; stride *= nc) {
        if (c[a] + 1 >= nc) continue;
        for (std::size_t m = 0; m < nm; ++m)
          if (std::fabs(sol.at(k, m, i) - sol.at(k, m, i + stride)) > jump * umax)
            flag[i] = flag[i + stride] = 1;
      }
    }
  }
  std::vector<State> fine;
  std::vector<std::size_t> flagged;
  std::size_t per = 1;
  for (std::size_t a = 0; a < N; ++a) per *= static_cast<std::size_t>(sub);
  for (std::size_t i = 0; i < count; ++i) {
    if (!flag[i]) continue;
    flagged.push_back(i);
    for (std::size_t j = 0; j < per; ++j) {
      State x{};
      std::size_t rem = j;
      for (std::size_t a = N; a-- > 0;) {
        const auto c = static_cast<double>(rem % static_cast<std::size_t>(sub));
        rem /= static_cast<std::size_t>(sub);
        x[a] = pts[i][a] - 0.5 * h[a] + (c + 0.5) * h[a] / sub;
      }
      fine.push_back(x);
    }
  }
  const auto solf = rt::evaluate<M>(fine, times, par, co);
  EXPECT_TRUE(solf.ok()) << rt::describe<M>(solf.failure);
  std::printf("[ shipped ] %zu of %zu cells refined (%zu sub-cells)\n", flagged.size(), count,
              fine.size());
  double vol = 1.0;
  for (std::size_t a = 0; a < N; ++a) vol *= h[a];
  Moments<N> mom(times.size(), std::vector<std::array<double, P>>(nm));
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t m = 0; m < nm; ++m) {
      for (std::size_t i = 0; i < count; ++i) {
        if (flag[i]) continue;
        const double u = sol.at(k, m, i) * vol;
        const auto p = phis(pts[i]);
        for (std::size_t q = 0; q < P; ++q) mom[k][m][q] += u * p[q];
      }
      for (std::size_t i = 0; i < fine.size(); ++i) {
        const double u = solf.at(k, m, i) * vol / static_cast<double>(per);
        const auto p = phis(fine[i]);
        for (std::size_t q = 0; q < P; ++q) mom[k][m][q] += u * p[q];
      }
    }
  return mom;
}

/// Worst |got − ref| / (mass · sup_box|φ|) over times, modes and test functions (mass: the
/// reference's total over the modes at that time), printed with the names of the generated
/// model M.
template <class M, std::size_t N>
double compare(const Moments<N>& got, const Moments<N>& ref, const std::vector<double>& times,
               const std::array<double, N>& lo, const std::array<double, N>& hi) {
  constexpr std::size_t P = kPhi<N>;
  std::array<double, P> sup{};
  for (unsigned corner = 0; corner < (1u << N); ++corner) {
    std::array<double, N> c{};
    for (std::size_t a = 0; a < N; ++a) c[a] = (corner >> a) & 1u ? hi[a] : lo[a];
    const auto p = phis(c);
    for (std::size_t q = 0; q < P; ++q) sup[q] = std::max(sup[q], std::fabs(p[q]));
  }
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    double mass = 0.0;
    for (const auto& r : ref[k]) mass += r[0];
    for (std::size_t m = 0; m < ref[k].size(); ++m)
      for (std::size_t q = 0; q < P; ++q) {
        const double e = std::fabs(got[k][m][q] - ref[k][m][q]) / (mass * sup[q]);
        worst = std::max(worst, e);
        std::printf("[ shipped ] t = %.2f %-6s %-14s: %.9f (reference %.9f) diff %.2e\n", times[k],
                    M::mode_names[m], phi_name<M>(q).c_str(), got[k][m][q], ref[k][m][q], e);
      }
  }
  std::printf("[ shipped ] worst relative difference %.3e\n", worst);
  return worst;
}

/// The generated kernel M against the hand model at its parameters: the guard table, and at
/// 200 states from `point(rng)` the flow, divergence and u0 of every mode, the support, and
/// every guard's surface, gradient, reset, inverse reset and DΔ; J at 200 points of each guard
/// from `on_guard(g, rng)`.
template <class M, class H, class Point, class OnGuard>
void expect_kernel_matches(const H& hand, Point point, OnGuard on_guard) {
  constexpr auto N = static_cast<std::size_t>(M::n_state);
  using State = std::array<double, N>;
  const auto par = hand.par();
  ASSERT_EQ(M::n_state, static_cast<int>(N));
  ASSERT_EQ(M::n_param, static_cast<int>(par.size()));
  ASSERT_EQ(M::n_mode, H::n_mode);
  ASSERT_EQ(M::n_guard, static_cast<int>(H::guards.size()));
  for (std::size_t g = 0; g < H::guards.size(); ++g) {
    EXPECT_EQ(M::guards[g].from, H::guards[g].from) << M::guard_names[g];
    EXPECT_EQ(M::guards[g].to, H::guards[g].to) << M::guard_names[g];
    EXPECT_EQ(M::guards[g].direction, H::guards[g].dir) << M::guard_names[g];
  }
  auto same = [](const double* got, const auto& want, const char* what, int i) {
    for (std::size_t a = 0; a < want.size(); ++a)
      EXPECT_TRUE(close(got[a], want[a])) << what << " " << i << ", component " << a;
  };
  std::mt19937_64 rng(16008);
  for (int n = 0; n < 200; ++n) {
    const State x = point(rng);
    State out{};
    std::array<double, N * N> jac{};
    for (int m = 0; m < H::n_mode; ++m) {
      M::flow(m, x.data(), par.data(), out.data());
      same(out.data(), hand.flow(m, x), "flow of mode", m);
      EXPECT_TRUE(close(M::divergence(m, x.data(), par.data()), hand.divergence(m, x))) << m;
      EXPECT_TRUE(close(M::initial_density(m, x.data(), par.data()), hand.initial(m, x))) << m;
    }
    EXPECT_EQ(M::in_support(x.data(), par.data()), hand.in_support(x));
    for (int g = 0; g < M::n_guard; ++g) {
      EXPECT_TRUE(close(M::guard_surface(g, x.data(), par.data()), hand.surface(g, x))) << g;
      M::guard_gradient(g, x.data(), par.data(), out.data());
      same(out.data(), hand.gradient(g, x), "gradient of guard", g);
      M::reset(g, x.data(), par.data(), out.data());
      same(out.data(), hand.reset(g, x), "reset of guard", g);
      M::reset_jacobian(g, x.data(), par.data(), jac.data());
      same(jac.data(), hand.reset_jacobian(g, x), "DΔ of guard", g);
      EXPECT_TRUE(M::guards[static_cast<std::size_t>(g)].has_inverse) << g;
      M::reset_inverse(g, x.data(), par.data(), out.data());
      same(out.data(), hand.reset_inverse(g, x), "inverse reset of guard", g);
      const State z = on_guard(g, rng);
      EXPECT_TRUE(close(M::hybrid_jacobian(g, z.data(), par.data()), hand.hybrid_jacobian(g, z)))
          << "J of guard " << g;
    }
  }
}

/// Composite Gauss–Legendre (4 nodes) on [lo, hi] split at the `cuts` inside it, about
/// `panels` panels in all (at least one between consecutive cuts).
inline rt::AxisRule split_rule(double lo, double hi, std::vector<double> cuts, int panels) {
  std::erase_if(cuts, [&](double c) { return !(c > lo && c < hi); });
  cuts.push_back(lo);
  cuts.push_back(hi);
  std::sort(cuts.begin(), cuts.end());
  std::vector<double> bp{lo};
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    const double len = cuts[c + 1] - cuts[c];
    const int n = std::max(1, static_cast<int>(std::lround(panels * len / (hi - lo))));
    for (int j = 1; j <= n; ++j) bp.push_back(j == n ? cuts[c + 1] : cuts[c] + len * j / n);
  }
  return rt::gauss_legendre_rule(bp, 4);
}

}  // namespace hybgen::testing::validation
