// Stage 2 (check): AST -> Model. Good models give the expected Model; every
// kind of mistake gives a ModelError at the right line:column.

#include <gtest/gtest.h>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/check_lie.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/gen/reduce.hpp"

namespace hybgen::gen {
namespace {

Model check_text(const std::string& text) {
  SourceText src("t.model", text);
  return check(parse(src), src);
}

/// Expect a ModelError whose message starts with "t.model:LINE:COL: error: "
/// and contains `fragment`.
void expect_error(const std::string& text, int line, int col, const std::string& fragment) {
  try {
    check_text(text);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ModelError& e) {
    std::string what = e.what();
    std::string prefix =
        "t.model:" + std::to_string(line) + ":" + std::to_string(col) + ": error: ";
    EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
    EXPECT_NE(what.find(fragment), std::string::npos) << what;
    EXPECT_EQ(e.exit_code(), ExitCode::ModelError);
  }
}

const char* kBall = R"(model ball
parameter m = 1, g = 9.81
parameter e = 0.8
state x, p
mode flight {
  hamiltonian p^2/(2*m) + m*g*x
}
guard ground {
  when x = 0 decreasing
  reset restitution e
}
simulation {
  domain x in [0, 2]
  domain p in [-2, 2]
  grid 11x13
  initial exp(-(x-1)^2 - p^2)
  t_end 3
  method characteristics
}
)";

TEST(Check, BouncingBallModel) {
  Model m = check_text(kBall);
  EXPECT_EQ(m.name, "ball");
  ASSERT_EQ(m.state.size(), 2u);
  EXPECT_EQ(m.state[1], "p");
  ASSERT_EQ(m.params.size(), 3u);
  // 9.81 is the exact rational 981/100, not a float.
  EXPECT_TRUE((m.params[1].value - GiNaC::numeric(981, 100)).is_zero());
  EXPECT_DOUBLE_EQ(m.params[1].value_d, 9.81);
  ASSERT_EQ(m.modes.size(), 1u);
  ASSERT_TRUE(m.modes[0].hamiltonian.has_value());
  EXPECT_EQ(m.modes[0].coordinates, std::vector<int>{0});
  EXPECT_EQ(m.modes[0].momenta, std::vector<int>{1});
  ASSERT_EQ(m.guards.size(), 1u);
  EXPECT_EQ(m.guards[0].reset_kind, ResetDecl::Kind::Restitution);
  EXPECT_EQ(m.sim.grid, (std::vector<long>{11, 13}));
  EXPECT_DOUBLE_EQ(m.sim.settings.real<"t_end">(), 3.0);
  EXPECT_DOUBLE_EQ(m.sim.settings.real<"dt">(), 0.3);  // default: t_end / 10
  EXPECT_DOUBLE_EQ(m.sim.lo[1], -2.0);
}

TEST(Check, ExactDecimals) {
  EXPECT_EQ(exact_number("0.1"), GiNaC::numeric(1, 10));
  EXPECT_EQ(exact_number("2.5E+2"), GiNaC::numeric(250));
  EXPECT_EQ(exact_number(".5"), GiNaC::numeric(1, 2));
  EXPECT_EQ(exact_number("1e-3"), GiNaC::numeric(1, 1000));
  EXPECT_THROW(exact_number("1e999"), std::invalid_argument);
  // 0.1*3*x - 0.3*x is exactly zero with exact rationals (GINAC_NOTES).
  Model m = check_text("state x\nmode a { x' = 0.1*3*x - 0.3*x }\n");
  EXPECT_TRUE(m.modes[0].flow[0].is_zero());
}

TEST(Check, Overrides) {
  Model m = check_text(kBall);
  apply_overrides(m, {"e=0.5", "grid=21x31", "t_end=9.8", "dt=1/5", "domain.x=[0,3]"});
  EXPECT_DOUBLE_EQ(m.params[2].value_d, 0.5);
  EXPECT_EQ(m.sim.grid, (std::vector<long>{21, 31}));
  EXPECT_DOUBLE_EQ(m.sim.settings.real<"t_end">(), 9.8);
  EXPECT_DOUBLE_EQ(m.sim.settings.real<"dt">(), 0.2);
  EXPECT_DOUBLE_EQ(m.sim.hi[0], 3.0);
  EXPECT_THROW(apply_overrides(m, {"nosuch=1"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"grid=21"}), UsageError);     // wrong number of axes
  EXPECT_THROW(apply_overrides(m, {"grid=21xx3"}), UsageError);  // malformed
  EXPECT_THROW(apply_overrides(m, {"e=abc"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"e"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"t_end=-1"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"method=magic"}), UsageError);
  EXPECT_THROW(apply_overrides(m, {"e=1e999"}), UsageError);
}

// `observe NAME = [MODE:] EXPR`: f in the mode named (0 in the others) or in every mode;
// `--set observe.NAME=EXPR` adds one or replaces the model's, its errors located in the
// argument itself.
TEST(Check, Observables) {
  const std::string two_modes =
      "state T\nmode heat { T' = 4 - T }\nmode cool { T' = -T }\n"
      "guard off { from heat to cool; when T = 2 increasing; reset identity }\n"
      "simulation {\n  domain T in [0, 3]\n  initial heat: 1\n";
  Model m = check_text(two_modes + "  observe T2 = T^2\n  observe heating = heat: 1\n}\n");
  ASSERT_EQ(m.sim.observables.size(), 2U);
  const GiNaC::ex T = m.state_symbols[0];
  EXPECT_EQ(m.sim.observables[0].name, "T2");
  EXPECT_TRUE((m.sim.observables[0].per_mode[0] - T * T).is_zero());
  EXPECT_TRUE((m.sim.observables[0].per_mode[1] - T * T).is_zero());
  EXPECT_TRUE((m.sim.observables[1].per_mode[0] - 1).is_zero());
  EXPECT_TRUE(m.sim.observables[1].per_mode[1].is_zero());  // heat only
  EXPECT_EQ(m.sim.observables[0].mode, -1);                 // every mode
  EXPECT_EQ(m.sim.observables[1].mode, 0);                  // `heat:`
  apply_overrides(m, {"observe.T2=cool: 2*T", "observe.mean=T"});
  ASSERT_EQ(m.sim.observables.size(), 3U);
  EXPECT_TRUE(m.sim.observables[0].per_mode[0].is_zero());  // replaced: cool only
  EXPECT_TRUE((m.sim.observables[0].per_mode[1] - 2 * T).is_zero());
  EXPECT_EQ(m.sim.observables[2].name, "mean");
  // Located errors in the file, and in the --set argument (its columns).
  expect_error(two_modes + "  observe f = warm: T\n}\n", 8, 15,
               "unknown mode 'warm' (the modes: heat, cool)");
  expect_error(two_modes + "  observe f = hat: T\n}\n", 8, 15,
               "unknown mode 'hat' (did you mean 'heat'?)");
  expect_error(two_modes + "  observe f = T + y\n}\n", 8, 19, "unknown name 'y'");
  expect_error(two_modes + "  observe f = T\n  observe f = 1\n}\n", 9, 11,
               "observable 'f' is given twice (first at 8:11)");
  expect_error(two_modes + "  observe = T\n}\n", 8, 11, "expected the observable's name");
  try {
    apply_overrides(m, {"observe.g=T + q"});
    ADD_FAILURE() << "no error for an unknown name in --set observe";
  } catch (const ModelError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("--set:1:15: error: unknown name 'q'", 0), 0U)
        << e.what();
  }
}

