// The reduce stage (reduce.hpp): Lie-group models -> general models, through
// check_lie and reduce, then the ordinary derive.
//
// Size: one test file per source file (generator/src/reduce.cpp); every derived object of
// the reduction has its independent computation here.
//
// Every derived object is compared with an independent computation: matrix
// commutators for the structure constants and ad*, closed-form matrix
// expressions for ζ', Jacobi's formula for q', the energy/annihilator
// characterisation for Δζ, docs/design.md's determinant formula for J, and — the
// theorem itself — a numerical integration of the unreduced 2n-dimensional
// impact system against the reduced (n+1)-dimensional one; for the
// nonholonomic Chaplygin sleigh the twin is Lagrange–d'Alembert in the
// coordinates (x, y, th, ẋ, ẏ, θ̇), also checked against the sleigh written by
// hand.
//
// Paper disagreements asserted here (see also tests/gen/test_lie.cpp, E1–E10):
//  R1 §4.3: the hybrid Jacobian of the reduced GL₂ system is J = +1 for e = 1
//     (J = e² with restitution), not the paper's −1 (docs/design.md's determinant
//     formula: the reset's tangential block has det −e and the normal
//     velocity q' = (q + 1) tr ζ changes by the factor −e).
//  R2 §4.3: Δζ = −(2/n) tr(ζ) I_n is RIGHT (n = 2, 3), verified as the unique
//     nonzero λ I_n with h(ζ + λ I_n) = h(ζ), Δζ ∈ Ann(sl_n) = span(I_n).
//  R3 §4.3: q' = (q + 1) tr ζ is right for h = ½ tr(ζζᵀ); q(t) = q₀e^{Ct} − 1 is
//     not (q + 1 = (q₀ + 1) e^{Ct}) — in models/matrix_groups_impacts.model.

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <random>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/check_lie.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/emit.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/gen/reduce.hpp"
#include "support/pipeline.hpp"

