// The reduce stage's shared internals and its unreduced target: the
// 2n-dimensional impact system on T*G in the group coordinates (see reduce.hpp),
// or for a constrained model on TG by Lagrange–d'Alembert in the coordinates
// (see reduce_internal.hpp) — derived without the Lie algebra, so that the
// reduced-versus-unreduced test compares two independent derivations.

#include <algorithm>
#include <cctype>
#include <set>
#include <sstream>

#include "hybgen/gen/derive.hpp"
#include "reduce_internal.hpp"

namespace hybgen::gen::reduce_detail {

using GiNaC::ex;
using GiNaC::matrix;

std::string str(const ex& e) {
  std::ostringstream os;
  os << e;
  return os.str();
}

ModelError hypothesis_error(const SourceText& src, SourceLoc loc, const LieError& e) {
  return src.error(loc, "hypothesis '" + e.hypothesis() + "' fails: " + e.what());
}

void require_level_set(const LieModel& lm, const GuardSpec& g, const SourceText& src) {
  const std::size_t n = lm.base.state.size() - 1;
  for (std::size_t i = 0; i < n; ++i)
    if (g.surface.has(lm.base.state_symbols[i]))
      throw src.error(g.surface_loc, "the surface of guard '" + g.name +
                                         "' depends on the momentum " + lm.base.state[i] +
                                         ": in a Lie-group model an impact surface is a " +
                                         "level set of the reduced coordinate (write 'when " +
                                         lm.base.state[n] + " = c')");
}

namespace {

/// The parts common to both twins: name, parameters, and the state (c_1..c_n,
/// s_1..s_n) with s_i named `second_name(c_i)` (made unique against the
/// parameters and coordinates by appending '_'); `second` gets the s_i.
Model twin_skeleton(const LieModel& lm, const std::string& prefix, const std::string& suffix,
                    std::vector<ex>& second) {
  const unsigned n = lm.group.algebra().dim();
  const Model& b = lm.base;
  const std::vector<ex>& c = lm.group.coords();
  Model out;
  out.name = b.name + "_unreduced";
  out.path = b.path;
  out.source_hash = b.source_hash;
  out.params = b.params;
  out.limits = b.limits;
  std::set<std::string> taken;
  for (const auto& p : b.params) taken.insert(p.name);
  for (unsigned i = 0; i < n; ++i) {
    out.state.push_back(lm.coordinate_names[i]);
    out.state_symbols.push_back(c[i]);
    taken.insert(lm.coordinate_names[i]);
  }
  second.clear();
  for (unsigned i = 0; i < n; ++i) {
    std::string name = prefix + lm.coordinate_names[i] + suffix;
    while (taken.count(name)) name += "_";
    taken.insert(name);
    second.push_back(GiNaC::realsymbol(name));
    out.state.push_back(name);
    out.state_symbols.push_back(second.back());
  }
  for (const auto& s : out.state) out.tex[s] = tex_identifier(s);
  for (const auto& pr : b.params) out.tex[pr.name] = b.tex.at(pr.name);
  out.sim.present = false;
  out.sim.initial.assign(1, ex(0));
  return out;
}

/// The guard of the twin: the base guard with its surface s(q) pulled back to
/// the coordinates (q = q_expr(c)); the reset is left to the caller.
GuardSpec twin_guard(const LieModel& lm, std::size_t k, const SourceText& src) {
  GuardSpec g = lm.base.guards[k];
  require_level_set(lm, g, src);
  const ex q = lm.base.state_symbols.back();
  g.surface = g.surface.subs(GiNaC::exmap{{q, lm.q_expr}}, GiNaC::subs_options::no_pattern);
  return g;
}

/// The unconstrained twin on T*G: H(c, p) = h(ζ) at ζ = (ℓ_g)^* p and derive's
/// corner-condition resets.
Model unreduced_free(const LieModel& lm, const SourceText& src) {
  const unsigned n = lm.group.algebra().dim();
  const Model& b = lm.base;
  const matrix& L = lm.group.left_trivialization();
  std::vector<ex> p;
  Model out = twin_skeleton(lm, "p_", "", p);
  // ζ = (ℓ_g)^* p: ζ_i = p(g E_i) = Σ_j p_j L_ji(c).
  GiNaC::exmap zeta_of;
  for (unsigned i = 0; i < n; ++i) {
    ex zi = 0;
    for (unsigned j = 0; j < n; ++j) zi += p[j] * L(j, i);
    zeta_of[b.state_symbols[i]] = zi;
  }
  ModeSpec mode;
  mode.name = "flow";
  mode.loc = lm.group_loc;
  // H(c, p) is expanded only when its expansion is within the term limit:
  // ζ_i is a sum of n terms p_j L_ji(c), so on gl(3) (n = 9) ζ_2^2250 would
  // expand to C(2258, 8) ≈ 1.7·10^22 monomials (fuzz finding F7). Unexpanded
  // it is the same function, and derive differentiates it as it is.
  const ex h = lm.h.subs(zeta_of, GiNaC::subs_options::no_pattern);
  mode.hamiltonian = LimitScope::may_expand(h) ? h.expand() : h;
  for (unsigned i = 0; i < n; ++i) {
    mode.coordinates.push_back(static_cast<int>(i));
    mode.momenta.push_back(static_cast<int>(n + i));
  }
  out.modes.push_back(mode);
  for (std::size_t k = 0; k < b.guards.size(); ++k) {
    GuardSpec g = twin_guard(lm, k, src);
    const LieImpact& imp = lm.impacts[k];
    if (imp.kind == ResetDecl::Kind::Elastic || imp.kind == ResetDecl::Kind::Restitution) {
      g.reset_kind = imp.kind;
      g.restitution = imp.restitution;
    } else if (g.reset_kind == ResetDecl::Kind::Explicit) {
      throw src.error(g.reset_loc,
                      "the unreduced twin supports elastic, restitution and identity resets "
                      "only (this reset is explicit)");
    }
    out.guards.push_back(g);
  }
  return out;
}

// ------------------------------------------------ the constrained twin (TG)

/// normal() of e, and of e with sin(u)² → 1 − cos(u)² (an identity), whichever
/// is smaller: GiNaC's normal() treats sin u and cos u as independent, so
/// L⁻¹ of a rotation carries a factor 1/(cos²u + sin²u) that only this removes.
ex tidy(const ex& e) {
  const ex plain = GiNaC::normal(e);
  if (!plain.has(GiNaC::sin(GiNaC::wild())) || !plain.has(GiNaC::cos(GiNaC::wild()))) return plain;
  const ex pythagoras =
      GiNaC::pow(GiNaC::sin(GiNaC::wild()), 2) == 1 - GiNaC::pow(GiNaC::cos(GiNaC::wild()), 2);
  const ex nd = GiNaC::numer_denom(plain);
  const ex num = nd.op(0).expand().subs(pythagoras, GiNaC::subs_options::algebraic).expand();
  const ex den = nd.op(1).expand().subs(pythagoras, GiNaC::subs_options::algebraic).expand();
  const ex trig = GiNaC::normal(num / den);
  return expr_size(trig) < expr_size(plain) ? trig : plain;
}

/// tidy() of every entry.
matrix tidy(matrix m) {
  for (unsigned i = 0; i < m.rows(); ++i)
    for (unsigned j = 0; j < m.cols(); ++j) m(i, j) = tidy(m(i, j));
  return m;
}

/// The constraint rows C (C ξ = 0 on the allowed body velocities ξ = B w):
/// check_lie builds ξ(w) with ξ_i = w_k for a free velocity and ξ_i = r_i(w)
/// (linear) for a constrained one, so each constrained i gives the row
/// e_i − Σ_k ∂r_i/∂w_k e_{free(k)}. Verified: C B = 0 with n − r independent rows.
matrix constraint_rows(const LieModel& lm) {
  const unsigned n = lm.group.algebra().dim();
  const std::vector<ex> w(lm.base.state_symbols.begin(), lm.base.state_symbols.end() - 1);
  std::vector<int> free_index(w.size(), -1);
  std::vector<unsigned> constrained;
  for (unsigned i = 0; i < n; ++i) {
    const auto it = std::find(w.begin(), w.end(), lm.xi_of_w[i]);
    if (it != w.end())
      free_index[static_cast<std::size_t>(it - w.begin())] = static_cast<int>(i);
    else
      constrained.push_back(i);
  }
  if (constrained.size() + w.size() != n ||
      std::find(free_index.begin(), free_index.end(), -1) != free_index.end())
    throw InternalError("constrained twin: xi(w) is not of the form check_lie builds");
  matrix C(static_cast<unsigned>(constrained.size()), n);
  for (unsigned r = 0; r < constrained.size(); ++r) {
    C(r, constrained[r]) = 1;
    for (std::size_t k = 0; k < w.size(); ++k)
      C(r, static_cast<unsigned>(free_index[k])) -=
          lm.xi_of_w[constrained[r]].diff(GiNaC::ex_to<GiNaC::symbol>(w[k]));
  }
  for (unsigned r = 0; r < C.rows(); ++r)
    for (const auto& wk : w) {
      ex cb = 0;
      for (unsigned i = 0; i < n; ++i)
        cb += C(r, i) * lm.xi_of_w[i].diff(GiNaC::ex_to<GiNaC::symbol>(wk));
      if (!GiNaC::normal(cb).is_zero()) throw InternalError("constrained twin: C B != 0");
    }
  return C;
}

/// ∂/∂c_l of every entry of m.
matrix diff(const matrix& m, const ex& c) {
  matrix d(m.rows(), m.cols());
  for (unsigned i = 0; i < m.rows(); ++i)
    for (unsigned j = 0; j < m.cols(); ++j) d(i, j) = m(i, j).diff(GiNaC::ex_to<GiNaC::symbol>(c));
  return d;
}

/// The inverse of a square matrix that must be invertible as a function of the
/// state: a located error naming `what` when its determinant vanishes identically.
matrix inverse_or_error(const matrix& m, const SourceText& src, SourceLoc loc,
                        const std::string& what) {
  if (is_identically_zero(tidy(m.determinant()), {})) throw src.error(loc, what);
  return tidy(m.inverse(GiNaC::solve_algo::gauss));
}

/// A column vector from components.
matrix column(const std::vector<ex>& v) {
  matrix m(static_cast<unsigned>(v.size()), 1);
  for (unsigned i = 0; i < v.size(); ++i) m(i, 0) = v[i];
  return m;
}

/// The constrained twin on TG (see reduce_internal.hpp): Lagrange–d'Alembert
/// in the coordinates, derived without the Lie algebra.
Model unreduced_constrained(const LieModel& lm, const SourceText& src) {
  const unsigned n = lm.group.algebra().dim();
  const Model& b = lm.base;
  const std::vector<ex>& c = lm.group.coords();
  const matrix& L = lm.group.left_trivialization();
  std::vector<ex> cd;
  Model out = twin_skeleton(lm, "", "dot", cd);
  for (unsigned i = 0; i < n; ++i)
    out.tex[out.state[n + i]] = "\\dot{" + tex_identifier(out.state[i]) + "}";

  // ξ = L⁻¹ ċ: M = L⁻ᵀ I L⁻¹, M⁻¹ = L I⁻¹ Lᵀ, A = C L⁻¹.
  const matrix Linv = tidy(L.inverse(GiNaC::solve_algo::gauss));
  const matrix& I = lm.inertia;
  const matrix M = tidy(Linv.transpose().mul(I).mul(Linv));
  const matrix Iinv = inverse_or_error(I, src, lm.hamiltonian_loc,
                                       "the unreduced twin needs an invertible inertia "
                                       "(the kinetic energy is degenerate)");
  const matrix Minv = tidy(L.mul(Iinv).mul(L.transpose()));
  const matrix A = tidy(constraint_rows(lm).mul(Linv));
  const unsigned k = A.rows();
  const matrix v = column(cd);

  // M c̈ = F + Aᵀλ, F_j = ½ ċᵀ ∂M/∂c_j ċ − (Ṁ ċ)_j, Ṁ = Σ_l ∂M/∂c_l ċ_l.
  matrix Mdot(n, n), Adot(k, n), F(n, 1);
  for (unsigned l = 0; l < n; ++l) {
    Mdot = Mdot.add(diff(M, c[l]).mul_scalar(cd[l]));
    if (k > 0) Adot = Adot.add(diff(A, c[l]).mul_scalar(cd[l]));
  }
  const matrix Mdv = Mdot.mul(v);
  for (unsigned j = 0; j < n; ++j)
    F(j, 0) = tidy(v.transpose().mul(diff(M, c[j])).mul(v)(0, 0) / 2 - Mdv(j, 0));
  // A c̈ + Ȧ ċ = 0  ⇒  λ = −(A M⁻¹ Aᵀ)⁻¹ (A M⁻¹ F + Ȧ ċ).
  matrix force = F;
  if (k > 0) {
    const matrix Sinv =
        inverse_or_error(tidy(A.mul(Minv).mul(A.transpose())), src, lm.hamiltonian_loc,
                         "the unreduced twin cannot eliminate the constraint "
                         "multipliers (A M^-1 A^T is singular)");
    const matrix rhs = A.mul(Minv).mul(F).add(Adot.mul(v)).mul_scalar(-1);
    const matrix lambda = tidy(Sinv.mul(rhs));
    force = F.add(A.transpose().mul(lambda));
  }
  const matrix acc = Minv.mul(force);
  ModeSpec mode;
  mode.name = "flow";
  mode.loc = lm.group_loc;
  mode.flow = cd;
  for (unsigned i = 0; i < n; ++i) mode.flow.push_back(simplify(tidy(acc(i, 0))));
  out.modes.push_back(mode);

  for (std::size_t g_k = 0; g_k < b.guards.size(); ++g_k) {
    GuardSpec g = twin_guard(lm, g_k, src);
    const LieImpact& imp = lm.impacts[g_k];
    if (imp.kind != ResetDecl::Kind::Elastic && imp.kind != ResetDecl::Kind::Restitution) {
      if (g.reset_kind == ResetDecl::Kind::Explicit)
        throw src.error(g.reset_loc,
                        "the unreduced twin of a constrained (nonholonomic) model supports "
                        "elastic, restitution and identity resets only (this reset is explicit)");
      out.guards.push_back(g);
      continue;
    }
    // Impulsive Lagrange–d'Alembert: M Δċ = μ dsᵀ + Aᵀν, A Δċ = 0 (so
    // A ċ⁺ = A ċ, = 0 on the constraint set, and Δ stays invertible: its
    // determinant is −e), ds·Δċ = −(1 + e) ds·ċ. With G = [ds; A]:
    // Δċ = M⁻¹ Gᵀ y, (G M⁻¹ Gᵀ) y = (−(1 + e) ds·ċ, 0, …, 0).
    matrix G(k + 1, n);
    ex vn = 0;
    for (unsigned j = 0; j < n; ++j) {
      G(0, j) = g.surface.diff(GiNaC::ex_to<GiNaC::symbol>(c[j]));
      vn += G(0, j) * cd[j];
      for (unsigned r = 0; r < k; ++r) G(r + 1, j) = A(r, j);
    }
    const matrix Sinv = inverse_or_error(tidy(G.mul(Minv).mul(G.transpose())), src, g.reset_loc,
                                         "the constrained motion has no velocity normal to the "
                                         "surface of guard '" +
                                             g.name + "' (G M^-1 G^T is singular)");
    matrix rhs(k + 1, 1);
    rhs(0, 0) = -(1 + imp.restitution) * vn;
    const matrix dv = Minv.mul(G.transpose()).mul(Sinv).mul(rhs);
    g.reset_kind = ResetDecl::Kind::Explicit;
    g.reset = out.state_symbols;
    for (unsigned j = 0; j < n; ++j) g.reset[n + j] = simplify(tidy(cd[j] + dv(j, 0)));
    out.guards.push_back(g);
  }
  return out;
}

}  // namespace

Model unreduced(const LieModel& lm, const SourceText& src) {
  return lm.xi_of_w.empty() ? unreduced_free(lm, src) : unreduced_constrained(lm, src);
}

}  // namespace hybgen::gen::reduce_detail
