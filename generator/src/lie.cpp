// Symbolic core of hybrid Lie–Poisson reduction: see lie.hpp for the
// conventions. Every identity test is exact: expand()/normal() for polynomial
// and rational data, is_identically_zero (random rational points, evalf for
// transcendental ones) where the data may contain sin/cos.
//
// Size: matrix groups, Lie algebras from brackets, ad*, the Lie–Poisson and Suslov
// equations and the corollary's momentum jump, each tested against the others.

#include "hybgen/gen/lie.hpp"

#include <sstream>
#include <utility>

#include "hybgen/gen/derive.hpp"

namespace hybgen::gen {

using GiNaC::ex;
using GiNaC::matrix;

namespace {

const GiNaC::symbol& as_symbol(const ex& e) {
  return GiNaC::ex_to<GiNaC::symbol>(e);
}

/// Exact zero test of a (possibly transcendental) expression.
bool zero(const ex& e) {
  if (e.is_zero()) return true;
  ex x = e.expand();
  if (x.is_zero()) return true;
  return is_identically_zero(x, {});
}

std::string str(const ex& e) {
  std::ostringstream os;
  os << e;
  return os.str();
}

/// Rank of a matrix given as rows of expressions (normal()-based elimination).
unsigned rank_of_rows(const std::vector<Components>& rows, unsigned cols) {
  if (rows.empty() || cols == 0) return 0;
  matrix m(static_cast<unsigned>(rows.size()), cols);
  for (unsigned r = 0; r < rows.size(); ++r)
    for (unsigned c = 0; c < cols; ++c) m(r, c) = rows[r][c];
  return m.rank();
}

/// A basis of {x : M x = 0} for M given by rows (Gauss–Jordan with normal()).
std::vector<Components> null_space(std::vector<Components> rows, unsigned cols) {
  std::vector<int> pivot_of_col(cols, -1);
  unsigned r = 0;
  for (unsigned c = 0; c < cols && r < rows.size(); ++c) {
    unsigned p = r;
    while (p < rows.size() && GiNaC::normal(rows[p][c]).is_zero()) ++p;
    if (p == rows.size()) continue;
    std::swap(rows[p], rows[r]);
    const ex piv = rows[r][c];
    for (auto& x : rows[r]) x = GiNaC::normal(x / piv);
    for (unsigned o = 0; o < rows.size(); ++o) {
      if (o == r) continue;
      const ex f = rows[o][c];
      if (GiNaC::normal(f).is_zero()) continue;
      for (unsigned k = 0; k < cols; ++k) rows[o][k] = GiNaC::normal(rows[o][k] - f * rows[r][k]);
    }
    pivot_of_col[c] = static_cast<int>(r);
    ++r;
  }
  std::vector<Components> out;
  for (unsigned free = 0; free < cols; ++free) {
    if (pivot_of_col[free] >= 0) continue;
    Components v(cols, ex(0));
    v[free] = 1;
    for (unsigned c = 0; c < cols; ++c)
      if (pivot_of_col[c] >= 0) v[c] = -rows[static_cast<unsigned>(pivot_of_col[c])][free];
    out.push_back(std::move(v));
  }
  return out;
}

/// vec(A): row-major flattening of a square matrix.
Components vec(const matrix& a) {
  Components v;
  for (unsigned r = 0; r < a.rows(); ++r)
    for (unsigned c = 0; c < a.cols(); ++c) v.push_back(a(r, c));
  return v;
}

/// Greedily choose rows of B (given as its row list) that form an invertible
/// square submatrix of size `n`. Returns fewer rows when rank(B) < n.
std::vector<unsigned> independent_rows(const std::vector<Components>& rows, unsigned n) {
  std::vector<unsigned> chosen;
  std::vector<Components> acc;
  for (unsigned r = 0; r < rows.size() && chosen.size() < n; ++r) {
    acc.push_back(rows[r]);
    if (rank_of_rows(acc, n) == acc.size()) {
      chosen.push_back(r);
    } else {
      acc.pop_back();
    }
  }
  return chosen;
}

}  // namespace

// ---------------------------------------------------------------- LieAlgebra

LieAlgebra::LieAlgebra(unsigned n, std::vector<ex> c, std::vector<std::string> names,
                       std::vector<matrix> basis)
    : n_(n), c_(std::move(c)), names_(std::move(names)), basis_(std::move(basis)) {
  if (names_.empty())
    for (unsigned i = 0; i < n_; ++i) names_.push_back(std::string("E") + std::to_string(i + 1));
}

LieAlgebra LieAlgebra::from_structure_constants(const std::vector<std::vector<std::vector<ex>>>& c,
                                                std::vector<std::string> names) {
  const auto n = static_cast<unsigned>(c.size());
  if (n == 0) throw LieError("lie_algebra", "a Lie algebra needs at least one basis element");
  if (!names.empty() && names.size() != n)
    throw LieError("lie_algebra", std::string("expected ") + std::to_string(n) + " basis names");
  std::vector<ex> flat;
  for (const auto& ci : c) {
    if (ci.size() != n) throw LieError("lie_algebra", "structure constants must be n×n×n");
    for (const auto& cij : ci) {
      if (cij.size() != n) throw LieError("lie_algebra", "structure constants must be n×n×n");
      for (const auto& x : cij) flat.push_back(x);
    }
  }
  LieAlgebra a(n, std::move(flat), std::move(names), {});
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i; j < n; ++j)
      for (unsigned k = 0; k < n; ++k)
        if (!zero(a.c(i, j, k) + a.c(j, i, k)))
          throw LieError("lie_algebra", "structure constants not antisymmetric: C_" +
                                            std::to_string(i + 1) + std::to_string(j + 1) + "^" +
                                            std::to_string(k + 1) + " + C_" +
                                            std::to_string(j + 1) + std::to_string(i + 1) + "^" +
                                            std::to_string(k + 1) + " ≠ 0");
  // Jacobi: [[E_i,E_j],E_k] + [[E_j,E_k],E_i] + [[E_k,E_i],E_j] = 0.
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i + 1; j < n; ++j)
      for (unsigned k = j + 1; k < n; ++k)
        for (unsigned l = 0; l < n; ++l) {
          ex s = 0;
          for (unsigned m = 0; m < n; ++m)
            s += a.c(i, j, m) * a.c(m, k, l) + a.c(j, k, m) * a.c(m, i, l) +
                 a.c(k, i, m) * a.c(m, j, l);
          if (!zero(s))
            throw LieError("lie_algebra", "the Jacobi identity fails for (" + a.names_[i] + ", " +
                                              a.names_[j] + ", " + a.names_[k] + "): component " +
                                              a.names_[l] + " is " + str(s.expand()));
        }
  return a;
}