namespace hybgen::gen {
namespace {

using GiNaC::ex;
using GiNaC::matrix;
using GiNaC::numeric;

using hybgen::testing::Pipeline;

/// A shipped model, loaded relative to the source tree (provenance paths as
/// `hybgen generate models/X.model` writes them).
std::unique_ptr<Pipeline> shipped(const std::string& name,
                                  ReduceTarget target = ReduceTarget::Reduced) {
  const std::string text = read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/" + name + ".model");
  return std::make_unique<Pipeline>("models/" + name + ".model", text, target);
}

bool same(const ex& a, const ex& b) {
  return is_identically_zero((a - b).expand(), {});
}

ex sym_of(const Model& m, const std::string& name) {
  for (std::size_t i = 0; i < m.state.size(); ++i)
    if (m.state[i] == name) return m.state_symbols[i];
  for (const auto& p : m.params)
    if (p.name == name) return p.symbol;
  ADD_FAILURE() << "no symbol " << name;
  return 0;
}

/// ζ (row-major components) as an n×n matrix.
matrix as_matrix(const std::vector<ex>& z, unsigned n) {
  matrix m(n, n);
  for (unsigned k = 0; k < n * n; ++k) m(k / n, k % n) = z[k];
  return m;
}

ex mtrace(const matrix& m) {
  ex s = 0;
  for (unsigned i = 0; i < m.rows(); ++i) s += m(i, i);
  return s;
}

std::vector<ex> momenta(const Model& m, unsigned n) {
  return {m.state_symbols.begin(), m.state_symbols.begin() + n};
}

// --------------------------------------------------------------- GL_n models

/// The reduced GL_n system against closed forms (n = 2 from models/gl2.model,
/// n = 3 from models/gl3.model).
void check_gln(const Pipeline& p, unsigned n) {
  const Model& m = p.model;
  ASSERT_TRUE(m.reduction.has_value());
  const Reduction& r = *m.reduction;
  ASSERT_EQ(r.algebra_dim, n * n);
  ASSERT_EQ(m.state.size(), n * n + 1);
  const std::vector<ex> z = momenta(m, n * n);
  const ex q = m.state_symbols[n * n];
  const matrix Z = as_matrix(z, n);
  // Structure constants against matrix commutators of the elementary basis:
  // [E_ab, E_cd] = E_ab E_cd − E_cd E_ab.
  for (unsigned i = 0; i < n * n; ++i)
    for (unsigned j = 0; j < n * n; ++j) {
      matrix Ei(n, n), Ej(n, n);
      Ei(i / n, i % n) = 1;
      Ej(j / n, j % n) = 1;
      const matrix br = Ei.mul(Ej).sub(Ej.mul(Ei));
      for (unsigned k = 0; k < n * n; ++k)
        EXPECT_EQ(r.structure_constants[(i * n * n + j) * n * n + k], br(k / n, k % n));
    }
  // ad*_{∂h/∂ζ}: for h = ½ tr(ζζᵀ), ∂h/∂ζ = ζ and ad*_ξ ζ = [ξᵀ, ζ] (E2 of
  // test_lie.cpp): ζ' = ζᵀζ − ζζᵀ.
  const matrix closed = Z.transpose().mul(Z).sub(Z.mul(Z.transpose()));
  for (unsigned k = 0; k < n * n; ++k) {
    ex row = 0;
    for (unsigned l = 0; l < n * n; ++l) row += r.coadjoint(k, l) * z[l];
    EXPECT_TRUE(same(row, closed(k / n, k % n))) << k;
    EXPECT_TRUE(same(p.sys.modes[0].flow[k], closed(k / n, k % n))) << k;
  }
  // q' = (q + 1) tr ζ (R3), independently by Jacobi's formula: along Ȧ = Aζ,
  // d det A/dt = det A · tr ζ, and q = det A − 1.
  EXPECT_TRUE(same(p.sys.modes[0].flow[n * n], (q + 1) * mtrace(Z)));
  EXPECT_TRUE(same(r.q_dot, (q + 1) * mtrace(Z)));
  // div = tr ζ (ad* is trace-free in ζ' for gl_n: ∂ζ'_k/∂ζ_k sums to 0).
  EXPECT_TRUE(same(p.sys.modes[0].divergence, mtrace(Z)));
  // Δζ for e = 1 (R2). Independent characterisation: Δζ ∈ Ann(sl_n) means
  // Δζ = λ I_n; h(ζ + λ I) = h(ζ) ⇔ λ (2 tr ζ + n λ) = 0, whose nonzero root
  // is λ = −(2/n) tr ζ.
  const IrGuard& g = p.sys.guards[0];
  GiNaC::exmap elastic;
  for (const auto& par : m.params) elastic[par.symbol] = 1;
  const ex lambda = -ex(2) / n * mtrace(Z);
  ex h = 0;
  for (const auto& zi : z) h += zi * zi / 2;
  GiNaC::exmap after;
  for (unsigned k = 0; k < n * n; ++k) {
    const ex dz = g.reset[k].subs(elastic) - z[k];
    EXPECT_TRUE(same(dz, k % (n + 1) == 0 ? lambda : ex(0))) << k;
    after[z[k]] = g.reset[k].subs(elastic);
  }
  EXPECT_TRUE(same(h.subs(after), h));
  EXPECT_TRUE(same(g.reset[n * n], q));
}

TEST(ReduceGl, Gl2ReducedSystem) {
  const auto p = shipped("gl2");
  check_gln(*p, 2);
  const Model& m = p->model;
  // Hypotheses recorded, paper objects in the record.
  EXPECT_TRUE(m.reduction->normal && m.reduction->codim1 && m.reduction->left_invariant);
  EXPECT_TRUE(m.reduction->multiplicative);
  // Hybrid Jacobian (R1): J = e², so +1 for e = 1 (the paper prints −1).
  // Independent: docs/design.md's determinant quotient with the tangent basis
  // e_ζ1..e_ζ4 of the guard q = 0: J = det[DΔ e_1…DΔ e_4 | X(Δx)] / det[e_1…e_4 | X(x)].
  const IrGuard& g = p->sys.guards[0];
  const auto& X = p->sys.modes[0].flow;
  const auto& x = m.state_symbols;
  matrix num(5, 5), den(5, 5);
  GiNaC::exmap at_reset;
  for (unsigned i = 0; i < 5; ++i) at_reset[x[i]] = g.reset[i];
  for (unsigned r = 0; r < 5; ++r) {
    for (unsigned c = 0; c < 4; ++c) {
      num(r, c) = g.reset[r].diff(GiNaC::ex_to<GiNaC::symbol>(x[c]));
      den(r, c) = r == c ? 1 : 0;
    }
    num(r, 4) = X[r].subs(at_reset);
    den(r, 4) = X[r];
  }
  const ex q = x[4], e = sym_of(m, "e");
  const ex J = GiNaC::normal((num.determinant() / den.determinant()).subs(q == 0));
  EXPECT_TRUE(same(J, e * e)) << J;
  EXPECT_TRUE(same(g.hybrid_jacobian_on_surface, e * e)) << g.hybrid_jacobian_on_surface;
  EXPECT_EQ(GiNaC::normal(J.subs(e == 1)), ex(1));  // R1: paper −1
}

TEST(ReduceGl, Gl3DerivesWithinFiveSeconds) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto p = shipped("gl3");
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cout << "[ gl3 parse+check+reduce+derive ] " << secs << " s\n";
  EXPECT_LT(secs, 5.0);
  check_gln(*p, 3);
  // 10-D: a simulation block that keeps the marginals (tests/e2e/test_gl3.cpp runs it).
  EXPECT_TRUE(p->model.sim.present);
  EXPECT_EQ(p->model.sim.settings.word<"density">(), "marginals");
}

TEST(ReduceGl, RestitutionReset) {
  // Δζ = −((1 + e)/2) tr ζ I₂, so tr ζ⁺ = −e tr ζ⁻ (the normal velocity of the
  // corner conditions scaled by −e).
  const auto p = shipped("gl2");
  const std::vector<ex> z = momenta(p->model, 4);
  const ex e = sym_of(p->model, "e");
  const IrGuard& g = p->sys.guards[0];
  EXPECT_TRUE(same(g.reset[0] + g.reset[3], -e * (z[0] + z[3])));
  EXPECT_TRUE(same(g.reset[1], z[1]));
  EXPECT_TRUE(same(g.reset[2], z[2]));
}

// ------------------------------------------------------------ rejections

/// The ModelError of reducing `text`; fails the test if there is none.
std::string reduce_error(const std::string& text) {
  try {
    Pipeline p("t.model", text);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const ModelError& e) {
    EXPECT_EQ(e.exit_code(), ExitCode::ModelError);
    return e.what();
  }
  return "";
}

TEST(ReduceRejects, So3HasNoCodim1NormalSubgroup) {
  const std::string text =
      read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/so3_rigid_body.model");
  const std::string what = reduce_error(text);
  EXPECT_NE(what.find("hypothesis 'codim1' fails"), std::string::npos) << what;
  EXPECT_NE(what.find("perfect"), std::string::npos) << what;
  EXPECT_EQ(what.rfind("t.model:12:1: error:", 0), 0u) << what;  // at the group
}

TEST(ReduceRejects, Aff1KernelIsNotNormal) {
  const std::string text = read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/aff1.model");
  const std::string what = reduce_error(text);
  EXPECT_NE(what.find("hypothesis 'normal' fails"), std::string::npos) << what;
  EXPECT_NE(what.find("[E_b, E_a] = -E_b"), std::string::npos) << what;
  EXPECT_EQ(what.rfind("t.model:12:1: error:", 0), 0u) << what;  // at `reduced`
}

const char* kGl2Head = R"(model t
parameter e = 1
group A = gl(2)
momenta z1, z2, z3, z4
)";

