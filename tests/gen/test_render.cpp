// derive's text and LaTeX (generator/src/render.cpp) as a reader sees them: the sign of −div u
// folded into one term, counts in the singular, the jump condition at a point named by the
// states (a generic y or x would be one of them), and |J| without bars where J ≥ 0.

#include <gtest/gtest.h>

#include <string>

#include "hybgen/gen/frontend.hpp"
#include "hybgen/gen/render.hpp"

namespace {

using hybgen::gen::Frontend;
using hybgen::gen::SourceText;

/// A thermostat with a parameter in its divergence (div X = −a in both modes).
const char* kThermostat = R"(model thermo
parameter a = 1
state T
mode heat {
  T' = -a*T + 3
}
mode cool {
  T' = -a*T
}
guard off {
  from heat to cool
  when T = 2 increasing
  reset identity
}
guard on {
  from cool to heat
  when T = 1 decreasing
  reset identity
}
)";

/// A ball on a state named y, with restitution: J = e² ≥ 0.
const char* kBall = R"(model ball
parameter e = 0.5
state y, p
mode flight {
  hamiltonian p^2/2 + y
}
guard ground {
  when y = 0 decreasing
  reset restitution e
}
)";

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(Render, TextFoldsTheSignAndCountsInTheSingular) {
  const Frontend fe(SourceText("thermo.model", kThermostat));
  const std::string t = hybgen::gen::derive_text(fe.sys);
  EXPECT_TRUE(has(t, "1 state, 2 modes, 2 guards")) << t;
  EXPECT_TRUE(has(t, "= a u_heat\n")) << t;  // −div u = −(−a) u
  EXPECT_FALSE(has(t, "-(-a)")) << t;
  EXPECT_TRUE(has(t, "jump at off: u_cool(t+, T) = u_heat(t-, Delta^-1(T))")) << t;
  EXPECT_TRUE(has(t, "for (T) in Delta(S)")) << t;
}

TEST(Render, TheJumpIsWrittenAtTheStatesNotAtAGenericPoint) {
  // A generic "y" would collide with the state y.
  const Frontend fe(SourceText("ball.model", kBall));
  const std::string t = hybgen::gen::derive_text(fe.sys);
  EXPECT_TRUE(has(t, "jump at ground: u(t+, y, p) = u(t-, Delta^-1(y, p))")) << t;
  EXPECT_TRUE(has(t, "= u(t-, y, -p/e) / e^2   for (y, p) in Delta(S)")) << t;
  EXPECT_FALSE(has(t, "|e^2|")) << t;
  const std::string l = hybgen::gen::derive_latex(fe.sys);
  EXPECT_FALSE(has(l, "\\left|e^{2}\\right|")) << l;
  EXPECT_TRUE(has(l, "(y, p) \\in \\Delta")) << l;
  EXPECT_FALSE(has(l, "& x \\in")) << l;
}

// The observables close derive's text, each as the function it is in every mode, or in the one
// mode it is given in (`observe NAME = MODE: EXPR`).
TEST(Render, TextListsTheObservables) {
  hybgen::gen::FrontendOptions options;
  options.sets = {"observe.Tsq=T^2", "observe.warm=heat: a*T"};
  const Frontend fe(SourceText("thermo.model", kThermostat), options);
  const std::string t = hybgen::gen::derive_text(fe.sys);
  EXPECT_TRUE(has(t, "\nobservables (their means under the density, per output time)\n")) << t;
  EXPECT_TRUE(has(t, "  Tsq = T^2\n")) << t;
  EXPECT_TRUE(has(t, "  warm = T*a   in mode heat, 0 in the others\n")) << t;
  const Frontend plain(SourceText("thermo.model", kThermostat));
  EXPECT_FALSE(has(hybgen::gen::derive_text(plain.sys), "observables")) << t;
}

}  // namespace