LieAlgebra LieAlgebra::from_matrix_basis(const std::vector<matrix>& basis,
                                         std::vector<std::string> names) {
  const auto n = static_cast<unsigned>(basis.size());
  if (n == 0) throw LieError("lie_algebra", "a Lie algebra needs at least one basis element");
  if (!names.empty() && names.size() != n)
    throw LieError("lie_algebra", std::string("expected ") + std::to_string(n) + " basis names");
  const unsigned N = basis[0].rows();
  for (const auto& e : basis)
    if (e.rows() != N || e.cols() != N)
      throw LieError("lie_algebra", "basis matrices must all be square of the same size");
  if (names.empty())
    for (unsigned i = 0; i < n; ++i) names.push_back(std::string("E") + std::to_string(i + 1));

  // B: N²×n, column i = vec(E_i); rows as component lists.
  std::vector<Components> rows(N * N, Components(n));
  for (unsigned i = 0; i < n; ++i) {
    const Components v = vec(basis[i]);
    for (unsigned r = 0; r < N * N; ++r) rows[r][i] = v[r];
  }
  const std::vector<unsigned> sel = independent_rows(rows, n);
  if (sel.size() < n)
    throw LieError("lie_algebra", "the basis matrices are linearly dependent (rank " +
                                      std::to_string(sel.size()) + std::string(" < ") +
                                      std::to_string(n) +
                                      "): the parametrisation is not a chart at the identity");
  matrix bs(n, n);
  for (unsigned a = 0; a < n; ++a)
    for (unsigned i = 0; i < n; ++i) bs(a, i) = rows[sel[a]][i];
  const matrix bs_inv = bs.inverse();

  std::vector<ex> c(static_cast<std::size_t>(n) * n * n, ex(0));
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i + 1; j < n; ++j) {
      const matrix br = basis[i].mul(basis[j]).sub(basis[j].mul(basis[i]));
      const Components v = vec(br);
      matrix rhs(n, 1);
      for (unsigned a = 0; a < n; ++a) rhs(a, 0) = v[sel[a]];
      const matrix x = bs_inv.mul(rhs);
      // The solution must reproduce every entry: otherwise [E_i, E_j] ∉ span.
      for (unsigned r = 0; r < N * N; ++r) {
        ex s = -v[r];
        for (unsigned k = 0; k < n; ++k) s += rows[r][k] * x(k, 0);
        if (!zero(s))
          throw LieError("lie_algebra",
                         "[" + names[i] + ", " + names[j] + std::string("] = ") + str(br) +
                             " is not in the span of the basis: not the Lie algebra of a group "
                             "(the parametrisation is not a Lie group parametrisation)");
      }
      for (unsigned k = 0; k < n; ++k) {
        const ex ck = GiNaC::normal(x(k, 0));
        c[(i * n + j) * n + k] = ck;
        c[(j * n + i) * n + k] = -ck;
      }
    }
  return LieAlgebra(n, std::move(c), std::move(names), basis);
}

