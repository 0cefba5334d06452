// Stage 1 (parse): .model text -> AST.
//
// Size: one method per grammar rule of docs/model-language.md (general and Lie-group
// statements, expressions, the simulation block), which call one another: one class.
//
// The lexer (lexer.hpp) produces tokens on demand (so that errors are reported in
// source order); this file is the recursive-descent parser in the style of
// GiNaC's ginac/parser/parser.h: one method per grammar rule of
// docs/model-language.md, each with its rule written above it.

#include "hybgen/gen/parse.hpp"

#include <algorithm>
#include <cstddef>
#include <deque>
#include <iterator>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "lexer.hpp"

namespace hybgen::gen {

namespace {

using namespace lexing;  // Tok, Token, Lexer and the character classes

/// Deepest nesting of parentheses, signs and powers in one expression.
constexpr int kMaxNesting = 256;
/// Deepest expression tree (a sum of N terms is N levels deep).
constexpr int kMaxHeight = 512;
/// Largest node count of one grid axis.
constexpr long kMaxGridCount = 100000000;

/// The statement keywords (used to explain a missing '}').
constexpr std::string_view kStatementKeywords[] = {
    "model",   "parameter", "state",   "mode",        "guard",      "simulation", "group",
    "momenta", "inertia",   "reduced", "hamiltonian", "velocities", "constraint", "metric"};

bool is_statement_keyword(std::string_view word) {
  return std::find(std::begin(kStatementKeywords), std::end(kStatementKeywords), word) !=
         std::end(kStatementKeywords);
}

// ---------------------------------------------------------------------------
// Parser
// ---------------------------------------------------------------------------

/// An expression being built: its node, where its text starts (including
/// enclosing parentheses) and the height of its tree.
struct Parsed {
  std::shared_ptr<Expr> node;  ///< The node (still mutable while parsing).
  SourceLoc start;             ///< First character, '(' included.
  int height = 1;              ///< Levels of the tree.
};

/// Recursive-descent parser; one method per grammar rule.
class Parser {
 public:
  explicit Parser(const SourceText& src) : src_(src), lexer_(src.text()) {}

  // model := { statement [';'] }
  ModelAst parse_model() {
    ModelAst ast;
    ast.path = src_.path();
    while (tok().kind != Tok::End) {
      parse_statement(ast);
      if (at_punct(";")) take();
    }
    return ast;
  }

  // The whole text is one observe item (`--set observe.NAME=EXPR`, with the '.' read as a
  // space): observe_item END.
  ObserveDecl parse_observe_only() {
    ObserveDecl d = parse_observe_item();
    if (tok().kind != Tok::End) unexpected("the end of the observable's expression");
    return d;
  }

 private:
  // --- Tokens ------------------------------------------------------------

  /// The k-th token ahead (0: the current one). Does not report lexical errors.
  const Token& peek(std::size_t k) {
    while (buf_.size() <= k) buf_.push_back(lexer_.next());
    return buf_[k];
  }

  /// The current token; reports a lexical error when it is one.
  const Token& tok() {
    const Token& t = peek(0);
    if (t.kind == Tok::Error) fail(t.loc, t.text);
    return t;
  }

  /// Consume the current token.
  Token take() {
    tok();
    Token t = std::move(buf_.front());
    buf_.pop_front();
    return t;
  }

  bool at_punct(std::string_view p) {
    const Token& t = tok();
    return t.kind == Tok::Punct && t.text == p;
  }

  bool at_word(std::string_view w) {
    const Token& t = tok();
    return t.kind == Tok::Ident && t.text == w;
  }

  static bool is_punct(const Token& t, std::string_view p) {
    return t.kind == Tok::Punct && t.text == p;
  }

  [[noreturn]] void fail(SourceLoc loc, const std::string& message) const {
    throw src_.error(loc, message);
  }

  static std::string describe(const Token& t) {
    if (t.kind == Tok::End) return "end of file";
    return "'" + shorten(t.text) + "'";
  }

  /// "expected EXPECTED, found TOKEN" at the current token.
  [[noreturn]] void unexpected(const std::string& expected) {
    const Token& t = tok();
    if (t.kind == Tok::Grid)
      fail(t.loc, "grid literal '" + shorten(t.text) + "' is only valid after 'grid'");
    fail(t.loc, "expected " + expected + ", found " + describe(t));
  }

  /// Consume punctuation `p` or fail with "expected 'p' CONTEXT, found ...".
  Token expect_punct(std::string_view p, const std::string& context) {
    if (!at_punct(p)) unexpected("'" + std::string(p) + "' " + context);
    return take();
  }

