// Validation: a backward branch whose pre-image leaves the support ends there.
//
// A conveyor on the state space [0, 2]: x' = 1; a guard `loop` at x = 3 (increasing) resets
// x ↦ x − 3, i.e. it would feed the point 0 from x = 3, which is OUTSIDE the support. Nothing
// can reach x = 3 from the state space, so no mass ever enters at x = 0 and the exact density
// is the translate u(t, y) = u0(y − t) for y ≥ t, 0 for y < t (u0 = 0 outside [0, 2]).
// Backward from a node y, the tracer meets the incoming root b(x) = s(Δ⁻¹x) = x at x = 0; the
// pre-image z = 3 lies outside the support and must spawn no branch (characteristics.hpp,
// try_spawn): the trace records no reset. Before, it spawned a branch at z = 3 that died at
// its first step end; on models whose reversed resets chain outside the support (the issue's
// Heisenberg particle on an energy shell) such branches spawned pre-images until the event cap.
// The same with the expanding reset x ↦ 2x − 6 (J = 2).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

#include "hybgen/rt/methods/characteristics.hpp"

namespace {

namespace rt = hybgen::rt;

/// The conveyor with the reset x ↦ a·x − b at x = 3 (a = 1, b = 3 or a = 2, b = 6).
template <int A, int B>
struct Conveyor {
  static constexpr int n_state = 1;                                 ///< x
  static constexpr int n_param = 0;                                 ///< none
  static constexpr int n_mode = 1;                                  ///< one mode
  static constexpr int n_guard = 1;                                 ///< loop
  static constexpr const char* name = "conveyor";                   ///< Model name.
  static constexpr std::array<const char*, 1> state_names{"x"};     ///< State names.
  static constexpr std::array<const char*, 0> param_names{};        ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};          ///< No parameters.
  static constexpr std::array<const char*, 1> mode_names{"belt"};   ///< Mode names.
  static constexpr std::array<const char*, 1> guard_names{"loop"};  ///< Guard names.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, true}};  ///< loop
  /// X = 1.
  static void flow(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// s = x − 3.
  static double guard_surface(int, const double* x, const double*) { return x[0] - 3.0; }
  /// ∇s = 1.
  static void guard_gradient(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// Δ(x) = A x − B.
  static void reset(int, const double* x, const double*, double* out) { out[0] = A * x[0] - B; }
  /// Δ⁻¹(y) = (y + B)/A.
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = (x[0] + B) / A;
  }
  /// DΔ = A.
  static void reset_jacobian(int, const double*, const double*, double* out) { out[0] = A; }
  /// J = A·X(Δx)/X(x) = A.
  static double hybrid_jacobian(int, const double*, const double*) { return A; }
  /// u0 = 1 + x on [0, 2].
  static double initial_density(int, const double* x, const double*) {
    return x[0] >= 0.0 && x[0] <= 2.0 ? 1.0 + x[0] : 0.0;
  }
  /// The state space [0, 2].
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0 && x[0] <= 2.0; }
};

template <class M>
void expect_translate_without_resets() {
  const std::vector<double> times{0.0, 0.5, 1.0, 1.5, 4.0};
  rt::CharacteristicsOptions opt;
  opt.ode.rtol = 1e-12;
  opt.ode.atol = 1e-14;
  for (const double y : {0.05, 0.3, 0.8, 1.2, 1.9}) {
    std::vector<double> out(times.size());
    const auto st = rt::trace<M>(std::array<double, 1>{y}, 0, times, nullptr, opt, out);
    ASSERT_TRUE(st.ok()) << rt::trace_error_name(st.error);
    EXPECT_EQ(st.events, 0) << "y = " << y << ": a pre-image outside the support spawned";
    for (std::size_t k = 0; k < times.size(); ++k) {
      const double x0 = y - times[k];
      const double exact = x0 >= 0.0 ? 1.0 + x0 : 0.0;
      EXPECT_NEAR(out[k], exact, 1e-9) << "y = " << y << ", t = " << times[k];
    }
  }
}

TEST(SupportPruning, PreImageOutsideTheSupportSpawnsNoBranch) {
  expect_translate_without_resets<Conveyor<1, 3>>();
}

TEST(SupportPruning, ExpandingResetFromOutsideSpawnsNoBranch) {
  expect_translate_without_resets<Conveyor<2, 6>>();
}

/// The conveyor feeding 0 from x = 2, the support's own closed end (reset x ↦ x − 2): the
/// pre-image z = 2 is ON the support's boundary, where the flow arrives from inside.
struct Loop : Conveyor<1, 2> {
  /// s = x − 2.
  static double guard_surface(int, const double* x, const double*) { return x[0] - 2.0; }
};

/// The same loop with the support open at its end, [0, 2): z = 2 is outside by a hair, but
/// the flow arrives at it from inside, so the history is real (a review found the first
/// version of the pruning dropped it: it tested z instead of the state just before it).
struct OpenLoop : Loop {
  /// [0, 2).
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0 && x[0] < 2.0; }
};

template <class M>
void expect_rotation() {
  // A rotation of period 2: u(t, y) = u0((y − t) mod 2), u0 = 1 + x, with one reset per pass.
  const std::vector<double> times{0.0, 0.5, 1.5, 3.0};
  rt::CharacteristicsOptions opt;
  opt.ode.rtol = 1e-12;
  opt.ode.atol = 1e-14;
  for (const double y : {0.3, 1.1, 1.7}) {
    std::vector<double> out(times.size());
    const auto st = rt::trace<M>(std::array<double, 1>{y}, 0, times, nullptr, opt, out);
    ASSERT_TRUE(st.ok()) << rt::trace_error_name(st.error);
    EXPECT_GE(st.events, 1);
    for (std::size_t k = 0; k < times.size(); ++k) {
      const double x0 = std::fmod(std::fmod(y - times[k], 2.0) + 2.0, 2.0);
      EXPECT_NEAR(out[k], 1.0 + x0, 1e-8) << "y = " << y << ", t = " << times[k];
    }
  }
}

TEST(SupportPruning, PreImageOnAClosedOrOpenSupportBoundaryKeepsItsHistory) {
  expect_rotation<Loop>();
  expect_rotation<OpenLoop>();
}

}  // namespace