LieAlgebra LieAlgebra::gl(unsigned n) {
  std::vector<matrix> basis;
  std::vector<std::string> names;
  for (unsigned a = 0; a < n; ++a)
    for (unsigned b = 0; b < n; ++b) {
      matrix e(n, n);
      e(a, b) = 1;
      basis.push_back(e);
      std::ostringstream name;  // (not string concatenation: GCC 12 -Wrestrict false positive)
      name << 'E' << a + 1 << b + 1;
      names.push_back(name.str());
    }
  return from_matrix_basis(basis, std::move(names));
}

LieAlgebra LieAlgebra::so3() {
  // hat(x) = [[0, −x3, x2], [x3, 0, −x1], [−x2, x1, 0]], hat(x) y = x × y.
  std::vector<matrix> basis;
  for (unsigned i = 0; i < 3; ++i) {
    ex x[3] = {0, 0, 0};
    x[i] = 1;
    basis.push_back(matrix{{0, -x[2], x[1]}, {x[2], 0, -x[0]}, {-x[1], x[0], 0}});
  }
  return from_matrix_basis(basis, {"E1", "E2", "E3"});
}

Components LieAlgebra::bracket(const Components& x, const Components& y) const {
  Components out(n_, ex(0));
  for (unsigned i = 0; i < n_; ++i) {
    if (x[i].is_zero()) continue;
    for (unsigned j = 0; j < n_; ++j) {
      if (y[j].is_zero()) continue;
      for (unsigned k = 0; k < n_; ++k)
        if (!c(i, j, k).is_zero()) out[k] += c(i, j, k) * x[i] * y[j];
    }
  }
  for (auto& e : out) e = e.expand();
  return out;
}

matrix LieAlgebra::ad(const Components& xi) const {
  matrix m(n_, n_);
  for (unsigned k = 0; k < n_; ++k)
    for (unsigned j = 0; j < n_; ++j) {
      ex s = 0;
      for (unsigned i = 0; i < n_; ++i)
        if (!c(i, j, k).is_zero()) s += c(i, j, k) * xi[i];
      m(k, j) = s;
    }
  return m;
}

matrix LieAlgebra::coadjoint(const Components& xi) const {
  return ad(xi).transpose();
}

Components LieAlgebra::coadjoint_action(const Components& xi, const Components& zeta) const {
  const matrix m = coadjoint(xi);
  Components out(n_, ex(0));
  for (unsigned j = 0; j < n_; ++j) {
    ex s = 0;
    for (unsigned k = 0; k < n_; ++k)
      if (!m(j, k).is_zero()) s += m(j, k) * zeta[k];
    out[j] = s;
  }
  return out;
}