  /// Consume an identifier or fail with "expected WHAT, found ...".
  Name expect_name(const std::string& what) {
    if (tok().kind != Tok::Ident) unexpected(what);
    Token t = take();
    return {std::move(t.text), t.loc};
  }

  std::string unterminated(SourceLoc open) const {
    return "unterminated block: '{' at " + loc_str(open) + " has no matching '}'";
  }

  /// An identifier that starts no item of block `what`.
  [[noreturn]] void unknown_item(const Token& t, const std::string& what,
                                 const std::string& expected, SourceLoc open) {
    if (is_statement_keyword(t.text))
      fail(t.loc, "unknown item '" + t.text + "' in " + what + " (is the '}' closing the '{' at " +
                      loc_str(open) + " missing?)");
    fail(t.loc,
         "unknown item '" + shorten(t.text) + "' in " + what + " (expected " + expected + ")");
  }

  /// `'{' { ITEM [';'] } '}'`, calling `item(open)` for each item.
  template <class Item>
  void parse_block(const std::string& context, Item item) {
    const SourceLoc open = expect_punct("{", context).loc;
    while (!at_punct("}")) {
      if (tok().kind == Tok::End) fail(tok().loc, unterminated(open));
      item(open);
      if (at_punct(";")) take();
    }
    take();
  }

  // --- Statements ----------------------------------------------------------

  // statement := 'model' IDENT
  //            | 'parameter' IDENT '=' expr { ',' IDENT '=' expr }
  //            | 'state' IDENT { ',' IDENT }
  //            | 'mode' IDENT '{' { mode_item [';'] } '}'
  //            | 'guard' IDENT '{' { guard_item [';'] } '}'
  //            | 'simulation' '{' { sim_item [';'] } '}'
  //            | lie_statement
  void parse_statement(ModelAst& ast) {
    const Token& t = tok();
    if (t.kind != Tok::Ident)
      unexpected("a statement (model, parameter, state, mode, guard or simulation)");
    if (t.text == "model") return parse_model_statement(ast);
    if (t.text == "parameter") return parse_parameter_statement(ast);
    if (t.text == "state") return parse_state_statement(ast);
    if (t.text == "mode") return parse_mode_statement(ast);
    if (t.text == "guard") return parse_guard_statement(ast);
    if (t.text == "simulation") return parse_simulation_statement(ast);
    if (t.text == "group" || t.text == "momenta" || t.text == "hamiltonian" ||
        t.text == "inertia" || t.text == "metric" || t.text == "reduced" ||
        t.text == "velocities" || t.text == "constraint")
      return parse_lie_statement(ast);
    fail(t.loc, "unknown statement '" + shorten(t.text) +
                    "' (expected model, parameter, state, mode, guard or simulation), or in a "
                    "Lie-group model group, momenta, hamiltonian, inertia, metric or reduced");
  }

  // lie_statement := 'group' IDENT group_def
  //                | 'momenta' IDENT { ',' IDENT }
  //                | 'hamiltonian' expr
  //                | 'inertia' matrix
  //                | 'metric' matrix
  //                | 'reduced' IDENT '=' expr
  //                | 'velocities' IDENT { ',' IDENT }
  //                | 'constraint' IDENT '=' expr
  void parse_lie_statement(ModelAst& ast) {
    if (!ast.lie) ast.lie.emplace();
    LieDecl& lie = *ast.lie;
    const Token kw = take();
    auto twice = [&](SourceLoc first) {
      fail(kw.loc, "a second '" + kw.text + "' statement (the first is at " + loc_str(first) + ")");
    };
    if (kw.text == "group") {
      if (lie.group.loc.line != 0) twice(lie.group.loc);
      lie.group.loc = kw.loc;
      lie.group.name = expect_name("a group name after 'group'");
      parse_group_def(lie.group);
    } else if (kw.text == "momenta") {
      if (!lie.momenta.empty()) twice(lie.momenta_loc);
      lie.momenta_loc = kw.loc;
      lie.momenta = parse_name_list("a momentum name", "'momenta'");
    } else if (kw.text == "hamiltonian") {
      if (lie.hamiltonian) twice(lie.hamiltonian_loc);
      lie.hamiltonian_loc = kw.loc;
      lie.hamiltonian = parse_expr().node;
    } else if (kw.text == "velocities") {
      if (!lie.velocities.empty()) twice(lie.velocities_loc);
      lie.velocities_loc = kw.loc;
      lie.velocities = parse_name_list("a velocity name", "'velocities'");
    } else if (kw.text == "constraint") {
      if (tok().kind != Tok::Ident) unexpected("a velocity name after 'constraint'");
      Parsed lhs = parse_expr();
      expect_punct("=", "in the constraint 'NAME = EXPR'");
      Parsed rhs = parse_expr();
      lie.constraints.push_back({std::move(lhs.node), "=", std::move(rhs.node), lhs.start});
    } else if (kw.text == "inertia") {
      if (lie.inertia) twice(lie.inertia_loc);
      lie.inertia_loc = kw.loc;
      lie.inertia = parse_matrix("after 'inertia'");
    } else if (kw.text == "metric") {
      if (lie.metric) twice(lie.metric_loc);
      lie.metric_loc = kw.loc;
      lie.metric = parse_matrix("after 'metric'");
    } else {
      if (lie.reduced) twice(lie.reduced_loc);
      lie.reduced_loc = kw.loc;
      lie.reduced = expect_name("the name of the reduced coordinate after 'reduced'");
      expect_punct("=", "after 'reduced " + lie.reduced->name + "'");
      lie.reduced_expr = parse_expr().node;
    }
  }

