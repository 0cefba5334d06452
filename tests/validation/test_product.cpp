// Validation in 3-D and 4-D: products of independent 1-D cycles on the unit cube, one mode and
// one guard per axis, against the closed-form density (nothing here comes from hybgen).
//
// Axis i: x_i' = f_i(x_i) = 1 + c_i x_i > 0 on [0, 1]; guard `wrap_i`: s = x_i − 1 increasing,
// reset x_i ↦ 0 (the other coordinates unchanged): a constant component. DΔ = I − e_i e_iᵀ
// has the adjugate e_i e_iᵀ (D ≥ 2), so J = ∇sᵀ adj(DΔ) X⁺ / ∇sᵀ X⁻ = f_i(0)/f_i(1) =
// 1/(1 + c_i), the flux ratio.
// Each coordinate rotates in its phase θ_i = ln(1 + c_i x_i)/c_i (θ_i = x_i for c_i = 0), period
// P_i = ln(1 + c_i)/c_i, and in 1-D the flux u·f is carried along the phase (Liouville plus the
// jump condition u⁺ = u⁻/|J|); the axes are independent, so for a product initial flux
//   u(t, x) = Π_i q_i(θ_i(x_i) − t mod P_i) / f_i(x_i).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/transfer.hpp"

namespace {

namespace rt = hybgen::rt;

/// The rate constants c_i of the axes (up to 4).
constexpr std::array<double, 4> kRate{1.0, 0.0, 2.0, 0.5};

/// The product of D cycles.
template <int D>
struct Product {
  static constexpr int n_state = D;               ///< x_0 … x_{D−1}
  static constexpr int n_param = 0;               ///< none
  static constexpr int n_mode = 1;                ///< one mode
  static constexpr int n_guard = D;               ///< one wrap per axis
  static constexpr const char* name = "product";  ///< Model name.
  static constexpr std::array<const char*, D> state_names = [] {
    std::array<const char*, D> a{};
    constexpr std::array<const char*, 4> all{"x0", "x1", "x2", "x3"};
    for (int i = 0; i < D; ++i) a[static_cast<std::size_t>(i)] = all[static_cast<std::size_t>(i)];
    return a;
  }();                                                            ///< State names.
  static constexpr std::array<const char*, 0> param_names{};      ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};        ///< No parameters.
  static constexpr std::array<const char*, 1> mode_names{"run"};  ///< Mode names.
  static constexpr std::array<const char*, D> guard_names = [] {
    std::array<const char*, D> a{};
    constexpr std::array<const char*, 4> all{"wrap0", "wrap1", "wrap2", "wrap3"};
    for (int i = 0; i < D; ++i) a[static_cast<std::size_t>(i)] = all[static_cast<std::size_t>(i)];
    return a;
  }();  ///< Guard names.
  /// wrap_i: from run to run, increasing, no inverse (a constant component).
  static constexpr std::array<rt::GuardInfo, D> guards = [] {
    std::array<rt::GuardInfo, D> a{};
    for (auto& g : a) g = rt::GuardInfo{0, 0, +1, false};
    return a;
  }();
  /// f_i(x) = 1 + c_i x.
  static double f(int i, double x) { return 1.0 + kRate[static_cast<std::size_t>(i)] * x; }
  /// X_i = f_i(x_i).
  static void flow(int, const double* x, const double*, double* out) {
    for (int i = 0; i < D; ++i) out[i] = f(i, x[i]);
  }
  /// div X = Σ c_i.
  static double divergence(int, const double*, const double*) {
    double s = 0.0;
    for (int i = 0; i < D; ++i) s += kRate[static_cast<std::size_t>(i)];
    return s;
  }
  /// s_g = x_g − 1.
  static double guard_surface(int g, const double* x, const double*) { return x[g] - 1.0; }
  /// ∇s_g = e_g.
  static void guard_gradient(int g, const double*, const double*, double* out) {
    for (int i = 0; i < D; ++i) out[i] = i == g ? 1.0 : 0.0;
  }
  /// x_g ↦ 0.
  static void reset(int g, const double* x, const double*, double* out) {
    for (int i = 0; i < D; ++i) out[i] = i == g ? 0.0 : x[i];
  }
  /// Unused (no inverse).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    for (int i = 0; i < D; ++i) out[i] = x[i];
  }
  /// DΔ_g = I − e_g e_gᵀ.
  static void reset_jacobian(int g, const double*, const double*, double* out) {
    for (int i = 0; i < D; ++i)
      for (int j = 0; j < D; ++j) out[i * D + j] = (i == j && i != g) ? 1.0 : 0.0;
  }
  /// J = f_g(0)/f_g(1).
  static double hybrid_jacobian(int g, const double*, const double*) { return 1.0 / f(g, 1.0); }
  /// u0 = Π q_i(θ_i)/f_i (see `exact`).
  static double initial_density(int, const double* x, const double*);
  /// The unit cube.
  static bool in_support(const double* x, const double*) {
    for (int i = 0; i < D; ++i)
      if (!(x[i] >= 0.0 && x[i] <= 1.0)) return false;
    return true;
  }
};

