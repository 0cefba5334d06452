// Tests of stage 1 (parse): .model text -> AST.
//
// Size: one test file per source file (generator/src/parse.cpp), and the grammar of
// docs/model-language.md has a rule for every statement; each test names the rule it covers.

#include "hybgen/gen/parse.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {
namespace {

ModelAst parse_text(const std::string& text) {
  const SourceText src("t.model", text);
  return parse(src);
}

/// "LINE:COL".
std::string at(SourceLoc loc) {
  return std::to_string(loc.line) + ":" + std::to_string(loc.col);
}

/// An S-expression of an expression tree: binary (op a b), unary (u- a),
/// call name[a, b].
std::string dump(const ExprPtr& e) {
  if (!e) return "<null>";
  switch (e->kind) {
    case Expr::Kind::Number:
    case Expr::Kind::Symbol:
      return e->args.empty() ? e->text : "<leaf with args>";
    case Expr::Kind::Unary:
      if (e->args.size() != 1) return "<bad unary>";
      return "(u" + e->text + " " + dump(e->args[0]) + ")";
    case Expr::Kind::Binary:
      if (e->args.size() != 2) return "<bad binary>";
      return "(" + e->text + " " + dump(e->args[0]) + " " + dump(e->args[1]) + ")";
    case Expr::Kind::Call: {
      std::string s = e->text + "[";
      for (std::size_t i = 0; i < e->args.size(); ++i) s += (i ? ", " : "") + dump(e->args[i]);
      return s + "]";
    }
  }
  return "<bad kind>";
}

/// The expression of `parameter q = TEXT`.
ExprPtr expr_of(const std::string& text) {
  ModelAst ast = parse_text("parameter q = " + text);
  if (ast.params.size() != 1) return nullptr;
  return ast.params[0].value;
}

std::string dump_of(const std::string& text) {
  return dump(expr_of(text));
}

/// The error parsing `text` raises (a failed expectation when there is none).
ModelError error_of(const std::string& text) {
  try {
    parse_text(text);
  } catch (const ModelError& e) {
    return e;
  }
  ADD_FAILURE() << "no error for:\n" << text;
  return ModelError("none", {}, "no error");
}

/// Expect a ModelError at LINE:COL whose message contains `part`.
void expect_error(const std::string& text, int line, int col, const std::string& part) {
  SCOPED_TRACE(text);
  const ModelError e = error_of(text);
  const std::string prefix =
      "t.model:" + std::to_string(line) + ":" + std::to_string(col) + ": error: ";
  const std::string what = e.what();
  EXPECT_EQ(what.substr(0, prefix.size()), prefix) << what;
  EXPECT_EQ(e.loc().line, line);
  EXPECT_EQ(e.loc().col, col);
  EXPECT_NE(e.bare_message().find(part), std::string::npos) << e.bare_message();
  EXPECT_EQ(e.exit_code(), ExitCode::ModelError);
}

const char* const kBouncingBall =
    "# The bouncing ball of the paper's \xC2\xA7"
    "4.1.\n"                                                                              // 1
    "model bouncing_ball\n"                                                               // 2
    "\n"                                                                                  // 3
    "parameter m = 1        # mass\n"                                                     // 4
    "parameter g = 1        # gravity\n"                                                  // 5
    "parameter e = 1        # coefficient of restitution (1: elastic)\n"                  // 6
    "\n"                                                                                  // 7
    "state x, p             # height and momentum\n"                                      // 8
    "\n"                                                                                  // 9
    "mode flight {\n"                                                                     // 10
    "  hamiltonian p^2/(2*m) + m*g*x     # x' = dH/dp = p/m,  p' = -dH/dx = -m*g\n"       // 11
    "}\n"                                                                                 // 12
    "\n"                                                                                  // 13
    "guard ground {\n"                                                                    // 14
    "  when x = 0 decreasing             # s(x, p) = x crosses 0 from above\n"            // 15
    "  reset restitution e               # p -> p - (1+e) (M^-1(ds,p)/M^-1(ds,ds)) ds\n"  // 16
    "}\n"                                                                                 // 17
    "\n"                                                                                  // 18
    "simulation {\n"                                                                      // 19
    "  domain x in [0, 2]\n"                                                              // 20
    "  domain p in [-2, 2]\n"                                                             // 21
    "  grid 75x75\n"                                                                      // 22
    "  initial exp(-(x-1)^2 - p^2)\n"                                                     // 23
    "  t_end 10\n"                                                                        // 24
    "  dt 0.2\n"                                                                          // 25
    "  method characteristics\n"                                                          // 26
    "}\n";                                                                                // 27

// --- The example of docs/model-language.md ------------------------------------

TEST(Parse, DocumentationExample) {
  std::ifstream in(std::string(HYBGEN_SOURCE_DIR) + "/docs/model-language.md");
  ASSERT_TRUE(in) << "cannot open docs/model-language.md";
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string doc = ss.str();
  const std::size_t open = doc.find("```text\n");
  ASSERT_NE(open, std::string::npos);
  const std::size_t begin = open + 8;
  const std::size_t end = doc.find("```", begin);
  ASSERT_NE(end, std::string::npos);
  const std::string example = doc.substr(begin, end - begin);
  const ModelAst ast = parse_text(example);
  ASSERT_TRUE(ast.name);
  EXPECT_EQ(ast.name->name, "bouncing_ball");
  ASSERT_EQ(ast.params.size(), 3U);
  EXPECT_EQ(ast.params[2].name, "e");
  ASSERT_EQ(ast.states.size(), 2U);
  ASSERT_EQ(ast.modes.size(), 1U);
  EXPECT_EQ(dump(ast.modes[0].hamiltonian), "(+ (/ (^ p 2) (* 2 m)) (* (* m g) x))");
  ASSERT_EQ(ast.guards.size(), 1U);
  EXPECT_EQ(ast.guards[0].reset.kind, ResetDecl::Kind::Restitution);
  ASSERT_TRUE(ast.simulation);
  EXPECT_EQ(ast.simulation->domains.size(), 2U);
  ASSERT_TRUE(ast.simulation->grid);
  EXPECT_EQ(ast.simulation->grid->counts, (std::vector<long>{75, 75}));
  EXPECT_EQ(ast.simulation->settings.size(), 3U);
}

TEST(Parse, BouncingBallInDetail) {
  const ModelAst ast = parse_text(kBouncingBall);
  EXPECT_EQ(ast.path, "t.model");
  ASSERT_TRUE(ast.name);
  EXPECT_EQ(ast.name->name, "bouncing_ball");
  EXPECT_EQ(at(ast.name->loc), "2:7");

  ASSERT_EQ(ast.params.size(), 3U);
  const char* names[] = {"m", "g", "e"};
  for (int i = 0; i < 3; ++i) {
    const ParamDecl& p = ast.params[static_cast<std::size_t>(i)];
    EXPECT_EQ(p.name, names[i]);
    EXPECT_EQ(at(p.loc), std::to_string(4 + i) + ":11");
    ASSERT_TRUE(p.value);
    EXPECT_EQ(p.value->kind, Expr::Kind::Number);
    EXPECT_EQ(p.value->text, "1");
    EXPECT_EQ(at(p.value->loc), std::to_string(4 + i) + ":15");
  }

  ASSERT_EQ(ast.states.size(), 2U);
  EXPECT_EQ(ast.states[0].name, "x");
  EXPECT_EQ(at(ast.states[0].loc), "8:7");
  EXPECT_EQ(ast.states[1].name, "p");
  EXPECT_EQ(at(ast.states[1].loc), "8:10");

  ASSERT_EQ(ast.modes.size(), 1U);
  const ModeDecl& mode = ast.modes[0];
  EXPECT_EQ(mode.name.name, "flight");
  EXPECT_EQ(at(mode.name.loc), "10:6");
  EXPECT_TRUE(mode.flows.empty());
  EXPECT_TRUE(mode.coordinates.empty());
  EXPECT_TRUE(mode.momenta.empty());
  EXPECT_TRUE(mode.where.empty());
  EXPECT_EQ(at(mode.hamiltonian_loc), "11:3");
  const ExprPtr& h = mode.hamiltonian;
  ASSERT_TRUE(h);
  EXPECT_EQ(dump(h), "(+ (/ (^ p 2) (* 2 m)) (* (* m g) x))");
  EXPECT_EQ(h->kind, Expr::Kind::Binary);
  EXPECT_EQ(at(h->loc), "11:15");                    // the sum starts at 'p'
  EXPECT_EQ(at(h->args[0]->loc), "11:15");           // p^2/(2*m)
  EXPECT_EQ(at(h->args[0]->args[1]->loc), "11:20");  // 2*m, inside its parentheses
  EXPECT_EQ(at(h->args[1]->loc), "11:27");           // m*g*x
  EXPECT_EQ(at(h->args[1]->args[1]->loc), "11:31");  // x

  ASSERT_EQ(ast.guards.size(), 1U);
  const GuardDecl& g = ast.guards[0];
  EXPECT_EQ(g.name.name, "ground");
  EXPECT_EQ(at(g.name.loc), "14:7");
  EXPECT_FALSE(g.from);
  EXPECT_FALSE(g.to);
  EXPECT_TRUE(g.has_when);
  EXPECT_EQ(g.when.op, "=");
  EXPECT_EQ(dump(g.when.lhs), "x");
  EXPECT_EQ(dump(g.when.rhs), "0");
  EXPECT_EQ(at(g.when.loc), "15:8");
  EXPECT_EQ(at(g.when.rhs->loc), "15:12");
  EXPECT_EQ(g.direction, Direction::Decreasing);
  EXPECT_EQ(at(g.direction_loc), "15:14");
  EXPECT_TRUE(g.has_reset);
  EXPECT_EQ(g.reset.kind, ResetDecl::Kind::Restitution);
  EXPECT_EQ(at(g.reset.loc), "16:3");
  EXPECT_EQ(dump(g.reset.coefficient), "e");
  EXPECT_EQ(at(g.reset.coefficient->loc), "16:21");
  EXPECT_TRUE(g.reset.components.empty());

  ASSERT_TRUE(ast.simulation);
  const SimulationDecl& s = *ast.simulation;
  EXPECT_EQ(at(s.loc), "19:1");
  ASSERT_EQ(s.domains.size(), 2U);
  EXPECT_EQ(s.domains[0].var.name, "x");
  EXPECT_EQ(at(s.domains[0].var.loc), "20:10");
  EXPECT_EQ(dump(s.domains[0].lo), "0");
  EXPECT_EQ(at(s.domains[0].lo->loc), "20:16");
  EXPECT_EQ(dump(s.domains[0].hi), "2");
  EXPECT_EQ(at(s.domains[0].hi->loc), "20:19");
  EXPECT_EQ(s.domains[1].var.name, "p");
  EXPECT_EQ(dump(s.domains[1].lo), "(u- 2)");
  EXPECT_EQ(at(s.domains[1].lo->loc), "21:16");
  ASSERT_TRUE(s.grid);
  EXPECT_EQ(s.grid->counts, (std::vector<long>{75, 75}));
  EXPECT_EQ(at(s.grid->loc), "22:8");
  ASSERT_EQ(s.initial.size(), 1U);
  EXPECT_FALSE(s.initial[0].mode);
  EXPECT_EQ(at(s.initial[0].loc), "23:3");
  const ExprPtr& u0 = s.initial[0].density;
  EXPECT_EQ(dump(u0), "exp[(- (u- (^ (- x 1) 2)) (^ p 2))]");
  EXPECT_EQ(at(u0->loc), "23:11");
  const ExprPtr& diff = u0->args[0];
  EXPECT_EQ(at(diff->loc), "23:15");                             // starts at the unary minus
  EXPECT_EQ(at(diff->args[0]->loc), "23:15");                    // the unary minus
  EXPECT_EQ(at(diff->args[0]->args[0]->loc), "23:16");           // (x-1)^2 starts at '('
  EXPECT_EQ(at(diff->args[0]->args[0]->args[0]->loc), "23:17");  // x-1 itself
  EXPECT_TRUE(s.support.empty());
  ASSERT_EQ(s.settings.size(), 3U);
  EXPECT_EQ(s.settings[0].key.name, "t_end");
  EXPECT_EQ(at(s.settings[0].key.loc), "24:3");
  EXPECT_EQ(dump(s.settings[0].value), "10");
  EXPECT_EQ(s.settings[0].word, "");
  EXPECT_EQ(at(s.settings[0].value_loc), "24:9");
  EXPECT_EQ(s.settings[1].key.name, "dt");
  EXPECT_EQ(dump(s.settings[1].value), "0.2");
  EXPECT_EQ(at(s.settings[1].value_loc), "25:6");
  EXPECT_EQ(s.settings[2].key.name, "method");
  EXPECT_EQ(s.settings[2].word, "characteristics");
  EXPECT_EQ(dump(s.settings[2].value), "characteristics");
  EXPECT_EQ(at(s.settings[2].value_loc), "26:10");
}

// --- Expressions ----------------------------------------------------------------

TEST(Parse, Precedence) {
  EXPECT_EQ(dump_of("a + b * c"), "(+ a (* b c))");
  EXPECT_EQ(dump_of("a * b + c"), "(+ (* a b) c)");
  EXPECT_EQ(dump_of("a - b - c"), "(- (- a b) c)");
  EXPECT_EQ(dump_of("a / b * c"), "(* (/ a b) c)");
  EXPECT_EQ(dump_of("a / b / c"), "(/ (/ a b) c)");
  EXPECT_EQ(dump_of("(a + b) * c"), "(* (+ a b) c)");
  EXPECT_EQ(dump_of("a ^ b * c"), "(* (^ a b) c)");
  EXPECT_EQ(dump_of("a * b ^ c"), "(* a (^ b c))");
  EXPECT_EQ(dump_of("-a * b"), "(* (u- a) b)");
  EXPECT_EQ(dump_of("a - -b"), "(- a (u- b))");
  EXPECT_EQ(dump_of("--x"), "(u- (u- x))");
  EXPECT_EQ(dump_of("+x"), "(u+ x)");
  EXPECT_EQ(dump_of("((x))"), "x");
}

TEST(Parse, PowerIsRightAssociativeAndBindsTighterThanUnaryMinus) {
  EXPECT_EQ(dump_of("2^3^2"), "(^ 2 (^ 3 2))");
  EXPECT_EQ(dump_of("-x^2"), "(u- (^ x 2))");
  EXPECT_EQ(dump_of("-2^2"), "(u- (^ 2 2))");
  EXPECT_EQ(dump_of("2^-1"), "(^ 2 (u- 1))");
  EXPECT_EQ(dump_of("x^-y^2"), "(^ x (u- (^ y 2)))");
  EXPECT_EQ(dump_of("(2^3)^2"), "(^ (^ 2 3) 2)");
  EXPECT_EQ(dump_of("a**b**c"), "(^ a (^ b c))");  // '**' is stored as '^'
  EXPECT_EQ(dump_of("a**-b"), "(^ a (u- b))");
}

TEST(Parse, CallsAndLocations) {
  EXPECT_EQ(dump_of("sin(x)"), "sin[x]");
  EXPECT_EQ(dump_of("f(x, y + 1, g(z))"), "f[x, (+ y 1), g[z]]");
  EXPECT_EQ(dump_of("exp(-x^2/2)"), "exp[(/ (u- (^ x 2)) 2)]");
  // parameter q = 2 * (a + b)
  // 1234567890123456789012345
  const ExprPtr e = expr_of("2 * (a + b)");
  ASSERT_TRUE(e);
  EXPECT_EQ(at(e->loc), "1:15");
  EXPECT_EQ(at(e->args[1]->loc), "1:20");  // a + b: its own text, not the '('
  const ExprPtr f = expr_of("(a + b) * 2");
  ASSERT_TRUE(f);
  EXPECT_EQ(at(f->loc), "1:15");           // the product starts at '('
  EXPECT_EQ(at(f->args[0]->loc), "1:16");  // the sum starts at 'a'
  const ExprPtr g = expr_of("-  sqrt(y)");
  ASSERT_TRUE(g);
  EXPECT_EQ(at(g->loc), "1:15");
  EXPECT_EQ(g->kind, Expr::Kind::Unary);
  EXPECT_EQ(g->args[0]->kind, Expr::Kind::Call);
  EXPECT_EQ(at(g->args[0]->loc), "1:18");
  EXPECT_EQ(at(g->args[0]->args[0]->loc), "1:23");
}

TEST(Parse, NumberLiteralsKeepTheirText) {
  for (const char* lit : {"12", "0.25", ".5", "1e-3", "2.5E+2", "1E5", "007", "1.", "3.e2"}) {
    const ExprPtr e = expr_of(lit);
    ASSERT_TRUE(e) << lit;
    EXPECT_EQ(e->kind, Expr::Kind::Number) << lit;
    EXPECT_EQ(e->text, lit);
  }
  EXPECT_EQ(dump_of("1e-3-2"), "(- 1e-3 2)");
  EXPECT_EQ(dump_of("2.5E+2+.5"), "(+ 2.5E+2 .5)");
}

TEST(Parse, ExpressionsSpanLines) {
  const ModelAst ast = parse_text("mode m {\n  hamiltonian p^2\n    + x^2\n  where x\n  > 0\n}\n");
  ASSERT_EQ(ast.modes.size(), 1U);
  EXPECT_EQ(dump(ast.modes[0].hamiltonian), "(+ (^ p 2) (^ x 2))");
  ASSERT_EQ(ast.modes[0].where.size(), 1U);
  EXPECT_EQ(ast.modes[0].where[0].op, ">");
  EXPECT_EQ(at(ast.modes[0].where[0].loc), "4:9");
}

// --- Statements -----------------------------------------------------------------

TEST(Parse, CommentsAndSemicolons) {
  const ModelAst ast = parse_text(
      "// leading comment\n"
      "model a; state x; # trailing comment with @ and \xC3\xA9\n"
      "parameter k = 4/2; // k is 2\n"
      "parameter j = k/2 // a comment; k/ /2 would be an error\n");
  ASSERT_TRUE(ast.name);
  EXPECT_EQ(ast.name->name, "a");
  ASSERT_EQ(ast.states.size(), 1U);
  ASSERT_EQ(ast.params.size(), 2U);
  EXPECT_EQ(dump(ast.params[0].value), "(/ 4 2)");
  EXPECT_EQ(at(ast.params[0].loc), "3:11");
  EXPECT_EQ(dump(ast.params[1].value), "(/ k 2)");
}

TEST(Parse, CommentOnlyFileGivesAnEmptyAst) {
  const ModelAst ast = parse_text("# nothing\n// here\n");
  EXPECT_FALSE(ast.name);
  EXPECT_TRUE(ast.params.empty());
  EXPECT_TRUE(ast.states.empty());
  EXPECT_TRUE(ast.modes.empty());
  EXPECT_TRUE(ast.guards.empty());
  EXPECT_FALSE(ast.simulation);
}

TEST(Parse, ParameterLists) {
  const ModelAst ast = parse_text("parameter a = 1, b = a * 2,\n  c = -b\nparameter d = 3");
  ASSERT_EQ(ast.params.size(), 4U);
  EXPECT_EQ(ast.params[0].name, "a");
  EXPECT_EQ(ast.params[1].name, "b");
  EXPECT_EQ(at(ast.params[1].loc), "1:18");
  EXPECT_EQ(dump(ast.params[1].value), "(* a 2)");
  EXPECT_EQ(ast.params[2].name, "c");
  EXPECT_EQ(at(ast.params[2].loc), "2:3");
  EXPECT_EQ(dump(ast.params[2].value), "(u- b)");
  EXPECT_EQ(ast.params[3].name, "d");
}

TEST(Parse, ModeItems) {
  const ModelAst ast = parse_text(
      "state q1, q2, p1, p2\n"
      "mode left {\n"
      "  q1' = p1; q2' = p2\n"
      "  p1' = -q1\n"
      "  p2' = -sin(q2)\n"
      "  where q1 < 0; where q2 >= -1\n"
      "}\n"
      "mode h { hamiltonian p1^2 + p2^2; coordinates q1, q2; momenta p1, p2; where q1 <= 1; "
      "where q2 > 2 }\n");
  ASSERT_EQ(ast.modes.size(), 2U);
  const ModeDecl& a = ast.modes[0];
  EXPECT_FALSE(a.hamiltonian);
  ASSERT_EQ(a.flows.size(), 4U);
  EXPECT_EQ(a.flows[0].var.name, "q1");
  EXPECT_EQ(at(a.flows[0].var.loc), "3:3");
  EXPECT_EQ(dump(a.flows[0].rhs), "p1");
  EXPECT_EQ(at(a.flows[0].rhs->loc), "3:9");
  EXPECT_EQ(a.flows[1].var.name, "q2");
  EXPECT_EQ(at(a.flows[1].var.loc), "3:13");
  EXPECT_EQ(dump(a.flows[3].rhs), "(u- sin[q2])");
  ASSERT_EQ(a.where.size(), 2U);
  EXPECT_EQ(a.where[0].op, "<");
  EXPECT_EQ(dump(a.where[0].lhs), "q1");
  EXPECT_EQ(dump(a.where[0].rhs), "0");
  EXPECT_EQ(at(a.where[0].loc), "6:9");
  EXPECT_EQ(a.where[1].op, ">=");
  EXPECT_EQ(dump(a.where[1].rhs), "(u- 1)");

  const ModeDecl& b = ast.modes[1];
  EXPECT_EQ(dump(b.hamiltonian), "(+ (^ p1 2) (^ p2 2))");
  EXPECT_EQ(at(b.hamiltonian_loc), "8:10");
  ASSERT_EQ(b.coordinates.size(), 2U);
  EXPECT_EQ(b.coordinates[1].name, "q2");
  EXPECT_EQ(at(b.coordinates[1].loc), "8:51");
  ASSERT_EQ(b.momenta.size(), 2U);
  EXPECT_EQ(b.momenta[0].name, "p1");
  ASSERT_EQ(b.where.size(), 2U);
  EXPECT_EQ(b.where[0].op, "<=");
  EXPECT_EQ(b.where[1].op, ">");
}

TEST(Parse, KeywordsAreContextual) {
  // A state may be called like an item keyword: `where' = ...` is a flow.
  const ModelAst ast = parse_text("state where, in\nmode m { where' = in; in' = where }");
  ASSERT_EQ(ast.modes.size(), 1U);
  ASSERT_EQ(ast.modes[0].flows.size(), 2U);
  EXPECT_EQ(ast.modes[0].flows[0].var.name, "where");
  EXPECT_EQ(dump(ast.modes[0].flows[0].rhs), "in");
  EXPECT_EQ(ast.modes[0].flows[1].var.name, "in");
}

TEST(Parse, GuardItems) {
  const ModelAst ast = parse_text(
      "guard a { from up to down; when x - 1 = y*2 increasing; reset identity }\n"
      "guard b { to down\n when x = 0 decreasing\n reset elastic }\n"
      "guard c { from up; when x = 0 decreasing; reset (x, -p, 2*z) }\n"
      "guard d { reset restitution 1/2 + k; from p to q }\n");
  ASSERT_EQ(ast.guards.size(), 4U);
  const GuardDecl& a = ast.guards[0];
  ASSERT_TRUE(a.from);
  EXPECT_EQ(a.from->name, "up");
  EXPECT_EQ(at(a.from->loc), "1:16");
  ASSERT_TRUE(a.to);
  EXPECT_EQ(a.to->name, "down");
  EXPECT_EQ(at(a.to->loc), "1:22");
  EXPECT_EQ(dump(a.when.lhs), "(- x 1)");
  EXPECT_EQ(dump(a.when.rhs), "(* y 2)");
  EXPECT_EQ(at(a.when.loc), "1:33");
  EXPECT_EQ(a.direction, Direction::Increasing);
  EXPECT_EQ(at(a.direction_loc), "1:45");
  EXPECT_EQ(a.reset.kind, ResetDecl::Kind::Identity);
  EXPECT_EQ(at(a.reset.loc), "1:57");

  const GuardDecl& b = ast.guards[1];
  EXPECT_FALSE(b.from);
  ASSERT_TRUE(b.to);
  EXPECT_EQ(b.to->name, "down");
  EXPECT_EQ(b.direction, Direction::Decreasing);
  EXPECT_EQ(b.reset.kind, ResetDecl::Kind::Elastic);
  EXPECT_EQ(at(b.reset.loc), "4:2");

  const GuardDecl& c = ast.guards[2];
  ASSERT_TRUE(c.from);
  EXPECT_FALSE(c.to);
  EXPECT_EQ(c.reset.kind, ResetDecl::Kind::Explicit);
  ASSERT_EQ(c.reset.components.size(), 3U);
  EXPECT_EQ(dump(c.reset.components[1]), "(u- p)");
  EXPECT_EQ(dump(c.reset.components[2]), "(* 2 z)");
  EXPECT_EQ(at(c.reset.components_loc), "5:49");
  EXPECT_EQ(at(c.reset.components[0]->loc), "5:50");

  const GuardDecl& d = ast.guards[3];
  EXPECT_FALSE(d.has_when);
  EXPECT_TRUE(d.has_reset);
  EXPECT_EQ(d.reset.kind, ResetDecl::Kind::Restitution);
  EXPECT_EQ(dump(d.reset.coefficient), "(+ (/ 1 2) k)");
  ASSERT_TRUE(d.from);
  EXPECT_EQ(d.from->name, "p");
  ASSERT_TRUE(d.to);
  EXPECT_EQ(d.to->name, "q");
}

TEST(Parse, SimulationItems) {
  const ModelAst ast = parse_text(
      "simulation {\n"
      "  initial plus: x + 1\n"
      "  initial minus : exp(x)\n"
      "  initial x * 2\n"
      "  initial y\n"
      "  support x^2 + y^2 <= 4\n"
      "  grid 33x33x33\n"
      "  tol 1e-10; max_events 100\n"
      "  dt t_end / 10\n"
      "  t_end T\n"
      "  method characteristics }\n"
      "parameter z = 1\n");
  ASSERT_TRUE(ast.simulation);
  const SimulationDecl& s = *ast.simulation;
  ASSERT_EQ(s.initial.size(), 4U);
  ASSERT_TRUE(s.initial[0].mode);
  EXPECT_EQ(s.initial[0].mode->name, "plus");
  EXPECT_EQ(at(s.initial[0].mode->loc), "2:11");
  EXPECT_EQ(dump(s.initial[0].density), "(+ x 1)");
  ASSERT_TRUE(s.initial[1].mode);
  EXPECT_EQ(s.initial[1].mode->name, "minus");
  EXPECT_EQ(dump(s.initial[1].density), "exp[x]");
  EXPECT_FALSE(s.initial[2].mode);
  EXPECT_EQ(dump(s.initial[2].density), "(* x 2)");
  EXPECT_FALSE(s.initial[3].mode);
  EXPECT_EQ(dump(s.initial[3].density), "y");
  ASSERT_EQ(s.support.size(), 1U);
  EXPECT_EQ(s.support[0].op, "<=");
  EXPECT_EQ(dump(s.support[0].lhs), "(+ (^ x 2) (^ y 2))");
  EXPECT_EQ(at(s.support[0].loc), "6:11");
  ASSERT_TRUE(s.grid);
  EXPECT_EQ(s.grid->counts, (std::vector<long>{33, 33, 33}));
  ASSERT_EQ(s.settings.size(), 5U);
  EXPECT_EQ(s.settings[0].key.name, "tol");
  EXPECT_EQ(dump(s.settings[0].value), "1e-10");
  EXPECT_EQ(s.settings[1].key.name, "max_events");
  EXPECT_EQ(dump(s.settings[1].value), "100");
  EXPECT_EQ(s.settings[2].key.name, "dt");
  EXPECT_EQ(s.settings[2].word, "");  // an identifier followed by an operator
  EXPECT_EQ(dump(s.settings[2].value), "(/ t_end 10)");
  EXPECT_EQ(at(s.settings[2].value_loc), "9:6");
  EXPECT_EQ(s.settings[3].key.name, "t_end");
  EXPECT_EQ(s.settings[3].word, "T");  // a lone identifier: word and symbol
  EXPECT_EQ(dump(s.settings[3].value), "T");
  EXPECT_EQ(s.settings[4].word, "characteristics");
  ASSERT_EQ(ast.params.size(), 1U);
}

TEST(Parse, SettingValueInParenthesesIsAnExpression) {
  const ModelAst ast = parse_text("simulation { dt (h) t_end -h method f(x) }");
  ASSERT_TRUE(ast.simulation);
  const auto& st = ast.simulation->settings;
  ASSERT_EQ(st.size(), 3U);
  EXPECT_EQ(st[0].word, "");
  EXPECT_EQ(dump(st[0].value), "h");
  EXPECT_EQ(at(st[0].value_loc), "1:17");
  EXPECT_EQ(st[1].word, "");
  EXPECT_EQ(dump(st[1].value), "(u- h)");
  EXPECT_EQ(st[2].word, "");
  EXPECT_EQ(dump(st[2].value), "f[x]");
}

TEST(Parse, GridSizes) {
  auto grid_of = [](const std::string& g) {
    const ModelAst ast = parse_text("simulation { grid " + g + " }");
    return ast.simulation && ast.simulation->grid ? ast.simulation->grid->counts
                                                  : std::vector<long>{};
  };
  EXPECT_EQ(grid_of("65"), (std::vector<long>{65}));
  EXPECT_EQ(grid_of("2x3"), (std::vector<long>{2, 3}));
  EXPECT_EQ(grid_of("100000000x1"), (std::vector<long>{100000000, 1}));
  EXPECT_EQ(grid_of("0007x0001"), (std::vector<long>{7, 1}));
  expect_error("simulation { grid 0 }", 1, 19,
               "a grid count must be a positive integer, found '0'");
  expect_error("simulation { grid 3x100000001 }", 1, 21, "too large (at most 100000000)");
  expect_error("simulation { grid 99999999999999999999999x2 }", 1, 19, "too large");
  expect_error("simulation { grid 4x4x00 }", 1, 23, "positive integer, found '00'");
  expect_error("simulation { grid 1.5 }", 1, 19,
               "expected a grid size after 'grid' (e.g. 75x75, or one integer N), found '1.5'");
  expect_error("simulation { grid 4 x }", 1, 23, "expected a value for setting 'x', found '}'");
  expect_error("simulation { grid 4x4y }", 1, 19, "malformed grid literal '4x4y'");
  expect_error("simulation { grid 1 grid 2 }", 1, 21, "the grid is given twice (first at 1:19)");
}

// --- Errors ---------------------------------------------------------------------

TEST(ParseErrors, MessageStartsWithLocationAndHasCaret) {
  const ModelError e = error_of("model a\nparameter m 1\n");
  EXPECT_EQ(std::string(e.what()),
            "t.model:2:13: error: expected '=' after parameter name 'm', found '1'\n"
            "  parameter m 1\n"
            "              ^");
  EXPECT_EQ(e.bare_message(), "expected '=' after parameter name 'm', found '1'");
}

TEST(ParseErrors, CaretUnderTheOffendingTokenAfterTabs) {
  const ModelError e = error_of("state x\n\tmode m {\t@ }\n");
  EXPECT_EQ(std::string(e.what()),
            "t.model:2:11: error: unexpected character '@'\n"
            "  \tmode m {\t@ }\n"
            "  \t        \t^");
}

TEST(ParseErrors, Statements) {
  expect_error("model a\nfoo x\n", 2, 1,
               "unknown statement 'foo' (expected model, parameter, state, mode, guard or "
               "simulation)");
  // The first error wins: 'foo' is reported, not the '@' after it.
  expect_error("foo @", 1, 1, "unknown statement 'foo'");
  expect_error("state x;;", 1, 9,
               "expected a statement (model, parameter, state, mode, guard or "
               "simulation), found ';'");
  expect_error("model", 1, 6, "expected a model name after 'model', found end of file");
  expect_error("model a\nmodel b\n", 2, 1, "the model is named twice (first at 1:7)");
  expect_error("state x,\n", 2, 1, "expected a state variable name after ',', found end of file");
  expect_error("state 1", 1, 7, "expected a state variable name after 'state', found '1'");
  expect_error("parameter a = 1, = 2", 1, 18, "expected a parameter name after ','");
  expect_error("simulation { }\nsimulation { }", 2, 1,
               "a second simulation block (the first is at 1:1)");
  expect_error("mode m hamiltonian x", 1, 8,
               "expected '{' after mode name 'm', found 'hamiltonian'");
}

TEST(ParseErrors, Lexical) {
  expect_error("state x @", 1, 9, "unexpected character '@'");
  expect_error("state x, \xC3\xBC", 1, 10,
               "unexpected character '\xC3\xBC' (U+00FC; only ASCII is allowed outside comments)");
  expect_error("parameter k = 1 # \xCF\x80\nparameter j = 2 \xE2\x88\x92 1", 2, 17, "U+2212");
  expect_error("state x\x01", 1, 8, "unexpected control character 0x01");
  expect_error(std::string("state x", 7) + std::string(1, '\0'), 1, 8,
               "unexpected control character 0x00");
  expect_error("parameter k = 2x", 1, 15, "a number is followed by letters: '2x' (write 2*x)");
  expect_error("parameter k = 1.5e", 1, 15, "a number is followed by letters: '1.5e'");
  expect_error("parameter k = 1e+", 1, 15, "malformed number '1e+': the exponent needs digits");
  expect_error("parameter k = 1.2.3", 1, 15, "malformed number '1.2.3'");
  expect_error("parameter k = .", 1, 15, "unexpected character '.'");
  expect_error("parameter k = 75x75", 1, 15, "grid literal '75x75' is only valid after 'grid'");
  expect_error("state x, y\nmode m { x' = 2x3 }", 2, 15, "grid literal '2x3' is only valid");
}

TEST(ParseErrors, Expressions) {
  expect_error("mode m {\n  x' = \n}\n", 3, 1, "expected an expression, found '}'");
  expect_error("parameter k = 2 * * 3", 1, 19, "expected an expression, found '*'");
  expect_error("parameter k = (1 + 2\nstate x", 2, 1,
               "expected ')' to close the '(' at 1:15, found 'state'");
  expect_error("parameter k = sin(x", 1, 20,
               "expected ',' or ')' in the call of 'sin' (opened at 1:18), found end of file");
  expect_error("parameter k = f()", 1, 17, "expected an expression, found ')'");
  expect_error("parameter k = 2 ^", 1, 18, "expected an expression, found end of file");
}

TEST(ParseErrors, Blocks) {
  expect_error("model a\nstate x\nmode flight {\n  hamiltonian x^2\n", 5, 1,
               "unterminated block: '{' at 3:13 has no matching '}'");
  expect_error("guard g {", 1, 10, "unterminated block: '{' at 1:9 has no matching '}'");
  expect_error("guard ground {\n  xyz 1\n}", 2, 3,
               "unknown item 'xyz' in guard 'ground' (expected from, to, when or reset)");
  expect_error("mode m {\n  hamiltonian x\nguard g { }", 3, 1,
               "unknown item 'guard' in mode 'm' (is the '}' closing the '{' at 1:8 missing?)");
  expect_error("simulation {\n  dt 1\nmode m { }", 3, 1,
               "unknown item 'mode' in the simulation block (is the '}' closing the '{' at 1:12 "
               "missing?)");
  expect_error("mode m { foo }", 1, 10, "unknown item 'foo' in mode 'm'");
  expect_error("mode m { x = 1 }", 1, 10, "(write x' = ... for a flow equation)");
  expect_error("mode m { x' 1 }", 1, 13, "expected '=' after x', found '1'");
  expect_error("mode m { 1 }", 1, 10, "expected an item of mode 'm'");
  expect_error("mode m { hamiltonian x; hamiltonian y }", 1, 25,
               "mode 'm' has a second hamiltonian (the first is at 1:10)");
  expect_error("mode m { coordinates q; coordinates r }", 1, 25,
               "mode 'm' names its coordinates twice (first at 1:22)");
  expect_error("mode m { where x = 1 }", 1, 18, "compares with '<', '<=', '>' or '>=', not '='");
  expect_error("mode m { where x }", 1, 18, "expected '<', '<=', '>' or '>=' in the condition");
}

TEST(ParseErrors, Guards) {
  expect_error("guard g { when x = 0 down }", 1, 22,
               "expected 'decreasing' or 'increasing' after the guard surface, found 'down'");
  expect_error("guard g { when x < 0 decreasing }", 1, 18,
               "a guard surface is written 'when L = R'");
  expect_error("guard g { when x == 0 decreasing }", 1, 19, "write '=', not '=='");
  expect_error("guard g { when x decreasing }", 1, 18, "expected '=' in the guard surface");
  expect_error("guard g { reset bounce }", 1, 17,
               "expected identity, elastic, restitution COEFFICIENT, absorb or (e1, ..., eN) "
               "after 'reset', found 'bounce'");
  expect_error("guard g { reset (x, -p }", 1, 24,
               "expected ',' or ')' in the reset components (opened at 1:17), found '}'");
  expect_error("guard g { when x = 0 decreasing; when x = 1 increasing }", 1, 34,
               "guard 'g' has a second 'when' (the first surface is at 1:16)");
  expect_error("guard g { from a to b; to c }", 1, 24,
               "guard 'g' names its target mode twice (first at 1:21)");
  expect_error("guard g { from a; from b }", 1, 19, "names its source mode twice");
  expect_error("guard g { reset identity reset elastic }", 1, 26, "has a second reset");
  expect_error("guard g { from }", 1, 16, "expected a mode name after 'from', found '}'");
}

TEST(ParseErrors, Simulation) {
  expect_error("simulation { domain x [0, 1] }", 1, 23,
               "expected 'in' after 'domain x', found '['");
  expect_error("simulation { domain x in [0 1] }", 1, 29,
               "expected ',' between the ends of domain 'x', found '1'");
  expect_error("simulation { domain x in [0, 1 }", 1, 32,
               "expected ']' after the upper end of domain 'x', found '}'");
  expect_error("simulation { t_end }", 1, 20, "expected a value for setting 't_end', found '}'");
  expect_error("simulation { initial }", 1, 22, "expected an expression, found '}'");
  expect_error("simulation { support x }", 1, 24,
               "expected '<', '<=', '>' or '>=' in the condition after 'support'");
  expect_error("simulation { = 1 }", 1, 14, "expected an item of the simulation block");
}

TEST(ParseErrors, NestingIsCapped) {
  // parameter k = (((...1...)))
  const std::string deep = "parameter k = " + std::string(300, '(') + "1" + std::string(300, ')');
  expect_error(deep, 1, 15 + 256, "expression is nested too deeply (more than 256 levels)");
  const std::string ok = "parameter k = " + std::string(200, '(') + "1" + std::string(200, ')');
  EXPECT_EQ(dump(parse_text(ok).params.at(0).value), "1");
  expect_error("parameter k = " + std::string(300, '-') + "1", 1, 15 + 256, "nested too deeply");
  std::string power = "parameter k = ";
  for (int i = 0; i < 300; ++i) power += "2^";
  expect_error(power + "2", 1, 15 + 2 * 256, "nested too deeply");
  // A million unclosed parentheses: an error, not a stack overflow.
  expect_error("parameter k = " + std::string(1000000, '('), 1, 15 + 256, "nested too deeply");
  std::string calls = "parameter k = ";
  for (int i = 0; i < 100000; ++i) calls += "f(";
  expect_error(calls, 1, 15 + 2 * 256, "nested too deeply");
}

TEST(ParseErrors, LongChainsAreCapped) {
  std::string sum = "parameter k = ";
  for (int i = 0; i < 600; ++i) sum += "1+";
  // The 512th '+' would make the tree 513 levels deep; it is at 14 + 2*512.
  expect_error(sum + "1", 1, 14 + 2 * 512, "expression is too long or too deeply nested");
  std::string product = "parameter k = ";
  for (int i = 0; i < 200000; ++i) product += "x*";
  expect_error(product + "x", 1, 14 + 2 * 512, "too long");
  std::string fine = "parameter k = ";
  for (int i = 0; i < 500; ++i) fine += "1+";
  EXPECT_EQ(parse_text(fine + "1").params.size(), 1U);
}

// --- Robustness -----------------------------------------------------------------

/// Parse `text`: success or a located ModelError are fine, anything else fails.
void expect_graceful(const std::string& text) {
  try {
    parse_text(text);
  } catch (const ModelError& e) {
    EXPECT_GE(e.loc().line, 1) << text;
    EXPECT_GE(e.loc().col, 1) << text;
    const auto lines = 1 + std::count(text.begin(), text.end(), '\n');
    EXPECT_LE(e.loc().line, lines) << text;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "unexpected exception " << e.what() << " for input:\n" << text;
  }
}

TEST(ParseRobustness, RandomBytes) {
  std::mt19937 rng(12345);
  std::uniform_int_distribution<int> len(0, 200), byte(0, 255);
  for (int n = 0; n < 3000; ++n) {
    std::string s(static_cast<std::size_t>(len(rng)), '\0');
    for (char& c : s) c = static_cast<char>(byte(rng));
    expect_graceful(s);
  }
}

TEST(ParseRobustness, RandomTokenSoup) {
  const std::vector<std::string> vocab = {
      "model",    "parameter",   "state",   "mode",        "guard",       "simulation",
      "x",        "p",           "sin",     "'",           "=",           "(",
      ")",        "{",           "}",       "[",           "]",           ",",
      ";",        ":",           "+",       "-",           "*",           "/",
      "^",        "**",          "<",       "<=",          ">",           ">=",
      "1",        "0.5",         ".5",      "1e-3",        "75x75",       "grid",
      "initial",  "when",        "reset",   "from",        "to",          "decreasing",
      "in",       "domain",      "support", "hamiltonian", "coordinates", "where",
      "identity", "restitution", "#c\n",    "//c\n",       "\n",          "@",
      "2x",       "\xC3\xA9"};
  std::mt19937 rng(777);
  std::uniform_int_distribution<std::size_t> pick(0, vocab.size() - 1);
  std::uniform_int_distribution<int> len(1, 60);
  for (int n = 0; n < 5000; ++n) {
    std::string s;
    const int k = len(rng);
    for (int i = 0; i < k; ++i) s += vocab[pick(rng)] + ((i % 3) ? " " : "");
    expect_graceful(s);
  }
}

TEST(ParseRobustness, MutatedValidModel) {
  const std::string base = kBouncingBall;
  std::mt19937 rng(4242);
  std::uniform_int_distribution<std::size_t> where(0, base.size() - 1);
  std::uniform_int_distribution<int> byte(0, 127);
  for (int n = 0; n < 3000; ++n) {
    std::string s = base;
    const int edits = 1 + static_cast<int>(where(rng) % 3);
    for (int e = 0; e < edits; ++e) {
      const std::size_t i = where(rng) % s.size();
      switch (where(rng) % 3) {
        case 0:
          s[i] = static_cast<char>(byte(rng));
          break;
        case 1:
          s.erase(i, 1);
          break;
        default:
          s.insert(i, 1, static_cast<char>(byte(rng)));
          break;
      }
      if (s.empty()) s.push_back('x');
    }
    expect_graceful(s);
  }
}

TEST(ParseRobustness, LargeValidInputIsFast) {
  std::string s = "state x\n";
  for (int i = 0; i < 20000; ++i) s += "parameter k" + std::to_string(i) + " = " + "1 + 2*x^2\n";
  const auto t0 = std::chrono::steady_clock::now();
  const ModelAst ast = parse_text(s);
  const auto ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0)
          .count();
  EXPECT_EQ(ast.params.size(), 20000U);
  EXPECT_EQ(at(ast.params.back().loc), "20001:11");
  EXPECT_LT(ms, 5000);
}

