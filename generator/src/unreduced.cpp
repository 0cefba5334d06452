// The reduce stage's shared internals and its unreduced target: the
// 2n-dimensional impact system on T*G in the group coordinates (see reduce.hpp).

#include <cctype>
#include <set>
#include <sstream>

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

std::string tex_of(const std::string& nm) {
  static const std::set<std::string> greek = {"alpha", "beta",  "gamma", "delta", "epsilon", "zeta",
                                              "eta",   "theta", "iota",  "kappa", "lambda",  "mu",
                                              "nu",    "xi",    "rho",   "sigma", "tau",     "phi",
                                              "chi",   "psi",   "omega"};
  const auto us = nm.find('_');
  if (us != std::string::npos && us + 1 < nm.size())
    return tex_of(nm.substr(0, us)) + "_{" + nm.substr(us + 1) + "}";
  std::size_t k = nm.size();
  while (k > 0 && std::isdigit(static_cast<unsigned char>(nm[k - 1]))) --k;
  const std::string base = nm.substr(0, k), sub = nm.substr(k);
  std::string t = greek.count(base) ? "\\" + base
                  : base.size() > 1 ? "\\mathrm{" + base + "}"
                                    : base;
  if (!sub.empty()) t += "_{" + sub + "}";
  return t;
}

Model unreduced(const LieModel& lm, const SourceText& src) {
  if (!lm.xi_of_w.empty())
    throw src.error(lm.group_loc,
                    "the unreduced twin of a constrained (nonholonomic) model is not "
                    "supported");
  const LieAlgebra& alg = lm.group.algebra();
  const unsigned n = alg.dim();
  const Model& b = lm.base;
  const std::vector<ex>& c = lm.group.coords();
  const matrix& L = lm.group.left_trivialization();
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
  std::vector<ex> p;
  for (unsigned i = 0; i < n; ++i) {
    std::string name = "p_" + lm.coordinate_names[i];
    while (taken.count(name)) name += "_";
    taken.insert(name);
    p.push_back(GiNaC::realsymbol(name));
    out.state.push_back(name);
    out.state_symbols.push_back(p.back());
  }
  for (const auto& s : out.state) out.tex[s] = tex_of(s);
  for (const auto& pr : b.params) out.tex[pr.name] = b.tex.at(pr.name);
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
  mode.hamiltonian = lm.h.subs(zeta_of, GiNaC::subs_options::no_pattern).expand();
  for (unsigned i = 0; i < n; ++i) {
    mode.coordinates.push_back(static_cast<int>(i));
    mode.momenta.push_back(static_cast<int>(n + i));
  }
  out.modes.push_back(mode);
  const ex q = b.state_symbols[n];
  for (std::size_t k = 0; k < b.guards.size(); ++k) {
    GuardSpec g = b.guards[k];
    const LieImpact& imp = lm.impacts[k];
    require_level_set(lm, g, src);
    g.surface = g.surface.subs(GiNaC::exmap{{q, lm.q_expr}}, GiNaC::subs_options::no_pattern);
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
  out.sim.present = false;
  out.sim.initial.assign(1, ex(0));
  return out;
}

}  // namespace hybgen::gen::reduce_detail