std::string LieAlgebra::format(const Components& x) const {
  std::ostringstream os;
  bool first = true;
  for (unsigned i = 0; i < x.size() && i < n_; ++i) {
    const ex e = GiNaC::normal(x[i]);
    if (e.is_zero()) continue;
    // Sign first ("E1 - E2", "-E1"), then the coefficient unless it is ±1.
    const bool neg =
        GiNaC::is_a<GiNaC::numeric>(e) && GiNaC::ex_to<GiNaC::numeric>(e).is_negative();
    const ex mag = neg ? ex(-e) : e;
    if (first)
      os << (neg ? "-" : "");
    else
      os << (neg ? " - " : " + ");
    if (mag != 1) os << "(" << mag << ")*";
    os << names_[i];
    first = false;
  }
  return first ? std::string("0") : os.str();
}

// --------------------------------------------------------------- MatrixGroup

namespace {

/// e(c0) = e.subs(at), at: c -> c0 the identity point. A pole there (GiNaC
/// throws from inside subs, e.g. "power::eval(): division by zero") is the
/// model's error: e is not defined at the identity, where every object of
/// the reduction is evaluated.
ex at_point(const ex& e, const std::vector<ex>& coords, const std::vector<ex>& c0,
            const std::string& what = "") {
  if (GiNaC::is_a<matrix>(e)) {  // entry by entry, so that the error names the entry
    matrix m = GiNaC::ex_to<matrix>(e);
    for (unsigned r = 0; r < m.rows(); ++r)
      for (unsigned c = 0; c < m.cols(); ++c)
        m(r, c) = at_point(m(r, c), coords, c0,
                           "entry (" + std::to_string(r + 1) + "," + std::to_string(c + 1) + ") ");
    return m;
  }
  GiNaC::exmap at;
  for (std::size_t i = 0; i < coords.size(); ++i) at[coords[i]] = c0[i];
  try {
    return e.subs(at);
  } catch (const std::exception& err) {
    std::string point;  // in the order of the coordinates (an exmap's order is GiNaC's)
    for (std::size_t i = 0; i < coords.size(); ++i)
      point += (i ? ", " : "") + str(coords[i]) + " = " + str(c0[i]);
    throw LieError("lie_algebra", what + str(e) + " is not defined at the identity point (" +
                                      point + "): " + err.what());
  }
}

LieAlgebra algebra_of(const matrix& g, const std::vector<ex>& coords, const std::vector<ex>& c0,
                      std::vector<std::string> names) {
  if (g.rows() != g.cols()) throw LieError("lie_algebra", "g(c) must be a square matrix");
  if (coords.empty() || coords.size() != c0.size())
    throw LieError("lie_algebra", "need one identity value per coordinate");
  for (const auto& c : coords)
    if (!GiNaC::is_a<GiNaC::symbol>(c))
      throw LieError("lie_algebra", std::string("coordinates must be symbols, got ") + str(c));
  const ex g0 = at_point(g, coords, c0);
  const matrix& g0m = GiNaC::ex_to<matrix>(g0);
  for (unsigned r = 0; r < g.rows(); ++r)
    for (unsigned c = 0; c < g.cols(); ++c)
      if (!zero(g0m(r, c) - (r == c ? 1 : 0)))
        throw LieError("lie_algebra", std::string("g(c0) is not the identity: entry (") +
                                          std::to_string(r + 1) + std::string(",") +
                                          std::to_string(c + 1) + ") is " + str(g0m(r, c)));
  std::vector<matrix> basis;
  for (const auto& c : coords) {
    matrix e = GiNaC::ex_to<matrix>(at_point(g.diff(as_symbol(c)), coords, c0));
    for (unsigned r = 0; r < e.rows(); ++r)
      for (unsigned k = 0; k < e.cols(); ++k) e(r, k) = GiNaC::normal(e(r, k));
    basis.push_back(e);
  }
  if (names.empty())
    for (const auto& c : coords) names.push_back(std::string("E_") + str(c));
  return LieAlgebra::from_matrix_basis(basis, std::move(names));
}

}  // namespace