// --- Lie-group models (docs/model-language.md, "Lie-group models") ----------

TEST(ParseLie, DocumentationExample) {
  // The second ```text block of the documentation is the gl2 example.
  std::ifstream in(std::string(HYBGEN_SOURCE_DIR) + "/docs/model-language.md");
  ASSERT_TRUE(in);
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string doc = ss.str();
  const std::size_t section = doc.find("## Lie-group models");
  ASSERT_NE(section, std::string::npos);
  const std::size_t begin = doc.find("```text\n", section) + 8;
  const std::string example = doc.substr(begin, doc.find("```", begin) - begin);
  const ModelAst ast = parse_text(example);
  ASSERT_TRUE(ast.lie);
  const LieDecl& lie = *ast.lie;
  EXPECT_EQ(lie.group.name.name, "A");
  EXPECT_EQ(lie.group.shortcut, "gl");
  EXPECT_EQ(lie.group.shortcut_n, 2);
  ASSERT_EQ(lie.momenta.size(), 4U);
  EXPECT_EQ(lie.momenta[3].name, "zeta4");
  EXPECT_EQ(dump(lie.hamiltonian),
            "(/ (+ (+ (+ (^ zeta1 2) (^ zeta2 2)) (^ zeta3 2)) (^ zeta4 2)) 2)");
  ASSERT_TRUE(lie.reduced);
  EXPECT_EQ(lie.reduced->name, "q");
  EXPECT_EQ(dump(lie.reduced_expr), "(- det[A] 1)");
  EXPECT_TRUE(ast.states.empty());
  EXPECT_TRUE(ast.modes.empty());
  ASSERT_EQ(ast.guards.size(), 1U);
  ASSERT_TRUE(ast.simulation);
  EXPECT_EQ(ast.simulation->domains.size(), 5U);
}

