// The front end as one function (generator/src/frontend.cpp): the stages in order, the
// overrides between check and derive, the Lie path, and the callers' caps.

#include "hybgen/gen/frontend.hpp"

#include <gtest/gtest.h>

#include <sstream>

#include "hybgen/gen/errors.hpp"
#include "support/model_texts.hpp"

namespace {

using namespace hybgen::gen;

const char* const kBall = R"(model ball
state x, p
parameter g = 9.81, e = 0.8
mode flight {
  x' = p
  p' = -g
}
guard ground {
  when x = 0 decreasing
  reset (x, -e*p)
}
simulation {
  domain x in [0, 2]
  domain p in [-3, 3]
  initial exp(-x^2 - p^2)
}
)";

TEST(Frontend, DerivesAndOwnsTheModelTheIrPointsAt) {
  const Frontend fe(SourceText("ball.model", kBall));
  EXPECT_EQ(fe.stage, FrontendStage::Derived);
  EXPECT_FALSE(fe.lie);
  EXPECT_EQ(fe.sys.model, &fe.model);
  EXPECT_EQ(fe.model.name, "ball");
  ASSERT_EQ(fe.sys.guards.size(), 1u);
  EXPECT_GT(fe.seconds, 0.0);
}

TEST(Frontend, OverridesApplyBeforeDeriveAndTheFileValuesAreKept) {
  FrontendOptions o;
  o.sets = {"e=0.5", "t_end=3"};
  const Frontend fe(SourceText("ball.model", kBall), o);
  ASSERT_EQ(fe.model.params.size(), 2u);
  EXPECT_EQ(fe.model.params[1].value_d, 0.5);
  EXPECT_EQ(fe.file_params, (std::vector<double>{9.81, 0.8}));  // the runner's defaults
  EXPECT_EQ(fe.model.sim.settings.real<"t_end">(), 3.0);
  o.sets = {"e=0.5", "t_end=-1"};
  EXPECT_THROW(Frontend(SourceText("ball.model", kBall), o), UsageError);
}

TEST(Frontend, CapsStopBeforeTheStageTheyGuard) {
  FrontendOptions o;
  bool asked = false;
  o.before_derive = [&](const Model& m) {
    asked = true;
    return m.state.size() > 2;  // refuse this 2-state model
  };
  const Frontend fe(SourceText("ball.model", kBall), o);
  EXPECT_TRUE(asked);
  EXPECT_EQ(fe.stage, FrontendStage::Checked);
  EXPECT_TRUE(fe.sys.modes.empty());
}

TEST(Frontend, LiePathReducesAndUnreducedIsForLieModelsOnly) {
  const SourceText heis =
      SourceText::load(std::string(HYBGEN_SOURCE_DIR) + "/models/heisenberg.model");
  const Frontend reduced(heis);
  EXPECT_TRUE(reduced.lie);
  EXPECT_EQ(reduced.stage, FrontendStage::Derived);
  EXPECT_EQ(reduced.model.state.size(), 4u);  // (zeta_x, zeta_y, zeta_z, q): n + 1
  FrontendOptions o;
  o.target = ReduceTarget::Unreduced;
  const Frontend twin(heis, o);
  EXPECT_EQ(twin.model.state.size(), 6u);  // T*H3: 2n

  bool asked = false;
  o.before_lie = [&](const ModelAst&) {
    asked = true;
    return false;
  };
  const Frontend parsed(heis, o);
  EXPECT_TRUE(asked);
  EXPECT_EQ(parsed.stage, FrontendStage::Parsed);

  FrontendOptions unreduced;
  unreduced.target = ReduceTarget::Unreduced;
  EXPECT_THROW(Frontend(SourceText("ball.model", kBall), unreduced), UsageError);
}

TEST(Frontend, AWarningNamesItsPlaceAndTheWayOut) {
  // support/model_texts.hpp's thermostat whose switch off is declared the wrong way: the
  // warning points at the direction word (line 11, col 14).
  const Frontend fe(SourceText("thermo.model", hybgen::testing::kWrongWayThermostat));
  std::ostringstream os;
  fe.print_warnings(os);
  const std::string w = os.str();
  EXPECT_NE(w.find("thermo.model:11:14: warning: guard 'off': at every sampled point"),
            std::string::npos)
      << w;
  EXPECT_NE(w.find("did you mean 'increasing'?\n    when T = 2 decreasing\n" +
                   std::string(15, ' ') + "^"),
            std::string::npos)
      << w;
}

TEST(Frontend, BadTextIsALocatedModelError) {
  try {
    const Frontend fe(SourceText("bad.model", "state x\nmode m { x' = y }\n"));
    FAIL() << "an unknown name was accepted";
  } catch (const ModelError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.model:2:"), std::string::npos) << e.what();
  }
}

}  // namespace
