// Stage 3 (derive): Model -> HybridSystem IR.
//
// Every derived formula is checked by an independent route:
//  - flows, divergences, resets against formulas derived by hand in the
//    comments (exact symbolic comparison);
//  - hybrid Jacobians against docs/design.md's basis formula
//        J = det[DΔ·t1 … DΔ·t(N−1) | X⁺(Δz)] / det[t1 … t(N−1) | X⁻(z)],
//    evaluated numerically with a tangent basis built from a finite-difference
//    gradient of s and with DΔ by central finite differences (so neither the
//    adjugate formula of derive.cpp nor its symbolic derivatives are reused);
//  - the paper's printed formulas, where they are right; where the paper is
//    wrong the test asserts the correct value and says so.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/parse.hpp"

namespace hybgen::gen {
namespace {

using GiNaC::ex;

/// A derived model kept alive together with its source.
struct Derived {
  SourceText src;
  Model model;
  HybridSystem sys;
  explicit Derived(const std::string& text, const std::string& path = "t.model") : src(path, text) {
    model = check(parse(src), src);
    sys = derive(model, src);
    sys.model = &model;
  }
  ex sym(const std::string& name) const {
    for (std::size_t i = 0; i < model.state.size(); ++i)
      if (model.state[i] == name) return model.state_symbols[i];
    for (const auto& p : model.params)
      if (p.name == name) return p.symbol;
    throw std::runtime_error("no symbol " + name);
  }
  std::vector<ex> symbols() const {
    std::vector<ex> s = model.state_symbols;
    for (const auto& p : model.params) s.push_back(p.symbol);
    return s;
  }
  bool same(const ex& a, const ex& b) const { return is_identically_zero(a - b, symbols()); }
  /// Evaluate with parameters at their defaults and the state at x.
  double eval(const ex& e, const std::vector<double>& x) const {
    GiNaC::exmap at;
    for (const auto& p : model.params) at[p.symbol] = GiNaC::numeric(p.value_d);
    for (std::size_t i = 0; i < x.size(); ++i) at[model.state_symbols[i]] = GiNaC::numeric(x[i]);
    ex v = GiNaC::evalf(e.subs(at));
    return GiNaC::ex_to<GiNaC::numeric>(v).to_double();
  }
};

std::string read_model(const std::string& name) {
  std::ifstream in(std::string(HYBGEN_SOURCE_DIR) + "/models/" + name);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

double det(std::vector<std::vector<double>> a) {
  const std::size_t n = a.size();
  double d = 1;
  for (std::size_t c = 0; c < n; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < n; ++r)
      if (std::fabs(a[r][c]) > std::fabs(a[piv][c])) piv = r;
    if (a[piv][c] == 0) return 0;
    if (piv != c) std::swap(a[piv], a[c]), d = -d;
    d *= a[c][c];
    for (std::size_t r = c + 1; r < n; ++r) {
      double f = a[r][c] / a[c][c];
      for (std::size_t k = c; k < n; ++k) a[r][k] -= f * a[c][k];
    }
  }
  return d;
}

/// docs/design.md's basis formula for the hybrid Jacobian at z ∈ S, numerically.
double basis_formula_J(const Derived& d, std::size_t gi, const std::vector<double>& z) {
  const IrGuard& g = d.sys.guards[gi];
  const std::size_t n = z.size();
  const double h = 1e-6;
  auto shifted = [&](std::size_t k, double s) {
    auto y = z;
    y[k] += s;
    return y;
  };
  // Gradient of s by central differences.
  std::vector<double> grad(n);
  for (std::size_t k = 0; k < n; ++k)
    grad[k] = (d.eval(g.surface, shifted(k, h)) - d.eval(g.surface, shifted(k, -h))) / (2 * h);
  // Tangent basis: Gram–Schmidt of e_1..e_N against ∇s, keep N−1 vectors.
  std::vector<std::vector<double>> basis{grad};
  std::vector<std::vector<double>> T;
  for (std::size_t k = 0; k < n && T.size() + 1 < n; ++k) {
    std::vector<double> v(n, 0.0);
    v[k] = 1;
    for (const auto& b : basis) {
      double bb = 0, vb = 0;
      for (std::size_t i = 0; i < n; ++i) bb += b[i] * b[i], vb += v[i] * b[i];
      for (std::size_t i = 0; i < n; ++i) v[i] -= vb / bb * b[i];
    }
    double norm = 0;
    for (double vi : v) norm += vi * vi;
    if (norm < 1e-12) continue;
    basis.push_back(v);
    T.push_back(v);
  }
  // DΔ by central differences of the reset.
  std::vector<std::vector<double>> D(n, std::vector<double>(n));
  for (std::size_t j = 0; j < n; ++j)
    for (std::size_t i = 0; i < n; ++i)
      D[i][j] = (d.eval(g.reset[i], shifted(j, h)) - d.eval(g.reset[i], shifted(j, -h))) / (2 * h);
  std::vector<double> dz(n);
  for (std::size_t i = 0; i < n; ++i) dz[i] = d.eval(g.reset[i], z);
  const IrMode& before = d.sys.modes[static_cast<std::size_t>(g.from)];
  const IrMode& after = d.sys.modes[static_cast<std::size_t>(g.to)];
  std::vector<std::vector<double>> num(n, std::vector<double>(n)), den(n, std::vector<double>(n));
  for (std::size_t c = 0; c + 1 < n; ++c)
    for (std::size_t i = 0; i < n; ++i) {
      double s = 0;
      for (std::size_t k = 0; k < n; ++k) s += D[i][k] * T[c][k];
      num[i][c] = s;
      den[i][c] = T[c][i];
    }
  for (std::size_t i = 0; i < n; ++i) {
    num[i][n - 1] = d.eval(after.flow[i], dz);
    den[i][n - 1] = d.eval(before.flow[i], z);
  }
  return det(num) / det(den);
}

// ---------------------------------------------------------------- bouncing ball
TEST(Derive, BouncingBall) {
  Derived d(read_model("bouncing_ball.model"), "models/bouncing_ball.model");
  ex x = d.sym("x"), p = d.sym("p"), m = d.sym("m"), g = d.sym("g"), e = d.sym("e");
  const IrMode& md = d.sys.modes.at(0);
  // Hamilton's equations of H = p²/(2m) + m g x: x' = p/m, p' = −m g (paper §4.1).
  EXPECT_TRUE(d.same(md.flow[0], p / m));
  EXPECT_TRUE(d.same(md.flow[1], -m * g));
  EXPECT_TRUE(md.divergence.is_zero());
  const IrGuard& gd = d.sys.guards.at(0);
  // Corner conditions with restitution: p⁺ = p − (1+e) (p/m)/(1/m) · 1 = −e p.
  // (The paper's Δ(0, p) = (0, −p) is the case e = 1.)
  EXPECT_TRUE(d.same(gd.reset[0], x));
  EXPECT_TRUE(d.same(gd.reset[1], -e * p));
  ASSERT_TRUE(gd.has_inverse);
  EXPECT_TRUE(d.same(gd.reset_inverse[1], -p / e));
  // J = e²: the paper's appendix theorem gives c⁴ with e = c² (docs/design.md).
  EXPECT_TRUE(d.same(gd.hybrid_jacobian_on_surface, e * e));
  for (double pv : {-0.3, -1.0, -1.7}) {
    std::vector<double> z{0.0, pv};
    EXPECT_NEAR(basis_formula_J(d, 0, z), d.eval(gd.hybrid_jacobian, z), 1e-7);
  }
  EXPECT_TRUE(d.sys.warnings.empty());
}

TEST(Derive, BouncingBallRestitutionJacobian) {
  // e = 0.8: J = 0.64 numerically by the basis formula too.
  std::string text = read_model("bouncing_ball.model");
  text.replace(text.find("parameter e = 1"), 15, "parameter e = 0.8");
  Derived d(text);
  EXPECT_NEAR(basis_formula_J(d, 0, {0.0, -0.9}), 0.64, 1e-7);
}

// ------------------------------------------ restitution in 2-D with a tilted wall
TEST(Derive, RestitutionTiltedWall) {
  // A particle of mass m in a plane with gravity, bouncing on the wall y = k x.
  // The normal component of the velocity becomes −e times itself, the
  // tangential one is kept, and (paper appendix, e = c²) J = e².
  Derived d(R"(parameter m = 2, g = 1, k = 0.5, e = 0.7
state x, y, px, py
mode fly { hamiltonian (px^2 + py^2)/(2*m) + m*g*y }
guard wall { when y - k*x = 0 decreasing; reset restitution e }
simulation { domain x in [-2, 2]; domain y in [-2, 2]; domain px in [-2, 2]; domain py in [-2, 2]; initial 1 }
)");
  const IrGuard& gd = d.sys.guards.at(0);
  ex px = d.sym("px"), py = d.sym("py"), k = d.sym("k"), e = d.sym("e");
  // n = ∇s = (−k, 1), t = (1, k): v·t preserved, v·n ↦ −e v·n (velocities = p/m).
  ex tp = gd.reset[2] + k * gd.reset[3], tm = px + k * py;
  ex np = -k * gd.reset[2] + gd.reset[3], nm = -k * px + py;
  EXPECT_TRUE(d.same(tp, tm));
  EXPECT_TRUE(d.same(np, -e * nm));
  EXPECT_TRUE(d.same(gd.reset[0], d.sym("x")));
  EXPECT_TRUE(d.same(gd.hybrid_jacobian_on_surface, e * e));
  std::vector<double> z{0.4, 0.2, 0.3, -1.1};  // on y = k x, moving into the wall
  EXPECT_NEAR(basis_formula_J(d, 0, z), 0.49, 1e-6);
}

// --------------------------------------------------------------------------- SIR
TEST(Derive, SirNormalised) {
  Derived d(read_model("sir.model"), "models/sir.model");
  ex s = d.sym("s"), i = d.sym("i"), beta = d.sym("beta"), gamma = d.sym("gamma"),
     delta = d.sym("delta"), mu = d.sym("mu"), f = d.sym("f"), alpha = d.sym("alpha");
  const IrMode& md = d.sys.modes.at(0);
  // With N' = −δI: s' = μ − μs − (β − δ)si, i' = βsi + δi² − (γ+μ+δ)i (paper §4.4, correct).
  // div = −μ − (β−δ)i + βs + 2δi − (γ+μ+δ); the paper's PDE (eq. SIR) has
  // −div = 2μ − β(s − i) + γ + δ − 3δi, which is right.
  EXPECT_TRUE(d.same(-md.divergence, 2 * mu - beta * (s - i) + gamma + delta - 3 * delta * i));
  const IrGuard& gd = d.sys.guards.at(0);
  EXPECT_TRUE(d.same(gd.reset[1], (1 - f) * i));
  EXPECT_TRUE(d.same(gd.reset_inverse[1], i / (1 - f)));
  // J = X_i(s, (1−f)α) / X_i(s, α). The paper's jump factor 1/J is printed as
  //   (−βαs + δα² − (g+μ+δ)α) / (−βαs(1−f) + δα²(1−f)² − (g+μ+δ)α(1−f)):
  // ERRATUM: the sign of the βαs terms is wrong (i' contains +βsi) and "g"
  // stands for γ. The correct factor is asserted here.
  ex correct_inv_J = (beta * alpha * s + delta * alpha * alpha - (gamma + mu + delta) * alpha) /
                     (beta * alpha * s * (1 - f) + delta * alpha * alpha * (1 - f) * (1 - f) -
                      (gamma + mu + delta) * alpha * (1 - f));
  EXPECT_TRUE(d.same(1 / gd.hybrid_jacobian_on_surface, correct_inv_J));
  ex paper_inv_J = (-beta * alpha * s + delta * alpha * alpha - (gamma + mu + delta) * alpha) /
                   (-beta * alpha * s * (1 - f) + delta * alpha * alpha * (1 - f) * (1 - f) -
                    (gamma + mu + delta) * alpha * (1 - f));
  EXPECT_FALSE(d.same(1 / gd.hybrid_jacobian_on_surface, paper_inv_J));
  for (double sv : {0.05, 0.1, 0.25}) {
    std::vector<double> z{sv, 0.7};
    EXPECT_NEAR(basis_formula_J(d, 0, z), d.eval(gd.hybrid_jacobian_on_surface, z), 1e-7);
  }
}

TEST(Derive, SirThreeDimensionalAsInThePaper) {
  // The paper's 3-D model treats N as a constant parameter; then its claims
  // hold: J = 1 − f and div = β(S − I)/N − 3μ − γ − δ (its PDE carries −div·u
  // moved to the left as −(β(I − S)/N + 3μ + δ + γ) u, the same thing).
  Derived d(R"(parameter beta = 0.1, gamma = 0.1, delta = 0.2, mu = 0.1, f = 0.3, alpha = 0.7, N = 1
state S, I, R
mode e {
  S' = mu*N - beta*S*I/N - mu*S
  I' = beta*S*I/N - gamma*I - mu*I - delta*I
  R' = gamma*I - mu*R
}
guard g { when I = alpha*N decreasing; reset (S, (1 - f)*I, R + f*I) }
)");
  ex S = d.sym("S"), I = d.sym("I"), N = d.sym("N"), beta = d.sym("beta"), mu = d.sym("mu"),
     gamma = d.sym("gamma"), delta = d.sym("delta"), f = d.sym("f");
  EXPECT_TRUE(d.same(d.sys.modes[0].divergence, beta * (S - I) / N - 3 * mu - gamma - delta));
  EXPECT_TRUE(d.same(d.sys.guards[0].hybrid_jacobian_on_surface, 1 - f));
}

TEST(Derive, SirThreeDimensionalShipped) {
  // The shipped model keeps N = S + I + R; J then differs from 1 − f. Checked
  // against the basis formula at points of the guard I = α(S + I + R).
  Derived d(read_model("sir_3d.model"), "models/sir_3d.model");
  const IrGuard& gd = d.sys.guards.at(0);
  for (auto [S, R] : {std::pair{0.1, 0.1}, std::pair{0.2, 0.05}}) {
    double I = 0.7 * (S + R) / 0.3;  // I = α(S + I + R)
    std::vector<double> z{S, I, R};
    EXPECT_NEAR(basis_formula_J(d, 0, z), d.eval(gd.hybrid_jacobian, z), 1e-6);
  }
}

// ----------------------------------------------------------------------- Filippov
TEST(Derive, Filippov) {
  Derived d(read_model("filippov.model"), "models/filippov.model");
  ex alpha = d.sym("alpha");
  // Both fields have divergence −2.
  EXPECT_TRUE(d.same(d.sys.modes[0].divergence, ex(-2)));
  EXPECT_TRUE(d.same(d.sys.modes[1].divergence, ex(-2)));
  // A → B happens on the x axis: J = X_B,y / X_A,y = (−x/α)/(−αx) = 1/α².
  // B → A happens on the y axis: J = X_A,x / X_B,x = (y/α)/(αy) = 1/α².
  // (The paper gives the example without computing J.)
  const double a = 2;
  for (double xv : {0.5, 1.5}) {
    std::vector<double> z{xv, 0.0};
    EXPECT_NEAR(d.eval(d.sys.guards[0].hybrid_jacobian, z), 1 / (a * a), 1e-12);
    EXPECT_NEAR(basis_formula_J(d, 0, z), 1 / (a * a), 1e-7);
  }
  for (double yv : {0.5, 1.5}) {
    std::vector<double> z{0.0, yv};
    EXPECT_NEAR(d.eval(d.sys.guards[1].hybrid_jacobian, z), 1 / (a * a), 1e-12);
    EXPECT_NEAR(basis_formula_J(d, 1, z), 1 / (a * a), 1e-7);
  }
  (void)alpha;
}

// ---------------------------------------------------------- Chaplygin, energy surface
TEST(Derive, ChaplyginEnergySurface) {
  Derived d(read_model("chaplygin_energy.model"), "models/chaplygin_energy.model");
  ex v = d.sym("v"), a = d.sym("a"), m = d.sym("m"), I = d.sym("I");
  // v' = a(C1 − C2 v²) ⇒ div = −2 a C2 v with C2 = m/(I + m a²). ERRATUM: the
  // paper's PDE writes "+ 2aC2 v u" on the left-hand side, i.e. div = +2aC2v;
  // the correct left-hand side carries −2aC2 v u (mass piles up at v* > 0,
  // as the paper's own figure shows).
  ex C2 = m / (I + m * a * a);
  EXPECT_TRUE(d.same(d.sys.modes[0].divergence, -2 * a * C2 * v));
  EXPECT_TRUE(d.same(d.sys.modes[1].divergence, -2 * a * C2 * v));
  // Switching branch at θ = ±θ0 with the identity reset: J = θ'⁺/θ'⁻ = −1
  // (orientation flips); |J| = 1 so u⁺ = u⁻, as the paper's jump condition says.
  EXPECT_TRUE(d.same(d.sys.guards[0].hybrid_jacobian_on_surface, ex(-1)));
  EXPECT_TRUE(d.same(d.sys.guards[1].hybrid_jacobian_on_surface, ex(-1)));
  EXPECT_NEAR(basis_formula_J(d, 0, {0.3, 1.0}), -1.0, 1e-7);
  EXPECT_NEAR(basis_formula_J(d, 1, {-0.6, -1.0}), -1.0, 1e-7);
}

// -------------------------------------------------------------------- failed checks
void expect_derive_error(const std::string& text, int line, int col, const std::string& fragment) {
  try {
    Derived d(text);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ModelError& e) {
    std::string what = e.what();
    std::string prefix =
        "t.model:" + std::to_string(line) + ":" + std::to_string(col) + ": error: ";
    EXPECT_EQ(what.rfind(prefix, 0), 0u) << what;
    EXPECT_NE(what.find(fragment), std::string::npos) << what;
  }
}

TEST(Derive, FailedChecks) {
  // The flow is tangent to the surface everywhere.
  expect_derive_error(
      "state x, y\nmode a { x' = 1; y' = 0 }\nguard g { when y = 0 decreasing; reset identity }\n",
      3, 16, "never crosses");
  // The target mode's flow is tangent to Δ(S): J ≡ 0.
  expect_derive_error(R"(state x, y
mode a { x' = -1; y' = 1 }
mode b { x' = 0; y' = 1 }
guard g { from a to b; when x = 0 decreasing; reset identity }
)",
                      4, 47, "identically zero");
  // A reset that is not injective on its guard: every (0, p) of S = {x = 0} goes to (0, 1)
  // (det(DΔᵀDΔ + ∇s∇sᵀ) = det diag(2, 0) = 0).
  expect_derive_error(
      "state x, p\nmode a { x' = p; p' = -1 }\nguard g { when x = 0 decreasing; reset (x, 0*p + 1) "
      "}\n",
      3, 34, "collapses its guard");
  // H.5: the identity reset of the ball lands on the guard with p < 0: beating.
  expect_derive_error(R"(state x, p
mode a { x' = p; p' = -1 }
guard g { when x = 0 decreasing; reset identity }
simulation { domain x in [0, 2]; domain p in [-2, 2]; initial 1 }
)",
                      3, 34, "H.5");
  // A Hamiltonian that is not natural (a term linear in p).
  expect_derive_error(
      "state x, p\nmode a { hamiltonian p^2/2 + x*p + x }\nguard g { when x = 0 decreasing; reset "
      "elastic }\n",
      3, 34, "natural Hamiltonian");
  // A surface that depends on the momentum, with a corner-condition reset.
  expect_derive_error(
      "state x, p\nmode a { hamiltonian p^2/2 + x }\nguard g { when x + p = 0 decreasing; reset "
      "elastic }\n",
      3, 16, "depends on the momenta");
}