TEST(ParseLie, ParametrisedGroupAndInertia) {
  const ModelAst ast = parse_text(
      "group g(x, y, theta) = [[cos(theta), -sin(theta), x],\n"   // 1
      "  [sin(theta), cos(theta), y], [0, 0, 1]] at (0, 0, 0)\n"  // 2
      "momenta v, w, omega\n"                                     // 3
      "inertia [[m, 0, 0], [0, m, 0], [0, 0, I]]\n"               // 4
      "reduced q = theta\n");                                     // 5
  ASSERT_TRUE(ast.lie);
  const GroupDecl& g = ast.lie->group;
  EXPECT_EQ(at(g.loc), "1:1");
  EXPECT_EQ(g.name.name, "g");
  EXPECT_TRUE(g.shortcut.empty());
  ASSERT_EQ(g.coordinates.size(), 3U);
  EXPECT_EQ(g.coordinates[2].name, "theta");
  EXPECT_EQ(at(g.coordinates[2].loc), "1:15");
  ASSERT_EQ(g.matrix.rows.size(), 3U);
  EXPECT_EQ(at(g.matrix.loc), "1:24");
  EXPECT_EQ(dump(g.matrix.rows[0][1]), "(u- sin[theta])");
  EXPECT_EQ(dump(g.matrix.rows[2][2]), "1");
  ASSERT_EQ(g.identity.size(), 3U);
  EXPECT_EQ(at(g.identity_loc), "2:43");
  ASSERT_TRUE(ast.lie->inertia);
  EXPECT_EQ(ast.lie->inertia->rows.size(), 3U);
  EXPECT_EQ(dump(ast.lie->inertia->rows[2][2]), "I");
  EXPECT_EQ(at(ast.lie->inertia_loc), "4:1");
  EXPECT_EQ(at(ast.lie->reduced_loc), "5:1");
  EXPECT_FALSE(ast.lie->hamiltonian);
}

