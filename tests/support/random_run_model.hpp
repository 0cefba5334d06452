#pragma once
/// \file random_run_model.hpp
/// Random hybrid models that hybgen can RUN, for the density-level differential campaign
/// (tests/validation/test_differential.cpp, scripts/differential.sh). random_model.hpp draws
/// models to test `derive`'s formulas; these are drawn so that their densities are worth
/// comparing: flows that neither blow up nor stall over the run, guards that the initial
/// density's mass reaches and crosses in their firing direction, resets that land near the
/// box, and a smooth initial density inside it. The model is kept as expression trees
/// (random_model.hpp's TreeNode), so that an independent tracer
/// (tests/support/independent_tracer.hpp) evaluates it without hybgen.
///
/// A model (random_run_model(seed), deterministic per seed) has n = 1–4 states x0…, 0–2
/// parameters p0… (flow coefficients), 1–3 modes and 1–3 guards:
///  - flows X^i = a_i + Σ_j b_ij x_j + c·sin(x_j + d) or c·cos(x_j): affine plus a bounded
///    nonlinearity, so every trajectory exists for all time (|X| ≤ A + B|x|) in both
///    directions — the backward characteristics leave the box and the tracer follows them
///    in the whole space, as hybgen's does;
///  - a guard from mode a to mode b (a = b with one mode) is s = α x_k + Σ_j c_j x_j
///    [+ 0.2 sin x_j] − c through the point P that the initial density's centre reaches
///    after a fraction of the run in mode a, with x_k the flow's largest component there and
///    the crossing direction the one the flow has at P, so that mass does cross it;
///  - a reset: `identity` (between two modes), affine Δ(x) = A x + b with |det A| ≥ 0.3, or
///    triangular Δ_i = d_i x_i + e_i x_i³ + h_i(x_j, j < i) + b_i (d_i e_i > 0: a
///    diffeomorphism of the whole space), its offset chosen so that Δ(P) lies in the box;
///  - initial exp(−Σ k_i (x_i − c_i)²), c in the inner half of the box;
///  - one model in three with 2 or 4 states is MECHANICAL: the first half of the states are
///    coordinates q, the second their momenta p, each mode `hamiltonian Σ p_i²/(2m) + V(q)`
///    (V: linear, quadratic and a sine; the tracer gets the flow q' = p/m, p' = −∇V written
///    here), the guards' surfaces affine in q, and their resets (one in two) `restitution e`,
///    which the tracer applies as p⁺ = p − (1 + e)(∇s·p/∇s·∇s)∇s (M = m·I) written here;
///  - one model in four has a `support` line, a half-space c·x ≥ d that cuts a corner off
///    the box, so that the state space ends inside the box;
///  - one model in three with two modes splits the initial density between them by `where`
///    lines w(x) > 0 and w(x) < 0 (w affine);
///  - one guard in five is a trap instead (`reset absorb`: its mass leaves the system), drawn
///    from a stream of its own after the rest, so that the other draws, and every model
///    without a trap, are those of the seed before traps existed.
/// The simulation block gives the box, a grid of about 600–2400 nodes, t_end and two output
/// intervals.

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "support/random_model.hpp"

namespace hybgen::testing {

/// A reset family of random_run_model.
enum class RunResetKind {
  Identity,     ///< `reset identity` (two different modes).
  Affine,       ///< Δ = A x + b.
  Triangular,   ///< Δ_i = d_i x_i + e_i x_i³ + h_i(earlier states) + b_i.
  Restitution,  ///< `restitution e` of a mechanical model.
  Absorb,       ///< `reset absorb`: a trap (RandomRunModel::absorbing).
};

/// A runnable random model: random_model.hpp's representation plus what a run needs.
struct RandomRunModel {
  RandomModel model;                ///< States, parameters, box, modes, guards, text.
  std::vector<RunResetKind> kinds;  ///< Per guard: its reset's family.
  std::vector<double> centre;       ///< The initial density's centre c.
  std::vector<double> rate;         ///< Its k_i (u0 = exp(−Σ k_i (x_i − c_i)²)).
  Tree initial;                     ///< u0 as a tree.
  Tree support;                     ///< The state space is support ≥ 0 (null: everywhere).
  Tree where;                       ///< Two modes: m0 where w > 0, m1 where w < 0 (or null).
  bool mechanical = false;          ///< Hamiltonian modes (see the file comment).
  std::vector<Tree> hamiltonians;   ///< Per mode, when mechanical: H as printed.
  std::vector<double> restitution;  ///< Per guard: e of `restitution e`, or −1.
  /// Per guard: whether it absorbs (`reset absorb`; its drawn reset and target are unused).
  std::vector<char> absorbing;
  std::vector<int> grid;  ///< Nodes per axis.
  double t_end = 1;       ///< Final time (frames at 0, t_end/2, t_end).
};

namespace detail {

/// The generator behind random_run_model (one object per model).
class RunModelGenerator : RandomDraws {
 public:
  /// Seed the engine (the seed is mixed so that nearby seeds give unrelated models).
  explicit RunModelGenerator(std::uint64_t seed) : RandomDraws(seed * 0x9E3779B97F4A7C15ULL + 17) {
    r_.model.seed = seed;
  }