  // group_def := '=' IDENT '(' NUMBER ')'                          (gl(N))
  //            | '=' 'algebra' '(' IDENT { ',' IDENT } ')'
  //                  '{' { '[' IDENT ',' IDENT ']' '=' expr [ ',' | ';' ] } '}'
  //            | '(' IDENT { ',' IDENT } ')' '=' matrix 'at' '(' expr { ',' expr } ')'
  //
  // The `algebra` form names the basis E_1..E_n and lists brackets
  // [E_i, E_j] = Σ_k C_ij^k E_k; unlisted brackets are 0 and [E_j, E_i] is
  // implied (checked by check_lie: antisymmetry, Jacobi).
  void parse_group_def(GroupDecl& group) {
    if (at_punct("(")) {
      const SourceLoc open = take().loc;
      for (;;) {
        group.coordinates.push_back(expect_name("a coordinate name"));
        if (at_punct(")")) break;
        if (!at_punct(","))
          unexpected("',' or ')' in the coordinates of group '" + group.name.name +
                     "' (opened at " + loc_str(open) + ")");
        take();
      }
      take();
      expect_punct("=", "after the coordinates of group '" + group.name.name + "'");
      group.matrix = parse_matrix("after 'group " + group.name.name + "(...) ='");
      if (!at_word("at"))
        unexpected(
            "'at (c1, ..., cn)' (the coordinates of the identity) after the matrix of group '" +
            group.name.name + "'");
      group.identity_loc = take().loc;
      const SourceLoc popen = expect_punct("(", "after 'at'").loc;
      for (;;) {
        group.identity.push_back(parse_expr().node);
        if (at_punct(")")) break;
        if (!at_punct(","))
          unexpected("',' or ')' in the identity point (opened at " + loc_str(popen) + ")");
        take();
      }
      take();
      return;
    }
    expect_punct("=", "after 'group " + group.name.name + "' (write 'group " + group.name.name +
                          " = gl(2)' or 'group " + group.name.name +
                          "(x, y) = [[...]] at (0, 0)')");
    if (at_word("algebra")) return parse_algebra_def(group);
    if (!at_word("gl"))
      unexpected(
          "'gl(N)', 'algebra(E1, ..., En) { ... }' or coordinates '(c1, ..., cn)' before '='");
    group.shortcut = take().text;
    expect_punct("(", "after 'gl'");
    const Token& t = tok();
    const bool integer = t.kind == Tok::Number && std::all_of(t.text.begin(), t.text.end(),
                                                              [](char c) { return is_digit(c); });
    if (!integer || t.text.size() > 2) unexpected("a matrix size N (1 to 99) in 'gl(N)'");
    const Token n = take();  // t dangles after take() (fuzz finding F10: gl(0))
    group.shortcut_n = std::stol(n.text);
    if (group.shortcut_n < 1) fail(n.loc, "gl(N) needs N >= 1");
    expect_punct(")", "after 'gl(N'");
  }

