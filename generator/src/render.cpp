// `hybgen derive`'s renderings of a derived system (render.hpp): text, LaTeX (a fragment, or
// a document pdflatex compiles) and the JSON of docs/design.md, printed through the
// expression DAG (expr_printer.hpp). report.md (emit.cpp) embeds the LaTeX.

#include "hybgen/gen/render.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "expr_printer.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/emit.hpp"
#include "hybgen/gen/latex_lines.hpp"
#include "hybgen/gen/tex.hpp"
#include "hybgen/rt/method_table.hpp"

namespace hybgen::gen {

using GiNaC::ex;

namespace {

const char* direction_word(Direction d) {
  return d == Direction::Decreasing ? "decreasing" : "increasing";
}

/// |e| without bars where they are not needed: the value of a number, or e itself where GiNaC
/// shows it is ≥ 0 (an even power of a real symbol); nullopt where the bars stay.
std::optional<ex> abs_without_bars(const ex& e) {
  if (GiNaC::is_a<GiNaC::numeric>(e)) return ex(GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(e)));
  const ex a = GiNaC::abs(e);
  if (!a.has(GiNaC::abs(GiNaC::wild()))) return a;
  return std::nullopt;
}

/// |J| in LaTeX (abs_without_bars).
std::string abs_latex(ExprPrinter& pr, const ex& e) {
  if (const auto a = abs_without_bars(e)) return pr.latex(*a);
  return "\\left|" + pr.latex(e) + "\\right|";
}

std::string tuple_latex(ExprPrinter& pr, const std::vector<ex>& v) {
  std::string s = "\\left(";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + pr.latex(v[i]);
  return s + "\\right)";
}

/// |e| in text (abs_without_bars).
std::string abs_text(ExprPrinter& pr, const ex& e) {
  if (const auto a = abs_without_bars(e)) return pr.ginac(*a);
  return "|" + pr.ginac(e) + "|";
}

/// c·u in text: "0", "u", "-u", "c u", or "(c) u" for a sum.
std::string scaled_text(ExprPrinter& pr, const ex& c, const std::string& u) {
  if (c.is_zero()) return "0";
  if (c.is_equal(1)) return u;
  if (c.is_equal(-1)) return "-" + u;
  return (GiNaC::is_a<GiNaC::add>(c) ? "(" + pr.ginac(c) + ")" : pr.ginac(c)) + " " + u;
}

std::string tuple_text(ExprPrinter& pr, const std::vector<ex>& v) {
  std::string s = "(";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + pr.ginac(v[i]);
  return s + ")";
}

/// J∘Δ⁻¹: the factor of the jump condition written at the post-reset point.
ex jacobian_at_preimage(const HybridSystem& sys, const IrGuard& g) {
  if (!g.has_inverse) return g.hybrid_jacobian_on_surface;
  GiNaC::exmap at;
  for (std::size_t i = 0; i < g.reset_inverse.size(); ++i)
    at[sys.model->state_symbols[i]] = g.reset_inverse[i];
  return simplify(g.hybrid_jacobian_on_surface.subs(at, GiNaC::subs_options::no_pattern));
}

std::string pde_latex(const HybridSystem& sys, ExprPrinter& pr, const IrMode& md,
                      const std::string& u) {
  const Model& m = *sys.model;
  std::string s = "\\frac{\\partial " + u + "}{\\partial t}";
  for (std::size_t i = 0; i < m.state.size(); ++i) {
    if (md.flow[i].is_zero()) continue;
    // A coefficient ±1 is a sign only (not "+ 1 ∂u/∂x").
    const std::string coefficient = md.flow[i].is_equal(1)    ? " + "
                                    : md.flow[i].is_equal(-1) ? " - "
                                                              : pr.signed_term(md.flow[i]) + "\\,";
    s += coefficient + "\\frac{\\partial " + u + "}{\\partial " + m.tex.at(m.state[i]) + "}";
  }
  if (md.divergence.is_zero()) return s + " = 0";
  // −div·u, with the sign folded into a single term when div is not a sum.
  const std::string rhs = GiNaC::is_a<GiNaC::add>(md.divergence)
                              ? "-\\left(" + pr.latex(md.divergence) + "\\right)"
                              : pr.latex(-md.divergence);
  return s + " = " + rhs + "\\, " + u;
}

std::string state_args_latex(const Model& m) {
  std::string s;
  for (const auto& x : m.state) s += ", " + m.tex.at(x);
  return s;
}

/// "(e1, e2, ...)" of names.
std::string name_tuple(const std::vector<std::string>& v) {
  std::string s = "(";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s + ")";
}

/// " - c" of q = φ − c: nothing for c = 0, " + 2" for c = −2, " - (a + b)" for sums.
std::string minus_level(const ex& c, const std::function<std::string(const ex&)>& print,
                        const std::string& open, const std::string& close) {
  if (c.is_zero()) return "";
  if (GiNaC::is_a<GiNaC::numeric>(c))
    return GiNaC::ex_to<GiNaC::numeric>(c).is_negative() ? " + " + print(-c) : " - " + print(c);
  if (GiNaC::is_a<GiNaC::add>(c)) return " - " + open + print(c) + close;
  return " - " + print(c);
}

/// The width of a display line, in ems of the 11-point document of derive_latex_document
/// (US letter less 2 cm margins: 500 pt, 45 em), less a margin for latex_width's estimate.
constexpr double kLineEms = 41.0;
/// A row's label (`mode heat:`) goes on a line of its own above its equations when a
/// right-hand side does not fit beside it and the label leaves less than this for them.
constexpr double kMinRhsEms = 22.0;
/// A state tuple wider than this is written as the point x in the PDE's display.
constexpr double kLongTupleEms = 10.0;

/// An `aligned` display of rows `lhs &= rhs` after `label` (may be empty), each rhs broken
/// into lines that fit beside the label and the widest lhs (latex_lines.hpp).
void aligned_display(std::ostream& os, const std::string& label,
                     const std::vector<std::pair<std::string, std::string>>& rows) {
  double lhs = 0.0, widest = 0.0;
  for (const auto& [l, r] : rows) {
    lhs = std::max(lhs, latex_width(l));
    widest = std::max(widest, latex_width(r));
  }
  double rhs = kLineEms - lhs - latex_width("=");
  os << "\\[\n";
  if (!label.empty()) {
    const double beside = rhs - latex_width(label);
    os << "  " << label << "\n";
    if (widest > beside && beside < kMinRhsEms)
      os << "\\]\n\\[\n";  // the label alone, its rows in a display of their own
    else
      rhs = beside;
  }
  os << "  \\begin{aligned}\n";
  for (std::size_t k = 0; k < rows.size(); ++k)
    os << "    " << rows[k].first << " &= " << latex_aligned_rhs(rows[k].second, rhs)
       << (k + 1 < rows.size() ? ", \\\\\n" : "\n");
  os << "  \\end{aligned}\n\\]\n";
}

/// A case of the `cases` display: `expr` broken into lines of `width` ems, stacked in an
/// `aligned` block when it takes more than one (centred on its condition: KaTeX, which
/// renders the report, takes no `[t]`).
std::string case_latex(const std::string& expr, double width) {
  const std::string rows = latex_aligned_rhs(expr, width, "    ");
  if (rows.find(" \\\\\n") == std::string::npos) return expr;
  return "\\begin{aligned}\n    &" + rows + "\n  \\end{aligned}";
}

/// The reduction objects of a Lie-group model in text (derive --format text).
void reduction_text(std::ostream& os, const Model& m, ExprPrinter& pr) {
  const Reduction& r = *m.reduction;
  const unsigned n = r.algebra_dim;
  os << "\nLie-group reduction (paper §3.2, Impact Lie-Poisson Reduction theorem)\n";
  if (r.coordinates.empty())
    os << "  group        " << r.group << ", given by structure constants on the basis "
       << name_tuple(r.basis) << "\n";
  else
    os << "  group        " << r.group << ", coordinates " << name_tuple(r.coordinates)
       << ", basis E_i = dg/dc_i at the identity " << name_tuple(r.basis) << "\n";
  os << "  brackets     ";
  bool any = false;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i + 1; j < n; ++j)
      if (r.bracket[i][j] != "0") {
        os << (any ? ", " : "") << "[" << r.basis[i] << ", " << r.basis[j]
           << "] = " << r.bracket[i][j];
        any = true;
      }
  os << (any ? "   (others zero)\n" : "all zero (abelian)\n");
  if (r.constrained) {
    os << "  constraints  body velocity xi(w) = " << tuple_text(pr, r.dh)
       << "   (Euler-Poincare-Suslov, multipliers eliminated)\n";
    os << "  energy       = " << pr.ginac(r.hamiltonian)
       << "   (1/2 xi^T I xi on the constraints)\n";
    os << "  ad*_{xi}     (mu' = ad*_{xi} mu + constraint forces, mu = I xi)\n";
  } else {
    os << "  h(zeta)      = " << pr.ginac(r.hamiltonian)
       << "   (H(g, p) = h((l_g)^* p): left-invariant)\n";
    os << "  zeta^#       = dh/dzeta = " << tuple_text(pr, r.dh) << "\n";
    os << "  ad*_{dh}     (zeta' = ad*_{dh} zeta for the column vector zeta)\n";
  }
  for (unsigned i = 0; i < n; ++i) {
    os << "    [";
    for (unsigned j = 0; j < n; ++j) os << (j ? ", " : "") << pr.ginac(r.coadjoint(i, j));
    os << "]\n";
  }
  os << "  q            = phi(g)"
     << minus_level(
            r.level, [&](const ex& e) { return pr.ginac(e); }, "(", ")")
     << (r.coordinates.empty() ? std::string() : ",  phi = " + pr.ginac(r.phi)) << "  ("
     << (r.multiplicative ? "a homomorphism to R*" : "a homomorphism to R or S^1")
     << (r.coordinates.empty() ? ", given by dphi_e" : "") << ")\n";
  os << "  K            = ker phi,  k = ker dphi_e,  dphi_e = " << tuple_text(pr, r.dphi_e) << "\n";
  os << "  q'           = " << pr.ginac(r.q_dot) << "   (depends on (zeta, q) only)\n";
  for (std::size_t k = 0; k < r.momentum_jumps.size() && k < m.guards.size(); ++k)
    os << (r.constrained ? "  Delta w      = " : "  Delta zeta   = ")
       << tuple_text(pr, r.momentum_jumps[k]) << "   (guard " << m.guards[k].name
       << (r.constrained ? "; I B Delta w in Ann(k) + constraint forms)\n" : "; in Ann(k))\n");
  os << "  hypotheses   normal: " << (r.normal ? "yes" : "no")
     << ", codim1: " << (r.codim1 ? "yes" : "no")
     << ", left_invariant: " << (r.left_invariant ? "yes" : "no")
     << ", transversal: " << (r.transversal ? "yes" : "no") << "\n";
}