  /// Draw the whole model and print its text.
  RandomRunModel run() {
    RandomModel& m = r_.model;
    const double ru = uniform();
    n_ = ru < 0.25 ? 1 : ru < 0.65 ? 2 : ru < 0.9 ? 3 : 4;
    r_.mechanical = n_ % 2 == 0 && chance(0.35);
    mass_ = chance(0.5) ? 1 : 2;
    for (int i = 0; i < n_; ++i) m.states.push_back("x" + std::to_string(i));
    const int np = integer(0, 2);
    for (int i = 0; i < np; ++i) {
      const Tree c = constant(integer(2, 12) * (chance(0.3) ? -1 : 1), 1);
      m.params.push_back({"p" + std::to_string(i), c->text, c->value});
    }
    for (int i = 0; i < n_; ++i) {
      const double lo = -0.5 * integer(1, 4);
      m.lo.push_back(lo);
      m.hi.push_back(lo + 0.5 * integer(4, 6));
    }
    for (int i = 0; i < n_; ++i) {
      const double w = m.hi[i] - m.lo[i];
      r_.centre.push_back(m.lo[i] + w * (0.25 + 0.5 * uniform()));
      r_.centre[i] = std::round(r_.centre[i] * 100) / 100;
      // σ between 8 % and 16 % of the box's width: k = 1/(2σ²).
      const double sigma = w * (0.08 + 0.08 * uniform());
      r_.rate.push_back(std::round(10.0 / (2 * sigma * sigma)) / 10);
    }
    r_.t_end = 0.5 * integer(1, 3);
    const int nm = integer(1, 3);
    for (int k = 0; k < nm; ++k) {
      RandomMode md;
      md.name = "m" + std::to_string(k);
      if (r_.mechanical)
        mechanical_mode(md);
      else
        for (int i = 0; i < n_; ++i) md.flow.push_back(flow_component(i));
      m.modes.push_back(std::move(md));
    }
    const int ng = integer(1, 3);
    for (int gi = 0; gi < ng; ++gi) make_guard(gi);
    r_.initial = initial_tree();
    if (chance(0.25)) r_.support = half_space(true);
    if (nm == 2 && chance(0.33)) r_.where = half_space(false);
    r_.grid = n_ == 1   ? std::vector<int>{81}
              : n_ == 2 ? std::vector<int>{25, 25}
              : n_ == 3 ? std::vector<int>{9, 9, 9}
                        : std::vector<int>{7, 7, 7, 7};
    // Traps, from their own stream (the file comment).
    std::mt19937_64 traps(m.seed * 0xD1B54A32D192ED03ULL + 0x7A7);
    for (std::size_t g = 0; g < m.guards.size(); ++g) {
      r_.absorbing.push_back(traps() % 5 == 0 ? 1 : 0);
      if (r_.absorbing.back()) r_.kinds[g] = RunResetKind::Absorb;
    }
    m.has_simulation = true;
    m.text = print();
    return std::move(r_);
  }

