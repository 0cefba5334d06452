// The reduce stage: LieModel -> general Model. See reduce.hpp for the maths.

#include "hybgen/gen/reduce.hpp"

#include <cctype>
#include <new>
#include <set>
#include <sstream>

#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/limits.hpp"
#include "reduce_internal.hpp"

namespace hybgen::gen {

namespace {

using GiNaC::ex;
using GiNaC::matrix;
using namespace reduce_detail;

/// q' = dφ_e(ζ^♯) (additive) or (q + c) dφ_e(ζ^♯) (multiplicative), with the
/// factor (q + c) kept and dφ_e(ζ^♯) expanded (a canonical form); checked
/// against q_equation's result, which proved that q' depends on (ζ, q) only.
ex factored_q_dot(const Reduction& red, const std::vector<ex>& sharp, const ex& q,
                  const QEquation& qe) {
  ex rate = 0;
  for (std::size_t i = 0; i < sharp.size(); ++i) rate += red.dphi_e[i] * sharp[i];
  rate = rate.expand();
  const ex q_dot = red.multiplicative ? (q + red.level) * rate : rate;
  if (!is_identically_zero((q_dot - qe.q_dot).expand(), {}))
    throw InternalError("the q equation's two forms disagree");
  return q_dot;
}

/// The name of the symbol φ of a group without coordinates (in reports): not
/// an identifier, so it cannot clash with a name of the model.
const char* const kPhiName = "phi(g)";

/// (φ, level) with q = φ − level. Matrix group: φ = q_expr − q(e) + 1, so
/// φ(e) = 1 until q_equation decides whether φ is additive (then q_equation_of
/// shifts φ and the level by 1) or multiplicative. Without coordinates φ is
/// known by dφ_e only: the symbol φ, level 0 (additive) or 1 (multiplicative).
/// Sets red.dphi_e and checks that ker dφ_e is an ideal (hypothesis normal).
std::pair<ex, ex> phi_and_level(const LieModel& lm, Reduction& red, const SourceText& src) {
  std::pair<ex, ex> out;
  if (lm.group.has_coordinates()) {
    const MatrixGroup& group = lm.group.matrix_group();
    const ex q0 = simplify(group.at_identity(lm.q_expr));
    out = {lm.q_expr - q0 + 1, 1 - q0};
    red.dphi_e = group.differential_at_identity(out.first);
  } else {
    out = {GiNaC::realsymbol(kPhiName),
           lm.phi_kind == HomomorphismKind::Multiplicative ? ex(1) : ex(0)};
    red.dphi_e = lm.dphi_e;
  }
  try {
    require_normal_kernel(lm.group.algebra(), red.dphi_e);
  } catch (const LieError& e) {
    throw hypothesis_error(src, lm.reduced_loc, e);
  }
  return out;
}

/// q' along g' = g ξ (the theorem): q_equation for a matrix group (hypothesis
/// coset), q_equation_of_form without coordinates; sets red.multiplicative,
/// red.phi, red.level and red.q_dot.
void q_equation_of(const LieModel& lm, const ex& phi, const ex& level, const std::vector<ex>& xi,
                   const ex& q, Reduction& red, const SourceText& src) {
  QEquation qe;
  if (lm.group.has_coordinates()) {
    try {
      qe = q_equation(lm.group.matrix_group(), phi, level, Components(xi.begin(), xi.end()), q);
    } catch (const LieError& e) {
      throw hypothesis_error(src, lm.reduced_loc, e);
    }
    red.multiplicative = qe.kind == HomomorphismKind::Multiplicative;
    red.phi = (red.multiplicative ? phi : phi - 1).expand();
    red.level = (red.multiplicative ? level : level - 1).expand();
  } else {
    qe = q_equation_of_form(lm.phi_kind, red.dphi_e, Components(xi.begin(), xi.end()), q);
    red.multiplicative = qe.kind == HomomorphismKind::Multiplicative;
    red.phi = phi;
    red.level = level;
  }
  red.q_dot = factored_q_dot(red, xi, q, qe);
}

/// Hypothesis transversal (docs/design.md "guard transversal"): on the surface
/// s(q) = 0 of guard g, the rate s'(q) q' must not vanish identically (in the
/// momenta and the parameters), or the flow is tangent to the whole surface and
/// never crosses it — e.g. `when q = -1` for q = det − 1, where q' = (q + 1) tr ζ
/// vanishes (φ = 0 lies outside the group). Decided when s is affine in q
/// (s = a q + b, a ≢ 0, the form `when q = c`): q' is restricted to q = −b/a.
/// Other surfaces are left to derive's global check (∇s·X ≢ 0).
void require_transversal(const GuardSpec& g, const ex& q, const std::string& q_name,
                         const ex& q_dot, const SourceText& src) {
  const ex s = g.surface.expand();
  const ex a = s.diff(GiNaC::ex_to<GiNaC::symbol>(q));
  if (a.has(q) || is_identically_zero(a, {})) return;
  const ex level = simplify(-(s - a * q).expand() / a);
  const ex rate = simplify(q_dot.subs(GiNaC::exmap{{q, level}}, GiNaC::subs_options::no_pattern));
  if (is_identically_zero(rate, {}))
    throw hypothesis_error(
        src, g.surface_loc,
        LieError("transversal", "on the surface " + q_name + " = " + str(level) + " of guard '" +
                                    g.name + "' the rate " + q_name + "' = " + str(q_dot) +
                                    " vanishes identically: the flow is tangent to the surface "
                                    "and never crosses it"));
}

Model reduced(const LieModel& lm, const SourceText& src) {
  const LieAlgebra& alg = lm.group.algebra();
  const unsigned n = alg.dim();
  const Model& b = lm.base;
  const std::vector<ex> zeta(b.state_symbols.begin(), b.state_symbols.begin() + n);
  const ex q = b.state_symbols[n];

  // codim1: a codimension-1 ideal exists iff Ann([𝔤, 𝔤]) ≠ 0.
  if (codim1_ideal_forms(alg).empty())
    throw hypothesis_error(
        src, lm.group_loc,
        LieError("codim1", "the Lie algebra of group '" + lm.group_name +
                               "' is perfect ([g, g] = g, as for so(3)): the group has no normal "
                               "subgroup of codimension 1, so no impact surface is a coset of "
                               "one and the impact system cannot be reduced"));

  // φ with φ(e) = 0 (additive) or 1 (multiplicative): q = φ − level.
  Reduction red;
  const auto [phi, level] = phi_and_level(lm, red, src);
  const LiePoisson lp = lie_poisson(alg, zeta, lm.h);
  q_equation_of(lm, phi, level, lp.dh, q, red, src);
  const std::vector<Components> kernel = kernel_of_form(red.dphi_e);

  // Every derived expression is handed on EXPANDED: GiNaC's automatic
  // evaluation orders sums by hash and may store a factor (a − b) as −(b − a),
  // so "the smallest form" of an unexpanded sum is not reproducible from run to
  // run; the expanded form is canonical (the printers sort its terms), which
  // keeps generated/ byte-identical.
  auto canonical = [](std::vector<ex> v) {
    for (auto& e : v) e = e.expand();
    return v;
  };
  Model out = b;
  out.modes[0].flow = canonical(lp.zeta_dot);
  out.modes[0].flow.push_back(red.q_dot);
  for (std::size_t k = 0; k < out.guards.size(); ++k) {
    GuardSpec& g = out.guards[k];
    const LieImpact& imp = lm.impacts[k];
    require_level_set(lm, g, src);
    require_transversal(g, q, b.state.back(), red.q_dot, src);
    std::vector<ex> reset;
    if (imp.kind == ResetDecl::Kind::Elastic || imp.kind == ResetDecl::Kind::Restitution) {
      Components dz;
      try {
        dz = momentum_jump(red.dphi_e, zeta, lm.h, imp.restitution);
      } catch (const LieError& e) {
        throw hypothesis_error(src, g.reset_loc, e);
      }
      dz = canonical(dz);
      for (unsigned i = 0; i < n; ++i) reset.push_back((zeta[i] + dz[i]).expand());
      reset.push_back(q);
      red.momentum_jumps.push_back(dz);
    } else {
      reset = g.reset_kind == ResetDecl::Kind::Explicit ? g.reset : b.state_symbols;
      if (!is_identically_zero(reset[n] - q, {}))
        throw hypothesis_error(
            src, g.reset_loc,
            LieError("reset", "the reset must keep the reduced coordinate (" + b.state[n] + " -> " +
                                  b.state[n] + "): the group element does not jump"));
      Components dz;
      for (unsigned i = 0; i < n; ++i) dz.push_back((reset[i] - zeta[i]).expand());
      for (const auto& kv : kernel) {
        ex pair = 0;
        for (unsigned i = 0; i < n; ++i) pair += dz[i] * kv[i];
        if (!is_identically_zero(pair, {}))
          throw hypothesis_error(src, g.reset_loc,
                                 LieError("reset",
                                          "the momentum jump must annihilate the Lie algebra of K "
                                          "(Delta zeta in Ann(k), the theorem), but it pairs to " +
                                              str(simplify(pair)) + " with " + alg.format(kv)));
      }
      red.momentum_jumps.push_back(dz);
    }
    g.reset_kind = ResetDecl::Kind::Explicit;
    g.reset = reset;
  }

  for (const auto& cn : lm.coordinate_names) out.tex[cn] = tex_identifier(cn);
  if (!lm.group.has_coordinates()) out.tex[kPhiName] = "\\phi(g)";
  red.group = lm.group_name;
  red.coordinates = lm.coordinate_names;
  red.basis = alg.names();
  red.algebra_dim = n;
  red.momenta.assign(b.state.begin(), b.state.begin() + n);
  red.q = b.state[n];
  red.bracket.assign(n, std::vector<std::string>(n));
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) {
      Components ei(n, ex(0)), ej(n, ex(0));
      ei[i] = 1;
      ej[j] = 1;
      red.bracket[i][j] = alg.format(alg.bracket(ei, ej));
      for (unsigned k = 0; k < n; ++k) red.structure_constants.push_back(alg.c(i, j, k));
    }
  red.hamiltonian = lm.h.expand();
  red.dh = canonical(lp.dh);
  red.coadjoint = lp.ad_star;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) red.coadjoint(i, j) = red.coadjoint(i, j).expand();
  out.reduction = std::move(red);
  return out;
}

