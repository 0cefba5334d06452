#pragma once
/// \file ast.hpp
/// The abstract syntax tree of a `.model` file: the output of `parse`, the
/// input of `check`. It records what the user wrote and where (1-based line and
/// column of the first character of each construct), nothing derived.

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace hybgen::gen {

/// A position in a source file: 1-based line and column (columns count bytes).
struct SourceLoc {
  int line = 0;  ///< 1-based line number; 0 means "no position".
  int col = 0;   ///< 1-based column (byte offset in the line + 1).
};

struct Expr;
/// Shared, immutable expression node.
using ExprPtr = std::shared_ptr<const Expr>;

/// An expression as written: numbers keep their literal text so that `0.1`
/// becomes the exact rational 1/10 later, never a float.
struct Expr {
  /// What kind of node this is.
  enum class Kind {
    Number,  ///< `text` is the literal, e.g. "2", "0.25", "1e-3".
    Symbol,  ///< `text` is the identifier.
    Unary,   ///< `text` is "-" or "+"; one argument.
    Binary,  ///< `text` is one of "+", "-", "*", "/", "^"; two arguments.
    Call,    ///< `text` is the function name; arguments in order.
  };
  Kind kind = Kind::Number;   ///< Node kind.
  SourceLoc loc;              ///< Position of the node's first character/operator.
  std::string text;           ///< Literal, name, operator or function name.
  std::vector<ExprPtr> args;  ///< Operands / call arguments.
};

/// A relation `lhs OP rhs` with OP one of "<", "<=", ">", ">=", "=".
struct Relation {
  ExprPtr lhs;     ///< Left side.
  std::string op;  ///< Relational operator.
  ExprPtr rhs;     ///< Right side.
  SourceLoc loc;   ///< Position of the left side's first character.
};

/// `parameter NAME = EXPR` (EXPR may use earlier parameters).
struct ParamDecl {
  std::string name;  ///< Parameter name.
  SourceLoc loc;     ///< Position of the name.
  ExprPtr value;     ///< Default value (must evaluate to a finite real).
};

/// A name with the place it was written.
struct Name {
  std::string name;  ///< The identifier.
  SourceLoc loc;     ///< Its position.
};

/// `X' = EXPR` inside a mode.
struct FlowEq {
  Name var;     ///< The state variable being differentiated.
  ExprPtr rhs;  ///< Its time derivative.
};

/// `mode NAME { ... }`: either explicit flow equations, or a Hamiltonian from
/// which Hamilton's equations are derived (never both).
struct ModeDecl {
  Name name;                      ///< Mode name.
  std::vector<FlowEq> flows;      ///< `x' = ...` lines, in source order.
  ExprPtr hamiltonian;            ///< `hamiltonian EXPR`, or null.
  SourceLoc hamiltonian_loc;      ///< Position of the `hamiltonian` keyword.
  std::vector<Name> coordinates;  ///< `coordinates q1, q2` (optional).
  std::vector<Name> momenta;      ///< `momenta p1, p2` (optional).
  std::vector<Relation> where;    ///< `where REL` conditions: the mode's region.
};

/// Crossing direction of a guard surface s(x) = 0.
enum class Direction {
  Decreasing,  ///< s goes from positive to negative (ds·X < 0).
  Increasing,  ///< s goes from negative to positive (ds·X > 0).
};

/// `reset ...` inside a guard.
struct ResetDecl {
  /// Which form of reset was written.
  enum class Kind {
    Identity,     ///< `reset identity`
    Elastic,      ///< `reset elastic`
    Restitution,  ///< `reset restitution EXPR`
    Explicit,     ///< `reset (e1, e2, ..., eN)` — one component per state.
    Absorb,       ///< `reset absorb`: the mass that reaches the guard leaves the system.
  };
  Kind kind = Kind::Identity;       ///< Form.
  SourceLoc loc;                    ///< Position of the `reset` keyword.
  ExprPtr coefficient;              ///< Restitution coefficient (Kind::Restitution).
  std::vector<ExprPtr> components;  ///< New state (Kind::Explicit).
  SourceLoc components_loc;         ///< Position of the opening parenthesis.
};

/// `guard NAME { from A to B  when LHS = RHS DIRECTION  reset ... }`.
struct GuardDecl {
  Name name;                                    ///< Guard name.
  std::optional<Name> from;                     ///< Source mode (optional when there is one mode).
  std::optional<Name> to;                       ///< Target mode (optional: defaults to `from`).
  Relation when;                                ///< The surface, always with op "=".
  Direction direction = Direction::Decreasing;  ///< Crossing direction of lhs - rhs.
  SourceLoc direction_loc;                      ///< Position of the direction word.
  ResetDecl reset;                              ///< The reset.
  bool has_when = false;                        ///< Whether `when` was given.
  bool has_reset = false;                       ///< Whether `reset` was given.
};

/// `domain X in [LO, HI]` inside `simulation`.
struct DomainDecl {
  Name var;    ///< State variable.
  ExprPtr lo;  ///< Lower end.
  ExprPtr hi;  ///< Upper end.
};

/// `initial [MODE:] EXPR` inside `simulation`.
struct InitialDecl {
  std::optional<Name> mode;  ///< Mode the density lives in (optional).
  ExprPtr density;           ///< Initial density u0(x).
  SourceLoc loc;             ///< Position of the `initial` keyword.
};

/// A simple `KEY VALUE` setting of the simulation block (t_end, dt, tol, ...).
struct Setting {
  Name key;             ///< Setting name.
  ExprPtr value;        ///< Numeric value (for numeric settings), or null.
  std::string word;     ///< Word value (e.g. `method characteristics`), or "".
  SourceLoc value_loc;  ///< Position of the value.
};

/// `grid 75x75` (one count per state variable).
struct GridDecl {
  std::vector<long> counts;  ///< Nodes per axis.
  SourceLoc loc;             ///< Position of the grid literal.
};

/// `observe NAME = [MODE:] EXPR` inside `simulation` (or `--set observe.NAME=EXPR`): a
/// quantity in the states and parameters whose expectation over the density every method
/// reports per output time; with MODE, EXPR in that mode and 0 in the others.
struct ObserveDecl {
  Name name;                 ///< The observable's name.
  std::optional<Name> mode;  ///< The one mode it is EXPR in (else every mode).
  ExprPtr value;             ///< Its expression.
  SourceLoc loc;             ///< Position of the `observe` keyword.
};

/// `simulation { ... }`.
struct SimulationDecl {
  SourceLoc loc;                     ///< Position of the `simulation` keyword.
  std::vector<DomainDecl> domains;   ///< One per state variable.
  std::optional<GridDecl> grid;      ///< Grid node counts.
  std::vector<InitialDecl> initial;  ///< Initial densities.
  std::vector<Relation> support;     ///< `support REL`: state space restriction.
  std::vector<Setting> settings;     ///< t_end, dt, method, tol, ...
  std::vector<ObserveDecl> observe;  ///< Observables, in order.
};

/// A matrix literal `[[e11, e12], [e21, e22]]`, rows in order.
struct MatrixLiteral {
  std::vector<std::vector<ExprPtr>> rows;  ///< Entries, row by row.
  SourceLoc loc;                           ///< Position of the opening '['.
};

/// One bracket `[Ei, Ej] = EXPR` of a group given by structure constants; EXPR
/// is a linear combination of the basis names with parameter coefficients.
struct BracketDecl {
  Name left;      ///< E_i.
  Name right;     ///< E_j.
  ExprPtr value;  ///< Σ_k C_ij^k E_k.
  SourceLoc loc;  ///< Position of the opening '['.
};

/// `group NAME = gl(N)`, `group NAME(c1, ..., cn) = MATRIX at (v1, ..., vn)` or
/// `group NAME = algebra(E1, ..., En) { [Ei, Ej] = EXPR, ... }`: a matrix Lie
/// group by a shortcut or by a parametrisation g(c) with g(c0) = 1, or a group
/// known only by the structure constants of its Lie algebra (no coordinates).
struct GroupDecl {
  Name name;                          ///< The group's name (used as `det(NAME)`).
  SourceLoc loc;                      ///< Position of the `group` keyword.
  std::string shortcut;               ///< "gl" for `gl(N)`, "algebra" for `algebra(...)`, else "".
  long shortcut_n = 0;                ///< N of `gl(N)`.
  std::vector<Name> basis;            ///< E_1..E_n of `algebra(E1, ..., En)`.
  std::vector<BracketDecl> brackets;  ///< The brackets listed (the others are 0).
  std::vector<Name> coordinates;      ///< c1..cn (parametrised form).
  MatrixLiteral matrix;               ///< g(c) (parametrised form).
  std::vector<ExprPtr> identity;      ///< c0 with g(c0) = identity (parametrised form).
  SourceLoc identity_loc;             ///< Position of the `at` keyword.
};

/// The statements of a Lie-group model (docs/model-language.md, "Lie-group
/// models"): present iff the file has one of the statements `group`,
/// `momenta`, `hamiltonian`, `inertia`, `metric`, `velocities`, `constraint`
/// or `reduced` at the top level.
struct LieDecl {
  GroupDecl group;            ///< The group.
  std::vector<Name> momenta;  ///< ζ_1..ζ_n, one per basis element E_i = ∂g/∂c_i(c0).
  SourceLoc momenta_loc;      ///< Position of the `momenta` keyword.
  ExprPtr hamiltonian;        ///< h(ζ) (`hamiltonian EXPR`), or null.
  SourceLoc hamiltonian_loc;  ///< Position of the `hamiltonian` keyword.
  std::optional<MatrixLiteral> inertia;  ///< `inertia MATRIX`: h = ½ ζᵀ I⁻¹ ζ.
  SourceLoc inertia_loc;                 ///< Position of the `inertia` keyword.
  /// `metric MATRIX`: the kinetic energy ½ ċᵀ M(c) ċ in the group coordinates
  /// (checked to be left-invariant; then as `inertia` with I = Lᵀ M L).
  std::optional<MatrixLiteral> metric;
  SourceLoc metric_loc;  ///< Position of the `metric` keyword.
  std::vector<Name>
      velocities;            ///< `velocities v1, ...`: body velocities ξ_i (constrained models).
  SourceLoc velocities_loc;  ///< Position of the `velocities` keyword.
  std::vector<Relation> constraints;  ///< `constraint NAME = EXPR`: ξ_NAME, linear in the others.
  std::optional<Name> reduced;        ///< `reduced q = EXPR`: the name of q.
  /// φ(g) − c as an expression in the coordinates, or (groups given by
  /// structure constants) `additive(λ1, ..., λn)` / `multiplicative(...)`.
  ExprPtr reduced_expr;
  SourceLoc reduced_loc;  ///< Position of the `reduced` keyword.
};

/// A whole `.model` file.
struct ModelAst {
  std::string path;                          ///< File path as given (for diagnostics).
  std::optional<Name> name;                  ///< `model NAME` (else the file stem).
  std::vector<ParamDecl> params;             ///< Parameters in order.
  std::vector<Name> states;                  ///< State variables in order.
  std::vector<ModeDecl> modes;               ///< Modes in order.
  std::vector<GuardDecl> guards;             ///< Guards in order.
  std::optional<SimulationDecl> simulation;  ///< The simulation block, if any.
  std::optional<LieDecl> lie;                ///< Lie-group statements (a `lie` model), if any.
};

}  // namespace hybgen::gen