 private:
  /// A coefficient: a decimal, or (one time in five, when there are parameters) a parameter.
  Tree coefficient(int lo_units, int hi_units) {
    const int np = static_cast<int>(r_.model.params.size());
    if (np > 0 && chance(0.2)) return parameter(integer(0, np - 1));
    return signed_decimal(lo_units, hi_units, 1);
  }
  static Tree sum(const std::vector<Tree>& terms) {
    Tree s = terms.at(0);
    for (std::size_t i = 1; i < terms.size(); ++i) s = add(s, terms[i]);
    return s;
  }
  std::vector<double> params() const { return r_.model.parameter_values(); }
  std::vector<double> eval_all(const std::vector<Tree>& f, const std::vector<double>& x) const {
    std::vector<double> out;
    for (const Tree& t : f) out.push_back(evaluate(t, x, params()));
    return out;
  }

  // ---- flows: a_i + Σ b_ij x_j + a bounded nonlinearity
  Tree flow_component(int i) {
    std::vector<Tree> terms{coefficient(0, 15)};
    for (int j = 0; j < n_; ++j)
      if (j == i ? chance(0.6) : chance(0.35)) terms.push_back(mul(coefficient(1, 8), state(j)));
    if (chance(0.5)) {
      const int j = integer(0, n_ - 1);
      terms.push_back(
          mul(signed_decimal(1, 6, 1),
              chance(0.5) ? sin_of(add(state(j), signed_decimal(0, 10, 1))) : cos_of(state(j))));
    }
    return sum(terms);
  }

  /// A constant node holding the double v (for the tracer's trees only: never printed).
  static Tree raw(double v) {
    auto c = std::make_shared<TreeNode>();
    c->op = TreeOp::Constant;
    c->value = v;
    c->text = "?";
    return c;
  }

  // ---- Hamiltonian modes: H = Σ p_i²/(2m) + V(q), V = Σ (a_i q_i + b_i q_i²/2) + c sin q_j
  void mechanical_mode(RandomMode& md) {
    const int dof = n_ / 2;
    std::vector<Tree> h, force(static_cast<std::size_t>(dof));
    for (int i = 0; i < dof; ++i)
      h.push_back(mul(constant(mass_ == 1 ? 5 : 25, mass_ == 1 ? 1 : 2), power(state(dof + i), 2)));
    for (int i = 0; i < dof; ++i) {
      const Tree a = signed_decimal(0, 15, 1), b = signed_decimal(0, 10, 1);
      h.push_back(mul(a, state(i)));
      h.push_back(mul(mul(constant(5, 1), b), power(state(i), 2)));
      force[i] = add(a, mul(b, state(i)));  // ∂V/∂q_i without the sine
    }
    if (chance(0.5)) {
      const int j = integer(0, dof - 1);
      const Tree c = signed_decimal(1, 5, 1);
      h.push_back(mul(c, sin_of(state(j))));
      force[j] = add(force[j], mul(c, cos_of(state(j))));
    }
    r_.hamiltonians.push_back(sum(h));
    for (int i = 0; i < dof; ++i) md.flow.push_back(mul(raw(1.0 / mass_), state(dof + i)));
    for (int i = 0; i < dof; ++i) md.flow.push_back(neg(force[i]));
  }

  /// c·x − d, c a random direction: through a point of the box's middle half (a `where`
  /// split), or (`corner`, a support) cutting off the 15 % of the box's range of c·x at its
  /// low end, so that the state space is most of the box and most resets land in it (a
  /// plane through the middle had 22 of 179 models refused for images outside it).
  Tree half_space(bool corner) {
    std::vector<Tree> terms;
    std::vector<double> point(static_cast<std::size_t>(n_));
    double low = 0, high = 0;  // the range of c·x over the box
    for (int i = 0; i < n_; ++i) {
      const double lo = r_.model.lo[i], w = r_.model.hi[i] - lo;
      point[i] = lo + w * (0.25 + 0.5 * uniform());
      const Tree ci = signed_decimal(1, 10, 1);
      low += std::fmin(ci->value * lo, ci->value * (lo + w));
      high += std::fmax(ci->value * lo, ci->value * (lo + w));
      terms.push_back(mul(ci, state(i)));
    }
    const Tree c = sum(terms);
    const double d = corner ? low + 0.15 * (high - low) : evaluate(c, point, params());
    return sub(c, constant(std::llround(d * 1000), 3));
  }