  // 'algebra' '(' IDENT { ',' IDENT } ')' '{' { bracket [ ',' | ';' ] } '}'
  // bracket := '[' IDENT ',' IDENT ']' '=' expr
  void parse_algebra_def(GroupDecl& group) {
    group.shortcut = take().text;
    const SourceLoc popen = expect_punct("(", "after 'algebra' (the basis names)").loc;
    for (;;) {
      group.basis.push_back(expect_name("a basis name"));
      if (at_punct(")")) break;
      if (!at_punct(","))
        unexpected("',' or ')' in the basis of group '" + group.name.name + "' (opened at " +
                   loc_str(popen) + ")");
      take();
    }
    take();
    const SourceLoc open =
        expect_punct("{", "after the basis (the brackets, e.g. '{ [E1, E2] = E3 }')").loc;
    while (!at_punct("}")) {
      if (tok().kind == Tok::End) fail(tok().loc, unterminated(open));
      BracketDecl b;
      b.loc = expect_punct("[", "to open a bracket '[Ei, Ej] = ...' (or '}')").loc;
      b.left = expect_name("a basis name in the bracket");
      expect_punct(",", "between the two elements of the bracket");
      b.right = expect_name("a basis name in the bracket");
      expect_punct("]", "to close the bracket opened at " + loc_str(b.loc));
      expect_punct("=", "after the bracket '[" + b.left.name + ", " + b.right.name + "]'");
      b.value = parse_expr().node;
      group.brackets.push_back(std::move(b));
      if (at_punct(",") || at_punct(";")) take();
    }
    take();
  }

  // matrix := '[' row { ',' row } ']'      row := '[' expr { ',' expr } ']'
  MatrixLiteral parse_matrix(const std::string& context) {
    MatrixLiteral m;
    m.loc = expect_punct("[", "(a matrix [[a, b], [c, d]]) " + context).loc;
    for (;;) {
      const SourceLoc ropen = expect_punct("[", "to open a matrix row").loc;
      std::vector<ExprPtr> row;
      for (;;) {
        row.push_back(parse_expr().node);
        if (at_punct("]")) break;
        if (!at_punct(",")) unexpected("',' or ']' in the matrix row opened at " + loc_str(ropen));
        take();
      }
      take();
      m.rows.push_back(std::move(row));
      if (at_punct("]")) break;
      if (!at_punct(",")) unexpected("',' or ']' in the matrix opened at " + loc_str(m.loc));
      take();
    }
    take();
    return m;
  }

  // statement := 'model' IDENT
  void parse_model_statement(ModelAst& ast) {
    const Token kw = take();
    if (ast.name)
      fail(kw.loc, "the model is named twice (first at " + loc_str(ast.name->loc) + ")");
    ast.name = expect_name("a model name after 'model'");
  }

  // statement := 'parameter' IDENT '=' expr { ',' IDENT '=' expr }
  void parse_parameter_statement(ModelAst& ast) {
    take();
    std::string after = "'parameter'";
    for (;;) {
      Name name = expect_name("a parameter name after " + after);
      expect_punct("=", "after parameter name '" + name.name + "'");
      ExprPtr value = parse_expr().node;
      ast.params.push_back({std::move(name.name), name.loc, std::move(value)});
      if (!at_punct(",")) break;
      take();
      after = "','";
    }
  }

  // statement := 'state' IDENT { ',' IDENT }
  void parse_state_statement(ModelAst& ast) {
    take();
    ast.states = parse_name_list("a state variable name", "'state'");
  }

  // IDENT { ',' IDENT }   (after `state`, `coordinates`, `momenta`)
  std::vector<Name> parse_name_list(const std::string& what, const std::string& after) {
    std::vector<Name> names;
    names.push_back(expect_name(what + " after " + after));
    while (at_punct(",")) {
      take();
      names.push_back(expect_name(what + " after ','"));
    }
    return names;
  }

  // statement := 'mode' IDENT '{' { mode_item [';'] } '}'
  void parse_mode_statement(ModelAst& ast) {
    take();
    ModeDecl mode;
    mode.name = expect_name("a mode name after 'mode'");
    parse_block("after mode name '" + mode.name.name + "'",
                [&](SourceLoc open) { parse_mode_item(mode, open); });
    ast.modes.push_back(std::move(mode));
  }