TEST(Derive, WarnsWhenGuardNeverFires) {
  // SIR with an 'increasing' guard: i' < 0 on i = α for the paper's parameters.
  std::string text = read_model("sir.model");
  text.replace(text.find("when i = alpha decreasing"), 25, "when i = alpha increasing");
  Derived d(text);
  ASSERT_EQ(d.sys.warnings.size(), 1u);
  EXPECT_NE(d.sys.warnings[0].text.find("never fires"), std::string::npos);
  // Located at the direction word, with the way out.
  EXPECT_NE(d.sys.warnings[0].text.find("did you mean 'decreasing'?"), std::string::npos)
      << d.sys.warnings[0].text;
  const std::size_t at = text.find("when i = alpha increasing") + 15;  // the 'increasing'
  std::size_t line = 1, col = 1;
  for (std::size_t k = 0; k < at; ++k) {
    col = text[k] == '\n' ? 1 : col + 1;
    line += text[k] == '\n' ? 1 : 0;
  }
  EXPECT_EQ(d.sys.warnings[0].loc.line, static_cast<int>(line));
  EXPECT_EQ(d.sys.warnings[0].loc.col, static_cast<int>(col));
}

TEST(Derive, WarnsWhenTheFlowLeavesTheSupportWhereTheGuardDoesNotFire) {
  // The ball with its wall declared 'increasing': on x = 0 the flow with p < 0 leaves the
  // support x >= 0 and no guard catches it (a run then books that mass as an atom "at a Zeno
  // point"). The warning names the guard, a point with p < 0 and the likely fix. With the
  // wall declared right, the same scan finds nothing.
  const std::string good = read_model("bouncing_ball.model");
  std::string text = good;
  text.replace(text.find("when x = 0 decreasing"), 21, "when x = 0 increasing");
  Derived d(text);
  ASSERT_EQ(d.sys.warnings.size(), 1u);
  const std::string& w = d.sys.warnings[0].text;
  EXPECT_NE(w.find("guard 'ground': at (x = 0, p = -"), std::string::npos) << w;
  EXPECT_NE(w.find("leaves the support"), std::string::npos) << w;
  EXPECT_NE(w.find("did you mean 'decreasing'?"), std::string::npos) << w;
  Derived ok(good);
  EXPECT_TRUE(ok.sys.warnings.empty());
}