TEST(ReduceRejects, HamiltonianNotAtTheIdentity) {
  const std::string what = reduce_error(std::string(kGl2Head) +
                                        "hamiltonian (z1^2 + z2^2 + z3^2 + z4^2)*a11^2/2\n"
                                        "reduced q = det(A) - 1\n");
  EXPECT_NE(what.find("hypothesis 'left_invariant' fails"), std::string::npos) << what;
  EXPECT_NE(what.find("coordinate a11"), std::string::npos) << what;
}

TEST(ReduceRejects, QEquationDependingOnACoordinate) {
  // φ = det A + a12 a21 has dφ_e = tr (normal kernel sl_2) but is not a
  // homomorphism: q' still depends on the group element.
  const std::string what = reduce_error(std::string(kGl2Head) +
                                        "hamiltonian (z1^2 + z2^2 + z3^2 + z4^2)/2\n"
                                        "reduced q = det(A) + a12*a21 - 1\n");
  EXPECT_NE(what.find("hypothesis 'coset' fails"), std::string::npos) << what;
  EXPECT_NE(what.find("depends on the coordinate a"), std::string::npos) << what;
  EXPECT_EQ(what.rfind("t.model:6:1: error:", 0), 0u) << what;
}

TEST(ReduceRejects, ResetOutsideTheAnnihilator) {
  // Swapping ζ2 and ζ3 is a jump in the direction E12 − E21 ∈ sl_2: not in Ann(sl_2).
  const std::string what =
      reduce_error(std::string(kGl2Head) +
                   "hamiltonian (z1^2 + z2^2 + z3^2 + z4^2)/2\n"
                   "reduced q = det(A) - 1\n"
                   "guard g { when q = 0 decreasing; reset (z1, z3, z2, z4, q) }\n");
  EXPECT_NE(what.find("hypothesis 'reset' fails"), std::string::npos) << what;
  EXPECT_EQ(what.rfind("t.model:7:34: error:", 0), 0u) << what;
}

TEST(ReduceRejects, SurfaceMustBeALevelSetOfQ) {
  const std::string what = reduce_error(std::string(kGl2Head) +
                                        "hamiltonian (z1^2 + z2^2 + z3^2 + z4^2)/2\n"
                                        "reduced q = det(A) - 1\n"
                                        "guard g { when q + z1 = 0 decreasing; reset elastic }\n");
  EXPECT_NE(what.find("depends on the momentum z1"), std::string::npos) << what;
}

TEST(ReduceRejects, NonQuadraticHamiltonianWithElasticReset) {
  const std::string what = reduce_error(std::string(kGl2Head) +
                                        "hamiltonian (z1^2 + z2^2 + z3^2 + z4^2)^2\n"
                                        "reduced q = det(A) - 1\n"
                                        "guard g { when q = 0 decreasing; reset elastic }\n");
  EXPECT_NE(what.find("hypothesis 'quadratic' fails"), std::string::npos) << what;
}

// ------------------------------------------------------- the unreduced twin

TEST(ReduceTwin, Gl2TwinHamiltonianIsHOfBodyMomenta) {
  const auto p = shipped("gl2", ReduceTarget::Unreduced);
  const Model& m = p->model;
  ASSERT_EQ(m.state.size(), 8u);
  EXPECT_FALSE(m.reduction.has_value());
  EXPECT_EQ(m.name, "gl2_unreduced");
  // H(A, P) = ½ tr(AᵀPPᵀA) (paper §4.3), independently by matrix products.
  matrix A(2, 2), P(2, 2);
  for (unsigned k = 0; k < 4; ++k)
    A(k / 2, k % 2) = m.state_symbols[k], P(k / 2, k % 2) = m.state_symbols[4 + k];
  const matrix M = A.transpose().mul(P);
  const ex H = mtrace(M.mul(M.transpose())) / 2;
  ASSERT_TRUE(m.modes[0].hamiltonian.has_value());
  EXPECT_TRUE(same(*m.modes[0].hamiltonian, H));
  // The guard is det A − 1 = 0 and the reset the corner conditions.
  EXPECT_TRUE(same(p->sys.guards[0].surface, GiNaC::determinant(A) - 1));
}

// ----------------------------------------- the theorem, numerically (GL₂)

/// A compiled expression: evaluates a GiNaC expression (rational functions,
/// powers — sqrt is a power —, sin, cos, exp) on a state vector, without GiNaC
/// in the loop.
using Fn = std::function<double(const std::vector<double>&)>;