  // mode_item := IDENT '\'' '=' expr
  //            | 'hamiltonian' expr
  //            | 'coordinates' IDENT { ',' IDENT }
  //            | 'momenta' IDENT { ',' IDENT }
  //            | 'where' relation
  void parse_mode_item(ModeDecl& mode, SourceLoc open) {
    const std::string what = "mode '" + mode.name.name + "'";
    const std::string items = "x' = ..., hamiltonian, coordinates, momenta or where";
    if (tok().kind != Tok::Ident) unexpected("an item of " + what + " (" + items + ")");
    const Token t = tok();
    if (is_punct(peek(1), "'")) {
      take();
      take();
      expect_punct("=", "after " + t.text + "'");
      ExprPtr rhs = parse_expr().node;
      mode.flows.push_back({{t.text, t.loc}, std::move(rhs)});
    } else if (t.text == "hamiltonian") {
      if (mode.hamiltonian)
        fail(t.loc, what + " has a second hamiltonian (the first is at " +
                        loc_str(mode.hamiltonian_loc) + ")");
      take();
      mode.hamiltonian = parse_expr().node;
      mode.hamiltonian_loc = t.loc;
    } else if (t.text == "coordinates" || t.text == "momenta") {
      std::vector<Name>& list = t.text == "coordinates" ? mode.coordinates : mode.momenta;
      if (!list.empty())
        fail(t.loc,
             what + " names its " + t.text + " twice (first at " + loc_str(list.front().loc) + ")");
      take();
      list = parse_name_list("a state variable name", "'" + t.text + "'");
    } else if (t.text == "where") {
      take();
      mode.where.push_back(parse_relation("'where'"));
    } else if (is_punct(peek(1), "=")) {
      fail(t.loc, "unknown item '" + shorten(t.text) + "' in " + what + " (write " +
                      shorten(t.text) + "' = ... for a flow equation)");
    } else {
      unknown_item(t, what, items, open);
    }
  }

  // statement := 'guard' IDENT '{' { guard_item [';'] } '}'
  void parse_guard_statement(ModelAst& ast) {
    take();
    GuardDecl guard;
    guard.name = expect_name("a guard name after 'guard'");
    parse_block("after guard name '" + guard.name.name + "'",
                [&](SourceLoc open) { parse_guard_item(guard, open); });
    ast.guards.push_back(std::move(guard));
  }

  // guard_item := 'from' IDENT [ 'to' IDENT ]
  //             | 'to' IDENT
  //             | 'when' expr '=' expr direction
  //             | 'reset' reset
  void parse_guard_item(GuardDecl& guard, SourceLoc open) {
    const std::string what = "guard '" + guard.name.name + "'";
    if (tok().kind != Tok::Ident) unexpected("an item of " + what + " (from, to, when or reset)");
    const Token t = tok();
    auto parse_to = [&]() {
      const Token kw = take();
      if (guard.to)
        fail(kw.loc,
             what + " names its target mode twice (first at " + loc_str(guard.to->loc) + ")");
      guard.to = expect_name("a mode name after 'to'");
    };
    if (t.text == "from") {
      if (guard.from)
        fail(t.loc,
             what + " names its source mode twice (first at " + loc_str(guard.from->loc) + ")");
      take();
      guard.from = expect_name("a mode name after 'from'");
      if (at_word("to")) parse_to();
    } else if (t.text == "to") {
      parse_to();
    } else if (t.text == "when") {
      if (guard.has_when)
        fail(t.loc, what + " has a second 'when' (the first surface is at " +
                        loc_str(guard.when.loc) + ")");
      take();
      Parsed lhs = parse_expr();
      if (at_punct("<") || at_punct("<=") || at_punct(">") || at_punct(">="))
        fail(tok().loc,
             "a guard surface is written 'when L = R' followed by 'decreasing' or "
             "'increasing', not with '" +
                 tok().text + "'");
      expect_punct("=", "in the guard surface 'when L = R'");
      if (at_punct("=")) fail(tok().loc, "write '=', not '==', in the guard surface");
      Parsed rhs = parse_expr();
      guard.when = {std::move(lhs.node), "=", std::move(rhs.node), lhs.start};
      guard.has_when = true;
      parse_direction(guard);
    } else if (t.text == "reset") {
      if (guard.has_reset)
        fail(t.loc,
             what + " has a second reset (the first is at " + loc_str(guard.reset.loc) + ")");
      take();
      guard.reset.loc = t.loc;
      parse_reset(guard.reset);
      guard.has_reset = true;
    } else {
      unknown_item(t, what, "from, to, when or reset", open);
    }
  }

  // direction := 'decreasing' | 'increasing'
  void parse_direction(GuardDecl& guard) {
    if (at_word("decreasing")) {
      guard.direction = Direction::Decreasing;
    } else if (at_word("increasing")) {
      guard.direction = Direction::Increasing;
    } else {
      unexpected("'decreasing' or 'increasing' after the guard surface");
    }
    guard.direction_loc = take().loc;
  }

