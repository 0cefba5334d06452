// Stage 2 for Lie-group models: AST -> LieModel (check_lie.hpp; the theorem: reduce.hpp).
//
// The parts a Lie-group model shares with general models (parameters, guards
// in the reduced state, the simulation block) are checked by `check` itself on
// a general AST with the state (ζ_1..ζ_n, q) and one placeholder mode, so both
// kinds obey the same rules and messages. What is specific (the group, h, q) is
// converted here with check's Converter (check_internal.hpp).

#include "hybgen/gen/check_lie.hpp"

#include <algorithm>
#include <cctype>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <utility>

#include "check_internal.hpp"
#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/reduce.hpp"

namespace hybgen::gen {

namespace {

using GiNaC::ex;

std::string loc_str(SourceLoc loc) {
  return std::to_string(loc.line) + ":" + std::to_string(loc.col);
}

/// A ModelError at `loc` for a failed hypothesis of the reduction.
ModelError hypothesis_error(const SourceText& src, SourceLoc loc, const LieError& e) {
  return src.error(loc, "hypothesis '" + e.hypothesis() + "' fails: " + e.what());
}

/// The scope name of `det(G)`: not an identifier, so no user name can clash.
std::string det_name(const std::string& group) {
  return "det(" + group + ")";
}

/// A copy of `e` in which every call `det(G)` of the group G is the symbol
/// named det_name(G) (bound to det g(c) in the scope).
ExprPtr rewrite_det(const ExprPtr& e, const std::string& group) {
  if (!e) return e;
  if (e->kind == Expr::Kind::Call && e->text == "det" && e->args.size() == 1 &&
      e->args[0]->kind == Expr::Kind::Symbol && e->args[0]->text == group) {
    auto s = std::make_shared<Expr>();
    s->kind = Expr::Kind::Symbol;
    s->loc = e->loc;
    s->text = det_name(group);
    return s;
  }
  if (e->args.empty()) return e;
  auto c = std::make_shared<Expr>(*e);
  for (auto& a : c->args) a = rewrite_det(a, group);
  return c;
}

/// The number literal `0` at `loc`.
ExprPtr zero_at(SourceLoc loc) {
  auto z = std::make_shared<Expr>();
  z->kind = Expr::Kind::Number;
  z->loc = loc;
  z->text = "0";
  return z;
}

/// The Lie algebra of `group NAME = algebra(E1, ..., En) { [Ei, Ej] = EXPR, ... }`:
/// each EXPR must be a linear combination Σ_k C_ij^k E_k of the basis names with
/// coefficients in the parameters; unlisted brackets are 0, [E_j, E_i] = −[E_i, E_j]
/// is implied, and a bracket given twice (in either order) is an error.
/// from_structure_constants then checks antisymmetry and Jacobi (LieError).
LieAlgebra algebra_of_brackets(const GroupDecl& gd, const std::map<std::string, ex>& params,
                               const std::map<std::string, ex>& names, const SourceText& src) {
  const std::size_t n = gd.basis.size();
  // The Jacobi check is O(n⁵): the same bound as gl(N ≤ 6), dimension 36.
  constexpr std::size_t kMaxBasis = 36;
  if (n > kMaxBasis)
    throw src.error(gd.basis[kMaxBasis].loc,
                    "a Lie algebra given by structure constants is limited to " +
                        std::to_string(kMaxBasis) + " basis elements (the dimension of gl(6))");
  std::map<std::string, ex> scope = params;
  std::map<std::string, std::size_t> index;
  std::vector<ex> e;
  std::vector<std::string> basis;
  for (const auto& b : gd.basis) {
    if (names.count(b.name) || b.name == "pi" || b.name == gd.name.name)
      throw src.error(b.loc, "the basis element '" + b.name +
                                 "' clashes with a parameter, a momentum, q or the group's name");
    if (!index.emplace(b.name, e.size()).second)
      throw src.error(b.loc, "basis element '" + b.name + "' is given twice");
    e.push_back(GiNaC::realsymbol(b.name));
    scope[b.name] = e.back();
    basis.push_back(b.name);
  }
  std::vector<std::vector<std::vector<ex>>> c(
      n, std::vector<std::vector<ex>>(n, std::vector<ex>(n, ex(0))));
  std::map<std::pair<std::size_t, std::size_t>, SourceLoc> given;
  for (const auto& br : gd.brackets) {
    auto idx = [&](const Name& nm) {
      const auto it = index.find(nm.name);
      if (it == index.end())
        throw src.error(nm.loc,
                        "'" + nm.name + "' is not a basis element of group '" + gd.name.name + "'");
      return it->second;
    };
    const std::size_t i = idx(br.left), j = idx(br.right);
    const std::string what = "[" + br.left.name + ", " + br.right.name + "]";
    const std::pair<std::size_t, std::size_t> key{std::min(i, j), std::max(i, j)};
    if (const auto it = given.find(key); it != given.end())
      throw src.error(
          br.loc, "the bracket " + what + " is given twice (first at " + loc_str(it->second) + ")");
    given.emplace(key, br.loc);
    const ex v = detail::convert_expression(src, scope, "the bracket " + what, br.value).expand();
    ex rest = v;
    for (std::size_t k = 0; k < n; ++k) {
      const ex coeff = v.diff(GiNaC::ex_to<GiNaC::symbol>(e[k]));
      bool constant = true;
      for (const auto& ek : e) constant = constant && !coeff.has(ek);
      if (!constant)
        throw src.error(br.value->loc, "the bracket " + what +
                                           " must be a linear combination of the basis "
                                           "elements with constant coefficients");
      c[i][j][k] = coeff;
      c[j][i][k] = -coeff;
      rest -= coeff * e[k];
    }
    if (!rest.expand().is_zero())
      throw src.error(br.value->loc, "the bracket " + what +
                                         " must be a linear combination of the basis elements "
                                         "(it has a constant term)");
    if (i == j) {
      bool zero_bracket = true;
      for (std::size_t k = 0; k < n; ++k) zero_bracket = zero_bracket && c[i][i][k].is_zero();
      if (!zero_bracket)
        throw src.error(br.loc, "the bracket " + what + " of an element with itself must be 0");
    }
  }
  return LieAlgebra::from_structure_constants(c, basis);
}

SourceLoc first_lie_loc(const LieDecl& lie) {
  for (SourceLoc l : {lie.group.loc, lie.momenta_loc, lie.hamiltonian_loc, lie.inertia_loc,
                      lie.metric_loc, lie.reduced_loc})
    if (l.line != 0) return l;
  return {1, 1};
}

}  // namespace

bool is_lie_model(const ModelAst& ast) {
  return ast.lie.has_value();
}

/// The combinations of Lie statements a model may have: no `state` or modes, a group, its
/// momenta or (constrained) velocities, one way of giving the kinetic energy, and a reduced
/// coordinate. Throws a located error naming what is missing or given twice.
void check_lie_statements(const ModelAst& ast, const LieDecl& lie, const SourceText& src) {
  const SourceLoc at = first_lie_loc(lie);
  const bool constrained = !lie.velocities.empty() || !lie.constraints.empty();
  if (!ast.states.empty())
    throw src.error(ast.states.front().loc,
                    "a Lie-group model has no 'state' statement: its state is the momenta "
                    "followed by the reduced coordinate (statement 'group' at " +
                        loc_str(at) + ")");
  if (!ast.modes.empty())
    throw src.error(ast.modes.front().name.loc,
                    "a Lie-group model has no modes: its one vector field is derived from the "
                    "group and the Hamiltonian");
  if (lie.group.loc.line == 0)
    throw src.error(at,
                    "a Lie-group model needs a group (write 'group A = gl(2)' or "
                    "'group g(x, y) = [[...]] at (0, 0)')");
  if (lie.momenta.empty() && lie.velocities.empty())
    throw src.error(lie.group.loc,
                    "a Lie-group model needs its momenta (write 'momenta zeta1, ..., zetaN', "
                    "one per coordinate of the group)");
  if (constrained && !lie.momenta.empty())
    throw src.error(lie.momenta_loc,
                    "a constrained model names its body velocities ('velocities'), not momenta");
  if (constrained && lie.velocities.empty())
    throw src.error(lie.constraints.front().loc,
                    "constraints need the body velocities: write 'velocities v1, ..., vN'");
  if (constrained && !lie.inertia && !lie.metric)
    throw src.error(lie.velocities_loc,
                    "a constrained model gives its kinetic energy by 'inertia [[...]]' (the "
                    "metric at the identity) or 'metric [[...]]' (in the coordinates)");
  if (!lie.hamiltonian && !lie.inertia && !lie.metric)
    throw src.error(lie.group.loc,
                    "a Lie-group model needs a Hamiltonian h(zeta) ('hamiltonian EXPR'), "
                    "an inertia at the identity ('inertia [[...]]') or a metric in the "
                    "coordinates ('metric [[...]]')");
  if (lie.hamiltonian && lie.inertia)
    throw src.error(lie.inertia_loc,
                    "give either 'hamiltonian' or 'inertia', not both (the "
                    "Hamiltonian is at " +
                        loc_str(lie.hamiltonian_loc) + ")");
  if (lie.metric && (lie.hamiltonian || lie.inertia))
    throw src.error(lie.metric_loc,
                    "give one of 'hamiltonian', 'inertia' and 'metric', not two (the " +
                        std::string(lie.hamiltonian ? "Hamiltonian" : "inertia") + " is at " +
                        loc_str(lie.hamiltonian ? lie.hamiltonian_loc : lie.inertia_loc) + ")");
  if (!lie.reduced)
    throw src.error(lie.group.loc,
                    "a Lie-group model needs its reduced coordinate: write 'reduced q = "
                    "PHI - c' with PHI a homomorphism such as det(A) or an angle");
}

/// The general part of a Lie-group model, checked by `check` on the reduced state: the
/// momenta (or the velocities no constraint eliminates) and q, one mode `flow` whose vector
/// field reduce() derives, and the guards with their mechanical resets left to reduce()
/// (recorded in `impacts`).
Model check_general_part(const ModelAst& ast, const LieDecl& lie, const SourceText& src,
                         bool constrained, std::vector<LieImpact>& impacts) {
  // The general part, checked by `check` on the reduced state (ζ, q).
  ModelAst general = ast;
  general.lie.reset();
  // Constrained: the state is the velocities not eliminated by a constraint.
  std::set<std::string> eliminated;
  for (const auto& c : lie.constraints) {
    const bool is_velocity = c.lhs->kind == Expr::Kind::Symbol &&
                             std::any_of(lie.velocities.begin(), lie.velocities.end(),
                                         [&](const Name& v) { return v.name == c.lhs->text; });
    if (!is_velocity)
      throw src.error(c.loc,
                      "a constraint is written 'NAME = EXPR' with NAME one of the velocities");
    if (!eliminated.insert(c.lhs->text).second)
      throw src.error(c.loc, "velocity '" + c.lhs->text + "' is constrained twice");
  }
  if (constrained) {
    for (const auto& v : lie.velocities)
      if (!eliminated.count(v.name)) general.states.push_back(v);
  } else {
    general.states = lie.momenta;
  }
  general.states.push_back(*lie.reduced);
  ModeDecl flow;
  flow.name = {"flow", lie.group.loc};
  for (const auto& s : general.states) flow.flows.push_back({s, zero_at(lie.group.loc)});
  general.modes = {flow};
  for (auto& g : general.guards) {
    if (g.from) throw src.error(g.from->loc, "a Lie-group model has one mode: omit 'from'");
    if (g.to) throw src.error(g.to->loc, "a Lie-group model has one mode: omit 'to'");
    if (g.has_reset && g.reset.kind == ResetDecl::Kind::Absorb)
      throw src.error(g.reset.loc,
                      "'reset absorb' is for general hybrid models; an impact of a Lie-group "
                      "model resets the momentum (elastic, restitution e or explicit)");
    LieImpact imp;
    imp.kind = g.reset.kind;
    if (g.has_reset && (g.reset.kind == ResetDecl::Kind::Elastic ||
                        g.reset.kind == ResetDecl::Kind::Restitution)) {
      g.reset.kind = ResetDecl::Kind::Identity;  // derived by reduce (the corollary)
    }
    impacts.push_back(imp);
  }
  return check(general, src);
}

/// The group of `lie` (gl(N), a matrix parametrisation g(c) at an identity point, or
/// structure constants), its coordinates' names appended to `coord_names` after checking
/// they clash with no parameter, momentum, q or the group's name. Throws a located error.
LieGroup make_group(const LieDecl& lie, const std::map<std::string, ex>& params,
                    const std::map<std::string, ex>& names, const SourceText& src,
                    std::vector<std::string>& coord_names) {
  const GroupDecl& gd = lie.group;
  const std::string gname = gd.name.name;
  auto declare_coordinate = [&](const std::string& name, SourceLoc loc) {
    if (names.count(name) || name == "pi" || name == gname)
      throw src.error(loc, "the coordinate '" + name +
                               "' of the group clashes with a parameter, a momentum, q or the "
                               "group's name");
    coord_names.push_back(name);
  };
  std::optional<LieGroup> group;
  try {
    if (gd.shortcut == "algebra") {
      group.emplace(algebra_of_brackets(gd, params, names, src));
    } else if (!gd.shortcut.empty()) {
      // gl(5)'s q equation differentiates and divides out a symbolic 5×5 determinant
      // (120 terms): minutes in GiNaC's normal(), not interruptible (fuzz finding F4).
      if (gd.shortcut_n > 4)
        throw src.error(gd.loc, "gl(N) is limited to N <= 4 (the reduction of gl(" +
                                    std::to_string(gd.shortcut_n) +
                                    ") would take minutes of symbolic work)");
      std::string prefix(1, static_cast<char>(std::tolower(static_cast<unsigned char>(gname[0]))));
      group.emplace(MatrixGroup::gl(static_cast<unsigned>(gd.shortcut_n), prefix));
      for (const auto& c : group->coords()) {
        std::ostringstream os;
        os << c;
        declare_coordinate(os.str(), gd.loc);
      }
    } else {
      std::map<std::string, ex> cscope = params;
      std::vector<ex> coords;
      for (const auto& c : gd.coordinates) {
        declare_coordinate(c.name, c.loc);
        const ex sym = GiNaC::realsymbol(c.name);
        cscope[c.name] = sym;
        coords.push_back(sym);
      }
      std::set<std::string> seen;
      for (const auto& c : gd.coordinates)
        if (!seen.insert(c.name).second)
          throw src.error(c.loc, "coordinate '" + c.name + "' is given twice");
      const std::size_t N = gd.matrix.rows.size();
      GiNaC::matrix g(static_cast<unsigned>(N), static_cast<unsigned>(N));
      for (std::size_t r = 0; r < N; ++r) {
        if (gd.matrix.rows[r].size() != N)
          throw src.error(gd.matrix.rows[r].front()->loc,
                          "the matrix of group '" + gname + "' must be square: row " +
                              std::to_string(r + 1) + " has " +
                              std::to_string(gd.matrix.rows[r].size()) + " entries, expected " +
                              std::to_string(N));
        for (std::size_t c = 0; c < N; ++c)
          g(static_cast<unsigned>(r), static_cast<unsigned>(c)) = detail::convert_expression(
              src, cscope, "the matrix of group '" + gname + "'", gd.matrix.rows[r][c]);
      }
      if (gd.identity.size() != coords.size())
        throw src.error(gd.identity_loc, "the identity point has " +
                                             std::to_string(gd.identity.size()) +
                                             " values, the group has " +
                                             std::to_string(coords.size()) + " coordinates");
      std::vector<ex> c0;
      for (const auto& v : gd.identity)
        c0.push_back(detail::convert_expression(src, params, "the identity point", v));
      std::vector<std::string> basis;
      for (const auto& c : gd.coordinates) basis.push_back("E_" + c.name);
      group.emplace(MatrixGroup(g, coords, c0, basis));
    }
  } catch (const LieError& e) {
    throw hypothesis_error(src, gd.loc, e);
  }
  return std::move(*group);
}

LieModel check_lie(const ModelAst& ast, const SourceText& src) {
  if (!ast.lie) throw InternalError("check_lie called on a general model");
  const LieDecl& lie = *ast.lie;
  check_lie_statements(ast, lie, src);
  const bool constrained = !lie.velocities.empty() || !lie.constraints.empty();
  std::vector<LieImpact> impacts;
  Model base = check_general_part(ast, lie, src, constrained, impacts);

  // Scopes: parameters, momenta, q.
  std::map<std::string, ex> params, names;
  for (const auto& p : base.params) params[p.name] = p.symbol;
  names = params;
  for (std::size_t i = 0; i < base.state.size(); ++i) names[base.state[i]] = base.state_symbols[i];
  const std::size_t n = constrained ? lie.velocities.size() : lie.momenta.size();
  const std::size_t n_red = base.state.size() - 1;  // momenta, or unconstrained velocities
  const std::vector<ex> zeta(base.state_symbols.begin(),
                             base.state_symbols.begin() + static_cast<long>(n_red));
  const ex q = base.state_symbols[n_red];

  // Restitution coefficients (parameters only).
  for (std::size_t k = 0; k < ast.guards.size(); ++k) {
    const GuardDecl& g = ast.guards[k];
    if (g.reset.kind == ResetDecl::Kind::Restitution)
      impacts[k].restitution = detail::convert_expression(
          src, params, "the restitution coefficient of guard '" + g.name.name + "'",
          g.reset.coefficient);
  }

  // The group.
  const GroupDecl& gd = lie.group;
  const std::string gname = gd.name.name;
  std::vector<std::string> coord_names;
  std::optional<LieGroup> group;
  group.emplace(make_group(lie, params, names, src, coord_names));
  const unsigned dim = group->algebra().dim();
  if (n != dim)
    throw src.error(constrained ? lie.velocities_loc : lie.momenta_loc,
                    "group '" + gname + "' has dimension " + std::to_string(dim) +
                        ", so it needs " + std::to_string(dim) +
                        (constrained ? " velocities, not " : " momenta, not ") + std::to_string(n));

  // Scope with coordinates and det(G).
  std::map<std::string, ex> all = names;
  for (std::size_t i = 0; i < coord_names.size(); ++i) all[coord_names[i]] = group->coords()[i];
  if (group->has_coordinates())
    all[det_name(gname)] = GiNaC::determinant(group->matrix_group().g());

  // h(ζ): the Hamiltonian restricted to 𝔤* (left-invariant by construction);
  // a coordinate in it means H was not given at the identity.
  ex h;
  SourceLoc hloc;
  GiNaC::matrix inertia;
  if (lie.hamiltonian) {
    hloc = lie.hamiltonian_loc;
    h = detail::convert_expression(src, all, "the Hamiltonian h(zeta)",
                                   rewrite_det(lie.hamiltonian, gname));
  } else {
    // An n×n matrix literal with the names of `scope` visible.
    auto square = [&](const MatrixLiteral& lit, const std::map<std::string, ex>& scope,
                      const std::string& what, const std::string& rows_are) {
      const auto& rows = lit.rows;
      if (rows.size() != n)
        throw src.error(lit.loc, "the " + what + " must be " + std::to_string(n) + "x" +
                                     std::to_string(n) + " (one row per " + rows_are + ")");
      GiNaC::matrix m(static_cast<unsigned>(n), static_cast<unsigned>(n));
      for (std::size_t row = 0; row < n; ++row) {
        if (rows[row].size() != n)
          throw src.error(rows[row].front()->loc, "row " + std::to_string(row + 1) + " of the " +
                                                      what + " has " +
                                                      std::to_string(rows[row].size()) +
                                                      " entries, expected " + std::to_string(n));
        for (std::size_t c = 0; c < n; ++c)
          m(static_cast<unsigned>(row), static_cast<unsigned>(c)) =
              detail::convert_expression(src, scope, "the " + what, rows[row][c]);
      }
      return m;
    };
    if (lie.inertia) {
      hloc = lie.inertia_loc;
      inertia = square(*lie.inertia, params, "inertia", "momentum");
    } else {
      // A metric M(c) in the coordinates: left-invariant iff I = Lᵀ M L is
      // constant; then it is the inertia I(c0).
      hloc = lie.metric_loc;
      if (!group->has_coordinates())
        throw src.error(lie.metric_loc,
                        "a metric in coordinates needs a group with coordinates; group '" + gname +
                            "' is given by structure constants (give 'inertia [[...]]', the "
                            "metric at the identity)");
      std::map<std::string, ex> cscope = params;
      for (std::size_t i = 0; i < coord_names.size(); ++i)
        cscope[coord_names[i]] = group->coords()[i];
      const GiNaC::matrix metric = square(*lie.metric, cscope, "metric", "coordinate");
      for (unsigned i = 0; i < n; ++i)
        for (unsigned j = i + 1; j < n; ++j)
          if (!is_identically_zero((metric(i, j) - metric(j, i)).expand(), {}))
            throw src.error(lie.metric->rows[i][j]->loc,
                            "the metric must be symmetric: entry (" + std::to_string(i + 1) + ", " +
                                std::to_string(j + 1) + ") differs from entry (" +
                                std::to_string(j + 1) + ", " + std::to_string(i + 1) + ")");
      try {
        inertia = left_invariant_inertia(group->matrix_group(), metric);
      } catch (const LieError& e) {
        throw hypothesis_error(src, hloc, e);
      }
    }
    if (!constrained) {
      try {
        h = inertia_hamiltonian(inertia, zeta);
      } catch (const LieError& e) {
        throw hypothesis_error(src, hloc, e);
      }
    }
  }
  // Constrained: ξ(w) from the constraints (linear in w), h = ½ ξᵀ I ξ as a
  // function of w (the kinetic energy on the constraint distribution).
  std::vector<ex> xi_of_w;
  if (constrained) {
    std::size_t k = 0;
    for (const auto& v : lie.velocities) {
      const auto c = std::find_if(lie.constraints.begin(), lie.constraints.end(),
                                  [&](const Relation& rel) { return rel.lhs->text == v.name; });
      if (c == lie.constraints.end()) {
        xi_of_w.push_back(zeta[k++]);
        continue;
      }
      const ex rhs = detail::convert_expression(src, names, "the constraint on " + v.name, c->rhs);
      bool linear = !rhs.has(q);
      for (const auto& w : zeta)
        for (const auto& w2 : zeta)
          linear = linear && rhs.diff(GiNaC::ex_to<GiNaC::symbol>(w))
                                 .diff(GiNaC::ex_to<GiNaC::symbol>(w2))
                                 .expand()
                                 .is_zero();
      ex rest = rhs;
      try {
        for (const auto& w : zeta) rest = rest.subs(w == 0);
      } catch (const std::exception&) {
        linear = false;  // a pole at zero velocity (GiNaC throws from inside subs)
      }
      if (!linear || !rest.expand().is_zero())
        throw src.error(c->rhs->loc,
                        "a constraint must be linear in the other velocities "
                        "(a left-invariant linear velocity constraint)");
      xi_of_w.push_back(rhs);
    }
    ex quad = 0;
    for (unsigned i = 0; i < n; ++i)
      for (unsigned j = 0; j < n; ++j) quad += xi_of_w[i] * inertia(i, j) * xi_of_w[j];
    h = (quad / 2).expand();
  }
  for (std::size_t i = 0; i < coord_names.size(); ++i)
    if (h.has(group->coords()[i]))
      throw src.error(hloc,
                      "hypothesis 'left_invariant' fails: h must be the Hamiltonian at the "
                      "identity, a function of the momenta only, but it depends on the "
                      "coordinate " +
                          coord_names[i] + " (H(g, p) = h((l_g)^* p) is then not left-invariant)");
  if (h.has(q))
    throw src.error(hloc, "the Hamiltonian h(zeta) cannot depend on the reduced coordinate " +
                              lie.reduced->name);

  if (!group->has_coordinates()) {
    // q = φ(g) or φ(g) − 1 with φ given by dφ_e: `additive(...)`, `multiplicative(...)`.
    const ExprPtr& r = lie.reduced_expr;
    const bool form =
        r->kind == Expr::Kind::Call && (r->text == "additive" || r->text == "multiplicative");
    if (!form)
      throw src.error(r->loc,
                      "group '" + gname +
                          "' has no coordinates (it is given by structure constants): write "
                          "'reduced " +
                          lie.reduced->name + " = additive(l1, ..., l" + std::to_string(n) +
                          ")' (phi: G -> R or S^1, q = phi(g)) or 'multiplicative(...)' (phi: "
                          "G -> R*, q = phi(g) - 1), the components of dphi_e in the dual basis");
    if (r->args.size() != n)
      throw src.error(r->loc, "'" + r->text + "' needs the " + std::to_string(n) +
                                  " components of dphi_e (one per basis element), not " +
                                  std::to_string(r->args.size()));
    Components dphi;
    for (const auto& a : r->args)
      dphi.push_back(detail::convert_expression(src, params, "a component of dphi_e", a));
    const HomomorphismKind kind =
        r->text == "additive" ? HomomorphismKind::Additive : HomomorphismKind::Multiplicative;
    return LieModel{
        std::move(base),    gname,   std::move(*group), coord_names, h,    ex(0),
        std::move(impacts), xi_of_w, inertia,           gd.loc,      hloc, lie.reduced_loc,
        std::move(dphi),    kind};
  }

  // q = φ(g) − c in the coordinates.
  const ex q_expr = detail::convert_expression(src, all, "the reduced coordinate",
                                               rewrite_det(lie.reduced_expr, gname));
  bool has_coordinate = false;
  for (const auto& c : group->coords()) has_coordinate = has_coordinate || q_expr.has(c);
  if (!has_coordinate)
    throw src.error(lie.reduced_expr->loc,
                    "the reduced coordinate must be a function on the group (of its "
                    "coordinates), e.g. det(" +
                        gname + ") - 1");
  for (const auto& z : names)
    if (z.second != ex(0) && !params.count(z.first) && q_expr.has(z.second))
      throw src.error(lie.reduced_expr->loc,
                      "the reduced coordinate is a function on the group only; it cannot "
                      "depend on '" +
                          z.first + "'");

  LieModel lm{std::move(base),
              gname,
              std::move(*group),
              coord_names,
              h,
              q_expr,
              std::move(impacts),
              xi_of_w,
              inertia,
              gd.loc,
              hloc,
              lie.reduced_loc,
              {},
              HomomorphismKind::Additive};
  return lm;
}

}  // namespace hybgen::gen