MatrixGroup::MatrixGroup(matrix g, std::vector<ex> coords, std::vector<ex> identity_point,
                         std::vector<std::string> names)
    : g_(std::move(g)),
      coords_(std::move(coords)),
      c0_(std::move(identity_point)),
      algebra_(algebra_of(g_, coords_, c0_, std::move(names))) {
  const auto n = static_cast<unsigned>(coords_.size());
  const unsigned N = g_.rows();
  // J(c): N²×n, column j = vec(∂g/∂c_j); gE: N²×n, column i = vec(g E_i).
  std::vector<Components> j_rows(N * N, Components(n)), j0_rows(N * N, Components(n));
  std::vector<Components> ge_rows(N * N, Components(n));
  for (unsigned j = 0; j < n; ++j) {
    const Components v = vec(GiNaC::ex_to<matrix>(g_.diff(as_symbol(coords_[j]))));
    const Components v0 = vec(algebra_.matrices()[j]);
    for (unsigned r = 0; r < N * N; ++r) j_rows[r][j] = v[r], j0_rows[r][j] = v0[r];
  }
  for (unsigned i = 0; i < n; ++i) {
    const Components v = vec(g_.mul(algebra_.matrices()[i]));
    for (unsigned r = 0; r < N * N; ++r) ge_rows[r][i] = v[r];
  }
  // Rows where J(c0) is invertible; J(c) restricted to them is then invertible
  // near c0 (and generically), and L = J_R(c)⁻¹ (gE)_R.
  const std::vector<unsigned> sel = independent_rows(j0_rows, n);
  matrix js(n, n), rhs(n, n);
  for (unsigned a = 0; a < n; ++a)
    for (unsigned k = 0; k < n; ++k) js(a, k) = j_rows[sel[a]][k], rhs(a, k) = ge_rows[sel[a]][k];
  matrix l;
  try {
    l = js.inverse(GiNaC::solve_algo::gauss).mul(rhs);
  } catch (const std::exception& e) {
    throw LieError("lie_algebra", std::string("cannot express left translation in the coordinates "
                                              "(singular chart): ") +
                                      e.what());
  }
  for (unsigned a = 0; a < n; ++a)
    for (unsigned k = 0; k < n; ++k) l(a, k) = simplify(l(a, k));
  // Tangency: J(c) L = vec(g E) in every row, identically in c.
  for (unsigned r = 0; r < N * N; ++r)
    for (unsigned i = 0; i < n; ++i) {
      ex s = -ge_rows[r][i];
      for (unsigned k = 0; k < n; ++k) s += j_rows[r][k] * l(k, i);
      if (!zero(s))
        throw LieError("lie_algebra", "g(c)·" + algebra_.names()[i] +
                                          " is not tangent to the parametrised set: g(c) is not "
                                          "closed under multiplication (not a group)");
    }
  left_ = l;
}

MatrixGroup MatrixGroup::gl(unsigned n, const std::string& prefix) {
  matrix g(n, n);
  std::vector<ex> coords, c0;
  std::vector<std::string> names;
  for (unsigned a = 0; a < n; ++a)
    for (unsigned b = 0; b < n; ++b) {
      const std::string rc = std::to_string(a + 1) + std::to_string(b + 1);
      GiNaC::realsymbol s(prefix + rc);
      g(a, b) = s;
      coords.push_back(s);
      c0.push_back(a == b ? 1 : 0);
      names.push_back("E" + rc);
    }
  return MatrixGroup(g, coords, c0, names);
}

Components MatrixGroup::left_trivialized_differential(const ex& f) const {
  const auto n = static_cast<unsigned>(coords_.size());
  Components df;
  for (const auto& c : coords_) df.push_back(f.diff(as_symbol(c)));
  Components out(n, ex(0));
  for (unsigned i = 0; i < n; ++i) {
    ex s = 0;
    for (unsigned j = 0; j < n; ++j)
      if (!left_(j, i).is_zero()) s += df[j] * left_(j, i);
    out[i] = simplify(s);
  }
  return out;
}

Components MatrixGroup::differential_at_identity(const ex& f) const {
  Components out;
  for (const auto& c : coords_) out.push_back(simplify(at_identity(f.diff(as_symbol(c)))));
  return out;
}