  // reset := 'identity' | 'elastic' | 'restitution' expr | 'absorb'
  //        | '(' expr { ',' expr } ')'
  void parse_reset(ResetDecl& reset) {
    if (at_word("identity")) {
      take();
      reset.kind = ResetDecl::Kind::Identity;
    } else if (at_word("absorb")) {
      take();
      reset.kind = ResetDecl::Kind::Absorb;
    } else if (at_word("elastic")) {
      take();
      reset.kind = ResetDecl::Kind::Elastic;
    } else if (at_word("restitution")) {
      take();
      reset.kind = ResetDecl::Kind::Restitution;
      reset.coefficient = parse_expr().node;
    } else if (at_punct("(")) {
      reset.kind = ResetDecl::Kind::Explicit;
      reset.components_loc = take().loc;
      for (;;) {
        reset.components.push_back(parse_expr().node);
        if (at_punct(")")) break;
        if (!at_punct(","))
          unexpected("',' or ')' in the reset components (opened at " +
                     loc_str(reset.components_loc) + ")");
        take();
      }
      take();
    } else {
      unexpected(
          "identity, elastic, restitution COEFFICIENT, absorb or (e1, ..., eN) after "
          "'reset'");
    }
  }

  // statement := 'simulation' '{' { sim_item [';'] } '}'
  void parse_simulation_statement(ModelAst& ast) {
    const Token kw = take();
    if (ast.simulation)
      fail(kw.loc,
           "a second simulation block (the first is at " + loc_str(ast.simulation->loc) + ")");
    SimulationDecl sim;
    sim.loc = kw.loc;
    parse_block("after 'simulation'", [&](SourceLoc open) { parse_sim_item(sim, open); });
    ast.simulation = std::move(sim);
  }

  // sim_item := 'domain' IDENT 'in' '[' expr ',' expr ']'
  //           | 'grid' GRID
  //           | 'initial' [ IDENT ':' ] expr
  //           | 'support' relation
  //           | observe_item
  //           | IDENT ( expr | IDENT )
  void parse_sim_item(SimulationDecl& sim, SourceLoc open) {
    if (tok().kind != Tok::Ident)
      unexpected(
          "an item of the simulation block (domain, grid, initial, support, observe or a "
          "setting)");
    const Token t = tok();
    if (t.text == "domain") return parse_domain(sim);
    if (t.text == "grid") return parse_grid(sim);
    if (t.text == "initial") return parse_initial(sim);
    if (t.text == "observe") return sim.observe.push_back(parse_observe_item());
    if (t.text == "support") {
      take();
      sim.support.push_back(parse_relation("'support'"));
      return;
    }
    if (is_statement_keyword(t.text))
      unknown_item(t, "the simulation block",
                   "domain, grid, initial, support, observe or a setting", open);
    parse_setting(sim);
  }

  // sim_item := 'domain' IDENT 'in' '[' expr ',' expr ']'
  void parse_domain(SimulationDecl& sim) {
    take();
    DomainDecl domain;
    domain.var = expect_name("a state variable name after 'domain'");
    const std::string where = "domain '" + domain.var.name + "'";
    if (!at_word("in")) unexpected("'in' after 'domain " + domain.var.name + "'");
    take();
    expect_punct("[", "after 'domain " + domain.var.name + " in'");
    domain.lo = parse_expr().node;
    expect_punct(",", "between the ends of " + where);
    domain.hi = parse_expr().node;
    expect_punct("]", "after the upper end of " + where);
    sim.domains.push_back(std::move(domain));
  }

  // sim_item := 'grid' GRID       (GRID: 75x75, 33x33x33, or one integer N)
  void parse_grid(SimulationDecl& sim) {
    const Token kw = take();
    if (sim.grid) fail(kw.loc, "the grid is given twice (first at " + loc_str(sim.grid->loc) + ")");
    const Token& t = tok();
    const bool integer = t.kind == Tok::Number && std::all_of(t.text.begin(), t.text.end(),
                                                              [](char c) { return is_digit(c); });
    if (t.kind != Tok::Grid && !integer)
      unexpected("a grid size after 'grid' (e.g. 75x75, or one integer N)");
    const Token g = take();
    GridDecl grid;
    grid.loc = g.loc;
    std::size_t i = 0;
    while (i < g.text.size()) {
      std::size_t j = i;
      while (j < g.text.size() && is_digit(g.text[j])) ++j;
      const std::string digits = g.text.substr(i, j - i);
      const SourceLoc at{g.loc.line, g.loc.col + static_cast<int>(i)};
      const std::size_t first = std::min(digits.find_first_not_of('0'), digits.size());
      long count = 0;
      if (digits.size() - first > 9) {
        count = kMaxGridCount + 1;
      } else {
        for (std::size_t k = first; k < digits.size(); ++k) count = count * 10 + (digits[k] - '0');
      }
      if (count <= 0) fail(at, "a grid count must be a positive integer, found '" + digits + "'");
      if (count > kMaxGridCount)
        fail(at, "grid count '" + shorten(digits) + "' is too large (at most " +
                     std::to_string(kMaxGridCount) + ")");
      grid.counts.push_back(count);
      i = j + 1;  // skip the 'x'
    }
    sim.grid = std::move(grid);
  }