/// The reduction objects in LaTeX (derive --format latex and report.md), one row each.
void reduction_latex(std::ostream& os, const Model& m, ExprPrinter& pr) {
  const Reduction& r = *m.reduction;
  const unsigned n = r.algebra_dim;
  const std::string q = m.tex.at(r.q);
  os << "% Lie-group reduction (Impact Lie--Poisson Reduction theorem), group " << r.group << "\n";
  const std::string ad = "\\mathrm{ad}^*_{\\partial h/\\partial\\zeta}";
  std::string matrix = "\\begin{pmatrix}\n";
  for (unsigned i = 0; i < n; ++i) {
    matrix += "      ";
    for (unsigned j = 0; j < n; ++j) matrix += (j ? " & " : "") + pr.latex(r.coadjoint(i, j));
    matrix += i + 1 < n ? " \\\\\n" : "\n";
  }
  matrix += "    \\end{pmatrix}";
  std::vector<std::pair<std::string, std::string>> rows = {
      {"h(\\zeta)", pr.latex(r.hamiltonian)},
      {"\\zeta^\\sharp = \\frac{\\partial h}{\\partial\\zeta}", tuple_latex(pr, r.dh)},
      {ad, matrix},
      {"\\dot\\zeta", ad + "\\,\\zeta"},
      {tex_dot(q), pr.latex(r.q_dot)},
      {q, pr.latex(r.phi) +
              minus_level(
                  r.level, [&](const ex& e) { return pr.latex(e); }, "\\left(", "\\right)")},
      {"d\\phi_e", tuple_latex(pr, r.dphi_e) + ", \\qquad \\mathfrak k = \\ker d\\phi_e"}};
  for (std::size_t k = 0; k < r.momentum_jumps.size() && k < m.guards.size(); ++k)
    rows.emplace_back("\\Delta\\zeta_{" + tex_label(m.guards[k].name) + "}",
                      tuple_latex(pr, r.momentum_jumps[k]));
  aligned_display(os, "", rows);
}