TEST(ParseLie, VelocitiesAndConstraints) {
  const ModelAst ast = parse_text(
      "velocities v, w, omega\n"    // 1
      "constraint w = 0\n"          // 2
      "constraint v = 2*omega\n");  // 3
  ASSERT_TRUE(ast.lie);
  ASSERT_EQ(ast.lie->velocities.size(), 3U);
  EXPECT_EQ(ast.lie->velocities[2].name, "omega");
  EXPECT_EQ(at(ast.lie->velocities_loc), "1:1");
  ASSERT_EQ(ast.lie->constraints.size(), 2U);
  EXPECT_EQ(dump(ast.lie->constraints[0].lhs), "w");
  EXPECT_EQ(dump(ast.lie->constraints[1].rhs), "(* 2 omega)");
  EXPECT_EQ(at(ast.lie->constraints[1].loc), "3:12");
  expect_error("constraint 1 = 0\n", 1, 12, "a velocity name after 'constraint'");
  expect_error("constraint w 0\n", 1, 14, "'=' in the constraint");
}

TEST(ParseLie, GeneralModelsHaveNoLieDecl) {
  EXPECT_FALSE(parse_text(kBouncingBall).lie);
}

TEST(ParseLie, GroupByStructureConstantsAndMetric) {
  const ModelAst ast = parse_text(
      "group H = algebra(E1, E2, E3) {\n"           // 1
      "  [E1, E2] = E3, [E1, E3] = -k*E2\n"         // 2
      "  [E2, E3] = 0; }\n"                         // 3
      "metric [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"  // 4
      "reduced q = additive(1, 0, 0)\n");           // 5
  ASSERT_TRUE(ast.lie);
  const GroupDecl& g = ast.lie->group;
  EXPECT_EQ(g.shortcut, "algebra");
  ASSERT_EQ(g.basis.size(), 3U);
  EXPECT_EQ(g.basis[1].name, "E2");
  EXPECT_EQ(at(g.basis[1].loc), "1:23");
  ASSERT_EQ(g.brackets.size(), 3U);
  EXPECT_EQ(g.brackets[1].left.name, "E1");
  EXPECT_EQ(g.brackets[1].right.name, "E3");
  EXPECT_EQ(at(g.brackets[1].loc), "2:18");
  EXPECT_EQ(dump(g.brackets[1].value), "(* (u- k) E2)");
  EXPECT_EQ(dump(g.brackets[2].value), "0");
  EXPECT_TRUE(g.coordinates.empty());
  ASSERT_TRUE(ast.lie->metric);
  EXPECT_EQ(at(ast.lie->metric_loc), "4:1");
  EXPECT_EQ(ast.lie->metric->rows.size(), 3U);
  EXPECT_FALSE(ast.lie->inertia);
  EXPECT_EQ(dump(ast.lie->reduced_expr), "additive[1, 0, 0]");
  // Empty braces: an abelian algebra.
  EXPECT_TRUE(parse_text("group R = algebra(E) {}\n").lie->group.brackets.empty());
}