TEST(Check, Errors) {
  expect_error("state x\nmode a { x' = y }\n", 2, 15, "unknown name 'y'");
  expect_error("state x\nmode a { x' = sinn(x) }\n", 2, 15,
               "unknown function 'sinn' (did you mean 'sin'?)");
  expect_error("state x\nmode a { x' = sin(x, x) }\n", 2, 15, "takes 1 argument");
  expect_error("state x, x\nmode a { x' = 1 }\n", 1, 10, "'x' is already declared at 1:7");
  expect_error("parameter x = 1\nstate x\nmode a { x' = 1 }\n", 2, 7, "already declared");
  expect_error("state sin\nmode a { sin' = 1 }\n", 1, 7, "function name");
  expect_error("state x\nmode a { y' = 1 }\n", 2, 10, "'y' in mode 'a' is not a state variable");
  expect_error("state x, y\nmode a { x' = 1 }\n", 2, 6, "no equation for y'");
  expect_error("state x\nmode a { x' = 1; x' = 2 }\n", 2, 18, "gives x' twice");
  expect_error("state x\nmode a { x' = 1 }\nmode a { x' = 2 }\n", 3, 6, "already declared");
  expect_error("parameter k = 1/0\nstate x\nmode a { x' = 1 }\n", 1, 17, "division by zero");
  expect_error("parameter k = 1e400\nstate x\nmode a { x' = 1 }\n", 1, 15, "out of range");
  expect_error("parameter k = log(0)\nstate x\nmode a { x' = 1 }\n", 1, 15, "log(0)");
  expect_error("parameter k = sqrt(-1)\nstate x\nmode a { x' = 1 }\n", 1, 15, "not a finite real");
  expect_error("parameter k = j\nparameter j = 1\nstate x\nmode a { x' = 1 }\n", 1, 15,
               "unknown name 'j'");
  // Guards.
  expect_error("state x\nmode a { x' = -1 }\nguard g { when x = 0 decreasing; reset (x, 1) }\n", 3,
               40, "has 2 components, expected 1 (one per state variable: x)");
  expect_error(
      "state x\nmode a { x' = -1 }\nmode b { x' = 1 }\nguard g { when x = 0 decreasing; reset "
      "identity }\n",
      4, 7, "needs 'from MODE'");
  expect_error(
      "state x\nmode a { x' = -1 }\nguard g { from c; when x = 0 decreasing; reset identity }\n", 3,
      16, "unknown mode 'c'");
  expect_error("state x\nmode a { x' = -1 }\nguard g { when x = 0 decreasing }\n", 3, 7,
               "has no reset");
  expect_error("state x\nmode a { x' = -1 }\nguard g { reset identity }\n", 3, 7, "has no surface");
  expect_error(
      "parameter c = 1\nstate x\nmode a { x' = -1 }\nguard g { when c = 0 decreasing; reset "
      "identity }\n",
      4, 16, "does not depend on the state");
  expect_error(
      "state x, p\nmode a { x' = p; p' = -1 }\nguard g { when x = 0 decreasing; reset elastic }\n",
      3, 34, "needs a Hamiltonian");
  expect_error("state x, p, z\nmode a { hamiltonian p^2 }\n", 2, 10,
               "as many momenta as coordinates");
  // Simulation block.
  expect_error("state x\nmode a { x' = 1 }\nsimulation { domain x in [0, 1]; t_end 1 }\n", 3, 1,
               "no initial density");
  expect_error(
      "state x, y\nmode a { x' = 1; y' = 1 }\nsimulation { domain x in [0, 1]; initial 1 }\n", 3, 1,
      "no domain for 'y'");
  expect_error("state x\nmode a { x' = 1 }\nsimulation { domain x in [1, 0]; initial 1 }\n", 3, 27,
               "is empty");
  expect_error(
      "state x\nmode a { x' = 1 }\nsimulation { domain x in [0, 1]; grid 3x3; initial 1 }\n", 3, 39,
      "the grid has 2 axes, the state has 1");
  expect_error(
      "state x\nmode a { x' = 1 }\nsimulation { domain x in [0, 1]; initial 1; t_end -2 }\n", 3, 51,
      "setting 't_end': must be positive");
  expect_error(
      "state x\nmode a { x' = 1 }\nsimulation { domain x in [0, 1]; initial 1; method magic }\n", 3,
      52, "setting 'method': unknown value 'magic' (available: characteristics, transfer");
  expect_error("state x\nmode a { x' = 1 }\nsimulation { domain x in [0, 1]; initial 1; tend 2 }\n",
               3, 45, "unknown simulation setting 'tend' (did you mean 't_end'?)");
  expect_error("state x\nmode a { x' = 1 }\nsimulation { domain x in [0, 1]; initial b: 1 }\n", 3,
               42, "unknown mode 'b'");
}

