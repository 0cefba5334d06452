// Long LaTeX formulas broken into lines (latex_lines.hpp).
//
// The input is what hybgen's printers write (dag_print.cpp, render.cpp): binary operators with
// a space on each side (" + ", " - ", " = "), a unary minus without one, tuples with ", ",
// fractions as \frac{N}{D}, parentheses and bars as \left … \right pairs. A formula is read
// into units at its top level (a brace group, a command with its arguments, a \left … \right
// pair, a fraction, an operator, a comma), the units into terms between the operators and
// commas, and the terms are put on lines greedily. A term wider than a line is opened at its
// widest pair or fraction, whose inside is broken the same way (at most kMaxDepth deep).

#include "hybgen/gen/latex_lines.hpp"

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace hybgen::gen {

namespace {

/// How deep a term is opened: a fraction inside a pair inside a fraction, and so on.
constexpr int kMaxDepth = 8;

bool is_letter(char c) {
  return std::isalpha(static_cast<unsigned char>(c)) != 0;
}

/// The brace group that begins at s[i] == '{': its content; i moves past its '}'. An
/// unbalanced group runs to the end of s.
std::string_view brace_group(std::string_view s, std::size_t& i) {
  const std::size_t start = i + 1;
  int depth = 0;
  for (; i < s.size(); ++i) {
    if (s[i] == '\\') {
      ++i;  // \{ and \} are not braces
    } else if (s[i] == '{') {
      ++depth;
    } else if (s[i] == '}' && --depth == 0) {
      const std::string_view g = s.substr(start, i - start);
      ++i;
      return g;
    }
  }
  return s.substr(std::min(start, s.size()));
}

/// The command that begins at s[i] == '\\' (`\frac`, or `\,` of one other character);
/// i moves past it.
std::string_view command(std::string_view s, std::size_t& i) {
  const std::size_t start = i++;
  if (i < s.size() && is_letter(s[i])) {
    while (i < s.size() && is_letter(s[i])) ++i;
  } else if (i < s.size()) {
    ++i;
  }
  return s.substr(start, i - start);
}

/// The delimiter after \left, \right, \Bigl …: one character or a command (`\{`, `\|`).
std::string_view delimiter(std::string_view s, std::size_t& i) {
  if (i < s.size() && s[i] == '\\') return command(s, i);
  if (i < s.size()) return s.substr(i++, 1);
  return {};
}

/// A superscript's or subscript's argument at s[i]: a group, a command or a character.
std::string_view script_argument(std::string_view s, std::size_t& i) {
  if (i >= s.size()) return {};
  if (s[i] == '{') return brace_group(s, i);
  if (s[i] == '\\') return command(s, i);
  return s.substr(i++, 1);
}

/// The environment that begins at s[i] just past `\begin`: i moves past its `\end{…}`; its
/// body.
std::string_view environment(std::string_view s, std::size_t& i) {
  if (i >= s.size() || s[i] != '{') return {};
  const std::string_view name = brace_group(s, i);
  const std::string end = "\\end{" + std::string(name) + "}";
  const std::size_t at = s.find(end, i);
  const std::size_t stop = at == std::string_view::npos ? s.size() : at;
  const std::string_view body = s.substr(i, stop - i);
  i = std::min(s.size(), stop + end.size());
  return body;
}

/// The width of an environment's body as a matrix: its widest row, the cells of a row
/// separated by `&` and a column gap, rows by `\\`, with the parentheses of pmatrix.
double matrix_width(std::string_view body);

// ---------------------------------------------------------------------------------------
// Width

/// Widths in ems (Computer Modern, display style), rounded up: letters and digits of math
/// italic, an operator with its medium spaces, a relation with its thick ones.
constexpr double kLetter = 0.55, kCapital = 0.75, kDigit = 0.5, kBinary = 1.25, kRelation = 1.35,
                 kDelimiter = 0.4, kBigDelimiter = 0.55, kSymbol = 0.65;

double width_of(std::string_view s);

/// The width of a command and its arguments, at s[i] just past the command `c`.
double command_width(std::string_view c, std::string_view s, std::size_t& i, bool& atom) {
  atom = true;
  if (c == "\\frac" || c == "\\dfrac" || c == "\\tfrac") {
    const double scale = c == "\\tfrac" ? 0.7 : 1.0;
    double w = 0.0;
    if (i < s.size() && s[i] == '{') w = width_of(brace_group(s, i));
    if (i < s.size() && s[i] == '{') w = std::max(w, width_of(brace_group(s, i)));
    return scale * w + 0.25;
  }
  if (c == "\\begin") return matrix_width(environment(s, i)) + 1.0;
  if (c == "\\sqrt") {
    double w = 1.0;
    if (i < s.size() && s[i] == '[') {
      while (i < s.size() && s[i] != ']') ++i;
      if (i < s.size()) ++i;
    }
    if (i < s.size() && s[i] == '{') w += width_of(brace_group(s, i));
    return w;
  }
  if (c == "\\mathrm" || c == "\\text" || c == "\\operatorname" || c == "\\texttt" ||
      c == "\\mathit" || c == "\\mathbf") {
    if (i < s.size() && s[i] == '{') {
      const std::string_view g = brace_group(s, i);
      double n = 0.0;
      for (std::size_t k = 0; k < g.size(); ++k)
        if (g[k] != '\\') n += g[k] == ' ' ? 0.35 : 0.52;
      return n + (c == "\\operatorname" ? 0.2 : 0.0);
    }
    return 0.0;
  }
  if (c == "\\dot" || c == "\\ddot" || c == "\\hat" || c == "\\bar" || c == "\\tilde" ||
      c == "\\vec" || c == "\\overline" || c == "\\mathcal" || c == "\\mathfrak" ||
      c == "\\mathbb" || c == "\\boldsymbol") {
    const std::string_view a = script_argument(s, i);
    return std::max(width_of(a), c == "\\mathcal" || c == "\\mathbb" ? 0.8 : kLetter);
  }
  if (c == "\\left" || c == "\\right" || c == "\\bigl" || c == "\\bigr" || c == "\\Bigl" ||
      c == "\\Bigr" || c == "\\biggl" || c == "\\biggr" || c == "\\big" || c == "\\Big") {
    (void)delimiter(s, i);
    atom = c == "\\right" || c.back() == 'r';
    return c == "\\left" || c == "\\right" ? kDelimiter : kBigDelimiter;
  }
  atom = false;
  if (c == "\\quad") return 1.0;
  if (c == "\\qquad") return 2.0;
  if (c == "\\,") return 0.17;
  if (c == "\\:") return 0.22;
  if (c == "\\;") return 0.28;
  if (c == "\\ ") return 0.33;
  if (c == "\\!") return -0.17;
  if (c == "\\cdot" || c == "\\times" || c == "\\pm" || c == "\\mp" || c == "\\circ")
    return kBinary;
  if (c == "\\to" || c == "\\in" || c == "\\notin" || c == "\\leq" || c == "\\geq" || c == "\\le" ||
      c == "\\ge" || c == "\\neq" || c == "\\mapsto" || c == "\\rightarrow" || c == "\\approx" ||
      c == "\\equiv" || c == "\\sim" || c == "\\subset")
    return kRelation + 0.3;
  atom = true;
  if (c == "\\{" || c == "\\}" || c == "\\|") return 0.5;
  if (c == "\\sin" || c == "\\cos" || c == "\\tan" || c == "\\exp" || c == "\\log" ||
      c == "\\ker" || c == "\\arcsin" || c == "\\arccos" || c == "\\arctan" || c == "\\sinh" ||
      c == "\\cosh" || c == "\\tanh" || c == "\\ln")
    return 0.5 * static_cast<double>(c.size() - 1) + 0.2;
  return kSymbol;  // a Greek letter, \partial, \pi, \infty, …
}

double width_of(std::string_view s) {
  double w = 0.0;
  bool atom = false;  // whether the last thing set was an operand (a + after it is binary)
  std::size_t i = 0;
  while (i < s.size()) {
    const char c = s[i];
    if (c == ' ' || c == '&') {
      ++i;
    } else if (c == '\\') {
      const std::string_view cmd = command(s, i);
      w += command_width(cmd, s, i, atom);
    } else if (c == '{') {
      w += width_of(brace_group(s, i));
      atom = true;
    } else if (c == '^' || c == '_') {
      ++i;
      w += 0.72 * width_of(script_argument(s, i));
    } else if (c == '+' || c == '-') {
      w += atom ? kBinary : 0.8;
      atom = false;
      ++i;
    } else if (c == '=' || c == '<' || c == '>') {
      w += kRelation;
      atom = false;
      ++i;
    } else if (c == ',') {
      w += 0.45;
      atom = false;
      ++i;
    } else if (c == '(' || c == '[' || c == '|' || c == ')' || c == ']') {
      w += kDelimiter;
      atom = c == ')' || c == ']' || c == '|';
      ++i;
    } else {
      const auto u = static_cast<unsigned char>(c);
      w += std::isdigit(u) != 0 ? kDigit : std::isupper(u) != 0 ? kCapital : kLetter;
      atom = true;
      ++i;
    }
  }
  return w;
}

double matrix_width(std::string_view body) {
  double widest = 0.0, row = 0.0;
  std::size_t i = 0, cell = 0;
  auto end_cell = [&](std::size_t stop) { row += width_of(body.substr(cell, stop - cell)); };
  while (i < body.size()) {
    if (body[i] == '{') {
      (void)brace_group(body, i);
    } else if (body[i] == '&') {
      end_cell(i);
      row += 1.0;
      cell = ++i;
    } else if (body.compare(i, 2, "\\\\") == 0) {
      end_cell(i);
      widest = std::max(widest, row);
      row = 0.0;
      i += 2;
      cell = i;
    } else if (body[i] == '\\') {
      (void)command(body, i);
    } else {
      ++i;
    }
  }
  end_cell(body.size());
  return std::max(widest, row);
}

// ---------------------------------------------------------------------------------------
// Units and terms

enum class Kind {
  Plain,      ///< Text that is not broken at this level.
  Pair,       ///< \left<open> a \right<close>, then `suffix` (a power).
  Fraction,   ///< \frac{a}{b} (or \dfrac), then `suffix`.
  Operator,   ///< " + ", " - ", " = ".
  Separator,  ///< ", " of a tuple.
};

struct Unit {
  Kind kind = Kind::Plain;
  std::string text;  ///< The unit as written (with its suffix).
  std::string open, close, a, b, suffix;
};

/// The units of s at its top level.
std::vector<Unit> units_of(std::string_view s) {
  std::vector<Unit> out;
  auto plain = [&](std::string_view t) {
    if (!out.empty() && out.back().kind == Kind::Plain)
      out.back().text += t;
    else
      out.push_back({Kind::Plain, std::string(t), {}, {}, {}, {}, {}});
  };
  std::size_t i = 0;
  while (i < s.size()) {
    const char c = s[i];
    if (c == ' ' && i + 2 < s.size() && (s[i + 1] == '+' || s[i + 1] == '-' || s[i + 1] == '=') &&
        s[i + 2] == ' ') {
      out.push_back({Kind::Operator, std::string(s.substr(i, 3)), {}, {}, {}, {}, {}});
      i += 3;
    } else if (c == ',') {
      std::size_t j = i + 1;
      while (j < s.size() && s[j] == ' ') ++j;
      out.push_back({Kind::Separator, std::string(s.substr(i, j - i)), {}, {}, {}, {}, {}});
      i = j;
    } else if (c == '{') {
      const std::size_t start = i;
      (void)brace_group(s, i);
      plain(s.substr(start, i - start));
    } else if (c == '^' || c == '_') {
      const std::size_t start = i++;
      (void)script_argument(s, i);
      const std::string_view script = s.substr(start, i - start);
      if (!out.empty() && (out.back().kind == Kind::Pair || out.back().kind == Kind::Fraction)) {
        out.back().suffix += script;
        out.back().text += script;
      } else {
        plain(script);
      }
    } else if (c == '\\') {
      const std::size_t start = i;
      const std::string_view cmd = command(s, i);
      if (cmd == "\\begin") {
        // An environment (a matrix) is not broken.
        (void)environment(s, i);
        plain(s.substr(start, i - start));
      } else if (cmd == "\\left") {
        Unit u{Kind::Pair, {}, std::string(delimiter(s, i)), {}, {}, {}, {}};
        const std::size_t inner = i;
        std::size_t inner_end = s.size();
        int depth = 1;
        while (i < s.size()) {
          if (s[i] == '{') {
            (void)brace_group(s, i);
          } else if (s[i] == '\\') {
            const std::size_t at = i;
            const std::string_view c2 = command(s, i);
            if (c2 == "\\left") ++depth;
            if (c2 == "\\right" && --depth == 0) {
              inner_end = at;
              break;
            }
          } else {
            ++i;
          }
        }
        u.close = std::string(delimiter(s, i));
        u.a = std::string(s.substr(inner, inner_end - std::min(inner, inner_end)));
        u.text = std::string(s.substr(start, i - start));
        out.push_back(std::move(u));
      } else if ((cmd == "\\frac" || cmd == "\\dfrac") && i < s.size() && s[i] == '{') {
        const std::string_view a = brace_group(s, i);
        if (i < s.size() && s[i] == '{') {
          const std::string_view b = brace_group(s, i);
          out.push_back({Kind::Fraction,
                         std::string(s.substr(start, i - start)),
                         {},
                         {},
                         std::string(a),
                         std::string(b),
                         {}});
        } else {
          plain(s.substr(start, i - start));
        }
      } else {
        // Another command with its arguments: \sqrt[3]{x}, \mathrm{ab}, \dot{x}.
        if (i < s.size() && s[i] == '[') {
          while (i < s.size() && s[i] != ']') ++i;
          if (i < s.size()) ++i;
        }
        while (i < s.size() && s[i] == '{') (void)brace_group(s, i);
        plain(s.substr(start, i - start));
      }
    } else {
      plain(s.substr(i, 1));
      ++i;
    }
  }
  return out;
}

/// A term: the operator before it ("" for the first), its units, the separator after it.
struct Term {
  std::string lead;
  std::vector<Unit> body;
  std::string trail;
};

std::vector<Term> terms_of(const std::vector<Unit>& units) {
  std::vector<Term> out(1);
  for (const Unit& u : units) {
    if (u.kind == Kind::Operator) {
      if (!out.back().body.empty() || !out.back().lead.empty()) out.emplace_back();
      out.back().lead = u.text;
    } else if (u.kind == Kind::Separator) {
      out.back().trail = u.text;
      out.emplace_back();
    } else {
      out.back().body.push_back(u);
    }
  }
  if (out.back().body.empty() && out.back().lead.empty() && out.size() > 1) out.pop_back();
  return out;
}

std::string concat(const std::vector<Unit>& units, std::size_t from, std::size_t to) {
  std::string s;
  for (std::size_t k = from; k < to; ++k) s += units[k].text;
  return s;
}

/// Whether s has an operator or separator at its top level (can be broken there).
bool breakable(std::string_view s) {
  for (const Unit& u : units_of(s))
    if (u.kind == Kind::Operator || u.kind == Kind::Separator) return true;
  return false;
}

std::vector<std::string> pieces(std::string_view s, double width, int depth);

/// `inner` broken, wrapped in `before` … `after`.
void wrap(std::vector<std::string>& inner, const std::string& before, const std::string& after) {
  inner.front() = before + inner.front();
  inner.back() += after;
}

/// A term wider than `width` opened at one of its pairs or fractions (the widest that can be
/// broken), as pieces; empty when none can.
std::vector<std::string> open_term(const std::vector<Unit>& body, double width, int depth) {
  std::vector<std::size_t> order;
  for (std::size_t k = 0; k < body.size(); ++k)
    if (body[k].kind == Kind::Pair || (body[k].kind == Kind::Fraction && body[k].suffix.empty()))
      order.push_back(k);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
    return width_of(body[x].text) > width_of(body[y].text);
  });
  for (const std::size_t k : order) {
    const Unit& u = body[k];
    const std::string prefix = concat(body, 0, k), suffix = concat(body, k + 1, body.size());
    if (u.kind == Kind::Pair) {
      if (!breakable(u.a)) continue;
      std::vector<std::string> inner = pieces(u.a, width, depth + 1);
      wrap(inner, prefix + "\\Bigl" + u.open, "\\Bigr" + u.close + u.suffix + suffix);
      return inner;
    }
    // A fraction N/D: 1/D times (N) when D is short, else N times (D)^{-1}.
    const bool n_sum = breakable(u.a), d_sum = breakable(u.b);
    if (width_of(u.b) <= 0.5 * width) {
      if (!n_sum) continue;
      std::vector<std::string> inner = pieces(u.a, width, depth + 1);
      wrap(inner, prefix + "\\frac{1}{" + u.b + "}\\Bigl(", "\\Bigr)" + suffix);
      return inner;
    }
    if (!n_sum && !d_sum) continue;
    std::vector<std::string> num = pieces(u.a, width, depth + 1);
    if (n_sum) wrap(num, "\\Bigl(", "\\Bigr)");
    std::vector<std::string> den = pieces(u.b, width, depth + 1);
    wrap(den, "\\,\\Bigl(", "\\Bigr)^{-1}" + suffix);
    num.front() = prefix + num.front();
    num.back() += den.front();
    num.insert(num.end(), den.begin() + 1, den.end());
    return num;
  }
  return {};
}