/// The `reduction` block of derive --format json (docs/design.md).
nlohmann::ordered_json reduction_json(const Model& m, ExprPrinter& pr) {
  const Reduction& r = *m.reduction;
  const unsigned n = r.algebra_dim;
  auto strings = [&](const std::vector<ex>& v) {
    std::vector<std::string> out;
    for (const auto& e : v) out.push_back(pr.ginac(e));
    return out;
  };
  nlohmann::ordered_json j;
  j["algebra_dim"] = n;
  j["momenta"] = r.momenta;
  j["q"] = r.q;
  j["group"] = r.group;
  j["coordinates"] = r.coordinates;
  j["basis"] = r.basis;
  j["bracket"] = r.bracket;
  nlohmann::ordered_json c = nlohmann::ordered_json::array();
  for (unsigned i = 0; i < n; ++i) {
    nlohmann::ordered_json ci = nlohmann::ordered_json::array();
    for (unsigned k = 0; k < n; ++k) {
      std::vector<std::string> row;
      for (unsigned l = 0; l < n; ++l)
        row.push_back(pr.ginac(r.structure_constants[(i * n + k) * n + l]));
      ci.push_back(row);
    }
    c.push_back(ci);
  }
  j["structure_constants"] = c;
  nlohmann::ordered_json ad = nlohmann::ordered_json::array();
  for (unsigned i = 0; i < n; ++i) {
    std::vector<std::string> row;
    for (unsigned k = 0; k < n; ++k) row.push_back(pr.ginac(r.coadjoint(i, k)));
    ad.push_back(row);
  }
  j["coadjoint"] = ad;
  j["hamiltonian"] = pr.ginac(r.hamiltonian);
  j["dh"] = strings(r.dh);
  j["phi"] = pr.ginac(r.phi);
  j["level"] = pr.ginac(r.level);
  j["homomorphism"] = r.multiplicative ? "multiplicative" : "additive";
  j["dphi_e"] = strings(r.dphi_e);
  j["q_equation"] = pr.ginac(r.q_dot);
  nlohmann::ordered_json jumps = nlohmann::ordered_json::array();
  for (std::size_t k = 0; k < r.momentum_jumps.size() && k < m.guards.size(); ++k)
    jumps.push_back({{"guard", m.guards[k].name}, {"delta_zeta", strings(r.momentum_jumps[k])}});
  j["momentum_jumps"] = jumps;
  j["constrained"] = r.constrained;
  j["hypotheses"] = {{"normal", r.normal},
                     {"codim1", r.codim1},
                     {"left_invariant", r.left_invariant},
                     {"transversal", r.transversal}};
  return j;
}

}  // namespace

