#pragma once
/// \file latex_lines.hpp
/// Long LaTeX formulas broken into lines that fit a page (latex_lines.cpp): the renderings of
/// `hybgen derive --format latex` (render.cpp) put a derived expression of any length on a
/// line of its own, and a hybrid Jacobian of a few hundred terms ran 300 pt past the margin.
///
/// The width of a formula is estimated from its glyphs (latex_width), in ems of the font it is
/// set in: a letter about 0.55 em, a binary operator with its spaces 1.2 em, a fraction the
/// wider of its numerator and denominator. The estimate is checked against pdflatex's own
/// line widths by tests/e2e/test_latex.cpp (no overfull line in any shipped model's document).

#include <string>
#include <string_view>
#include <vector>

namespace hybgen::gen {

/// The width of LaTeX math `s` as a display sets it, in ems, estimated from its glyphs.
double latex_width(std::string_view s);

/// `s` (LaTeX math) as lines of at most `width` ems, broken before the top level's `+`, `−`
/// and `=` and after its commas. A term wider than a line is opened and broken inside:
/// `\left( … \right)` and `\left| … \right|` become `\Bigl( … \Bigr)` and `\Bigl| … \Bigr|`,
/// `\frac{N}{D}` becomes `\frac{1}{D}\Bigl(N\Bigr)` (D short) or `N\,\Bigl(D\Bigr)^{-1}`.
/// Every line after the first begins with its operator. A part that cannot be broken (a long
/// product, a square root) keeps a line of its own, however wide; `s` that fits is one line.
std::vector<std::string> latex_lines(std::string_view s, double width);

/// latex_lines of `s` as the right-hand side of a row of an `aligned` environment: the lines
/// after the first on rows of their own, `\\ &\quad {} + …`, each after `indent` in the source.
std::string latex_aligned_rhs(std::string_view s, double width, std::string_view indent = "      ");

}  // namespace hybgen::gen