/// s as pieces, each a term (its operator first, its separator last) or part of an opened one.
std::vector<std::string> pieces(std::string_view s, double width, int depth) {
  std::vector<std::string> out;
  for (const Term& t : terms_of(units_of(s))) {
    std::string text = t.lead + concat(t.body, 0, t.body.size()) + t.trail;
    if (depth < kMaxDepth && width_of(text) > width) {
      std::vector<std::string> opened = open_term(t.body, width, depth);
      if (opened.size() > 1) {
        wrap(opened, t.lead, t.trail);
        out.insert(out.end(), opened.begin(), opened.end());
        continue;
      }
    }
    out.push_back(std::move(text));
  }
  return out;
}

/// Whether p's last character other than a space is a comma.
bool ends_with_comma(const std::string& p) {
  const auto k = p.find_last_not_of(' ');
  return k != std::string::npos && p[k] == ',';
}

}  // namespace

double latex_width(std::string_view s) {
  return width_of(s);
}

std::vector<std::string> latex_lines(std::string_view s, double width) {
  if (width_of(s) <= width) return {std::string(s)};
  // Greedy, but a line that overflows breaks after its last comma instead when that keeps at
  // least half a line before it (a tuple's entries stay whole where they can).
  const std::vector<std::string> ps = pieces(s, width, 0);
  std::vector<std::string> lines;
  std::size_t first = 0;  // the current line's first piece
  std::string line;
  for (std::size_t k = 0; k < ps.size(); ++k) {
    if (k > first && width_of(line + ps[k]) > width) {
      std::size_t cut = k;
      std::string head;
      for (std::size_t j = first; j < k; ++j) {
        head += ps[j];
        if (ends_with_comma(ps[j]) && j + 1 < k && width_of(head) >= 0.5 * width) cut = j + 1;
      }
      line.clear();
      for (std::size_t j = first; j < cut; ++j) line += ps[j];
      lines.push_back(line);
      first = cut;
      line.clear();
      for (std::size_t j = first; j < k; ++j) line += ps[j];
    }
    line += ps[k];
  }
  lines.push_back(std::move(line));
  for (std::size_t k = 0; k < lines.size(); ++k) {
    if (k > 0) lines[k].erase(0, lines[k].find_first_not_of(' '));
    lines[k].erase(lines[k].find_last_not_of(' ') + 1);
  }
  return lines;
}

std::string latex_aligned_rhs(std::string_view s, double width, std::string_view indent) {
  const std::vector<std::string> lines = latex_lines(s, width);
  std::string out = lines.front();
  for (std::size_t k = 1; k < lines.size(); ++k) {
    // "{}" before a leading + or − keeps it binary (its spacing) on the new row.
    const bool op =
        !lines[k].empty() && (lines[k][0] == '+' || lines[k][0] == '-' || lines[k][0] == '=');
    out += " \\\\\n" + std::string(indent) + "&\\quad " + std::string(op ? "{}" : "") + lines[k];
  }
  return out;
}

}  // namespace hybgen::gen