double phase(int i, double x) {
  const double c = kRate[static_cast<std::size_t>(i)];
  return c == 0.0 ? x : std::log1p(c * x) / c;
}
double period(int i) {
  return phase(i, 1.0);
}

/// The flux profile of axis i over its phase: 1 + ½ sin(2πθ/P_i).
double q(int i, double theta) {
  return 1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * theta / period(i));
}

/// The exact density at time t.
template <int D>
double exact(const double* x, double t) {
  double u = 1.0;
  for (int i = 0; i < D; ++i) {
    const double P = period(i);
    const double th = std::fmod(std::fmod(phase(i, x[i]) - t, P) + P, P);
    u *= q(i, th) / Product<D>::f(i, x[i]);
  }
  return u;
}

template <int D>
double Product<D>::initial_density(int, const double* x, const double*) {
  return exact<D>(x, 0.0);
}

template <int D>
void expect_product(const std::vector<int>& sizes, double tol_coarse, double tol_fine,
                    double min_ratio) {
  // March with h = 0.05 to t = 1 (every coordinate wraps at least once, some within the same
  // step); the mass stays what it was (a closed system), densities ≥ 0, and the relative L1
  // error against the closed form is below the bounds and falls by min_ratio per doubling.
  static_assert(rt::HybridModel<Product<D>>);
  double prev = 0.0;
  for (const int n : sizes) {
    rt::TensorGrid<D> grid;
    for (auto& a : grid.axes) a = rt::GridAxis{0.0, 1.0, n};
    rt::TransferOptions o;
    o.step = 0.05;
    const auto op = rt::assemble_transfer<Product<D>>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto u0 = rt::initial_vector<Product<D>>(grid, nullptr);
    const std::vector<double> times{0.0, 1.0};
    const auto run = rt::march(op, u0, times);
    ASSERT_TRUE(run.ok()) << run.failure;
    double num = 0.0, den = 0.0;
    for (std::size_t r = 0; r < grid.size(); ++r) {
      const auto x = grid.node(r);
      const double ue = exact<D>(x.data(), 1.0), u = run.solution.u[grid.size() + r];
      ASSERT_GE(u, 0.0);
      num += op.weight[r] * std::fabs(u - ue);
      den += op.weight[r] * ue;
    }
    const double err = num / den;
    std::printf(
        "[ product ] %d-D %d^%d, %d samples/axis: assembly %.2f s, t = 1 rel L1 %.3e, "
        "mass %.12f -> %.12f, outflow %.1e\n",
        D, n, D, op.samples_per_axis, op.seconds, err, run.budget.mass0, run.budget.mass[1],
        run.budget.outflow[1]);
    EXPECT_NEAR(run.budget.mass[1], run.budget.mass0, 1e-12 * run.budget.mass0);
    EXPECT_EQ(run.budget.outflow[1], 0.0);
    EXPECT_EQ(run.budget.atom[1], 0.0);
    EXPECT_LT(err, prev == 0.0 ? tol_coarse : tol_fine);
    if (prev > 0.0) {
      EXPECT_GT(prev / err, min_ratio);
    }
    prev = err;
  }
}

// Measured: 17³ 1.89e-1, 33³ 6.17e-2 (ratio 3.1; `hat`, 3 samples per axis).
TEST(Product, ThreeCyclesIn3D) {
  expect_product<3>({17, 33}, 0.25, 0.08, 2.5);
}

// Measured: 9⁴ 4.79e-1, 17⁴ 2.31e-1 (ratio 2.1; 2 samples per axis: the 4-D default).
TEST(Product, FourCyclesIn4D) {
  expect_product<4>({9, 17}, 0.6, 0.3, 1.8);
}

}  // namespace