Fn compile(const ex& e, const std::map<std::string, std::size_t>& index) {
  if (GiNaC::is_a<GiNaC::numeric>(e)) {
    const double v = GiNaC::ex_to<GiNaC::numeric>(e).to_double();
    return [v](const std::vector<double>&) { return v; };
  }
  if (GiNaC::is_a<GiNaC::symbol>(e)) {
    const std::size_t i = index.at(GiNaC::ex_to<GiNaC::symbol>(e).get_name());
    return [i](const std::vector<double>& x) { return x[i]; };
  }
  std::vector<Fn> ops;
  for (std::size_t k = 0; k < e.nops(); ++k) ops.push_back(compile(e.op(k), index));
  if (GiNaC::is_a<GiNaC::add>(e))
    return [ops](const std::vector<double>& x) {
      double s = 0;
      for (const auto& f : ops) s += f(x);
      return s;
    };
  if (GiNaC::is_a<GiNaC::mul>(e))
    return [ops](const std::vector<double>& x) {
      double s = 1;
      for (const auto& f : ops) s *= f(x);
      return s;
    };
  if (GiNaC::is_a<GiNaC::power>(e))
    return [ops](const std::vector<double>& x) { return std::pow(ops[0](x), ops[1](x)); };
  if (GiNaC::is_a<GiNaC::function>(e)) {
    static const std::map<std::string, double (*)(double)> known = {
        {"sin", [](double u) { return std::sin(u); }},
        {"cos", [](double u) { return std::cos(u); }},
        {"exp", [](double u) { return std::exp(u); }}};
    const auto f = known.find(GiNaC::ex_to<GiNaC::function>(e).get_name());
    if (f != known.end() && ops.size() == 1)
      return [fn = f->second, arg = ops[0]](const std::vector<double>& x) { return fn(arg(x)); };
  }
  ADD_FAILURE() << "cannot compile " << e;
  return [](const std::vector<double>&) { return std::nan(""); };
}

/// A hybrid system compiled from the IR (parameters at their defaults).
struct Compiled {
  std::vector<Fn> flow;
  std::vector<Fn> surface;
  std::vector<int> direction;  // −1 decreasing, +1 increasing
  std::vector<std::vector<Fn>> reset;

  explicit Compiled(const HybridSystem& sys) {
    const Model& m = *sys.model;
    std::map<std::string, std::size_t> index;
    for (std::size_t i = 0; i < m.state.size(); ++i) index[m.state[i]] = i;
    GiNaC::exmap par;
    for (const auto& p : m.params) par[p.symbol] = p.value;
    for (const auto& f : sys.modes[0].flow) flow.push_back(compile(f.subs(par).expand(), index));
    for (const auto& g : sys.guards) {
      surface.push_back(compile(g.surface.subs(par), index));
      direction.push_back(g.direction == Direction::Decreasing ? -1 : 1);
      std::vector<Fn> r;
      for (const auto& c : g.reset) r.push_back(compile(GiNaC::normal(c.subs(par)), index));
      reset.push_back(std::move(r));
    }
  }

  std::vector<double> f(const std::vector<double>& x) const {
    std::vector<double> d(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) d[i] = flow[i](x);
    return d;
  }

  /// One classical RK4 step of size h.
  std::vector<double> rk4(const std::vector<double>& x, double h) const {
    auto axpy = [](const std::vector<double>& a, double s, const std::vector<double>& b) {
      std::vector<double> o(a.size());
      for (std::size_t i = 0; i < a.size(); ++i) o[i] = a[i] + s * b[i];
      return o;
    };
    const auto k1 = f(x), k2 = f(axpy(x, h / 2, k1)), k3 = f(axpy(x, h / 2, k2)),
               k4 = f(axpy(x, h, k3));
    std::vector<double> o(x.size());
    for (std::size_t i = 0; i < x.size(); ++i)
      o[i] = x[i] + h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
    return o;
  }

  /// Integrate from x to time t_end with step h, locating guard crossings (in
  /// their direction) by bisection on the step length, and applying the
  /// reset. Records the state at the sample times `at` and the impact times.
  std::vector<std::vector<double>> integrate(std::vector<double> x, double t_end, double h,
                                             const std::vector<double>& at,
                                             std::vector<double>& impacts) const {
    std::vector<std::vector<double>> out;
    double t = 0;
    std::size_t next = 0;
    while (t < t_end - 1e-15) {
      double step = std::min(h, t_end - t);
      // Land exactly on sample times.
      if (next < at.size() && at[next] < t + step) step = at[next] - t;
      std::vector<double> y = rk4(x, step);
      int hit = -1;
      for (std::size_t g = 0; g < surface.size(); ++g) {
        const double s0 = surface[g](x), s1 = surface[g](y);
        if (direction[g] < 0 ? (s0 > 0 && s1 <= 0) : (s0 < 0 && s1 >= 0)) hit = static_cast<int>(g);
      }
      if (hit >= 0) {
        const auto g = static_cast<std::size_t>(hit);
        double lo = 0, hi = step;  // s(x(lo)) has the pre-crossing sign
        for (int it = 0; it < 200 && hi - lo > 1e-15; ++it) {
          const double mid = (lo + hi) / 2;
          const double s = surface[g](rk4(x, mid));
          if (direction[g] < 0 ? s > 0 : s < 0)
            lo = mid;
          else
            hi = mid;
        }
        y = rk4(x, hi);
        std::vector<double> z(y.size());
        for (std::size_t i = 0; i < y.size(); ++i) z[i] = reset[g][i](y);
        x = z;
        t += hi;
        impacts.push_back(t);
        continue;
      }
      x = y;
      t += step;
      if (next < at.size() && std::fabs(t - at[next]) < 1e-13) {
        out.push_back(x);
        ++next;
      }
    }
    return out;
  }
};