std::string derive_text(const HybridSystem& sys) {
  const Model& m = *sys.model;
  ExprPrinter pr(m);
  std::ostringstream os;
  os << "model " << m.name << " ("
     << (m.reduction ? "Lie-group impact system reduced to g* x K\\G: " : "general hybrid system: ")
     << m.state.size() << " state" << (m.state.size() == 1 ? "" : "s") << ", " << sys.modes.size()
     << " mode" << (sys.modes.size() == 1 ? "" : "s") << ", " << sys.guards.size() << " guard"
     << (sys.guards.size() == 1 ? "" : "s") << ")\n";
  os << "state       (";
  for (std::size_t i = 0; i < m.state.size(); ++i) os << (i ? ", " : "") << m.state[i];
  os << ")   measure: Lebesgue in these coordinates\n";
  os << "parameters  ";
  for (std::size_t j = 0; j < m.params.size(); ++j)
    os << (j ? ", " : "") << m.params[j].name << " = " << pr.ginac(m.params[j].value);
  os << "\n";
  if (m.reduction) reduction_text(os, m, pr);
  for (const auto& md : sys.modes) {
    os << "\nmode " << md.name << "\n";
    if (md.hamiltonian)
      os << "  H = " << pr.ginac(*md.hamiltonian) << "   (Hamilton's equations)\n";
    for (std::size_t i = 0; i < m.state.size(); ++i)
      os << "  " << m.state[i] << "' = " << pr.ginac(md.flow[i]) << "\n";
    os << "  div X = " << pr.ginac(md.divergence) << "\n";
  }
  for (const auto& g : sys.guards) {
    os << "\nguard " << g.name << ": " << sys.modes[static_cast<std::size_t>(g.from)].name << " -> "
       << (g.absorbing ? "absorbed" : sys.modes[static_cast<std::size_t>(g.to)].name)
       << " when s = " << pr.ginac(g.surface) << " crosses 0, " << direction_word(g.direction)
       << "\n";
    if (g.absorbing) {
      os << "  reset            absorb: the mass that reaches the guard leaves the system\n";
      continue;
    }
    os << "  reset            Delta" << tuple_text(pr, m.state_symbols) << " = "
       << tuple_text(pr, g.reset) << "\n";
    if (g.has_inverse)
      os << "  inverse reset    Delta^-1" << tuple_text(pr, m.state_symbols) << " = "
         << tuple_text(pr, g.reset_inverse) << "\n";
    else if (g.inverse_on_guard_only && g.image_axis >= 0)
      os << "  inverse reset    on the guard only: the image lies on "
         << m.state[static_cast<std::size_t>(g.image_axis)] << " = "
         << pr.ginac(g.reset[static_cast<std::size_t>(g.image_axis)])
         << "; its pre-image on s = 0 by Newton at run time\n";
    else if (g.inverse_on_guard_only)
      os << "  inverse reset    none: locally injective on the guard only (methods "
         << rt::forward_methods() << ")\n";
    else
      os << "  inverse reset    numeric (Newton at run time)\n";
    os << "  hybrid Jacobian  J = " << pr.ginac(g.hybrid_jacobian_on_surface) << "   (on s = 0)\n";
    if (!g.surface_note.empty() &&
        !is_identically_zero(g.hybrid_jacobian - g.hybrid_jacobian_on_surface, {}))
      os << "                   general form: J = " << pr.ginac(g.hybrid_jacobian) << "\n";
  }
  os << "\nhybrid Frobenius-Perron PDE (paper Thm 3.11)\n";
  for (const auto& md : sys.modes) {
    std::string u = sys.modes.size() > 1 ? "u_" + md.name : "u";
    os << "  d" << u << "/dt";
    for (std::size_t i = 0; i < m.state.size(); ++i)
      if (!md.flow[i].is_zero())
        os << " + (" << pr.ginac(md.flow[i]) << ") d" << u << "/d" << m.state[i];
    os << " = " << scaled_text(pr, -md.divergence, u) << "\n";
  }
  // The post-reset point is named by the states themselves (a generic name such as y could
  // be one of them).
  const std::string point = tuple_text(pr, m.state_symbols);
  const std::string args = point.substr(1, point.size() - 2);
  for (const auto& g : sys.guards) {
    std::string uf =
        sys.modes.size() > 1 ? "u_" + sys.modes[static_cast<std::size_t>(g.from)].name : "u";
    if (g.absorbing) {
      os << "  at " << g.name << ": " << uf
         << " leaves through S (absorbed; the flux u X.n out of it is counted)\n";
      continue;
    }
    std::string ut =
        sys.modes.size() > 1 ? "u_" + sys.modes[static_cast<std::size_t>(g.to)].name : "u";
    os << "  jump at " << g.name << ": " << ut << "(t+, " << args << ") = " << uf << "(t-, Delta^-1"
       << point << ") / |J(Delta^-1" << point << ")|";
    if (g.has_inverse) {
      std::string pre = tuple_text(pr, g.reset_inverse);
      os << "\n      = " << uf << "(t-, " << pre.substr(1, pre.size() - 2) << ")";
      const ex J = jacobian_at_preimage(sys, g);
      if (const std::string a = abs_text(pr, J); a != "1") os << " / " << a;
    }
    os << "   for " << point << " in Delta(S)\n";
  }
  if (!m.sim.observables.empty()) {
    // What a run reports the mean of (runtime/include/hybgen/rt/methods/observables.hpp).
    os << "\nobservables (their means under the density, per output time)\n";
    for (const Observable& o : m.sim.observables) {
      const auto k = static_cast<std::size_t>(std::max(o.mode, 0));
      os << "  " << o.name << " = " << pr.ginac(o.per_mode.at(k));
      if (o.mode >= 0) os << "   in mode " << m.modes[k].name << ", 0 in the others";
      os << "\n";
    }
  }
  if (!sys.warnings.empty()) {
    os << "\nwarnings\n";
    for (const auto& w : sys.warnings) os << "  " << w.text << "\n";
  }
  return os.str();
}