ex MatrixGroup::at_identity(const ex& e) const {
  return at_point(e, coords_, c0_);
}

LieGroup::LieGroup(MatrixGroup group) : matrix_(std::move(group)) {}

LieGroup::LieGroup(LieAlgebra algebra) : algebra_(std::move(algebra)) {}

const LieAlgebra& LieGroup::algebra() const {
  return matrix_ ? matrix_->algebra() : *algebra_;
}

const MatrixGroup& LieGroup::matrix_group() const {
  if (!matrix_) throw InternalError("a group given by structure constants has no coordinates");
  return *matrix_;
}

const std::vector<ex>& LieGroup::coords() const {
  static const std::vector<ex> none;
  return matrix_ ? matrix_->coords() : none;
}

const matrix& LieGroup::left_trivialization() const {
  return matrix_group().left_trivialization();
}

matrix left_invariant_inertia(const MatrixGroup& group, const matrix& metric) {
  const auto n = static_cast<unsigned>(group.coords().size());
  if (metric.rows() != n || metric.cols() != n)
    throw InternalError("left_invariant_inertia: the metric must be n×n");
  const matrix& L = group.left_trivialization();
  const matrix body = L.transpose().mul(metric).mul(L);
  matrix out(n, n);
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) {
      const ex e = body(i, j);
      for (unsigned k = 0; k < n; ++k)
        if (!zero(e.diff(as_symbol(group.coords()[k]))))
          throw LieError("left_invariant",
                         "the metric is not left-invariant: the body inertia I = L^T M L has "
                         "I_" +
                             std::to_string(i + 1) + std::to_string(j + 1) + " = " +
                             str(simplify(e)) + ", which depends on the coordinate " +
                             str(group.coords()[k]) + " (I must be constant)");
      out(i, j) = simplify(group.at_identity(e));
    }
  return out;
}

// -------------------------------------------------------------- Lie–Poisson

std::vector<ex> make_symbols(unsigned n, const std::string& prefix) {
  std::vector<ex> out;
  for (unsigned i = 0; i < n; ++i) out.push_back(GiNaC::realsymbol(prefix + std::to_string(i + 1)));
  return out;
}

ex inertia_hamiltonian(const matrix& inertia, const std::vector<ex>& zeta) {
  const auto n = static_cast<unsigned>(zeta.size());
  if (inertia.rows() != n || inertia.cols() != n)
    throw LieError("quadratic", std::string("the inertia must be ") + std::to_string(n) + "×" +
                                    std::to_string(n));
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i + 1; j < n; ++j)
      if (!zero(inertia(i, j) - inertia(j, i)))
        throw LieError("quadratic", "the inertia must be symmetric");
  if (zero(inertia.determinant())) throw LieError("quadratic", "the inertia is singular");
  const matrix inv = inertia.inverse(GiNaC::solve_algo::gauss);
  ex h = 0;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j)
      if (!inv(i, j).is_zero()) h += zeta[i] * GiNaC::normal(inv(i, j)) * zeta[j];
  return (h / 2).expand();
}

LiePoisson lie_poisson(const LieAlgebra& g, const std::vector<ex>& zeta, const ex& h) {
  if (zeta.size() != g.dim())
    throw LieError("lie_algebra", std::string("need ") + std::to_string(g.dim()) + " momenta");
  LiePoisson lp;
  for (const auto& z : zeta) lp.dh.push_back(simplify(h.diff(as_symbol(z))));
  lp.ad_star = g.coadjoint(lp.dh);
  for (unsigned j = 0; j < g.dim(); ++j) {
    ex s = 0;
    for (unsigned k = 0; k < g.dim(); ++k)
      if (!lp.ad_star(j, k).is_zero()) s += lp.ad_star(j, k) * zeta[k];
    lp.zeta_dot.push_back(simplify(s));
  }
  return lp;
}

