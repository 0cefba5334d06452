#pragma once
/// \file model.hpp
/// The two representations after the parser:
///  - `Model`: the checked model (stage 2, `check`): every name resolved, every
///    expression a GiNaC expression in the model's symbols, every default
///    evaluated; still exactly what the user wrote (no derivation yet);
///  - `HybridSystem`: the IR (stage 3, `derive`): per mode the vector field and
///    its divergence, per guard the surface, reset, inverse reset and hybrid
///    Jacobian. The emitter and the runtime see only the IR.

#include <ginac/ginac.h>

#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/limits.hpp"

#include "hybgen/rt/settings.hpp"

namespace hybgen::gen {

/// A relation `expr OP 0` with OP one of <, <=, >, >= (lhs − rhs moved left).
struct Condition {
  GiNaC::ex expr;  ///< lhs − rhs.
  std::string op;  ///< "<", "<=", ">", ">=".
  SourceLoc loc;   ///< Where it was written.
};

/// A parameter with its exact default value.
struct Parameter {
  std::string name;    ///< Name.
  GiNaC::ex symbol;    ///< Its realsymbol.
  GiNaC::ex value;     ///< Exact default (rational, or an exact constant expression).
  double value_d = 0;  ///< The default as a double (finite).
  SourceLoc loc;       ///< Where it was declared.
};

/// A checked mode: explicit flow or a Hamiltonian (exactly one is set).
struct ModeSpec {
  std::string name;                      ///< Mode name.
  SourceLoc loc;                         ///< Where it was declared.
  std::vector<GiNaC::ex> flow;           ///< X^i (state order) when given explicitly.
  std::optional<GiNaC::ex> hamiltonian;  ///< H(q, p) when given.
  std::vector<int> coordinates;          ///< State indices of q (Hamiltonian modes).
  std::vector<int> momenta;              ///< State indices of p (Hamiltonian modes).
  std::vector<Condition> where;          ///< Region of the mode.
};

/// A checked guard.
struct GuardSpec {
  std::string name;       ///< Guard name.
  SourceLoc loc;          ///< Where it was declared.
  int from = 0;           ///< Source mode.
  int to = 0;             ///< Target mode; −1 for an absorbing guard (`reset absorb`).
  GiNaC::ex surface;      ///< s(x); the guard is s = 0.
  SourceLoc surface_loc;  ///< Where `when` was written.
  Direction direction = Direction::Decreasing;             ///< Crossing direction.
  SourceLoc direction_loc;                                 ///< Where the direction word is.
  ResetDecl::Kind reset_kind = ResetDecl::Kind::Identity;  ///< Form of the reset.
  GiNaC::ex restitution;                                   ///< e for Elastic (1) / Restitution.
  std::vector<GiNaC::ex> reset;  ///< Explicit components (Kind::Explicit).
  SourceLoc reset_loc;           ///< Where `reset` was written.
};

/// An observable (`observe NAME = [MODE:] EXPR`, or `--set observe.NAME=EXPR`): f(x, mode),
/// whose expectation over the density the runner reports per output time
/// (runtime/include/hybgen/rt/methods/observables.hpp).
struct Observable {
  std::string name;                 ///< Its name (summary.json, run.nc, the report).
  std::vector<GiNaC::ex> per_mode;  ///< f in each mode (0 in the modes it is not given in).
  int mode = -1;                    ///< The one mode it is given in (`MODE:`), or -1: every mode.
  SourceLoc loc;                    ///< Where it was written.
};

/// Simulation settings (defaults from the model, overridable by --set).
struct Simulation {
  bool present = false;                 ///< Whether the model had a block.
  SourceLoc loc;                        ///< Where it was written.
  std::vector<double> lo, hi;           ///< Domain per state variable.
  std::vector<long> grid;               ///< Nodes per axis.
  std::vector<GiNaC::ex> initial;       ///< Initial density per mode (0 if none).
  std::vector<Condition> support;       ///< State-space restriction.
  std::vector<Observable> observables;  ///< Observables, in order.
  /// Method, times and every method setting (runtime/include/hybgen/rt/settings.hpp: the
  /// table both sides share). dt is resolved (t_end/10 unless given) after the block.
  rt::Settings settings;
};

/// What the reduce stage derived for a Lie-group model (paper §3.2): carried by
/// the reduced Model so that derive's output can show it (derive JSON
/// `reduction` block). Every expression is in the momenta ζ, q and the
/// parameters, except `phi` (in the group coordinates).
struct Reduction {
  std::string group;                              ///< Group name (e.g. "A").
  std::vector<std::string> coordinates;           ///< Coordinates c_i of the group.
  std::vector<std::string> basis;                 ///< Names of E_i = ∂g/∂c_i(c0).
  unsigned algebra_dim = 0;                       ///< n = dim 𝔤.
  std::vector<std::string> momenta;               ///< ζ_1..ζ_n (state names).
  std::string q;                                  ///< Name of the reduced coordinate on K\G.
  std::vector<GiNaC::ex> structure_constants;     ///< C_ij^k at [(i n + j) n + k].
  std::vector<std::vector<std::string>> bracket;  ///< [E_i, E_j] as text, e.g. "E12 - E21".
  GiNaC::ex hamiltonian;                          ///< h(ζ) = H restricted to 𝔤*.
  std::vector<GiNaC::ex> dh;                      ///< ζ^♯ = ∂h/∂ζ.
  GiNaC::matrix coadjoint;                        ///< ad*_{∂h/∂ζ} acting on column vectors ζ.
  GiNaC::ex phi;                                  ///< The homomorphism φ(g) (coordinates).
  GiNaC::ex level;                                ///< q = φ(g) − level.
  bool multiplicative = false;                    ///< φ: G → ℝ* (det) rather than ℝ or S¹.
  std::vector<GiNaC::ex> dphi_e;                  ///< dφ at the identity; 𝔨 = ker dφ_e.
  GiNaC::ex q_dot;                                ///< q' (the theorem's d π (ℓ_σ)_* ζ^♯).
  std::vector<std::vector<GiNaC::ex>> momentum_jumps;  ///< Δζ per guard.
  bool normal = true;                                  ///< 𝔨 is an ideal (K normal).
  bool codim1 = true;                                  ///< 𝔨 has codimension 1.
  bool left_invariant = true;                          ///< H is left-invariant (h given on 𝔤*).
  bool transversal = true;  ///< On every guard q = c, q' restricted to the surface is not ≡ 0.
  /// Nonholonomic (`velocities`/`constraint`): the state holds body velocities
  /// w (ξ = ξ(w), `dh` = ξ) and `momentum_jumps` are jumps Δw, not Δζ.
  bool constrained = false;
};

/// The checked model (output of `check`).
struct Model {
  std::string name;                        ///< Model name.
  std::string path;                        ///< Source path (diagnostics only).
  std::string source_hash;                 ///< Hash of the source text.
  std::vector<std::string> state;          ///< State names in order.
  std::vector<GiNaC::ex> state_symbols;    ///< Their realsymbols.
  std::vector<Parameter> params;           ///< Parameters in order.
  std::vector<ModeSpec> modes;             ///< Modes.
  std::vector<GuardSpec> guards;           ///< Guards.
  Simulation sim;                          ///< Simulation defaults.
  std::map<std::string, std::string> tex;  ///< TeX names of symbols (theta -> \theta).
  DeriveLimits limits;                     ///< Resource limits of derive (--set).
  std::optional<Reduction> reduction;      ///< Set when reduced from a Lie-group model.
};

/// A mode of the IR.
struct IrMode {
  std::string name;                      ///< Mode name.
  std::vector<GiNaC::ex> flow;           ///< X^i in state order.
  GiNaC::ex divergence;                  ///< Σ ∂X^i/∂x^i.
  std::optional<GiNaC::ex> hamiltonian;  ///< Source Hamiltonian, if any.
  std::vector<Condition> where;          ///< Region.
};

/// A guard of the IR.
struct IrGuard {
  std::string name;  ///< Guard name.
  int from = 0;      ///< Source mode.
  int to = 0;        ///< Target mode; −1 for an absorbing guard (`absorbing`).
  /// `reset absorb`: the mass that reaches the guard leaves the system. The guard has a
  /// surface, its gradient and a direction only: no reset, inverse or hybrid Jacobian (their
  /// kernels' cases give NaN; the runtime never calls them: rt::GuardInfo::to = −1).
  bool absorbing = false;
  GiNaC::ex surface;                            ///< s(x).
  std::vector<GiNaC::ex> gradient;              ///< ∇s.
  Direction direction = Direction::Decreasing;  ///< Crossing direction.
  std::vector<GiNaC::ex> reset;                 ///< Δ(x).
  std::vector<GiNaC::ex> reset_jacobian;        ///< DΔ(x), row-major N×N.
  bool has_inverse = false;                     ///< Whether `reset_inverse` is symbolic.
  /// No inverse at all: DΔ is singular everywhere, but Δ is injective on the guard (a
  /// constant component). Only the forward methods (rt::forward_methods()) apply.
  bool inverse_on_guard_only = false;
  /// With `inverse_on_guard_only`: the index i of the reset's one constant component (Δ_i
  /// free of the state) when s and the other components are affine in the state, so that Δ
  /// maps S onto the plane x_i = Δ_i and the backward characteristics invert Δ on S
  /// (rt::GuardInfo::image_axis); −1: none, and only the forward methods apply.
  int image_axis = -1;
  std::vector<GiNaC::ex> reset_inverse;  ///< Δ⁻¹(y) in the state symbols.
  GiNaC::ex hybrid_jacobian;             ///< J(x) for x ∈ S (general formula).
  GiNaC::ex hybrid_jacobian_on_surface;  ///< J with s = 0 substituted when possible.
  std::string surface_note;              ///< How J was restricted to S (for reports).
};

/// A non-fatal finding of derive's checks, located where the model says what it is about
/// (loc.line 0: the model as a whole).
struct DeriveWarning {
  /// A finding `what` at `where` (implicit: a plain string is a warning about the model).
  DeriveWarning(std::string what, SourceLoc where = {}) : text(std::move(what)), loc(where) {}
  std::string text;  ///< What was found, and the way out.
  SourceLoc loc;     ///< Where.
};

/// The HybridSystem IR (output of `derive`).
struct HybridSystem {
  const Model* model = nullptr;         ///< The model it was derived from.
  std::vector<IrMode> modes;            ///< Modes.
  std::vector<IrGuard> guards;          ///< Guards.
  std::vector<DeriveWarning> warnings;  ///< Non-fatal findings of the checks.
};

}  // namespace hybgen::gen