  // ---- the initial density
  Tree initial_tree() const {
    std::vector<Tree> terms;
    for (int i = 0; i < n_; ++i) {
      const Tree k = constant(std::llround(r_.rate[i] * 10), 1);
      const Tree c = constant(std::llround(r_.centre[i] * 100), 2);
      terms.push_back(mul(k, power(sub(state(i), c), 2)));
    }
    return exp_of(neg(sum(terms)));
  }

  // ---- guards
  /// Where the initial density's centre is after time τ in mode `mode` (RK4, 50 steps).
  std::vector<double> advance(int mode, double tau) const {
    std::vector<double> x = r_.centre;
    const auto& f = r_.model.modes[static_cast<std::size_t>(mode)].flow;
    const double h = tau / 50;
    for (int s = 0; s < 50; ++s) {
      auto k1 = eval_all(f, x);
      std::vector<double> y(x.size());
      for (std::size_t i = 0; i < x.size(); ++i) y[i] = x[i] + 0.5 * h * k1[i];
      auto k2 = eval_all(f, y);
      for (std::size_t i = 0; i < x.size(); ++i) y[i] = x[i] + 0.5 * h * k2[i];
      auto k3 = eval_all(f, y);
      for (std::size_t i = 0; i < x.size(); ++i) y[i] = x[i] + h * k3[i];
      auto k4 = eval_all(f, y);
      for (std::size_t i = 0; i < x.size(); ++i)
        x[i] += h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
    }
    return x;
  }

  /// A point of the box's inner 80 % per axis (the nearest one to x).
  std::vector<double> clamp_inside(std::vector<double> x) const {
    for (int i = 0; i < n_; ++i) {
      const double lo = r_.model.lo[i], w = r_.model.hi[i] - lo;
      x[i] = std::fmin(std::fmax(x[i], lo + 0.1 * w), lo + 0.9 * w);
    }
    return x;
  }

  void make_guard(int gi) {
    RandomModel& m = r_.model;
    RandomGuard g;
    g.name = "g" + std::to_string(gi);
    const int nm = static_cast<int>(m.modes.size());
    g.from = integer(0, nm - 1);
    g.to = nm == 1 ? 0 : integer(0, nm - 1);
    // P: where the centre is after a fraction of the run in the source mode (in the box).
    std::vector<double> P = advance(g.from, r_.t_end * (0.2 + 0.5 * uniform()));
    if (clamp_inside(P) != P)  // out of the box's inner 80 %: a random point of it instead
      for (int i = 0; i < n_; ++i)
        P[i] = r_.model.lo[i] + (r_.model.hi[i] - r_.model.lo[i]) * (0.1 + 0.8 * uniform());
    const std::vector<double> XP = eval_all(m.modes[static_cast<std::size_t>(g.from)].flow, P);
    // The surface's variables: every state, or the coordinates of a mechanical model.
    const int nv = r_.mechanical ? n_ / 2 : n_;
    int k = 0;
    for (int i = 1; i < nv; ++i)
      if (std::fabs(XP[i]) > std::fabs(XP[k])) k = i;
    g.pivot = k;
    std::vector<Tree> terms{mul(signed_decimal(5, 15, 1), state(k))};
    for (int j = 0; j < nv; ++j)
      if (j != k && chance(0.5)) terms.push_back(mul(signed_decimal(1, 5, 1), state(j)));
    if (!r_.mechanical && n_ > 1 && chance(0.3)) {
      int j = k;
      while (j == k) j = integer(0, n_ - 1);
      terms.push_back(mul(constant(2, 1), sin_of(state(j))));
    }
    Tree s = sum(terms);
    // Through P: subtract s(P), rounded to 3 decimals (the surface moves by < 1e-3).
    const double sP = evaluate(s, P, params());
    g.surface = sub(s, constant(std::llround(sP * 1000), 3));
    // The crossing direction of the flow at P (a flow tangent there: either).
    std::vector<Dual<double>> xd;
    double ds = 0;
    for (int i = 0; i < n_; ++i) {
      for (int j = 0; j < n_; ++j) xd.push_back({P[j], i == j ? 1.0 : 0.0});
      std::vector<Dual<double>> pd;
      for (double p : params()) pd.push_back({p, 0.0});
      ds += evaluate(g.surface, xd, pd).d * XP[i];
      xd.clear();
    }
    g.decreasing = ds < 0;
    make_reset(g, P);
    m.guards.push_back(std::move(g));
  }