ex poisson_bracket(const LieAlgebra& g, const std::vector<ex>& zeta, const ex& f, const ex& k) {
  Components df, dk;
  for (const auto& z : zeta) df.push_back(f.diff(as_symbol(z))), dk.push_back(k.diff(as_symbol(z)));
  const Components br = g.bracket(df, dk);
  ex s = 0;
  for (unsigned i = 0; i < g.dim(); ++i) s -= zeta[i] * br[i];
  return simplify(s);
}

bool is_casimir(const LieAlgebra& g, const std::vector<ex>& zeta, const ex& casimir) {
  Components dc;
  for (const auto& z : zeta) dc.push_back(casimir.diff(as_symbol(z)));
  for (const auto& e : g.coadjoint_action(dc, Components(zeta.begin(), zeta.end())))
    if (!zero(e)) return false;
  return true;
}

ex lie_derivative(const ex& f, const std::vector<ex>& x, const Components& field) {
  ex s = 0;
  for (std::size_t j = 0; j < x.size(); ++j) s += f.diff(as_symbol(x[j])) * field[j];
  return simplify(s);
}

// ------------------------------------------------------- ideals / normality

std::vector<Components> kernel_of_form(const Components& form) {
  unsigned p = 0;
  while (p < form.size() && zero(form[p])) ++p;
  if (p == form.size())
    throw LieError("codim1", "dφ vanishes at the identity: ker dφ is not of codimension 1");
  std::vector<Components> out;
  for (unsigned j = 0; j < form.size(); ++j) {
    if (j == p) continue;
    Components v(form.size(), ex(0));
    v[j] = 1;
    v[p] = GiNaC::normal(-form[j] / form[p]);
    out.push_back(std::move(v));
  }
  return out;
}

IdealCheck check_ideal(const LieAlgebra& g, const std::vector<Components>& basis) {
  const unsigned n = g.dim();
  IdealCheck out;
  const auto m = static_cast<unsigned>(basis.size());
  if (rank_of_rows(basis, n) != m) {
    out.reason = "the given vectors of 𝔨 are linearly dependent";
    return out;
  }
  auto in_span = [&](const Components& v) {
    std::vector<Components> rows = basis;
    rows.push_back(v);
    return rank_of_rows(rows, n) == m;
  };
  auto name_of = [&](const Components& v) {
    // A basis vector of 𝔤 prints as its name, anything else as a combination.
    return g.format(v);
  };
  out.subalgebra = true;
  for (unsigned a = 0; a < m && out.subalgebra; ++a)
    for (unsigned b = a + 1; b < m; ++b) {
      const Components br = g.bracket(basis[a], basis[b]);
      if (!in_span(br)) {
        out.subalgebra = false;
        out.reason = "[" + name_of(basis[a]) + ", " + name_of(basis[b]) + "] = " + g.format(br) +
                     " ∉ 𝔨: 𝔨 is not even a subalgebra";
        break;
      }
    }
  if (!out.subalgebra) return out;
  for (unsigned i = 0; i < n; ++i) {
    Components e(n, ex(0));
    e[i] = 1;
    for (unsigned b = 0; b < m; ++b) {
      const Components br = g.bracket(e, basis[b]);
      if (!in_span(br)) {
        out.reason = "[" + g.names()[i] + ", " + name_of(basis[b]) + "] = " + g.format(br) +
                     " ∉ 𝔨: 𝔨 is not an ideal, so K is not a normal subgroup";
        return out;
      }
    }
  }
  out.ideal = true;
  return out;
}

std::vector<Components> codim1_ideal_forms(const LieAlgebra& g) {
  const unsigned n = g.dim();
  std::vector<Components> rows;  // spanning set of [𝔤, 𝔤]
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i + 1; j < n; ++j) {
      Components v(n);
      for (unsigned k = 0; k < n; ++k) v[k] = g.c(i, j, k);
      rows.push_back(std::move(v));
    }
  if (rows.empty()) rows.push_back(Components(n, ex(0)));
  return null_space(rows, n);
}

void require_normal_kernel(const LieAlgebra& g, const Components& form) {
  const IdealCheck c = check_ideal(g, kernel_of_form(form));
  if (!c.ideal)
    throw LieError("normal", "the impact surface is not a coset of a normal subgroup: " + c.reason);
}