std::string derive_latex(const HybridSystem& sys) {
  const Model& m = *sys.model;
  ExprPrinter pr(m);
  std::ostringstream os;
  const bool multi = sys.modes.size() > 1;
  os << "% hybgen " << generator_version() << ": hybrid Frobenius--Perron PDE of '" << m.name
     << "' (needs amsmath)\n";
  if (m.reduction) reduction_latex(os, m, pr);
  // Each mode's field, one line per state (its own derivative), and its divergence.
  for (const auto& md : sys.modes) {
    std::vector<std::pair<std::string, std::string>> rows;
    for (std::size_t i = 0; i < m.state.size(); ++i)
      rows.emplace_back(tex_dot(m.tex.at(m.state[i])), pr.latex(md.flow[i]));
    rows.emplace_back("\\operatorname{div}_\\mu X", pr.latex(md.divergence));
    aligned_display(os, "\\text{mode } " + tex_label(md.name) + ":\\qquad", rows);
  }
  // Each guard: its surface, its reset (and inverse) and the hybrid Jacobian.
  for (const auto& g : sys.guards) {
    std::vector<std::pair<std::string, std::string>> rows;
    rows.emplace_back("\\mathcal S_{" + tex_label(g.name) + "}",
                      "\\{" + pr.latex(g.surface) + " = 0\\}");
    if (!g.absorbing) {  // a trap has its surface only
      rows.emplace_back("\\Delta" + tuple_latex(pr, m.state_symbols), tuple_latex(pr, g.reset));
      if (g.has_inverse)
        rows.emplace_back("\\Delta^{-1}" + tuple_latex(pr, m.state_symbols),
                          tuple_latex(pr, g.reset_inverse));
      rows.emplace_back("\\mathcal J^X_\\mu(\\Delta)", pr.latex(g.hybrid_jacobian_on_surface));
    }
    const std::string target = g.absorbing
                                   ? "\\text{absorbed}"
                                   : tex_label(sys.modes[static_cast<std::size_t>(g.to)].name);
    aligned_display(os,
                    "\\text{guard } " + tex_label(g.name) + "\\ (" +
                        tex_label(sys.modes[static_cast<std::size_t>(g.from)].name) + " \\to " +
                        target + "):\\qquad",
                    rows);
  }
  // The PDE per mode and the jump per guard, each beside where it holds: the left column
  // gets the line less the widest condition, the brace and the columns' \quad. A long state
  // is written x (bold: no state's name), defined below the display.
  const std::string args = state_args_latex(m);
  const bool bold = latex_width(args) > kLongTupleEms;
  const std::string point = bold ? "\\mathbf{x}" : "(" + args.substr(2) + ")";
  const std::string at = bold ? ", \\mathbf{x}" : args;
  double condition = latex_width(point + " \\notin \\Delta(\\mathcal S);");
  for (const auto& g : sys.guards)
    if (!g.absorbing)
      condition = std::max(condition, latex_width(point + " \\in \\Delta(\\mathcal S_{" +
                                                  tex_label(g.name) + "});"));
  const double column = kLineEms - condition - 2.5;
  os << "\\[\n\\begin{cases}\n";
  for (const auto& md : sys.modes) {
    std::string u = multi ? "u_{" + tex_label(md.name) + "}" : "u";
    os << "  " << case_latex(pde_latex(sys, pr, md, u), column) << ", & " << point
       << " \\notin \\Delta(\\mathcal S); \\\\[1ex]\n";
  }
  std::size_t last_jump = 0;  // one past the last guard with a jump
  for (std::size_t k = 0; k < sys.guards.size(); ++k)
    if (!sys.guards[k].absorbing) last_jump = k + 1;
  for (std::size_t k = 0; k < sys.guards.size(); ++k) {
    const auto& g = sys.guards[k];
    if (g.absorbing) continue;  // no jump: the mass leaves (its guard's display says so)
    std::string uf =
        multi ? "u_{" + tex_label(sys.modes[static_cast<std::size_t>(g.from)].name) + "}" : "u";
    std::string ut =
        multi ? "u_{" + tex_label(sys.modes[static_cast<std::size_t>(g.to)].name) + "}" : "u";
    // The jump at the pre-image written out; where that does not fit its column, in terms of
    // Δ⁻¹ and J, both displayed with the guard above.
    const std::string inner = at.substr(2);
    const std::string generic = "\\dfrac{" + uf + "(t^-, \\Delta^{-1}(" + inner +
                                "))}{\\left|\\mathcal J(\\Delta^{-1}(" + inner + "))\\right|}";
    std::string jump = generic;
    if (g.has_inverse) {
      std::string pre;
      for (const auto& e : g.reset_inverse) pre += ", " + pr.latex(e);
      const ex Jpre = jacobian_at_preimage(sys, g);
      if (GiNaC::is_a<GiNaC::numeric>(Jpre) && GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(Jpre)) == 1)
        jump = uf + "(t^-" + pre + ")";
      else
        jump = "\\dfrac{" + uf + "(t^-" + pre + ")}{" + abs_latex(pr, Jpre) + "}";
      if (latex_width(ut + "(t^+" + at + ") = " + jump) > column) jump = generic;
    }
    os << "  " << case_latex(ut + "(t^+" + at + ") = " + jump, column) << ", & " << point
       << " \\in \\Delta(\\mathcal S_{" << tex_label(g.name) << "})"
       << (k + 1 < last_jump ? ";\\\\[1ex]" : ".") << "\n";
  }
  os << "\\end{cases}\n\\]\n";
  if (bold)
    os << "\\[\n  \\text{where } \\mathbf{x} = \\left(" << args.substr(2) << "\\right).\n\\]\n";
  return os.str();
}