/// Solve A x = b (n×n, row-major) by Gaussian elimination with partial pivoting.
std::vector<double> solve(std::vector<double> A, std::vector<double> b) {
  const std::size_t n = b.size();
  for (std::size_t c = 0; c < n; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < n; ++r)
      if (std::fabs(A[r * n + c]) > std::fabs(A[piv * n + c])) piv = r;
    for (std::size_t k = 0; k < n; ++k) std::swap(A[c * n + k], A[piv * n + k]);
    std::swap(b[c], b[piv]);
    for (std::size_t r = c + 1; r < n; ++r) {
      const double f = A[r * n + c] / A[c * n + c];
      for (std::size_t k = c; k < n; ++k) A[r * n + k] -= f * A[c * n + k];
      b[r] -= f * b[c];
    }
  }
  std::vector<double> x(n);
  for (std::size_t i = n; i-- > 0;) {
    double s = b[i];
    for (std::size_t k = i + 1; k < n; ++k) s -= A[i * n + k] * x[k];
    x[i] = s / A[i * n + i];
  }
  return x;
}

/// The theorem, numerically: integrate the unreduced 2n-dimensional system and
/// the reduced one from the same initial condition through the impacts, and
/// compare the reduced variables recovered from the twin with the reduced
/// solution at 40 sample times and the impact times.
///  - Unconstrained: the twin is (c, p) with Hamilton's equations and the
///    corner-condition reset of derive; p0 = L(c0)⁻ᵀ ζ0 and ζ = L(c)ᵀp.
///  - Constrained: the twin is (c, ċ) with the Lagrange–d'Alembert flow and
///    impulsive reset; ċ0 = L(c0) B w0 (B = ∂ξ/∂w, constant), and w is read
///    back from ξ = L(c)⁻¹ċ by least squares, w = (BᵀB)⁻¹Bᵀξ; the residual
///    |ξ − B w| (how far the twin left the constraint) counts in `worst` too.
/// q = q(c) in both. Returns the number of impacts; `worst` gets the largest
/// difference.
std::size_t compare_with_unreduced(const std::string& text, const std::vector<double>& c0,
                                   const std::vector<double>& z0, double t_end, double& worst) {
  const SourceText src("t.model", text);
  const LieModel lm = check_lie(parse(src), src);
  Model mr = reduce(lm, src, ReduceTarget::Reduced), mf = reduce(lm, src, ReduceTarget::Unreduced);
  HybridSystem sr = derive(mr, src), sf = derive(mf, src);
  sr.model = &mr;
  sf.model = &mf;
  const Compiled cr(sr), cf(sf);
  const std::size_t n = c0.size(), r = z0.size();
  // L(c) and q(c) as functions of the unreduced state, parameters at defaults.
  std::map<std::string, std::size_t> index;
  for (std::size_t i = 0; i < mf.state.size(); ++i) index[mf.state[i]] = i;
  GiNaC::exmap par;
  for (const auto& p : mf.params) par[p.symbol] = p.value;
  std::vector<Fn> L;
  for (unsigned j = 0; j < n; ++j)
    for (unsigned i = 0; i < n; ++i)
      L.push_back(compile(lm.group.left_trivialization()(j, i).subs(par), index));
  const Fn qf = compile(lm.q_expr.subs(par).expand(), index);
  // B (n×r, row-major) for constrained models.
  std::vector<double> B;
  for (std::size_t i = 0; i < lm.xi_of_w.size(); ++i)
    for (std::size_t k = 0; k < r; ++k)
      B.push_back(
          GiNaC::ex_to<GiNaC::numeric>(
              GiNaC::evalf(
                  lm.xi_of_w[i].diff(GiNaC::ex_to<GiNaC::symbol>(mr.state_symbols[k])).subs(par)))
              .to_double());
  const bool constrained = !B.empty();
  // The reduced variables (and the constraint residual) of a twin state x.
  auto reduced_of = [&](const std::vector<double>& x, double& residual) {
    std::vector<double> red(r);
    residual = 0;
    if (!constrained) {
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < n; ++j) red[i] += x[n + j] * L[j * n + i](x);
    } else {
      std::vector<double> Lx(n * n);
      for (std::size_t k = 0; k < n * n; ++k) Lx[k] = L[k](x);
      const std::vector<double> xi = solve(Lx, std::vector<double>(x.begin() + n, x.end()));
      std::vector<double> BtB(r * r), Btxi(r);
      for (std::size_t a = 0; a < r; ++a)
        for (std::size_t i = 0; i < n; ++i) {
          Btxi[a] += B[i * r + a] * xi[i];
          for (std::size_t b = 0; b < r; ++b) BtB[a * r + b] += B[i * r + a] * B[i * r + b];
        }
      red = solve(BtB, Btxi);
      for (std::size_t i = 0; i < n; ++i) {
        double bw = 0;
        for (std::size_t a = 0; a < r; ++a) bw += B[i * r + a] * red[a];
        residual = std::max(residual, std::fabs(xi[i] - bw));
      }
    }
    red.push_back(qf(x));
    return red;
  };
  std::vector<double> xf(c0);
  xf.resize(2 * n, 0.0);
  if (!constrained) {
    // Lᵀ(c0) p0 = ζ0, i.e. Σ_j L_ji p_j = ζ0_i.
    std::vector<double> LT(n * n);
    for (std::size_t j = 0; j < n; ++j)
      for (std::size_t i = 0; i < n; ++i) LT[i * n + j] = L[j * n + i](xf);
    const std::vector<double> p0 = solve(LT, z0);
    for (std::size_t j = 0; j < n; ++j) xf[n + j] = p0[j];
  } else {
    // ċ0 = L(c0) ξ0, ξ0 = B w0.
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j)
        for (std::size_t a = 0; a < r; ++a) xf[n + i] += L[i * n + j](xf) * B[j * r + a] * z0[a];
  }
  std::vector<double> xr(z0);
  xr.push_back(qf(xf));
  std::vector<double> at;
  for (int k = 1; k <= 40; ++k) at.push_back(t_end * k / 40);
  std::vector<double> imp_r, imp_f;
  const double h = 1e-3;
  const auto samples_r = cr.integrate(xr, t_end, h, at, imp_r);
  const auto samples_f = cf.integrate(xf, t_end, h, at, imp_f);
  EXPECT_EQ(samples_r.size(), at.size());
  EXPECT_EQ(samples_f.size(), at.size());
  EXPECT_EQ(imp_r.size(), imp_f.size());
  for (std::size_t k = 0; k < std::min(imp_r.size(), imp_f.size()); ++k)
    EXPECT_NEAR(imp_r[k], imp_f[k], 1e-9) << "impact " << k;
  worst = 0;
  for (std::size_t s = 0; s < std::min(samples_r.size(), samples_f.size()); ++s) {
    double residual = 0;
    const std::vector<double> red = reduced_of(samples_f[s], residual);
    worst = std::max(worst, residual);
    for (std::size_t i = 0; i <= r; ++i)
      worst = std::max(worst, std::fabs(red[i] - samples_r[s][i]));
  }
  return imp_r.size();
}