TEST(Check, ErrorExcerptHasCaret) {
  try {
    check_text("state x\nmode a { x' = 2*y }\n");
    FAIL();
  } catch (const ModelError& e) {
    EXPECT_NE(std::string(e.what()).find("\n  mode a { x' = 2*y }\n                  ^"),
              std::string::npos)
        << e.what();
  }
}

TEST(Check, InitialDensitySplitByRegions) {
  Model m = check_text(R"(state x, y
mode A { where x*y > 0; x' = -x; y' = -y }
mode B { where x*y < 0; x' = -x; y' = -y }
simulation { domain x in [-1, 1]; domain y in [-1, 1]; initial exp(-x^2) }
)");
  ASSERT_EQ(m.sim.initial.size(), 2u);
  EXPECT_FALSE(m.sim.initial[0].is_zero());
  EXPECT_FALSE(m.sim.initial[1].is_zero());
  Model k = check_text(R"(state x
mode A { x' = 1 }
mode B { x' = -1 }
simulation { domain x in [-1, 1]; initial B: exp(-x^2) }
)");
  EXPECT_TRUE(k.sim.initial[0].is_zero());
  EXPECT_FALSE(k.sim.initial[1].is_zero());
}

// --- Lie-group models: check_lie (check_lie.hpp) ----------------------------

/// Expect check_lie of `text` to fail at LINE:COL with `fragment`.
void expect_lie_error(const std::string& text, int line, int col, const std::string& fragment) {
  SourceText src("t.model", text);
  try {
    check_lie(parse(src), src);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ModelError& e) {
    const std::string what = e.what();
    const std::string prefix =
        "t.model:" + std::to_string(line) + ":" + std::to_string(col) + ": error: ";
    EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
    EXPECT_NE(what.find(fragment), std::string::npos) << what;
  }
}

const char* kLieHead = R"(model t
parameter e = 1/2
group A = gl(2)
momenta z1, z2, z3, z4
hamiltonian (z1^2 + z2^2 + z3^2 + z4^2)/2
reduced q = det(A) - 1
)";

TEST(CheckLie, GoodModel) {
  const std::string text = std::string(kLieHead) +
                           "guard g { when q = 0 decreasing; reset restitution e }\n"
                           "simulation { domain z1 in [-1, 1]; domain z2 in [-1, 1]\n"
                           "  domain z3 in [-1, 1]; domain z4 in [-1, 1]; domain q in [0, 1]\n"
                           "  grid 3x3x3x3x3; initial exp(-q) }\n";
  SourceText src("t.model", text);
  const ModelAst ast = parse(src);
  ASSERT_TRUE(is_lie_model(ast));
  const LieModel lm = check_lie(ast, src);
  EXPECT_EQ(lm.base.state, (std::vector<std::string>{"z1", "z2", "z3", "z4", "q"}));
  EXPECT_EQ(lm.coordinate_names, (std::vector<std::string>{"a11", "a12", "a21", "a22"}));
  EXPECT_EQ(lm.group.algebra().dim(), 4u);
  ASSERT_EQ(lm.impacts.size(), 1u);
  EXPECT_EQ(lm.impacts[0].kind, ResetDecl::Kind::Restitution);
  // e is the model's parameter symbol, q = det(A) − 1 in the coordinates.
  EXPECT_TRUE(lm.impacts[0].restitution == lm.base.params[0].symbol);
  const auto& c = lm.group.coords();
  EXPECT_TRUE((lm.q_expr - (c[0] * c[3] - c[1] * c[2] - 1)).expand().is_zero());
  EXPECT_TRUE(lm.base.sim.present);
  EXPECT_EQ(lm.base.sim.grid, (std::vector<long>{3, 3, 3, 3, 3}));
  EXPECT_FALSE(is_lie_model(parse(SourceText("b.model", kBall))));
}

TEST(CheckLie, Errors) {
  expect_lie_error(std::string(kLieHead) + "state x\n", 7, 7, "no 'state' statement");
  expect_lie_error(std::string(kLieHead) + "mode m { x' = 1 }\n", 7, 6, "no modes");
  expect_lie_error("momenta a, b\nhamiltonian a^2\nreduced q = 1\n", 1, 1, "needs a group");
  expect_lie_error("group A = gl(2)\nhamiltonian 1\nreduced q = det(A)\n", 1, 1, "its momenta");
  expect_lie_error("group A = gl(2)\nmomenta a, b\nhamiltonian a^2\nreduced q = det(A)\n", 2, 1,
                   "needs 4 momenta");
  expect_lie_error("group A = gl(2)\nmomenta z1, z2, z3, z4\nreduced q = det(A)\n", 1, 1,
                   "needs a Hamiltonian");
  expect_lie_error("group A = gl(2)\nmomenta z1, z2, z3, z4\nhamiltonian z1^2\n", 1, 1,
                   "reduced coordinate");
  expect_lie_error(
      std::string(kLieHead) + "guard g { from flow; when q = 0 decreasing; reset elastic }\n", 7,
      16, "omit 'from'");
  // A coordinate named like a parameter.
  expect_lie_error(
      "parameter x = 1\ngroup g(x) = [[1, x], [0, 1]] at (0)\nmomenta z\n"
      "hamiltonian z^2\nreduced q = x\n",
      2, 9, "clashes");
  // Not a group: g(c0) is not the identity (hypothesis lie_algebra, at `group`).
  expect_lie_error(
      "group g(x) = [[2, x], [0, 1]] at (0)\nmomenta z\nhamiltonian z^2\nreduced q = x\n", 1, 1,
      "hypothesis 'lie_algebra' fails");
  expect_lie_error("group g(x) = [[1, x], [0]] at (0)\nmomenta z\nhamiltonian z^2\nreduced q = x\n",
                   1, 24, "must be square");
  expect_lie_error(
      "group g(x) = [[1, x], [0, 1]] at (0, 1)\nmomenta z\nhamiltonian z^2\nreduced q = x\n", 1, 31,
      "identity point has 2 values");
  // q must be a function on the group.
  expect_lie_error("group A = gl(1)\nmomenta z\nhamiltonian z^2\nreduced q = z\n", 4, 13,
                   "function on the group");
  // Inertia of the wrong size.
  expect_lie_error("group A = gl(1)\nmomenta z\ninertia [[1, 0], [0, 1]]\nreduced q = det(A)\n", 3,
                   9, "must be 1x1");
}

}  // namespace
}  // namespace hybgen::gen