TEST(Derive, WarnsWhenTheDomainReachesBehindAWall) {
  // The ball with its domain widened to x ∈ [−1, 2] and no support: the ground is a wall
  // (restitution maps x = 0 onto itself), and the states at x < 0 are never reached from the
  // front. With `support x >= 0` (as shipped) the same domain is fine.
  std::string text = read_model("bouncing_ball.model");
  text.replace(text.find("domain x in [0, 2]"), 18, "domain x in [-1, 2]");
  std::string bare = text;
  bare.replace(bare.find("support x >= 0"), 14, "");
  Derived d(bare);
  ASSERT_EQ(d.sys.warnings.size(), 1u);
  const std::string& w = d.sys.warnings[0].text;
  EXPECT_NE(w.find("guard 'ground' is a wall"), std::string::npos) << w;
  EXPECT_NE(w.find("reaches behind it, e.g. (x = -"), std::string::npos) << w;
  Derived ok(text);
  EXPECT_TRUE(ok.sys.warnings.empty());
}

TEST(Derive, ConstantComponentIsJudgedOnTheGuard) {
  // (x, y) ↦ (0, y) at x = 1: det DΔ ≡ 0, so no inverse in the plane, but on S = {x = 1} the
  // tangent e_y goes to e_y: injective there (det(DΔᵀDΔ + ∇s∇sᵀ) = det I = 1). Accepted, with
  // no inverse, and J = X⁺_x(Δx)/X⁻_x(x) = (1 + 0)/(1 + 1) = 1/2 for x' = 1 + x.
  Derived d(R"(state x, y
mode a { x' = 1 + x; y' = -y }
guard g { when x = 1 increasing; reset (0, y) }
)");
  const IrGuard& g = d.sys.guards[0];
  EXPECT_FALSE(g.has_inverse);
  EXPECT_TRUE(g.inverse_on_guard_only);
  EXPECT_EQ(g.image_axis, 0);  // the image is the line x = 0: inverted on S at run time
  EXPECT_TRUE(d.same(g.hybrid_jacobian_on_surface, ex(1) / 2));
  // Not affine, det DΔ = 0·(1 + 3y²) ≡ 0, injective on S: the same, through the numeric branch.
  Derived f(R"(state x, y
mode a { x' = 1 + x; y' = -y }
guard g { when x = 1 increasing; reset (0, y + y^3) }
)");
  EXPECT_TRUE(f.sys.guards[0].inverse_on_guard_only);
  // Its other component is not affine: the image might be part of the line x = 0 only, so no
  // axis (the characteristics refuse it).
  EXPECT_EQ(f.sys.guards[0].image_axis, -1);
  // Singular everywhere with no constant component, injective on S (e_y ↦ (1, 1)): no axis,
  // so the characteristics refuse it.
  Derived h(R"(state x, y
mode a { x' = 1 + x; y' = -y }
guard g { when x = 1 increasing; reset (x + y, x + y) }
)");
  EXPECT_TRUE(h.sys.guards[0].inverse_on_guard_only);
  EXPECT_EQ(h.sys.guards[0].image_axis, -1);
  // Not injective on S: every point of x = 1 goes to (0, 1).
  expect_derive_error(R"(state x, y
mode a { x' = 1 + x; y' = -y }
guard g { when x = 1 increasing; reset (0, 1 + 0*y^3) }
)",
                      3, 34, "collapses its guard");
  // An invertible reset is not flagged.
  Derived e(R"(state x, y
mode a { x' = 1 + x; y' = -y }
guard g { when x = 1 increasing; reset (x - 1, y) }
)");
  EXPECT_TRUE(e.sys.guards[0].has_inverse);
  EXPECT_FALSE(e.sys.guards[0].inverse_on_guard_only);
}

TEST(Derive, APiecewiseLinearResetIsNotAffine) {
  // 1 − |2y − 1| has a second derivative that vanishes wherever it is defined, but it is two
  // to one: no closed-form inverse (one branch of it would lose the other pre-image), Newton
  // and the pre-flight's count of pre-images instead.
  Derived d(R"(state x, y
mode a { x' = 1; y' = 0 }
guard g { when x = 1 increasing; reset (x - 1, 1 - abs(2*y - 1)) }
)");
  EXPECT_FALSE(d.sys.guards[0].has_inverse);
  EXPECT_FALSE(d.sys.guards[0].inverse_on_guard_only);
}

TEST(Derive, NonAffineResetHasNumericInverse) {
  Derived d(R"(state x, p
mode a { x' = p; p' = -1 }
guard g { when x = 0 decreasing; reset (x, -p - p^3/10) }
)");
  EXPECT_FALSE(d.sys.guards[0].has_inverse);
  ASSERT_FALSE(d.sys.warnings.empty());
}

}  // namespace
}  // namespace hybgen::gen