// Tolerance 1e-8 (the issue's): RK4 with h = 1e-3 on these smooth fields
// (polynomial; for the sleigh's twin trigonometric in θ with |θ̇| ≲ 2) has a
// global error of ~1e-12 and the impacts are bisected to 1e-15, so agreement
// to 1e-8 is a test of the equations, not of the integrator (measured: ≤ 1e-13).

const char* kGl2Box = R"(model gl2_box
parameter e = 0.8
group A = gl(2)
momenta zeta1, zeta2, zeta3, zeta4
hamiltonian (zeta1^2 + zeta2^2 + zeta3^2 + zeta4^2)/2
reduced q = det(A) - 1
guard bottom { when q = 0 decreasing; reset restitution e }
guard top { when q = 1/2 increasing; reset restitution e }
)";

TEST(ReduceTheorem, UnreducedAndReducedGl2AgreeThroughSeveralImpacts) {
  // GL₂ bouncing between det A = 1 (q = 0) and det A = 3/2 (q = 1/2): both
  // level sets of det are cosets of SL₂ (normal), so the theorem applies to
  // both guards; with restitution e = 4/5 the impacts are not symmetric.
  // A0 has det 1.35 (q0 = 0.35); tr ζ0 = −1.4 < 0 heads for det = 1.
  double worst = 0;
  const std::size_t impacts =
      compare_with_unreduced(kGl2Box, {1.2, 0.3, -0.1, 1.1}, {-0.6, 0.4, 0.2, -0.8}, 4.0, worst);
  std::cout << "[ theorem GL2 ] " << impacts << " impacts, max |reduced - unreduced| = " << worst
            << "\n";
  EXPECT_GE(impacts, 4u);
  EXPECT_LT(worst, 1e-8);
  // Control (the comparison can fail): the same comparison with a different
  // restitution in the reduced system parts at the first impact.
  std::string other = kGl2Box;
  other.replace(other.find("e = 0.8"), 7, "e = 0.7");
  const SourceText a("a.model", kGl2Box), b("b.model", other);
  Model ma = reduce(check_lie(parse(a), a), a), mb = reduce(check_lie(parse(b), b), b);
  HybridSystem sa = derive(ma, a), sb = derive(mb, b);
  sa.model = &ma;
  sb.model = &mb;
  std::vector<double> at = {4.0}, ia, ib;
  const std::vector<double> x0 = {-0.6, 0.4, 0.2, -0.8, 0.35};
  const auto ra = Compiled(sa).integrate(x0, 4.0, 1e-3, at, ia);
  const auto rb = Compiled(sb).integrate(x0, 4.0, 1e-3, at, ib);
  double diff = 0;
  for (int k = 0; k < 5; ++k) diff = std::max(diff, std::fabs(ra[0][k] - rb[0][k]));
  EXPECT_GT(diff, 1e-3);
}

TEST(ReduceTheorem, UnreducedAndReducedHeisenbergAgree) {
  // The shipped Heisenberg model with e = 0.9 (walls at x = ±1): the
  // left trivialisation is not the identity here (ẏ, ż mix with x), so this
  // also tests L(c) and the corner conditions in non-trivial coordinates.
  std::string text = read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/heisenberg.model");
  text.replace(text.find("parameter e = 1"), 15, "parameter e = 0.9");
  double worst = 0;
  const std::size_t impacts =
      compare_with_unreduced(text, {0.2, -0.3, 0.5}, {0.9, 0.2, 0.3}, 8.0, worst);
  std::cout << "[ theorem H3 ] " << impacts << " impacts, max |reduced - unreduced| = " << worst
            << "\n";
  EXPECT_GE(impacts, 3u);
  EXPECT_LT(worst, 1e-8);
}

/// The shipped Chaplygin sleigh with walls at θ = ±1/2 and restitution `e`
/// ("1": the shipped elastic reset).
std::string chaplygin_box(const std::string& e) {
  std::string text = read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/chaplygin.model");
  text.replace(text.find("parameter theta0 = 1"), 20, "parameter theta0 = 0.5");
  if (e != "1") {
    text.replace(text.find("parameter theta0"), 0, "parameter e = " + e + "\n");
    for (std::size_t at; (at = text.find("reset elastic")) != std::string::npos;)
      text.replace(at, 13, "reset restitution e");
  }
  return text;
}