  // sim_item := 'initial' [ IDENT ':' ] expr
  void parse_initial(SimulationDecl& sim) {
    InitialDecl initial;
    initial.loc = take().loc;
    if (tok().kind == Tok::Ident && is_punct(peek(1), ":")) {
      initial.mode = expect_name("a mode name");
      take();
    }
    initial.density = parse_expr().node;
    sim.initial.push_back(std::move(initial));
  }

  // observe_item := 'observe' IDENT '=' [ IDENT ':' ] expr
  ObserveDecl parse_observe_item() {
    ObserveDecl d;
    d.loc = take().loc;
    d.name = expect_name("the observable's name after 'observe'");
    expect_punct("=", "after 'observe " + d.name.name + "'");
    if (tok().kind == Tok::Ident && is_punct(peek(1), ":")) {
      d.mode = expect_name("a mode name");
      take();
    }
    d.value = parse_expr().node;
    return d;
  }

  /// Whether `t` continues an expression after an operand (an operator or '(').
  static bool continues_expr(const Token& t) {
    return t.kind == Tok::Punct &&
           (t.text == "+" || t.text == "-" || t.text == "*" || t.text == "/" || t.text == "^" ||
            t.text == "**" || t.text == "(");
  }

  // sim_item := IDENT ( expr | IDENT | IDENT '+' IDENT { '+' IDENT } )
  // A value that is one identifier not followed by an operator or '(' is a
  // word (and also kept as a Symbol expression); identifiers joined by '+' and
  // followed by no operator are a word list (`outputs netcdf + png`), kept as
  // "netcdf+png"; anything else an expression.
  void parse_setting(SimulationDecl& sim) {
    Setting setting;
    setting.key = expect_name("a setting name");
    const Token& t = tok();
    if (t.kind == Tok::Ident && is_punct(peek(1), "+")) {
      std::size_t k = 0;  // tokens of IDENT ('+' IDENT)*
      while (peek(k).kind == Tok::Ident && is_punct(peek(k + 1), "+") &&
             peek(k + 2).kind == Tok::Ident)
        k += 2;
      if (peek(k).kind == Tok::Ident && !continues_expr(peek(k + 1))) {
        setting.value_loc = t.loc;
        for (std::size_t i = 0; i <= k; ++i) {
          const Token w = take();
          if (w.kind == Tok::Ident) setting.word += (setting.word.empty() ? "" : "+") + w.text;
        }
        sim.settings.push_back(std::move(setting));
        return;
      }
    }
    if (t.kind == Tok::Ident && !continues_expr(peek(1))) setting.word = t.text;
    const bool starts_expr =
        t.kind == Tok::Number || t.kind == Tok::Ident ||
        (t.kind == Tok::Punct && (t.text == "(" || t.text == "+" || t.text == "-"));
    if (!starts_expr) unexpected("a value for setting '" + setting.key.name + "'");
    Parsed value = parse_expr();
    setting.value = std::move(value.node);
    setting.value_loc = value.start;
    sim.settings.push_back(std::move(setting));
  }

  // relation := expr ( '<' | '<=' | '>' | '>=' ) expr
  Relation parse_relation(const std::string& after) {
    Parsed lhs = parse_expr();
    if (at_punct("="))
      fail(tok().loc,
           "a condition after " + after + " compares with '<', '<=', '>' or '>=', not '='");
    if (!(at_punct("<") || at_punct("<=") || at_punct(">") || at_punct(">=")))
      unexpected("'<', '<=', '>' or '>=' in the condition after " + after);
    std::string op = take().text;
    Parsed rhs = parse_expr();
    return {std::move(lhs.node), std::move(op), std::move(rhs.node), lhs.start};
  }

  // --- Expressions ---------------------------------------------------------

  /// Counts nesting (every `unary`) and fails beyond kMaxNesting.
  class NestingGuard {
   public:
    NestingGuard(Parser& parser, SourceLoc loc) : parser_(parser) {
      if (++parser_.nesting_ > kMaxNesting)
        parser_.fail(loc, "expression is nested too deeply (more than " +
                              std::to_string(kMaxNesting) + " levels)");
    }
    ~NestingGuard() { --parser_.nesting_; }
    NestingGuard(const NestingGuard&) = delete;
    NestingGuard& operator=(const NestingGuard&) = delete;

