// Derivation limits (generator/include/hybgen/gen/limits.hpp): a
// symbolic blow-up ends with a located model error that names the object
// being derived and the limit, and the limits are settings (--set).

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <string>
#include <thread>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/limits.hpp"
#include "hybgen/gen/parse.hpp"

namespace hybgen::gen {
namespace {

using GiNaC::ex;

/// Parse, check, override and derive `text`; returns the model error's message or "".
std::string derive_error(const std::string& text, const std::vector<std::string>& sets = {}) {
  SourceText src("limits.model", text);
  Model m = check(parse(src), src);
  apply_overrides(m, sets);
  try {
    (void)derive(m, src);
  } catch (const ModelError& e) {
    EXPECT_EQ(e.exit_code(), ExitCode::ModelError);
    return e.what();
  }
  return "";
}

/// Σ_{i,j<8} x^i y^j written out: 64 terms, about 300 tree nodes, already simplest.
std::string big_polynomial(const std::string& x, const std::string& y) {
  std::string s;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j)
      s += (s.empty() ? "" : " + ") + std::to_string(i + j + 1) + "*" + x + "^" +
           std::to_string(i) + "*" + y + "^" + std::to_string(j);
  return s;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The estimate is exact for sums of distinct monomials raised to a power:
// (x+y)^3 has 4 monomials, (x+y+z+w)^4096 has C(4099, 3).
TEST(Limits, ExpandedTermsCountsMonomials) {
  const GiNaC::realsymbol x("x"), y("y"), z("z"), w("w");
  EXPECT_DOUBLE_EQ(expanded_terms(ex(x)), 1);
  EXPECT_NEAR(expanded_terms(GiNaC::pow(x + y, 3)), 4, 1e-9);
  EXPECT_NEAR(expanded_terms(GiNaC::pow(x + y, 3)),
              static_cast<double>(GiNaC::pow(x + y, 3).expand().nops()), 1e-9);
  EXPECT_NEAR(expanded_terms((x + y) * (z + w + 1)), 6, 1e-9);
  const double c = 4099.0 * 4098.0 * 4097.0 / 6.0;
  EXPECT_NEAR(expanded_terms(GiNaC::pow(x + y + z + w, 4096)) / c, 1.0, 1e-9);
  // The maximum over subexpressions: a function argument is expanded too.
  EXPECT_NEAR(expanded_terms(GiNaC::sin(GiNaC::pow(x + y, 3))), 4, 1e-9);
}

// (x+y+z+w)^4096 used to make simplify() ask GiNaC for 183 GB; now the
// expansion is skipped (the exact, unexpanded form is kept) and the model
// derives at once.
// Finding F8: expand(a^(c + x)) = a^c·a^x, so a symbolic exponent's constant
// part counts. (x + y)^(4000 + z) expands its factor (x + y)^4000 (4001
// monomials; the old estimate said 2), and (2/5)^(10^17 + z) makes GiNaC
// compute (2/5)^(10^17) exactly (a hang; the old estimate said 1). A constant
// part of 0 changes nothing: (2/5)^(10^17·z) has nothing to split off.
TEST(Limits, ConstantPartOfASymbolicExponentCounts) {
  const GiNaC::realsymbol x("x"), y("y"), z("z");
  const GiNaC::numeric huge("100000000000000000");
  EXPECT_NEAR(expanded_terms(GiNaC::pow(x + y, 4000 + z)), 4001, 1e-6);
  EXPECT_NEAR(expanded_terms(GiNaC::pow(x + y, 3 + z)),
              static_cast<double>(GiNaC::pow(x + y, 3).expand().nops()), 1e-9);
  EXPECT_GE(expanded_terms(GiNaC::pow(GiNaC::numeric(2, 5), huge + z)), 1e300);
  EXPECT_DOUBLE_EQ(expanded_terms(GiNaC::pow(GiNaC::numeric(2, 5), huge * z)), 1);
  // expanded_constant_bound: |constant term of expand(e)| is at most this.
  EXPECT_DOUBLE_EQ(expanded_constant_bound((x + 2) * (x - 3)), 6);  // x^2 - x - 6
  EXPECT_DOUBLE_EQ(expanded_constant_bound(GiNaC::pow(x + 2, 3) + 5 * x), 8);
  EXPECT_DOUBLE_EQ(expanded_constant_bound(huge * z), 0);
  EXPECT_DOUBLE_EQ(expanded_constant_bound(GiNaC::sin(GiNaC::ex(x)) + GiNaC::pow(2, z)), 0);
  // exact_power_too_large: (2/5)^n has 5·|n| bits.
  EXPECT_FALSE(exact_power_too_large(GiNaC::numeric(2, 5), GiNaC::numeric(13107)));
  EXPECT_TRUE(exact_power_too_large(GiNaC::numeric(2, 5), GiNaC::numeric(13108)));
  EXPECT_FALSE(exact_power_too_large(GiNaC::numeric(-1), huge));
  EXPECT_FALSE(exact_power_too_large(GiNaC::numeric(2, 5), GiNaC::numeric(huge.to_double())));
}

TEST(Limits, HugeExpansionIsSkippedNotAttempted) {
  const auto t0 = std::chrono::steady_clock::now();
  SourceText src("limits.model",
                 "state x, y, z, w\nmode m { x' = (x+y+z+w)^4096; y' = 1; z' = 1; w' = 1 }\n");
  Model m = check(parse(src), src);
  const HybridSystem sys = derive(m, src);
  ASSERT_EQ(sys.modes.size(), 1u);
  EXPECT_EQ(sys.modes[0].flow[0].nops(), 2u);  // still a power
  EXPECT_LT(seconds_since(t0), 10.0);
}

// max_expr_nodes: the error names the object, the limit, the key and the place.
TEST(Limits, ExpressionSizeLimitNamesTheObject) {
  const std::string text =
      "state x, y\n"
      "mode flying {\n"
      "  x' = " +
      big_polynomial("x", "y") +
      "\n"
      "  y' = 1\n"
      "}\n";
  EXPECT_EQ(derive_error(text), "");
  const std::string msg = derive_error(text, {"max_expr_nodes=100"});
  EXPECT_NE(msg.find("limits.model:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("the vector field of mode 'flying'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("max_expr_nodes = 100"), std::string::npos) << msg;
  EXPECT_NE(msg.find("--set max_expr_nodes="), std::string::npos) << msg;
}

// A guard's hybrid Jacobian is named when it is the object that grows.
TEST(Limits, GuardObjectsAreNamed) {
  const std::string text =
      "state x, p\n"
      "mode m { x' = p; p' = -1 }\n"
      "guard hit {\n"
      "  when x = 0 decreasing\n"
      "  reset (x, -p * (" +
      big_polynomial("x", "p") +
      "))\n"
      "}\n";
  EXPECT_EQ(derive_error(text), "");
  const std::string msg = derive_error(text, {"max_expr_nodes=200"});
  EXPECT_NE(msg.find("guard 'hit'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("max_expr_nodes"), std::string::npos) << msg;
}

// derive_seconds: a derivation past its budget ends at the next check.
TEST(Limits, TimeLimitEndsTheDerivation) {
  const std::string text =
      "state a, b, c, d\n"
      "mode m { a' = (a+b+c+d)^40; b' = (a-b+c-d)^40; c' = (a*b+c*d)^40; d' = (a+c)^40 }\n";
  const auto t0 = std::chrono::steady_clock::now();
  const std::string msg = derive_error(text, {"derive_seconds=0.001"});
  EXPECT_NE(msg.find("took longer than derive_seconds = 0.001"), std::string::npos) << msg;
  EXPECT_NE(msg.find("--set derive_seconds="), std::string::npos) << msg;
  EXPECT_LT(seconds_since(t0), 30.0);
}

// The limits are settings: in the model file and by --set, with checks.
TEST(Limits, LimitsAreSettings) {
  SourceText src("limits.model",
                 "state x\nmode m { x' = -x }\nsimulation {\n  domain x in [0, 1]\n  initial 1\n"
                 "  max_expr_nodes 5000\n  derive_seconds 7\n}\n");
  Model m = check(parse(src), src);
  EXPECT_EQ(m.limits.max_expr_nodes, 5000u);
  EXPECT_DOUBLE_EQ(m.limits.derive_seconds, 7);
  apply_overrides(m, {"max_expand_terms=10", "derive_seconds=2.5"});
  EXPECT_DOUBLE_EQ(m.limits.max_expand_terms, 10);
  EXPECT_DOUBLE_EQ(m.limits.derive_seconds, 2.5);
  EXPECT_THROW(apply_overrides(m, {"derive_seconds=0"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"max_expr_nodes=12.5"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"max_expr_nodes=fast"}), UsageError);
}

// The watchdog ends the process with exit 1 and a located message when one
// operation overruns; disarmed in time, it does nothing.
TEST(LimitsDeathTest, WatchdogEndsTheProcess) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        const Watchdog w("slow.model", 0.02, 0.05);
        std::this_thread::sleep_for(std::chrono::seconds(10));
      },
      ::testing::ExitedWithCode(1),
      "slow.model:1:1: error: deriving the model took longer than 0.05 s, inside one symbolic "
      "operation \\(derive_seconds = 0.02 s,");
  { const Watchdog w("fast.model", 5); }
  // The CLI's default: the budget, half of it again and 5 s (derive_seconds = 20 fires at 35 s).
  EXPECT_EQ(watchdog_seconds(20), 35.0);
}

// The safety net behind F11's check: a GiNaC pole met while deriving (a
// std::domain_error) becomes a model error at the object being derived, like a
// limit hit; any other exception passes through unchanged (a bug stays exit 70).
TEST(Limits, RethrowAtObjectLocatesWhatTheModelCaused) {
  SourceText src("net.model", "state x\nmode m { x' = 1 }\n");
  LimitScope scope(DeriveLimits{});
  scope.object("the reset of guard 'g'", SourceLoc{2, 3});
  auto rethrown = [&](auto&& thrower) -> std::string {
    try {
      try {
        thrower();
      } catch (...) {
        scope.rethrow_at_object(src);
      }
    } catch (const ModelError& e) {
      return std::string("model: ") + e.what();
    } catch (const std::exception& e) {
      return std::string("other: ") + e.what();
    }
    return "nothing";
  };
  const std::string pole = rethrown([] {
    // what GiNaC throws on 0^(-1) (thrown here directly: GiNaC leaks the power it built)
    throw GiNaC::pole_error("power::eval(): division by zero", 1);
  });
  EXPECT_EQ(pole.rfind("model: net.model:2:3: error: deriving the reset of guard 'g': it is "
                       "singular (power::eval(): division by zero)",
                       0),
            0u)
      << pole;
  const std::string limit = rethrown([] { throw LimitExceeded("too big"); });
  EXPECT_EQ(limit.rfind("model: net.model:2:3: error: deriving the reset of guard 'g': too big", 0),
            0u)
      << limit;
  EXPECT_EQ(rethrown([] { throw std::runtime_error("a bug"); }), "other: a bug");
  EXPECT_EQ(rethrown([] { throw InternalError("a bug"); }).rfind("other: ", 0), 0u);
}

}  // namespace
}  // namespace hybgen::gen