TEST(ReduceTheorem, UnreducedAndReducedChaplyginAgree) {
  // The nonholonomic case: the twin (x, y, th, ẋ, ẏ, θ̇) of Lagrange–d'Alembert
  // in the coordinates against the Euler–Poincaré–Suslov (v, omega, theta).
  // v0 = −1 < 0 makes |ω| grow at first (ω' = −m a v ω/(I + m a²)), so the
  // sleigh crosses the wedge |θ| < 1/2 five times (e = 1) / four times
  // (e = 0.8) in 6 s before ω decays. The worst difference includes the twin's
  // sideways body velocity (it must stay on the constraint).
  for (const std::string e : {"1", "0.8"}) {
    double worst = 0;
    const std::size_t impacts =
        compare_with_unreduced(chaplygin_box(e), {0.3, -0.2, 0.1}, {-1.0, 1.0}, 6.0, worst);
    std::cout << "[ theorem Chaplygin e=" << e << " ] " << impacts
              << " impacts, max |reduced - unreduced| = " << worst << "\n";
    EXPECT_GE(impacts, 4u) << e;
    EXPECT_LT(worst, 1e-8) << e;
  }
}

TEST(ReduceTheorem, UnreducedAndReducedFreeSleighAgree) {
  // The sleigh without its knife edge (velocities v, w, omega, no constraint):
  // the twin has no multiplier (A has no rows) and B = 1, so this checks the
  // Lagrange flow M c̈ = F and the impulsive reset in the coordinates alone.
  // ω is constant (no torque), so θ sweeps the wedge |θ| < 1/2 every 1/|ω| s.
  std::string text = chaplygin_box("0.8");
  text.replace(text.find("constraint w = 0"), 16, "");
  text.replace(text.find("  domain omega"), 0, "  domain w in [-1, 1]\n");
  text.replace(text.find("grid 21x21x21"), 13, "grid 5x5x5x5");
  double worst = 0;
  const std::size_t impacts =
      compare_with_unreduced(text, {0.3, -0.2, 0.1}, {-1.0, 0.3, 1.0}, 6.0, worst);
  std::cout << "[ theorem free sleigh e=0.8 ] " << impacts
            << " impacts, max |reduced - unreduced| = " << worst << "\n";
  EXPECT_GE(impacts, 3u);
  EXPECT_LT(worst, 1e-8);
}

// ------------------------------------------------- Chaplygin (constrained)

TEST(ReduceChaplygin, PaperEquationsFromGroupData) {
  // Independent derivation by hand (Lagrange–d'Alembert in body velocities):
  // ξ = (v, 0, ω) in the basis (E_x, E_y, E_th), [E_th, E_x] = E_y,
  // [E_th, E_y] = −E_x, μ = Iξ = (m v, m a ω, (I + m a²) ω);
  // (ad*_ξ μ)_x = ω μ_y = m a ω², (ad*_ξ μ)_th = −v μ_y = −m a v ω, and the
  // multiplier only enters the E_y row, so m v' = m a ω² and
  // (I + m a²) ω' = −m a v ω: the paper's v' = a ω², ω' = −(m a/(I + m a²)) v ω
  // (right), θ' = ω.
  const auto p = shipped("chaplygin");
  const Model& m = p->model;
  ASSERT_EQ(m.state, (std::vector<std::string>{"v", "omega", "theta"}));
  const ex v = m.state_symbols[0], w = m.state_symbols[1], th = m.state_symbols[2];
  const ex M = sym_of(m, "m"), I = sym_of(m, "I"), a = sym_of(m, "a"), t0 = sym_of(m, "theta0");
  const auto& X = p->sys.modes[0].flow;
  EXPECT_TRUE(same(GiNaC::normal(X[0] - a * w * w), 0)) << X[0];
  EXPECT_TRUE(same(GiNaC::normal(X[1] + M * a * v * w / (I + M * a * a)), 0)) << X[1];
  EXPECT_TRUE(same(X[2], w));
  // div = −m a v/(I + m a²) (the paper's PDE has "− (ma/(I+ma²)) v u" on the
  // left-hand side with a + sign convention of ∂u/∂t + ∇·(uX) = 0: consistent).
  EXPECT_TRUE(same(GiNaC::normal(p->sys.modes[0].divergence + M * a * v / (I + M * a * a)), 0));
  // Energy ½ m v² + ½ (I + m a²) ω² is conserved by the flow (independent check).
  const ex E = M * v * v / 2 + (I + M * a * a) * w * w / 2;
  EXPECT_TRUE(same(GiNaC::normal(E.diff(GiNaC::ex_to<GiNaC::symbol>(v)) * X[0] +
                                 E.diff(GiNaC::ex_to<GiNaC::symbol>(w)) * X[1]),
                   0));
  // Elastic reset with the constraint: (v, ω, θ) ↦ (v, −ω, θ) (paper, right);
  // J = 1 on both guards (tangential block det −1 times ω⁺/ω = −1).
  ASSERT_EQ(p->sys.guards.size(), 2u);
  for (const auto& g : p->sys.guards) {
    EXPECT_TRUE(same(g.reset[0], v));
    EXPECT_TRUE(same(g.reset[1], -w));
    EXPECT_TRUE(same(g.reset[2], th));
    EXPECT_TRUE(same(g.hybrid_jacobian_on_surface, 1)) << g.hybrid_jacobian_on_surface;
  }
  EXPECT_TRUE(same(p->sys.guards[0].surface, th - t0));
}