   private:
    Parser& parser_;
  };

  /// A leaf node for token `t`.
  static Parsed leaf(Expr::Kind kind, const Token& t) {
    auto node = std::make_shared<Expr>();
    node->kind = kind;
    node->loc = t.loc;
    node->text = t.text;
    return {std::move(node), t.loc, 1};
  }

  /// An inner node; `at` is where to report a too-deep tree.
  Parsed inner(Expr::Kind kind, std::string text, SourceLoc loc, SourceLoc start,
               std::vector<Parsed> args, SourceLoc at) const {
    auto node = std::make_shared<Expr>();
    node->kind = kind;
    node->loc = loc;
    node->text = std::move(text);
    int height = 0;
    for (Parsed& a : args) {
      height = std::max(height, a.height);
      node->args.push_back(std::move(a.node));
    }
    if (height + 1 > kMaxHeight)
      fail(at, "expression is too long or too deeply nested (more than " +
                   std::to_string(kMaxHeight) + " levels of operations)");
    return {std::move(node), start, height + 1};
  }

  /// A Binary node `lhs OP rhs`, positioned at the start of `lhs`.
  Parsed binary(const Token& op, Parsed lhs, Parsed rhs) const {
    const SourceLoc start = lhs.start;
    std::vector<Parsed> args;
    args.push_back(std::move(lhs));
    args.push_back(std::move(rhs));
    return inner(Expr::Kind::Binary, op.text == "**" ? "^" : op.text, start, start, std::move(args),
                 op.loc);
  }

  // expr := term { ('+' | '-') term }
  Parsed parse_expr() {
    Parsed lhs = parse_term();
    while (at_punct("+") || at_punct("-")) {
      const Token op = take();
      Parsed rhs = parse_term();
      lhs = binary(op, std::move(lhs), std::move(rhs));
    }
    return lhs;
  }

  // term := unary { ('*' | '/') unary }
  Parsed parse_term() {
    Parsed lhs = parse_unary();
    while (at_punct("*") || at_punct("/")) {
      const Token op = take();
      Parsed rhs = parse_unary();
      lhs = binary(op, std::move(lhs), std::move(rhs));
    }
    return lhs;
  }

  // unary := ('-' | '+') unary | power
  Parsed parse_unary() {
    const NestingGuard guard(*this, tok().loc);
    if (at_punct("-") || at_punct("+")) {
      const Token op = take();
      std::vector<Parsed> args;
      args.push_back(parse_unary());
      return inner(Expr::Kind::Unary, op.text, op.loc, op.loc, std::move(args), op.loc);
    }
    return parse_power();
  }

  // power := primary [ ('^' | '**') unary ]    (right-associative)
  Parsed parse_power() {
    Parsed base = parse_primary();
    if (at_punct("^") || at_punct("**")) {
      const Token op = take();
      Parsed exponent = parse_unary();
      return binary(op, std::move(base), std::move(exponent));
    }
    return base;
  }

  // primary := NUMBER | IDENT | IDENT '(' expr { ',' expr } ')' | '(' expr ')'
  Parsed parse_primary() {
    const Token& t = tok();
    if (t.kind == Tok::Number) return leaf(Expr::Kind::Number, take());
    if (t.kind == Tok::Ident) {
      const Token name = take();
      if (!at_punct("(")) return leaf(Expr::Kind::Symbol, name);
      const SourceLoc open = take().loc;
      std::vector<Parsed> args;
      for (;;) {
        args.push_back(parse_expr());
        if (at_punct(")")) break;
        if (!at_punct(","))
          unexpected("',' or ')' in the call of '" + name.text + "' (opened at " + loc_str(open) +
                     ")");
        take();
      }
      take();
      return inner(Expr::Kind::Call, name.text, name.loc, name.loc, std::move(args), name.loc);
    }
    if (is_punct(t, "(")) {
      const SourceLoc open = take().loc;
      Parsed e = parse_expr();
      if (!at_punct(")")) unexpected("')' to close the '(' at " + loc_str(open));
      take();
      e.start = open;
      return e;
    }
    unexpected("an expression");
  }

  const SourceText& src_;
  Lexer lexer_;
  std::deque<Token> buf_;
  int nesting_ = 0;
};

}  // namespace

ModelAst parse(const SourceText& src) {
  return Parser(src).parse_model();
}

ObserveDecl parse_observe(const SourceText& src) {
  return Parser(src).parse_observe_only();
}

}  // namespace hybgen::gen