/// The Euler–Poincaré–Suslov reduction of a constrained model: the body
/// velocity ξ = B w on the constraint distribution (B = ∂ξ/∂w), μ = I ξ,
/// μ' = ad*_ξ μ + λ_k a_k; applying Bᵀ (Bᵀ a_k = 0) eliminates the multipliers:
///     w' = (BᵀIB)⁻¹ Bᵀ ad*_ξ (I ξ),   q' as in the theorem with ζ^♯ = ξ.
/// The corner conditions with constraints: I B Δw ∈ Ann(𝔨) + span(a_k), so
/// Δw = α M⁻¹ s with M = BᵀIB, s = Bᵀσ, and the normal velocity sᵀw becomes
/// −e times itself: Δw = −(1 + e) (sᵀw)/(sᵀM⁻¹s) M⁻¹ s.
Model reduced_constrained(const LieModel& lm, const SourceText& src) {
  const LieAlgebra& alg = lm.group.algebra();
  const unsigned n = alg.dim();
  const Model& b = lm.base;
  const auto r = static_cast<unsigned>(b.state.size() - 1);
  const std::vector<ex> w(b.state_symbols.begin(), b.state_symbols.begin() + r);
  const ex q = b.state_symbols[r];
  if (codim1_ideal_forms(alg).empty())
    throw hypothesis_error(src, lm.group_loc,
                           LieError("codim1", "the Lie algebra of group '" + lm.group_name +
                                                  "' is perfect ([g, g] = g): no normal subgroup "
                                                  "of codimension 1"));
  Reduction red;
  const auto [phi, level] = phi_and_level(lm, red, src);
  const std::vector<ex>& xi = lm.xi_of_w;
  matrix B(n, r), I = lm.inertia;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned k = 0; k < r; ++k) B(i, k) = xi[i].diff(GiNaC::ex_to<GiNaC::symbol>(w[k]));
  const matrix M = B.transpose().mul(I).mul(B);
  matrix Minv;
  try {
    Minv = M.inverse(GiNaC::solve_algo::gauss);
  } catch (const std::exception&) {
    throw hypothesis_error(src, lm.hamiltonian_loc,
                           LieError("quadratic",
                                    "the kinetic energy is degenerate on the "
                                    "constraint distribution (B^T I B singular)"));
  }
  for (unsigned i = 0; i < r; ++i)
    for (unsigned j = 0; j < r; ++j) Minv(i, j) = GiNaC::normal(Minv(i, j));
  Components mu(n, ex(0));
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) mu[i] += I(i, j) * xi[j];
  const Components adm = alg.coadjoint_action(Components(xi.begin(), xi.end()), mu);
  std::vector<ex> wdot(r, ex(0));
  for (unsigned k = 0; k < r; ++k) {
    ex rhs_k = 0;
    for (unsigned i = 0; i < n; ++i) rhs_k += B(i, k) * adm[i];
    for (unsigned j = 0; j < r; ++j) wdot[j] += Minv(j, k) * rhs_k;
  }
  for (auto& e : wdot) e = e.expand();
  q_equation_of(lm, phi, level, xi, q, red, src);
  // s = Bᵀσ: the normal velocity σ(ξ) = sᵀw.
  Components s(r, ex(0));
  for (unsigned k = 0; k < r; ++k)
    for (unsigned i = 0; i < n; ++i) s[k] += B(i, k) * red.dphi_e[i];
  ex den = 0, sw = 0;
  Components Ms(r, ex(0));
  for (unsigned j = 0; j < r; ++j) {
    for (unsigned k = 0; k < r; ++k) Ms[j] += Minv(j, k) * s[k];
    den += s[j] * Ms[j];
    sw += s[j] * w[j];
  }
  Model out = b;
  out.modes[0].flow = wdot;
  out.modes[0].flow.push_back(red.q_dot);
  for (std::size_t k = 0; k < out.guards.size(); ++k) {
    GuardSpec& g = out.guards[k];
    const LieImpact& imp = lm.impacts[k];
    require_level_set(lm, g, src);
    require_transversal(g, q, b.state.back(), red.q_dot, src);
    std::vector<ex> reset;
    Components dw(r, ex(0));
    if (imp.kind == ResetDecl::Kind::Elastic || imp.kind == ResetDecl::Kind::Restitution) {
      if (is_identically_zero(den, {}))
        throw hypothesis_error(src, g.reset_loc,
                               LieError("codim1",
                                        "the constrained motion has no velocity "
                                        "normal to the surface (s^T M^-1 s = 0)"));
      for (unsigned j = 0; j < r; ++j)
        dw[j] = (-(1 + imp.restitution) * sw / den * Ms[j]).normal().expand();
      for (unsigned j = 0; j < r; ++j) reset.push_back((w[j] + dw[j]).expand());
      reset.push_back(q);
    } else {
      reset = g.reset_kind == ResetDecl::Kind::Explicit ? g.reset : b.state_symbols;
      if (!is_identically_zero(reset[r] - q, {}))
        throw hypothesis_error(src, g.reset_loc,
                               LieError("reset", "the reset must keep the reduced coordinate"));
      for (unsigned j = 0; j < r; ++j) dw[j] = (reset[j] - w[j]).expand();
      // I B Δw ∈ Ann(𝔨) + span(a): it annihilates 𝔨 ∩ B(ℝ^r) = {B u : sᵀu = 0}.
      bool s_zero = true;
      for (const auto& e : s) s_zero = s_zero && is_identically_zero(e, {});
      if (!s_zero)
        for (const auto& u : kernel_of_form(s)) {
          ex pair = 0;
          for (unsigned i = 0; i < r; ++i)
            for (unsigned j = 0; j < r; ++j) pair += dw[i] * M(i, j) * u[j];
          if (!is_identically_zero(pair, {}))
            throw hypothesis_error(
                src, g.reset_loc,
                LieError("reset",
                         "the momentum jump I B Delta w must annihilate the allowed "
                         "directions of K (the theorem with constraints)"));
        }
    }
    red.momentum_jumps.push_back(dw);
    g.reset_kind = ResetDecl::Kind::Explicit;
    g.reset = reset;
  }
  red.constrained = true;
  red.group = lm.group_name;
  red.coordinates = lm.coordinate_names;
  red.basis = alg.names();
  red.algebra_dim = n;
  red.momenta.assign(b.state.begin(), b.state.begin() + r);
  red.q = b.state[r];
  red.bracket.assign(n, std::vector<std::string>(n));
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) {
      Components ei(n, ex(0)), ej(n, ex(0));
      ei[i] = 1;
      ej[j] = 1;
      red.bracket[i][j] = alg.format(alg.bracket(ei, ej));
      for (unsigned k = 0; k < n; ++k) red.structure_constants.push_back(alg.c(i, j, k));
    }
  red.hamiltonian = lm.h.expand();
  for (const auto& e : xi) red.dh.push_back(e.expand());
  red.coadjoint = alg.coadjoint(Components(xi.begin(), xi.end()));
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) red.coadjoint(i, j) = red.coadjoint(i, j).expand();
  for (const auto& cn : lm.coordinate_names) out.tex[cn] = tex_identifier(cn);
  if (!lm.group.has_coordinates()) out.tex[kPhiName] = "\\phi(g)";
  out.reduction = std::move(red);
  return out;
}

}  // namespace

Model reduce(const LieModel& lie, const SourceText& src, ReduceTarget target) {
  const bool twin = target == ReduceTarget::Unreduced;
  if (twin && !lie.group.has_coordinates())
    throw src.error(lie.group_loc,
                    "the unreduced twin needs the group's coordinates, but group '" +
                        lie.group_name +
                        "' is given by structure constants (give it as 'group NAME(c1, ..., "
                        "cn) = [[...]] at (...)' to compare with the unreduced system)");
  // Both targets run under the model's derivation limits, like derive: a
  // blow-up ends with a located error naming the limit, not a hang.
  LimitScope scope(lie.base.limits);
  scope.object(
      (twin ? "the unreduced twin of group '" : "the reduction of group '") + lie.group_name + "'",
      lie.group_loc);
  try {
    if (twin) return unreduced(lie, src);
    return lie.xi_of_w.empty() ? reduced(lie, src) : reduced_constrained(lie, src);
  } catch (...) {
    scope.rethrow_at_object(src);
  }
}

}  // namespace hybgen::gen