  void make_reset(RandomGuard& g, const std::vector<double>& P) {
    const double r = uniform();
    r_.restitution.push_back(-1.0);
    if (r_.mechanical && chance(0.5)) {
      // restitution e: p⁺ = p − (1 + e)(∇s·p / ∇s·∇s) ∇s, q⁺ = q (∇s in q, constant here).
      const Tree e = constant(integer(3, 10), 1);
      r_.restitution.back() = e->value;
      const int dof = n_ / 2;
      std::vector<double> ds(static_cast<std::size_t>(dof));
      double dd = 0;
      for (int j = 0; j < dof; ++j) {
        std::vector<Dual<double>> xd, pd;
        for (int i = 0; i < n_; ++i) xd.push_back({P[i], i == j ? 1.0 : 0.0});
        for (double v : params()) pd.push_back({v, 0.0});
        ds[j] = evaluate(g.surface, xd, pd).d;
        dd += ds[j] * ds[j];
      }
      for (int i = 0; i < dof; ++i) g.reset.push_back(state(i));
      for (int i = 0; i < dof; ++i) {
        std::vector<Tree> terms{state(dof + i)};
        for (int j = 0; j < dof; ++j)
          terms.push_back(mul(raw(-(1 + e->value) * ds[i] * ds[j] / dd), state(dof + j)));
        g.reset.push_back(sum(terms));
      }
      g.inverse = InverseExpectation::ClosedForm;
      g.kind = "restitution";
      r_.kinds.push_back(RunResetKind::Restitution);
      return;
    }
    if (g.from != g.to && r < 0.25) {
      g.identity_keyword = true;
      for (int i = 0; i < n_; ++i) g.reset.push_back(state(i));
      g.inverse = InverseExpectation::ClosedForm;
      g.kind = "identity";
      r_.kinds.push_back(RunResetKind::Identity);
      return;
    }
    // Where Δ(P) should land: a random point of the box's inner 80 %.
    std::vector<double> Q(static_cast<std::size_t>(n_));
    for (int i = 0; i < n_; ++i)
      Q[i] = r_.model.lo[i] + (r_.model.hi[i] - r_.model.lo[i]) * (0.1 + 0.8 * uniform());
    std::vector<Tree> body(static_cast<std::size_t>(n_));
    const bool triangular = r < 0.6;
    if (!triangular) {
      // A = I + E with |det A| ≥ 0.3 (redrawn until it is).
      for (int attempt = 0;; ++attempt) {
        std::vector<std::vector<Tree>> A(n_, std::vector<Tree>(n_));
        std::vector<std::vector<double>> a(n_, std::vector<double>(n_));
        for (int i = 0; i < n_; ++i)
          for (int j = 0; j < n_; ++j) {
            A[i][j] = i == j        ? constant(integer(5, 15) * (chance(0.2) ? -1 : 1), 1)
                      : chance(0.4) ? signed_decimal(1, 5, 1)
                                    : nullptr;
            a[i][j] = A[i][j] ? A[i][j]->value : 0.0;
          }
        if (std::fabs(det(a)) < 0.3 && attempt < 50) continue;
        for (int i = 0; i < n_; ++i) {
          std::vector<Tree> terms;
          for (int j = 0; j < n_; ++j)
            if (A[i][j]) terms.push_back(mul(A[i][j], state(j)));
          body[i] = sum(terms);
        }
        break;
      }
      g.kind = "affine";
      r_.kinds.push_back(RunResetKind::Affine);
    } else {
      for (int i = 0; i < n_; ++i) {
        const long long d = integer(5, 15) * (chance(0.2) ? -1 : 1);
        std::vector<Tree> terms{mul(constant(d, 1), state(i))};
        if (chance(0.5))
          terms.push_back(mul(constant((d > 0 ? 1 : -1) * integer(1, 3), 1), power(state(i), 3)));
        for (int j = 0; j < i; ++j)
          if (chance(0.4))
            terms.push_back(
                mul(signed_decimal(1, 4, 1), chance(0.5) ? sin_of(state(j)) : power(state(j), 2)));
        body[i] = sum(terms);
      }
      g.kind = "triangular";
      r_.kinds.push_back(RunResetKind::Triangular);
    }
    // Offsets b = Q − body(P), rounded to 2 decimals.
    for (int i = 0; i < n_; ++i) {
      const double b = Q[i] - evaluate(body[i], P, params());
      g.reset.push_back(add(body[i], constant(std::llround(b * 100), 2)));
    }
    g.inverse = triangular ? InverseExpectation::Numeric : InverseExpectation::ClosedForm;
  }

