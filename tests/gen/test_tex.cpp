// TeX names of identifiers (generator/src/tex.cpp): the cases a model's names take.

#include <gtest/gtest.h>

#include "hybgen/gen/tex.hpp"

namespace {

using hybgen::gen::tex_identifier;
using hybgen::gen::tex_label;

TEST(Tex, GreekLettersAndDigitSubscripts) {
  EXPECT_EQ(tex_identifier("x"), "x");
  EXPECT_EQ(tex_identifier("theta"), "\\theta");
  EXPECT_EQ(tex_identifier("Omega"), "\\Omega");
  EXPECT_EQ(tex_identifier("theta0"), "\\theta_{0}");
  EXPECT_EQ(tex_identifier("a11"), "a_{11}");
}

TEST(Tex, TheWholeSuffixAfterAnUnderscoreIsTheSubscript) {
  // Not T subscript o followed by "ut".
  EXPECT_EQ(tex_identifier("T_out"), "T_{\\mathrm{out}}");
  EXPECT_EQ(tex_identifier("x_1"), "x_{1}");
  EXPECT_EQ(tex_identifier("p_theta"), "p_{\\theta}");
  EXPECT_EQ(tex_identifier("p_a11"), "p_{a_{11}}");
  EXPECT_EQ(tex_identifier("k_on_off"), "k_{\\mathrm{on}_{\\mathrm{off}}}");
}

TEST(Tex, SeveralLettersAreUprightAndStrayUnderscoresEscaped) {
  EXPECT_EQ(tex_identifier("Vmax"), "\\mathrm{Vmax}");
  EXPECT_EQ(tex_identifier("x_"), "\\mathrm{x\\_}");  // a renamed clash (unreduced twins)
  EXPECT_EQ(tex_label("A_to_B"), "\\mathrm{A\\_to\\_B}");
}

TEST(Tex, TheDotSitsOnTheBase) {
  EXPECT_EQ(hybgen::gen::tex_dot("T_{\\mathrm{room}}"), "\\dot{T}_{\\mathrm{room}}");
  EXPECT_EQ(hybgen::gen::tex_dot("\\theta"), "\\dot{\\theta}");
  EXPECT_EQ(hybgen::gen::tex_dot("\\zeta_{1}"), "\\dot{\\zeta}_{1}");
  EXPECT_EQ(hybgen::gen::tex_dot("\\mathrm{x\\_}"),
            "\\dot{\\mathrm{x\\_}}");  // escaped: no subscript
}

}  // namespace