TEST(ReduceChaplygin, UnreducedTwinIsLagrangeDAlembertInCoordinates) {
  // The twin on TG in (x, y, th, ẋ, ẏ, θ̇), checked against the sleigh written
  // by hand in the coordinates: the sideways velocity σ = −sin θ ẋ + cos θ ẏ
  // (the knife edge: σ = 0), the speed along the edge v = cos θ ẋ + sin θ ẏ.
  const auto p = shipped("chaplygin", ReduceTarget::Unreduced);
  const Model& m = p->model;
  ASSERT_EQ(m.state, (std::vector<std::string>{"x", "y", "th", "xdot", "ydot", "thdot"}));
  EXPECT_EQ(m.name, "chaplygin_unreduced");
  EXPECT_FALSE(m.reduction.has_value());
  const std::vector<ex>& X = m.state_symbols;
  const ex th = X[2], xd = X[3], yd = X[4], thd = X[5];
  const ex M = sym_of(m, "m"), I = sym_of(m, "I"), a = sym_of(m, "a"), t0 = sym_of(m, "theta0");
  const auto& F = p->sys.modes[0].flow;
  ASSERT_EQ(F.size(), 6u);
  for (unsigned i = 0; i < 3; ++i) EXPECT_TRUE(same(F[i], X[3 + i])) << F[i];
  // d/dt along the twin's flow.
  auto ddt = [&](const ex& f) {
    ex d = 0;
    for (unsigned i = 0; i < 6; ++i) d += f.diff(GiNaC::ex_to<GiNaC::symbol>(X[i])) * F[i];
    return d;
  };
  const ex sigma = -sin(th) * xd + cos(th) * yd, v = cos(th) * xd + sin(th) * yd;
  // The multiplier keeps σ: dσ/dt ≡ 0 everywhere (random points, exact in sin/cos).
  EXPECT_TRUE(is_identically_zero(ddt(sigma), {})) << ddt(sigma);
  // On the constraint set (ẋ, ẏ) = V (cos θ, sin θ), θ̇ = Ω the twin's v and θ̇
  // obey the paper's v' = a Ω², Ω' = −m a V Ω/(I + m a²) (the reduction theorem,
  // symbolically).
  const GiNaC::realsymbol V("V"), W("W");
  const GiNaC::exmap on{{xd, V * cos(th)}, {yd, V * sin(th)}, {thd, W}};
  EXPECT_TRUE(is_identically_zero(ddt(v).subs(on) - a * W * W, {}));
  EXPECT_TRUE(is_identically_zero(F[5].subs(on) + M * a * V * W / (I + M * a * a), {}));
  // Resets at θ = ±theta0: c ↦ c; σ kept (A Δċ = 0), so the constraint set is
  // invariant; on it (V, Ω) ↦ (V, −Ω), the paper's elastic reset.
  ASSERT_EQ(p->sys.guards.size(), 2u);
  EXPECT_TRUE(same(p->sys.guards[0].surface, th - t0));
  EXPECT_TRUE(same(p->sys.guards[1].surface, th + t0));
  for (const auto& g : p->sys.guards) {
    GiNaC::exmap after;
    for (unsigned i = 0; i < 6; ++i) after[X[i]] = g.reset[i];
    for (unsigned i = 0; i < 3; ++i) EXPECT_TRUE(same(g.reset[i], X[i])) << g.name;
    EXPECT_TRUE(is_identically_zero(sigma.subs(after) - sigma, {})) << g.name;
    EXPECT_TRUE(is_identically_zero(g.reset[3].subs(on) - V * cos(th), {})) << g.reset[3];
    EXPECT_TRUE(is_identically_zero(g.reset[4].subs(on) - V * sin(th), {})) << g.reset[4];
    EXPECT_TRUE(same(g.reset[5].subs(on), -W)) << g.reset[5];
    EXPECT_TRUE(g.has_inverse) << g.name;
  }
}

TEST(ReduceChaplygin, TwinRefusesAnExplicitReset) {
  std::string text = read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/chaplygin.model");
  const std::string el = "reset elastic          # (v, omega) -> (v, -omega)";
  text.replace(text.find(el), el.size(), "reset (v, -omega, theta)");
  const SourceText src("t.model", text);
  const LieModel lm = check_lie(parse(src), src);
  EXPECT_NO_THROW(reduce(lm, src, ReduceTarget::Reduced));
  try {
    reduce(lm, src, ReduceTarget::Unreduced);
    ADD_FAILURE() << "explicit reset accepted by the constrained twin";
  } catch (const ModelError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("constrained (nonholonomic)"), std::string::npos) << what;
    EXPECT_EQ(what.rfind("t.model:27:", 0), 0u) << what;  // at the reset
  }
}

// ------------------------------------------------------------ golden files

TEST(ReduceGolden, GeneratedFilesOfLieModelsAreUpToDate) {
  for (const std::string name :
       {"gl2", "gl3", "matrix_groups_impacts", "heisenberg", "chaplygin"}) {
    const auto p = shipped(name);
    const GeneratedFiles files = emit(p->sys);
    const std::string dir = std::string(HYBGEN_SOURCE_DIR) + "/generated/" + name;
    std::string header, report;
    ASSERT_NO_THROW(header = read_file(dir + "/" + files.header_name))
        << "missing golden file; run: hybgen generate models/" << name << ".model";
    ASSERT_NO_THROW(report = read_file(dir + "/" + files.report_name));
    EXPECT_EQ(header, files.header) << "generated/" << name << " is stale; regenerate with: "
                                    << "hybgen generate models/" << name << ".model";
    EXPECT_EQ(report, files.report) << "generated/" << name << "/report.md is stale";
  }
}

}  // namespace
}  // namespace hybgen::gen