TEST(ParseLieErrors, StructureConstantsAndMetric) {
  expect_error("group H = algebra E1\n", 1, 19, "'(' after 'algebra'");
  expect_error("group H = algebra(E1 E2) {}\n", 1, 22, "',' or ')' in the basis");
  expect_error("group H = algebra(E1, E2)\n", 2, 1, "'{' after the basis");
  expect_error("group H = algebra(E1, E2) { E1 }\n", 1, 29, "'[' to open a bracket");
  expect_error("group H = algebra(E1, E2) { [E1 E2] = 0 }\n", 1, 33, "',' between");
  expect_error("group H = algebra(E1, E2) { [E1, E2 = 0 }\n", 1, 37, "']' to close the bracket");
  expect_error("group H = algebra(E1, E2) { [E1, E2] E1 }\n", 1, 38, "'=' after the bracket");
  expect_error("group H = algebra(E1, E2) { [E1, E2] = E1\n", 2, 1, "unterminated block");
  expect_error("metric [[1]]\nmetric [[1]]\n", 2, 1, "a second 'metric'");
  expect_error("metric 1\n", 1, 8, "after 'metric'");
}

// Fuzz finding F10 (fuzz/regressions/frontend/crash-gl0-token-read-after-take.model):
// parse_group_def kept a reference to the token N of gl(N) and used it for the
// "N >= 1" error after take() had popped it; when N was the last token of a
// std::deque node, the node was freed (heap-use-after-free under ASan). The
// token lands on every offset of a node for some number of padding tokens;
// under the sanitizer build the old code fails here, and the location is
// checked everywhere.
TEST(ParseLieErrors, GlZeroIsReportedAtEveryTokenOffset) {
  std::string pad;
  for (int k = 0; k < 40; ++k) {
    expect_error(pad + "group A = gl(0)\n", k + 1, 14, "N >= 1");
    pad += "parameter p" + std::to_string(k) + " = 1\n";  // 4 tokens and a newline
  }
}

TEST(ParseLieErrors, Statements) {
  expect_error("group A = gl(x)\n", 1, 14, "a matrix size N");
  expect_error("group A = sl(2)\n", 1, 11, "'gl(N)'");
  expect_error("group A = gl(0)\n", 1, 14, "N >= 1");
  expect_error("group A = gl(2)\ngroup B = gl(3)\n", 2, 1, "a second 'group' statement");
  expect_error("momenta a\nmomenta b\n", 2, 1, "a second 'momenta'");
  expect_error("reduced q det(A)\n", 1, 11, "'=' after 'reduced q'");
  expect_error("group g(x) = [[1, x], [0, 1]]\n", 2, 1, "'at (c1, ..., cn)'");
  expect_error("group g(x) = [[1, x] [0, 1]] at (0)\n", 1, 22, "',' or ']' in the matrix");
  expect_error("group g(x = [[1]] at (0)\n", 1, 11, "',' or ')' in the coordinates");
  expect_error("group g(x) = [[1, x], [0, 1]] at (0\n", 2, 1, "',' or ')' in the identity");
  expect_error("inertia [1, 2]\n", 1, 10, "'[' to open a matrix row");
}

}  // namespace
}  // namespace hybgen::gen