std::string derive_latex_document(const HybridSystem& sys) {
  const Model& m = *sys.model;
  ExprPrinter pr(m);
  std::string name;
  for (char c : m.name) name += c == '_' ? std::string("\\_") : std::string(1, c);
  std::ostringstream os;
  os << "% hybgen " << generator_version() << ": pdflatex this file\n"
     << "\\documentclass[11pt]{article}\n\\usepackage[margin=2cm]{geometry}\n"
     << "\\usepackage{amsmath,amssymb}\n\\allowdisplaybreaks\n\\begin{document}\n"
     << "\\section*{The hybrid Frobenius--Perron equation of \\texttt{" << name << "}}\n"
     << "State $" << tuple_latex(pr, m.state_symbols) << "$";
  if (!m.params.empty()) {
    os << ", parameters ";
    for (std::size_t j = 0; j < m.params.size(); ++j)
      os << (j ? ", " : "") << "$" << m.tex.at(m.params[j].name) << " = "
         << pr.latex(m.params[j].value) << "$";
  }
  os << ". The density $u$ is with respect to the Lebesgue measure $\\mu$ in these "
        "coordinates.\n\n"
     << derive_latex(sys) << "\\end{document}\n";
  return os.str();
}

nlohmann::ordered_json derive_json(const HybridSystem& sys) {
  const Model& m = *sys.model;
  ExprPrinter pr(m);
  nlohmann::ordered_json j;
  j["model"] = m.name;
  j["kind"] = m.reduction ? "lie" : "hybrid";
  j["state"] = m.state;
  nlohmann::ordered_json params = nlohmann::ordered_json::object();
  for (const auto& p : m.params) {
    if (GiNaC::is_a<GiNaC::numeric>(p.value) &&
        GiNaC::ex_to<GiNaC::numeric>(p.value).is_integer() && std::fabs(p.value_d) < 9.0e15)
      params[p.name] = static_cast<long long>(p.value_d);
    else
      params[p.name] = p.value_d;
  }
  j["parameters"] = params;
  nlohmann::ordered_json modes = nlohmann::ordered_json::array();
  for (const auto& md : sys.modes) {
    nlohmann::ordered_json mj;
    mj["name"] = md.name;
    std::vector<std::string> flow;
    for (const auto& f : md.flow) flow.push_back(pr.ginac(f));
    mj["flow"] = flow;
    mj["divergence"] = pr.ginac(md.divergence);
    if (md.hamiltonian) mj["hamiltonian"] = pr.ginac(*md.hamiltonian);
    modes.push_back(mj);
  }
  j["modes"] = modes;
  nlohmann::ordered_json guards = nlohmann::ordered_json::array();
  for (const auto& g : sys.guards) {
    nlohmann::ordered_json gj;
    gj["name"] = g.name;
    gj["from"] = sys.modes[static_cast<std::size_t>(g.from)].name;
    gj["to"] = g.absorbing ? nlohmann::ordered_json(nullptr)
                           : nlohmann::ordered_json(sys.modes[static_cast<std::size_t>(g.to)].name);
    gj["surface"] = pr.ginac(g.surface);
    gj["direction"] = direction_word(g.direction);
    gj["absorbing"] = g.absorbing;
    if (g.absorbing) {
      // `reset absorb`: no target, reset, inverse or J (docs/design.md, the JSON contract).
      for (const char* key :
           {"reset", "reset_inverse", "hybrid_jacobian", "hybrid_jacobian_general"})
        gj[key] = nullptr;
      gj["reset_inverse_kind"] = "absorb";
      guards.push_back(gj);
      continue;
    }
    std::vector<std::string> reset, inverse;
    for (const auto& e : g.reset) reset.push_back(pr.ginac(e));
    gj["reset"] = reset;
    if (g.has_inverse) {
      for (const auto& e : g.reset_inverse) inverse.push_back(pr.ginac(e));
      gj["reset_inverse"] = inverse;
    } else {
      gj["reset_inverse"] = nullptr;
    }
    gj["reset_inverse_kind"] = g.has_inverse                                  ? "symbolic"
                               : g.inverse_on_guard_only && g.image_axis >= 0 ? "guard"
                               : g.inverse_on_guard_only                      ? "none"
                                                                              : "numeric";
    gj["hybrid_jacobian"] = pr.ginac(g.hybrid_jacobian_on_surface);
    gj["hybrid_jacobian_general"] = pr.ginac(g.hybrid_jacobian);
    guards.push_back(gj);
  }
  j["guards"] = guards;
  if (m.reduction)
    j["reduction"] = reduction_json(m, pr);
  else
    j["reduction"] = nullptr;
  nlohmann::ordered_json warnings = nlohmann::ordered_json::array();
  for (const auto& w : sys.warnings) warnings.push_back(w.text);
  j["warnings"] = warnings;
  return j;
}

}  // namespace hybgen::gen