  static double det(const std::vector<std::vector<double>>& a) {
    const std::size_t n = a.size();
    if (n == 1) return a[0][0];
    if (n == 2) return a[0][0] * a[1][1] - a[0][1] * a[1][0];
    return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
           a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
           a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
  }

  // ---- printing
  static std::string number(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v + 0.0);  // box ends are multiples of 0.5: exact
    return b;
  }

  std::string print() const {
    const RandomModel& m = r_.model;
    std::vector<std::string> pnames;
    for (const auto& p : m.params) pnames.push_back(p.name);
    auto text = [&](const Tree& t) { return to_text(t, m.states, pnames); };
    std::string s = "# random model, seed " + std::to_string(m.seed) +
                    " (tests/support/random_run_model.hpp)\nmodel random_run_" +
                    std::to_string(m.seed) + "\n";
    for (const auto& p : m.params) s += "parameter " + p.name + " = " + p.text + "\n";
    s += "state ";
    for (std::size_t i = 0; i < m.states.size(); ++i) s += (i ? ", " : "") + m.states[i];
    s += "\n";
    for (std::size_t k = 0; k < m.modes.size(); ++k) {
      const RandomMode& md = m.modes[k];
      s += "mode " + md.name + " {\n";
      if (r_.mechanical)
        s += "  hamiltonian " + text(r_.hamiltonians[k]) + "\n";
      else
        for (std::size_t i = 0; i < md.flow.size(); ++i)
          s += "  " + m.states[i] + "' = " + text(md.flow[i]) + "\n";
      if (r_.where)
        s += std::string("  where ") + text(r_.where) + (k == 0 ? " > 0" : " < 0") + "\n";
      s += "}\n";
    }
    for (const auto& g : m.guards) {
      const auto gi = static_cast<std::size_t>(&g - m.guards.data());
      const bool trap = gi < r_.absorbing.size() && r_.absorbing[gi];
      s += "guard " + g.name + " {\n";
      if (m.modes.size() > 1) {
        s += "  from " + m.modes[static_cast<std::size_t>(g.from)].name;
        if (g.to != g.from && !trap) s += " to " + m.modes[static_cast<std::size_t>(g.to)].name;
        s += "\n";
      }
      s += "  when " + text(g.surface) + " = 0 " + (g.decreasing ? "decreasing" : "increasing") +
           "\n";
      const double e = r_.restitution[gi];
      if (trap) {
        s += "  reset absorb\n";
      } else if (g.identity_keyword) {
        s += "  reset identity\n";
      } else if (e >= 0) {
        s += "  reset restitution " + number(e) + "\n";
      } else {
        s += "  reset (";
        for (std::size_t i = 0; i < g.reset.size(); ++i) s += (i ? ", " : "") + text(g.reset[i]);
        s += ")\n";
      }
      s += "}\n";
    }
    s += "simulation {\n";
    for (std::size_t i = 0; i < m.states.size(); ++i)
      s += "  domain " + m.states[i] + " in [" + number(m.lo[i]) + ", " + number(m.hi[i]) + "]\n";
    std::string grid;
    for (std::size_t i = 0; i < r_.grid.size(); ++i)
      grid += (i ? "x" : "") + std::to_string(r_.grid[i]);
    s += "  grid " + grid + "\n";
    s += "  initial " + text(r_.initial) + "\n";
    if (r_.support) s += "  support " + text(r_.support) + " >= 0\n";
    s += "  t_end " + number(r_.t_end) + "\n";
    s += "  dt " + number(r_.t_end / 2) + "\n";
    s += "}\n";
    return s;
  }

  RandomRunModel r_;
  int n_ = 1;
  int mass_ = 1;  ///< m of a mechanical model's kinetic energy p²/(2m).
};

}  // namespace detail

/// The runnable random model of `seed` (deterministic: the same seed, the same model).
inline RandomRunModel random_run_model(std::uint64_t seed) {
  return detail::RunModelGenerator(seed).run();
}

}  // namespace hybgen::testing
