// Long formulas broken into lines (generator/src/latex_lines.cpp). Whether the lines fit the
// page is pdflatex's verdict (tests/e2e/test_latex.cpp); here: where the breaks go, that the
// lines rejoin into the same formula, and that the delimiters stay paired.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "hybgen/gen/latex_lines.hpp"

namespace {

using hybgen::gen::latex_aligned_rhs;
using hybgen::gen::latex_lines;
using hybgen::gen::latex_width;

/// s with every space removed (lines rejoin into the formula up to spacing).
std::string squeeze(const std::string& s) {
  std::string out;
  for (const char c : s)
    if (c != ' ') out += c;
  return out;
}

/// The lines joined, without spaces.
std::string joined(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l;
  return squeeze(s);
}

/// n terms "a_{k} x^{k}" joined by " + " and " - ".
std::string long_sum(int n) {
  std::string s;
  for (int k = 0; k < n; ++k)
    s += (k ? (k % 3 ? " + " : " - ") : "") + std::string("a_{") + std::to_string(k) + "} x^{" +
         std::to_string(k) + "}";
  return s;
}

/// How many times `what` occurs in s.
std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (auto p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

TEST(LatexLines, WidthsGrowWithTheGlyphsAndFractionsTakeTheirWiderPart) {
  EXPECT_NEAR(latex_width("x"), 0.55, 1e-12);
  EXPECT_GT(latex_width("a + b"), latex_width("ab"));  // a binary operator's spaces
  EXPECT_LT(latex_width("-a"), latex_width("b - a"));  // a unary minus has none
  EXPECT_NEAR(latex_width("\\frac{x y z}{w}"), latex_width("x y z") + 0.25, 1e-12);
  EXPECT_LT(latex_width("x^{2}"), latex_width("x 2"));  // a script is smaller
  EXPECT_NEAR(latex_width("\\left(x\\right)"), latex_width("(x)"), 1e-12);
}

TEST(LatexLines, AFormulaThatFitsIsOneLine) {
  const std::vector<std::string> one = latex_lines("a + b", 10.0);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0], "a + b");
}

TEST(LatexLines, ASumBreaksBeforeItsOperatorsIntoLinesThatFit) {
  const std::string s = long_sum(60);
  const std::vector<std::string> lines = latex_lines(s, 20.0);
  ASSERT_GT(lines.size(), 3u);
  for (std::size_t k = 0; k < lines.size(); ++k) {
    EXPECT_LE(latex_width(lines[k]), 20.0) << lines[k];
    if (k > 0) {
      EXPECT_TRUE(lines[k][0] == '+' || lines[k][0] == '-') << lines[k];
    }
  }
  EXPECT_EQ(joined(lines), squeeze(s));
  // Rows of an aligned environment: the continuations keep their operator binary.
  const std::string rows = latex_aligned_rhs(s, 20.0);
  EXPECT_EQ(count(rows, "\\\\\n      &\\quad {}"), lines.size() - 1) << rows;
}

TEST(LatexLines, ALongParenthesisOpensIntoBigDelimitersThatStayPaired) {
  const std::string s = "-2 \\left(" + long_sum(40) + "\\right)^{2} y";
  const std::vector<std::string> lines = latex_lines(s, 20.0);
  ASSERT_GT(lines.size(), 2u);
  const std::string all = joined(lines);
  EXPECT_EQ(count(all, "\\left("), 0u);
  EXPECT_EQ(count(all, "\\Bigl("), 1u);
  EXPECT_EQ(count(all, "\\Bigr)^{2}y"), 1u);
  EXPECT_EQ(squeeze(lines.front()).rfind("-2\\Bigl(", 0), 0u) << lines.front();
  // The same formula with the pair's \left and \right as \Bigl and \Bigr.
  std::string expect = squeeze(s);
  expect.replace(expect.find("\\left("), 6, "\\Bigl(");
  expect.replace(expect.find("\\right)"), 7, "\\Bigr)");
  EXPECT_EQ(all, expect);
}

TEST(LatexLines, ALongNumeratorOverAShortDenominatorIsOneOverItTimesTheSum) {
  const std::string s = "\\frac{" + long_sum(40) + "}{x + y}";
  const std::vector<std::string> lines = latex_lines(s, 20.0);
  ASSERT_GT(lines.size(), 2u);
  EXPECT_EQ(lines.front().rfind("\\frac{1}{x + y}\\Bigl(", 0), 0u) << lines.front();
  EXPECT_EQ(joined(lines), squeeze("\\frac{1}{x + y}\\Bigl(" + long_sum(40) + "\\Bigr)"));
}

TEST(LatexLines, ALongDenominatorIsAnInversePower) {
  const std::string s = "\\frac{z}{" + long_sum(40) + "}";
  const std::vector<std::string> lines = latex_lines(s, 20.0);
  ASSERT_GT(lines.size(), 2u);
  EXPECT_EQ(joined(lines), squeeze("z\\,\\Bigl(" + long_sum(40) + "\\Bigr)^{-1}"));
}

TEST(LatexLines, TuplesBreakAfterTheirCommas) {
  std::string s = "\\left(";
  for (int k = 0; k < 12; ++k) s += (k ? ", " : "") + long_sum(3);
  s += "\\right)";
  const std::vector<std::string> lines = latex_lines(s, 25.0);
  ASSERT_GT(lines.size(), 1u);
  for (std::size_t k = 0; k + 1 < lines.size(); ++k) EXPECT_EQ(lines[k].back(), ',') << lines[k];
}

TEST(LatexLines, WhatCannotBeBrokenKeepsALineOfItsOwn) {
  // A product of many factors has no break point at any level: one line, too wide.
  std::string s;
  for (int k = 0; k < 60; ++k) s += (k ? " x_{" : "x_{") + std::to_string(k) + "}";
  const std::vector<std::string> lines = latex_lines(s, 10.0);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], s);
}

}  // namespace