// ------------------------------------------------------------ q equation

QEquation q_equation(const MatrixGroup& group, const ex& phi, const ex& level, const Components& xi,
                     const ex& q) {
  const auto n = static_cast<unsigned>(group.coords().size());
  if (xi.size() != n) throw LieError("lie_algebra", "ζ^♯ has the wrong number of components");
  QEquation out;
  out.dphi_e = group.differential_at_identity(phi);
  // r = dφ_g(g ξ) = ((ℓ_g)^* dφ_g)(ξ): the rate of φ along g' = g ξ.
  const Components sigma = group.left_trivialized_differential(phi);
  ex r = 0;
  for (unsigned i = 0; i < n; ++i) r += sigma[i] * xi[i];
  r = simplify(r);
  auto depends_on = [&](const ex& e) -> int {
    for (unsigned i = 0; i < n; ++i)
      if (!zero(e.diff(as_symbol(group.coords()[i])))) return static_cast<int>(i);
    return -1;
  };
  const int add_dep = depends_on(r);
  if (add_dep < 0) {
    out.kind = HomomorphismKind::Additive;
    out.q_dot = simplify(group.at_identity(r));
    return out;
  }
  const ex rho = simplify(r / phi);
  const int mul_dep = depends_on(rho);
  if (mul_dep < 0) {
    out.kind = HomomorphismKind::Multiplicative;
    out.q_dot = simplify((q + level) * group.at_identity(rho));
    return out;
  }
  throw LieError("coset",
                 std::string("q' = dφ(g ζ^♯) = ") + str(r) + " depends on the coordinate " +
                     str(group.coords()[static_cast<unsigned>(add_dep)]) +
                     std::string(" and not only on (ζ, q): the level sets of φ = ") + str(phi) +
                     " are not cosets of a normal subgroup (φ is not a homomorphism "
                     "to ℝ, ℝ* or S¹)");
}

QEquation q_equation_of_form(HomomorphismKind kind, const Components& dphi_e, const Components& xi,
                             const ex& q) {
  if (xi.size() != dphi_e.size())
    throw LieError("lie_algebra", "ζ^♯ has the wrong number of components");
  QEquation out;
  out.kind = kind;
  out.dphi_e = dphi_e;
  ex rate = 0;
  for (std::size_t i = 0; i < xi.size(); ++i) rate += dphi_e[i] * xi[i];
  out.q_dot = simplify(kind == HomomorphismKind::Multiplicative ? (q + 1) * rate : rate);
  return out;
}

// ----------------------------------------------------------- momentum jump

Components momentum_jump(const Components& sigma, const std::vector<ex>& zeta, const ex& h,
                         const ex& restitution) {
  const auto n = static_cast<unsigned>(zeta.size());
  if (sigma.size() != n) throw LieError("codim1", "σ has the wrong number of components");
  matrix hess(n, n);
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) {
      hess(i, j) = simplify(h.diff(as_symbol(zeta[i])).diff(as_symbol(zeta[j])));
      for (const auto& z : zeta)
        if (!zero(hess(i, j).diff(as_symbol(z))))
          throw LieError("quadratic",
                         "the reset of the corollary needs a Hamiltonian quadratic "
                         "in ζ (a metric); ∂²h/∂ζ∂ζ depends on " +
                             str(z));
    }
  ex quad = 0;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) quad += zeta[i] * hess(i, j) * zeta[j];
  if (!zero(h - quad / 2))
    throw LieError("quadratic",
                   "h is not a homogeneous quadratic form ½ ζᵀ H ζ (no potential or "
                   "linear terms allowed at the identity)");
  ex num = 0, den = 0;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = 0; j < n; ++j) {
      num += sigma[i] * hess(i, j) * zeta[j];
      den += sigma[i] * hess(i, j) * sigma[j];
    }
  if (zero(den))
    throw LieError("codim1", "σ(σ^♯) ≡ 0: the surface's conormal is null for the metric of h");
  Components out;
  for (unsigned i = 0; i < n; ++i)
    out.push_back(simplify(-(1 + restitution) * num / den * sigma[i]));
  return out;
}

}  // namespace hybgen::gen
