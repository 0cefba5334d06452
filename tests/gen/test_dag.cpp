// hybgen's expression DAG: canonical form, deterministic printers and CSE.
//
//  1. Determinism: expressions built so that GiNaC orders their terms
//     differently (operand order, symbols created in other orders, expand vs
//     typed, a-b vs -(b-a)) give the same node and byte-identical text; and
//     the test binary re-executes itself (ASLR changes GiNaC's term order
//     between processes) and compares the dumps.
//  2. Round trip: to_ginac parsed back by GiNaC::parser is the same node and
//     the same value at random points.
//  3. Emitted C is compiled with g++ -Werror -Wconversion -Wdouble-promotion,
//     run at 20 random points and compared with GiNaC evalf (Digits = 40).
//  4. CSE shares; 5. exact numbers; 6. errors; 7. the order is total.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <ginac/ginac.h>

#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/errors.hpp"

namespace hybgen::gen {
namespace {

namespace fs = std::filesystem;
using GiNaC::ex;
using GiNaC::numeric;
using GiNaC::pow;
using GiNaC::realsymbol;

using Syms = std::map<std::string, ex>;
using Builder = std::function<ex(const Syms&)>;

const std::vector<std::string> kNames = {"a", "b", "c", "d", "x", "y", "z", "m", "k"};

/// Fresh realsymbols with the given names, created in the given order.
Syms make_syms(std::vector<std::string> order) {
  Syms s;
  for (const auto& n : order) s[n] = realsymbol(n);
  return s;
}

Syms forward_syms() {
  return make_syms(kNames);
}
Syms reverse_syms() {
  return make_syms({kNames.rbegin(), kNames.rend()});
}

/// C binding of every test symbol.
std::map<std::string, std::string> c_bind() {
  return {{"a", "p[0]"}, {"b", "p[1]"}, {"c", "p[2]"},   {"d", "p[3]"},  {"x", "x[0]"},
          {"y", "x[1]"}, {"z", "x[2]"}, {"m", "par[0]"}, {"k", "par[1]"}};
}

/// Everything printed about a node.
std::string all_text(const ExprDag& dag, NodeId n) {
  std::ostringstream os;
  os << dag.to_ginac(n) << "\n"
     << dag.to_latex(n, {{"a", "\\alpha"}}) << "\n"
     << dag.to_c(n, c_bind()) << "\n"
     << emit_c_block(dag, {{"out[0]", n}, {"out[1]", n}}, c_bind()) << std::hex
     << dag.content_hash(n) << "\n";
  return os.str();
}

/// Pairs of differently built equal expressions.
struct Pair {
  const char* what;
  Builder one;
  Builder two;
};

std::vector<Pair> equal_pairs() {
  auto S = [](const Syms& s, const char* n) { return s.at(n); };
  return {
      {"sum order", [&](const Syms& s) { return S(s, "a") + S(s, "b"); },
       [&](const Syms& s) { return S(s, "b") + S(s, "a"); }},
      {"product order", [&](const Syms& s) { return S(s, "a") * S(s, "b") * S(s, "c"); },
       [&](const Syms& s) { return S(s, "c") * (S(s, "b") * S(s, "a")); }},
      {"a-b vs -(b-a)", [&](const Syms& s) { return S(s, "a") - S(s, "b"); },
       [&](const Syms& s) { return -(S(s, "b") - S(s, "a")); }},
      {"(b-a)/(c-d) vs (a-b)/(d-c)",
       [&](const Syms& s) { return (S(s, "b") - S(s, "a")) / (S(s, "c") - S(s, "d")); },
       [&](const Syms& s) { return (S(s, "a") - S(s, "b")) / (S(s, "d") - S(s, "c")); }},
      {"expand vs typed",
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y"), a = S(s, "a");
         return GiNaC::expand((x + 1) * (x - 1) * (y + a));
       },
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y"), a = S(s, "a");
         return -a - y + a * pow(x, 2) + pow(x, 2) * y;
       }},
      {"odd/even functions",
       [&](const Syms& s) {
         const ex a = S(s, "a"), b = S(s, "b"), c = S(s, "c"), d = S(s, "d");
         return sin(b - a) * cos(d - c) + tan(a - b) + abs(c - d) + sinh(2 * d - 2 * c);
       },
       [&](const Syms& s) {
         const ex a = S(s, "a"), b = S(s, "b"), c = S(s, "c"), d = S(s, "d");
         return -sin(a - b) * cos(c - d) - tan(b - a) + abs(d - c) - sinh(2 * c - 2 * d);
       }},
      {"sqrt and powers of differences",
       [&](const Syms& s) {
         const ex a = S(s, "a"), b = S(s, "b"), c = S(s, "c"), d = S(s, "d");
         return sqrt(b - a) + pow(a - b, 3) / pow(c - d, 2) + pow(b - a, -numeric(1, 2));
       },
       [&](const Syms& s) {
         const ex a = S(s, "a"), b = S(s, "b"), c = S(s, "c"), d = S(s, "d");
         return -pow(b - a, 3) / pow(d - c, 2) + sqrt(-a + b) + 1 / sqrt(b - a);
       }},
      {"exp log of differences",
       [&](const Syms& s) { return exp(S(s, "x") - S(s, "y")) * log(S(s, "y") - S(s, "x")); },
       [&](const Syms& s) {
         return log(-(S(s, "x") - S(s, "y"))) * exp(-(S(s, "y") - S(s, "x")));
       }},
      {"rational coefficients", [&](const Syms& s) { return 2 * S(s, "x") / (3 * S(s, "y")); },
       [&](const Syms& s) { return S(s, "x") * numeric(2, 3) / S(s, "y"); }},
      {"half powers and Pi",
       [&](const Syms& s) { return GiNaC::Pi * pow(S(s, "x"), numeric(3, 2)) / sqrt(S(s, "y")); },
       [&](const Syms& s) {
         return sqrt(S(s, "x")) * S(s, "x") * GiNaC::Pi * pow(S(s, "y"), -numeric(1, 2));
       }},
      {"derivatives",
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y");
         return sin(x * y) * pow(x - y, 2).diff(GiNaC::ex_to<GiNaC::symbol>(x));
       },
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y");
         return pow(y - x, 2).diff(GiNaC::ex_to<GiNaC::symbol>(x)) * sin(y * x);
       }},
      {"normal of a sum of fractions",
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y"), a = S(s, "a");
         return GiNaC::normal(1 / (x - y) + 1 / (y - a));
       },
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y"), a = S(s, "a");
         return GiNaC::normal(1 / (y - a) - 1 / (y - x));
       }},
      {"floats", [&](const Syms& s) { return 0.25 * S(s, "x") - 1.5 * S(s, "y") + 0.1; },
       [&](const Syms& s) { return numeric(0.1) - (1.5 * S(s, "y") - S(s, "x") * 0.25); }},
      {"nested",
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y"), m = S(s, "m");
         return exp(-pow(x - y, 2) / (2 * m)) / sqrt(2 * GiNaC::Pi * m) + atan((y - x) / m);
       },
       [&](const Syms& s) {
         const ex x = S(s, "x"), y = S(s, "y"), m = S(s, "m");
         return -atan((x - y) / m) +
                pow(2 * m * GiNaC::Pi, -numeric(1, 2)) * exp(-pow(y - x, 2) * pow(m, -1) / 2);
       }},
  };
}

TEST(DagDeterminism, DifferentlyBuiltEqualExpressionsPrintTheSame) {
  for (const Pair& p : equal_pairs()) {
    SCOPED_TRACE(p.what);
    const Syms s1 = forward_syms();
    const Syms s2 = reverse_syms();
    // Same dag: the same node, whichever symbol objects and term order.
    ExprDag dag;
    const NodeId n1 = dag.import(p.one(s1));
    const NodeId n2 = dag.import(p.two(s2));
    const NodeId n3 = dag.import(p.two(s1));
    const NodeId n4 = dag.import(p.one(s2));
    EXPECT_EQ(n1, n2) << dag.to_ginac(n1) << " vs " << dag.to_ginac(n2);
    EXPECT_EQ(n1, n3);
    EXPECT_EQ(n1, n4);
    // Separate dags, filled in different orders: byte-identical output.
    ExprDag d1, d2;
    d1.import(s1.at("z") * s1.at("k") + 1);
    const NodeId m1 = d1.import(p.one(s1));
    const NodeId m2 = d2.import(p.two(s2));
    EXPECT_EQ(all_text(d1, m1), all_text(d2, m2));
    EXPECT_EQ(all_text(d1, m1), all_text(dag, n1));
  }
}

TEST(DagDeterminism, SignNormalisationExamples) {
  const Syms s = forward_syms();
  const ex a = s.at("a"), b = s.at("b"), c = s.at("c"), d = s.at("d");
  ExprDag dag;
  EXPECT_EQ(dag.to_ginac(dag.import(a - b)), "a-b");
  EXPECT_EQ(dag.to_ginac(dag.import(b - a)), "b-a");
  EXPECT_EQ(dag.to_ginac(dag.import(-(b - a))), "a-b");
  // The sign of the quotient goes into its first sum (see ReadableSigns).
  EXPECT_EQ(dag.to_ginac(dag.import((b - a) / (c - d))), "(b-a)/(c-d)");
  EXPECT_EQ(dag.to_ginac(dag.import((a - b) / (d - c))), "(b-a)/(c-d)");
  EXPECT_EQ(dag.to_ginac(dag.import(sqrt(b - a))), "sqrt(b-a)");
  EXPECT_EQ(dag.to_ginac(dag.import(sin(b - a))), "-sin(a-b)");
  EXPECT_EQ(dag.to_ginac(dag.import(cos(b - a))), "cos(a-b)");
  EXPECT_EQ(dag.to_ginac(dag.import(-a - b)), "-a-b");
  EXPECT_EQ(dag.to_c(dag.import(b - a - c), c_bind()), "p[1] - p[0] - p[2]");
  // The stored form of b-a is Product(-1, a-b).
  const NodeId n = dag.import(b - a);
  ASSERT_EQ(dag.kind(n), NodeKind::Product);
  EXPECT_EQ(dag.payload(dag.operands(n)[0]), "-1");
  EXPECT_EQ(dag.to_ginac(dag.operands(n)[1]), "a-b");
}

/// Printed forms of one expression: to_ginac, to_latex, to_c.
struct Printed {
  std::string ginac, latex, c;
};

Printed print_all(const ex& e, const std::map<std::string, std::string>& bind) {
  ExprDag dag;
  const NodeId n = dag.import(e);
  return {dag.to_ginac(n), dag.to_latex(n), dag.to_c(n, bind)};
}

void expect_printed(const ex& e, const std::map<std::string, std::string>& bind,
                    const Printed& want) {
  SCOPED_TRACE(want.ginac);
  const Printed got = print_all(e, bind);
  EXPECT_EQ(got.ginac, want.ginac);
  EXPECT_EQ(got.latex, want.latex);
  EXPECT_EQ(got.c, want.c);
}

TEST(DagDeterminism, ReadableSigns) {
  // A negative product gives its sign to a sum factor with an odd exponent when that prints
  // fewer minus signs; terms of sums keep theirs; even powers never take it.
  const realsymbol f("f"), g("g"), i("i"), x("x"), e("e"), p("p"), q("q"), r("r");
  const realsymbol beta("beta"), s("s"), delta("delta"), gamma("gamma"), mu("mu");
  const std::map<std::string, std::string> bind = {
      {"f", "par[4]"}, {"g", "g"},     {"i", "x[1]"}, {"x", "x[0]"}, {"e", "e"},
      {"p", "p"},      {"q", "q"},     {"r", "r"},    {"beta", "b"}, {"s", "s"},
      {"delta", "d"},  {"gamma", "c"}, {"mu", "m"}};
  expect_printed((1 - f) * i, bind, {"i*(1-f)", "i \\left(1 - f\\right)", "x[1]*(1.0 - par[4])"});
  expect_printed(i / (1 - f), bind, {"i/(1-f)", "\\frac{i}{1 - f}", "x[1]/(1.0 - par[4])"});
  expect_printed(1 / (1 - f), bind, {"1/(1-f)", "\\frac{1}{1 - f}", "1.0/(1.0 - par[4])"});
  expect_printed(-pow(f - 1, 2), bind,
                 {"-(f-1)^2", "-\\left(f - 1\\right)^{2}", "-std::pow(par[4] - 1.0, 2.0)"});
  expect_printed(-pow(f - 1, 3), bind,
                 {"(1-f)^3", "\\left(1 - f\\right)^{3}", "std::pow(1.0 - par[4], 3.0)"});
  // A positive product keeps its factors as they are.
  expect_printed((1 - f) * (1 - g) * x, bind,
                 {"x*(f-1)*(g-1)", "x \\left(f - 1\\right) \\left(g - 1\\right)",
                  "x[0]*(par[4] - 1.0)*(g - 1.0)"});
  // Only one factor takes the sign: the first in canonical order on a tie.
  expect_printed(-(1 - f) * (1 - g) * x, bind,
                 {"x*(1-f)*(g-1)", "x \\left(1 - f\\right) \\left(g - 1\\right)",
                  "x[0]*(1.0 - par[4])*(g - 1.0)"});
  // No sum, or no sum that helps: unchanged.
  expect_printed(-e * p, bind, {"-e*p", "-e p", "-e*p"});
  expect_printed(-(1 + e) * q, bind, {"-q*(e+1)", "-q \\left(e + 1\\right)", "-q*(e + 1.0)"});
  expect_printed(p - (1 + e) * q * r, bind,
                 {"p-q*r*(e+1)", "p - q r \\left(e + 1\\right)", "p - q*r*(e + 1.0)"});
  // In a sum the term's sign stays the sum's minus.
  expect_printed(p - (f - 1) * q, bind,
                 {"p-q*(f-1)", "p - q \\left(f - 1\\right)", "p - q*(par[4] - 1.0)"});
  expect_printed(beta * s * i + delta * pow(i, 2) - (gamma + mu + delta) * i, bind,
                 {"beta*i*s+delta*i^2-i*(delta+gamma+mu)",
                  "\\mathrm{beta} i s + \\mathrm{delta} i^{2} - i \\left(\\mathrm{delta} + "
                  "\\mathrm{gamma} + \\mathrm{mu}\\right)",
                  "b*x[1]*s + d*(x[1]*x[1]) - x[1]*(d + c + m)"});
  // Positive terms first when a sum would start with a minus.
  expect_printed(-q * r + p, bind, {"p-q*r", "p - q r", "p - q*r"});
  expect_printed(-(f - 1 - g - p) * x, bind,
                 {"x*(g+p+1-f)", "x \\left(g + p + 1 - f\\right)", "x[0]*(g + p + 1.0 - par[4])"});
  // The factor that saves the most minus signs takes it: here the numerator.
  expect_printed(-(f - g - p - q) / (f + g - 1), bind,
                 {"(g+p+q-f)/(f+g-1)", "\\frac{g + p + q - f}{f + g - 1}",
                  "(g + p + q - par[4])/(par[4] + g - 1.0)"});
}

/// A rich set of expressions for the re-exec comparison and round trips.
std::vector<ex> sample_expressions(const Syms& s) {
  const ex a = s.at("a"), b = s.at("b"), c = s.at("c"), d = s.at("d");
  const ex x = s.at("x"), y = s.at("y"), z = s.at("z"), m = s.at("m"), k = s.at("k");
  std::vector<ex> v;
  for (const Pair& p : equal_pairs()) v.push_back(p.one(s));
  v.push_back(pow(x, 2) + 2 * x * y + pow(y, 2) - 1);
  v.push_back((x * y - z) / (m * pow(x, 2) + k));
  v.push_back(GiNaC::normal((a - b) / (c - d) + (c + d) / (b - a)));
  v.push_back(GiNaC::expand(pow(a - b + c - d, 4)));
  v.push_back(sin(x) * cos(y) + cos(x) * sin(y) - tan(z / 3));
  v.push_back(pow(x + 1, numeric(1, 3)) + pow(2, y) + pow(x, y));
  v.push_back(numeric(1, 3) * x - numeric(22, 7) * pow(y, -2) + GiNaC::Pi);
  v.push_back(abs(x - y) * exp(-z) * log(m));
  v.push_back(asin(x - y) + acos(y / 3) + atan(z - x) + sinh(x) + cosh(y - z) + tanh(-k));
  v.push_back(pow(x - y, -3) + pow(y - x, 7) + pow(z - m, 8));
  v.push_back(2.5 * x - 1e-20 * y + 1e20 * z);
  // Products whose sign is printed inside a sum factor.
  v.push_back((1 - a) * x);
  v.push_back(x / (1 - a) - 2 * y / ((1 - b) * (1 - c)));
  v.push_back(-pow(a - 1, 2) * x + pow(1 - b, 3) * y - 0.5 * z * (k - 1));
  v.push_back(sin((1 - a) * x) + sqrt(-(x - y - z) * m));
  v.push_back(-(a - b - c - d) / (a + b - 1));
  // A Jacobian entry of a 2-link arm.
  const ex q1 = x, q2 = y;
  const ex px = cos(q1) + cos(q1 + q2), py = sin(q1) + sin(q1 + q2);
  v.push_back((pow(px, 2) + pow(py, 2)).diff(GiNaC::ex_to<GiNaC::symbol>(q1)));
  v.push_back(px.diff(GiNaC::ex_to<GiNaC::symbol>(q2)) * py.diff(GiNaC::ex_to<GiNaC::symbol>(q1)));
  return v;
}

/// What the re-exec runs write: every printer output and hash of the sample set.
std::string dump_samples() {
  const Syms s = forward_syms();
  ExprDag dag;
  std::string out;
  std::vector<CAssignment> assigns;
  int i = 0;
  for (const ex& e : sample_expressions(s)) {
    const NodeId n = dag.import(e);
    out += all_text(dag, n);
    assigns.push_back({"o[" + std::to_string(i++) + "]", n});
  }
  out += emit_c_block(dag, assigns, c_bind(), "    ", "tmp");
  return out;
}

/// Not a test on its own: the body of one re-executed run (see the next test).
TEST(DagReexec, DISABLED_Dump) {
  const char* path = std::getenv("HYBGEN_DAG_DUMP");
  ASSERT_NE(path, nullptr);
  std::ofstream(path) << dump_samples();
  // Also record GiNaC's own (order-dependent) text, for information.
  const Syms s = forward_syms();
  std::ostringstream os;
  for (const ex& e : sample_expressions(s)) os << e << "\n";
  std::ofstream(std::string(path) + ".ginac") << os.str();
}

std::string read_file(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

/// A fresh temporary directory, removed on destruction.
struct TempDir {
  fs::path path;
  TempDir() {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("hybgen_test_dag_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
};

TEST(DagReexec, OutputIsIdenticalAcrossProcesses) {
  TempDir tmp;
  const fs::path exe = fs::read_symlink("/proc/self/exe");
  const std::string mine = dump_samples();
  std::set<std::string> ginac_texts;
  for (int run = 0; run < 5; ++run) {
    const fs::path out = tmp.path / ("dump" + std::to_string(run) + ".txt");
    const std::string cmd = "HYBGEN_DAG_DUMP='" + out.string() + "' '" + exe.string() +
                            "' --gtest_also_run_disabled_tests"
                            " --gtest_filter=DagReexec.DISABLED_Dump > '" +
                            (tmp.path / "log.txt").string() + "' 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << read_file(tmp.path / "log.txt");
    EXPECT_EQ(read_file(out), mine) << "run " << run;
    ginac_texts.insert(read_file(out.string() + ".ginac"));
  }
  // GiNaC's own printing usually differs between these runs; ours may not.
  std::cout << "[ info ] GiNaC printed the sample set in " << ginac_texts.size()
            << " different ways over 5 runs; hybgen's dag in 1\n";
}

// ---------------------------------------------------------------------------
// Round trip

/// Random exact dyadic rationals in [lo, hi] (exactly representable as doubles).
numeric random_dyadic(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(lo, hi);
  const double v = std::ldexp(std::round(std::ldexp(u(rng), 20)), -20);
  return numeric(static_cast<long>(std::ldexp(v, 20)), 1L << 20);
}

/// A random point: a..d in [1, 2], x, y, z in [0.2, 0.9] (valid for asin/acos/log of the
/// samples), m, k in [2, 3]; returned as a substitution map for symbols of `s`.
std::map<std::string, numeric> random_point(std::mt19937_64& rng) {
  std::map<std::string, numeric> pt;
  for (const char* n : {"a", "b", "c", "d"}) pt[n] = random_dyadic(rng, 1.0, 2.0);
  for (const char* n : {"x", "y", "z"}) pt[n] = random_dyadic(rng, 0.2, 0.9);
  for (const char* n : {"m", "k"}) pt[n] = random_dyadic(rng, 2.0, 3.0);
  return pt;
}

GiNaC::exmap subs_map(const Syms& s, const std::map<std::string, numeric>& pt) {
  GiNaC::exmap m;
  for (const auto& [name, v] : pt) m[s.at(name)] = v;
  return m;
}

/// High-precision value of e at a point (as a complex-capable numeric).
numeric eval_at(const ex& e, const Syms& s, const std::map<std::string, numeric>& pt) {
  const long saved = GiNaC::Digits;
  GiNaC::Digits = 40;
  const ex v = GiNaC::evalf(e.subs(subs_map(s, pt)));
  GiNaC::Digits = saved;
  if (!GiNaC::is_a<numeric>(v)) ADD_FAILURE() << "evalf did not give a number: " << v;
  return GiNaC::is_a<numeric>(v) ? GiNaC::ex_to<numeric>(v) : numeric(0);
}

TEST(DagRoundTrip, ParsedBackIsTheSameNodeAndValue) {
  const Syms s = forward_syms();
  GiNaC::symtab table;
  for (const auto& [name, sym] : s) table[name] = sym;
  GiNaC::parser reader(table, true);
  ExprDag dag;
  std::mt19937_64 rng(12345);
  for (const ex& e : sample_expressions(s)) {
    const NodeId n = dag.import(e);
    const std::string text = dag.to_ginac(n);
    SCOPED_TRACE(text);
    ex back;
    ASSERT_NO_THROW(back = reader(text));
    const NodeId m = dag.import(back);
    EXPECT_EQ(m, n) << "re-imported as " << dag.to_ginac(m);
    for (int i = 0; i < 5; ++i) {
      const auto pt = random_point(rng);
      const numeric v1 = eval_at(e, s, pt);
      const numeric v2 = eval_at(back, s, pt);
      const double scale = std::max(1.0, GiNaC::abs(v1).to_double());
      EXPECT_LT(GiNaC::abs(v1 - v2).to_double(), 1e-14 * scale) << v1 << " vs " << v2;
    }
  }
}

TEST(DagRoundTrip, RationalFunctionsAreExactlyEqual) {
  const Syms s = forward_syms();
  GiNaC::symtab table;
  for (const auto& [name, sym] : s) table[name] = sym;
  GiNaC::parser reader(table, true);
  const ex a = s.at("a"), b = s.at("b"), c = s.at("c"), d = s.at("d"), x = s.at("x");
  ExprDag dag;
  for (const ex& e : {ex((b - a) / (c - d)), ex(pow(x - a, -3) * numeric(5, 7) - b / (3 * c)),
                      GiNaC::normal((a - b) / (c - d) + (c + d) / (b - a)),
                      ex(pow(a + b, 5) - 2 * c * d / (a - d))}) {
    const ex back = reader(dag.to_ginac(dag.import(e)));
    EXPECT_TRUE(GiNaC::normal(e - back).is_zero()) << e << " vs " << back;
  }
}

// ---------------------------------------------------------------------------
// Emitted C: compile, run, compare

TEST(DagEmitC, CompiledKernelMatchesGinacEvalf) {
  const Syms s = forward_syms();
  const ex a = s.at("a"), b = s.at("b"), x = s.at("x"), y = s.at("y"), z = s.at("z");
  const ex m = s.at("m"), k = s.at("k");
  std::vector<ex> exprs = {
      (pow(x, 2) + y) / (1 + x * y),
      sqrt(pow(x, 2) + pow(y, 2)),
      m * pow(x + y, -numeric(1, 2)),
      pow(x + 2 * y, numeric(3, 2)) + k * pow(x, numeric(5, 2)) + pow(z, -numeric(3, 2)),
      sin(x) * cos(y) + tan(z / 3),
      exp(-pow(x, 2)) * log(1 + pow(y, 2)),
      abs(x - y) * GiNaC::Pi + abs(y - x),
      pow(x, -3) + pow(y, 7) + pow(x + y, 8) + pow(z, -8) + pow(m, 9) + pow(k, -2),
      atan(x) + asin(y / 3) + acos(z / 4) + sinh(x) + cosh(y) + tanh(z),
      (b - a) / (z - m) + (a - b) / (m - z) * x,
      numeric(1, 3) * x + numeric(2, 7) * pow(y, 2) + GiNaC::Pi,
      pow(x, numeric(1, 3)) + pow(2, y) + pow(x, y) + pow(z, -numeric(2, 3)),
      0.1 * x + 1e-3 * y + 2.5,
      numeric("12345678901234567890123") * x / numeric("10000000000000000000000000"),
      pow(x + y, 2) * sin(x + y) + pow(cos(x + y), 3) + pow(x + y, -1),
      (sqrt(pow(x, 2) + pow(y, 2)) * sin(x * y)).diff(GiNaC::ex_to<GiNaC::symbol>(x)),
      GiNaC::normal(1 / (x - m) + 1 / (y - k)) * numeric(1, 3),
      pow(a * x - b * y, 4) / pow(m - z, 2),
      -x / (3 * y * z),
      exp(x - y) * log(k - y) + exp(y - x),
      (1 - a) * x + y / (1 - b) - pow(1 - a, 3) * z,
      -(a - b - x - y) / (a + b - 1) * sin((1 - a) * z),
  };
  std::vector<CAssignment> out;
  ExprDag dag;
  for (std::size_t i = 0; i < exprs.size(); ++i)
    out.push_back({"o[" + std::to_string(i) + "]", dag.import(exprs[i])});
  const std::string block = emit_c_block(dag, out, c_bind(), "  ", "t");

  TempDir tmp;
  const std::size_t n_out = exprs.size();
  std::ofstream(tmp.path / "kernel.cpp")
      << "#include <cmath>\n#include <cstdio>\n\n"
         "static void kernel(const double* x, const double* p, const double* par, double* o) {\n"
      << block
      << "}\n\nint main() {\n"
         "  double x[3], p[4], par[2], o["
      << n_out
      << "];\n"
         "  while (std::scanf(\"%lf %lf %lf %lf %lf %lf %lf %lf %lf\", &p[0], &p[1], &p[2], "
         "&p[3], &x[0], &x[1], &x[2], &par[0], &par[1]) == 9) {\n"
         "    kernel(x, p, par, o);\n"
         "    for (double v : o) std::printf(\"%.17g \", v);\n"
         "    std::printf(\"\\n\");\n"
         "  }\n"
         "  return 0;\n}\n";
  const std::string compile =
      "g++ -std=c++20 -O2 -Wall -Wextra -Wpedantic -Wshadow -Werror "
      "-Wconversion -Wdouble-promotion -Wold-style-cast -o '" +
      (tmp.path / "kernel").string() + "' '" + (tmp.path / "kernel.cpp").string() + "' > '" +
      (tmp.path / "cc.log").string() + "' 2>&1";
  ASSERT_EQ(std::system(compile.c_str()), 0) << read_file(tmp.path / "cc.log") << "\n"
                                             << read_file(tmp.path / "kernel.cpp");

  std::mt19937_64 rng(2024);
  std::vector<std::map<std::string, numeric>> points;
  {
    std::ofstream in(tmp.path / "points.txt");
    for (int i = 0; i < 20; ++i) {
      points.push_back(random_point(rng));
      for (const char* n : {"a", "b", "c", "d", "x", "y", "z", "m", "k"}) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.17g ", points.back().at(n).to_double());
        in << buf;
      }
      in << "\n";
    }
  }
  const std::string run = "'" + (tmp.path / "kernel").string() + "' < '" +
                          (tmp.path / "points.txt").string() + "' > '" +
                          (tmp.path / "values.txt").string() + "'";
  ASSERT_EQ(std::system(run.c_str()), 0);
  std::istringstream values(read_file(tmp.path / "values.txt"));
  double worst = 0.0;
  for (const auto& pt : points) {
    for (std::size_t i = 0; i < n_out; ++i) {
      double got = 0.0;
      ASSERT_TRUE(values >> got) << "missing output";
      const numeric ref = eval_at(exprs[i], s, pt);
      ASSERT_TRUE(ref.is_real()) << exprs[i];
      const double r = ref.to_double();
      const double rel = std::fabs(got - r) / std::fabs(r);
      worst = std::max(worst, rel);
      EXPECT_LE(rel, 1e-13) << "output " << i << ": " << dag.to_ginac(out[i].value) << "\n got "
                            << got << " want " << r;
    }
  }
  std::cout << "[ info ] " << n_out << " outputs x 20 points, worst relative error " << worst
            << "\n";
}

// ---------------------------------------------------------------------------
// Power and division forms, CSE

std::size_t count(const std::string& hay, const std::string& needle) {
  std::size_t n = 0;
  for (auto pos = hay.find(needle); pos != std::string::npos; pos = hay.find(needle, pos + 1)) ++n;
  return n;
}

TEST(DagEmitC, PowerAndDivisionForms) {
  const Syms s = forward_syms();
  const ex x = s.at("x"), y = s.at("y");
  ExprDag dag;
  const auto bind = c_bind();
  auto c = [&](const ex& e) { return dag.to_c(dag.import(e), bind); };
  EXPECT_EQ(c(pow(x, 2)), "x[0]*x[0]");
  EXPECT_EQ(c(pow(x, 3)), "x[0]*x[0]*x[0]");
  EXPECT_EQ(c(sqrt(x)), "std::sqrt(x[0])");
  EXPECT_EQ(c(pow(x, -numeric(1, 2))), "1.0/std::sqrt(x[0])");
  EXPECT_EQ(c(pow(x, numeric(3, 2))), "x[0]*std::sqrt(x[0])");
  EXPECT_EQ(c(pow(x, numeric(1, 3))), "std::pow(x[0], (1.0/3.0))");
  EXPECT_EQ(c(pow(x, y)), "std::pow(x[0], x[1])");
  EXPECT_EQ(c(pow(x, 20)), "std::pow(x[0], 20.0)");
  EXPECT_EQ(c(1 / x), "1.0/x[0]");
  EXPECT_EQ(c(y / pow(x, 2)), "x[1]/(x[0]*x[0])");
  EXPECT_EQ(c(-2 * y / (3 * x)), "-(2.0/3.0)*x[1]/x[0]");
  EXPECT_EQ(c(y / sqrt(x)), "x[1]/std::sqrt(x[0])");
  EXPECT_EQ(c(abs(x) + GiNaC::Pi), "3.1415926535897931 + std::fabs(x[0])");
  EXPECT_EQ(c(x - y), "x[0] - x[1]");
  EXPECT_EQ(c(pow(x + y, 2)), "std::pow(x[0] + x[1], 2.0)");  // no CSE in to_c
  // In a block the base of a small power becomes a temporary and is squared.
  const std::string blk = emit_c_block(dag, {{"r", dag.import(pow(x + y, 4))}}, bind);
  EXPECT_EQ(blk,
            "  const double t0 = x[0] + x[1];\n"
            "  const double t1 = t0*t0;\n"
            "  r = t1*t1;\n");
  EXPECT_EQ(emit_c_block(dag, {{"r", dag.import(pow(x + y, -numeric(3, 2)))}}, bind),
            "  const double t0 = x[0] + x[1];\n"
            "  r = 1.0/(t0*std::sqrt(t0));\n");
}

TEST(DagEmitC, CseSharesAcrossOutputs) {
  const Syms s = forward_syms();
  const ex x = s.at("x"), y = s.at("y"), m = s.at("m");
  ExprDag dag;
  const ex sc = sin(x) * cos(y);
  const std::vector<CAssignment> out = {{"f[0]", dag.import(sc)},
                                        {"f[1]", dag.import(2 * m * sc + pow(y, 2))},
                                        {"f[2]", dag.import(exp(sc) - sin(x))}};
  const std::string blk = emit_c_block(dag, out, c_bind(), "\t", "cse_");
  EXPECT_EQ(count(blk, "std::sin("), 1u) << blk;
  EXPECT_EQ(count(blk, "std::cos("), 1u) << blk;
  // Products are flattened, so 2*m*sin*cos shares the two calls, not the product sin*cos.
  EXPECT_EQ(blk,
            "\tconst double cse_0 = std::cos(x[1]);\n"
            "\tconst double cse_1 = std::sin(x[0]);\n"
            "\tconst double cse_2 = cse_0*cse_1;\n"
            "\tf[0] = cse_2;\n"
            "\tf[1] = x[1]*x[1] + 2.0*par[0]*cse_0*cse_1;\n"
            "\tf[2] = std::exp(cse_2) - cse_1;\n");
  // Leaves never become temporaries; a single use is inlined.
  const std::string one = emit_c_block(dag, {{"g", dag.import(x * y + x)}}, c_bind());
  EXPECT_EQ(one, "  g = x[0] + x[0]*x[1];\n");
  // The same node assigned twice is computed once.
  const NodeId e = dag.import(exp(x + y));
  EXPECT_EQ(emit_c_block(dag, {{"u", e}, {"v", e}}, c_bind(), ""),
            "const double t0 = std::exp(x[0] + x[1]);\nu = t0;\nv = t0;\n");
}

// ---------------------------------------------------------------------------
// Numbers

std::string g17(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

TEST(DagNumbers, ExactRationalsHugeIntegersAndFloats) {
  ExprDag dag;
  const std::map<std::string, std::string> none;
  auto c = [&](const ex& e) { return dag.to_c(dag.import(e), none); };
  EXPECT_EQ(c(numeric(1, 3)), "(1.0/3.0)");
  EXPECT_EQ(c(numeric(-1, 3)), "-(1.0/3.0)");
  EXPECT_EQ(c(numeric(7)), "7.0");
  EXPECT_EQ(c(numeric(-7)), "-7.0");
  EXPECT_EQ(c(numeric(0)), "0.0");
  EXPECT_EQ(c(numeric("9007199254740992")), "9007199254740992.0");  // 2^53
  EXPECT_EQ(c(numeric("9007199254740993")), "9007199254740992.0");  // rounds to 2^53
  EXPECT_EQ(c(numeric("1000000000000000000000000000000")), "1e+30");
  EXPECT_EQ(c(numeric("123456789012345678901234567890")), "1.2345678901234568e+29");
  EXPECT_EQ(c(numeric(1, 9007199254740992LL)), "(1.0/9007199254740992.0)");
  // 1/3^40 and 12345678901234567890123/10^25: correctly rounded (Python's Fraction -> float).
  EXPECT_EQ(c(numeric(1) / numeric("12157665459056928801")), "8.2252633399699586e-20");
  EXPECT_EQ(c(numeric("12345678901234567890123") / numeric("10000000000000000000000000")),
            "0.0012345678901234567");
  EXPECT_EQ(c(numeric(0.1)), "0.10000000000000001");
  EXPECT_EQ(c(numeric(2.0)), "2.0");
  EXPECT_EQ(c(numeric(-1e300)), "-" + g17(1e300));
  EXPECT_THROW(c(pow(numeric(10), 400)), InternalError);  // not a finite double

  EXPECT_EQ(dag.to_ginac(dag.import(numeric(1, 3))), "1/3");
  EXPECT_EQ(dag.to_ginac(dag.import(numeric(-1, 3))), "-1/3");
  EXPECT_EQ(dag.to_ginac(dag.import(numeric(0.1))), "0.1");
  EXPECT_EQ(dag.to_ginac(dag.import(numeric(2.0))), "2.0");
  EXPECT_EQ(dag.to_ginac(dag.import(numeric(1e20))), "1e+20");
  EXPECT_EQ(dag.to_latex(dag.import(numeric(1, 3))), "\\frac{1}{3}");
  EXPECT_EQ(dag.to_latex(dag.import(numeric(-1.5e-7))), "-1.5 \\cdot 10^{-7}");
  // Rationals stay exact through normalisation: 1/3 - 1/3 cancels exactly.
  const Syms s = forward_syms();
  const ex x = s.at("x");
  EXPECT_EQ(dag.to_ginac(dag.import(numeric(1, 3) * x + x * numeric(2, 3))), "x");
  EXPECT_NE(dag.import(numeric(1, 2)), dag.import(numeric(0.5)));  // exact vs float
}

// ---------------------------------------------------------------------------
// LaTeX

TEST(DagLatex, Forms) {
  const Syms s = forward_syms();
  const ex a = s.at("a"), b = s.at("b"), x = s.at("x"), y = s.at("y");
  ExprDag dag;
  auto l = [&](const ex& e) {
    return dag.to_latex(dag.import(e), {{"a", "\\alpha"}, {"b", "\\beta"}});
  };
  EXPECT_EQ(l(a / b), "\\frac{\\alpha}{\\beta}");
  EXPECT_EQ(l(sqrt(x + 1)), "\\sqrt{x + 1}");
  EXPECT_EQ(l(pow(x, numeric(1, 3))), "\\sqrt[3]{x}");
  EXPECT_EQ(l(pow(sin(x), 2) + exp(-y)), "\\exp\\left(-y\\right) + \\sin^{2}\\left(x\\right)");
  EXPECT_EQ(l(pow(x + y, 2)), "\\left(x + y\\right)^{2}");
  EXPECT_EQ(l(-2 * x * (a - b)), "2 x \\left(\\beta - \\alpha\\right)");
  EXPECT_EQ(l(abs(x) * GiNaC::Pi), "\\pi \\left|x\\right|");
  EXPECT_EQ(l(pow(x, y)), "x^{y}");
  EXPECT_EQ(l(numeric(3, 4) * pow(x, -2)), "\\frac{3}{4 x^{2}}");
  const realsymbol theta("theta"), omega("omega_1"), speed("v_max");
  EXPECT_EQ(dag.to_latex(dag.import(theta * omega * speed), {{"theta", "\\theta"}}),
            "\\mathrm{omega}_{1} \\theta v_{\\mathrm{max}}");
}

// ---------------------------------------------------------------------------
// Errors

TEST(DagErrors, UnsupportedInputsAndUnboundSymbols) {
  const Syms s = forward_syms();
  const ex x = s.at("x"), y = s.at("y");
  ExprDag dag;
  auto message = [&](const ex& e) {
    try {
      dag.import(e);
    } catch (const InternalError& err) {
      return std::string(err.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(x + GiNaC::I).find("complex"), std::string::npos);
  EXPECT_NE(message(x == y).find("relational"), std::string::npos);
  EXPECT_NE(message(GiNaC::asinh(x)).find("asinh"), std::string::npos);
  EXPECT_NE(message(GiNaC::zeta(x)).find("zeta"), std::string::npos);
  EXPECT_NE(message(x * GiNaC::Euler).find("Euler"), std::string::npos);
  const NodeId n = dag.import(x + y);
  EXPECT_THROW((void)dag.to_c(n, {{"x", "x[0]"}}), InternalError);
  EXPECT_THROW((void)emit_c_block(dag, {{"o", n}}, {{"y", "x[1]"}}), InternalError);
  EXPECT_EQ(dag.to_c(n, {{"x", "s.x"}, {"y", "2*q"}}), "s.x + (2*q)");
  EXPECT_THROW((void)dag.kind(static_cast<NodeId>(dag.size())), InternalError);
}

// ---------------------------------------------------------------------------
// The canonical order

TEST(DagOrder, CompareIsATotalOrder) {
  const Syms s = forward_syms();
  ExprDag dag;
  for (const ex& e : sample_expressions(s)) dag.import(e);
  const auto n = static_cast<NodeId>(dag.size());
  std::vector<NodeId> ids(n);
  for (NodeId i = 0; i < n; ++i) ids[i] = i;
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<NodeId> pick(0, n - 1);
  for (int t = 0; t < 20000; ++t) {
    const NodeId a = pick(rng), b = pick(rng), c = pick(rng);
    const int ab = dag.compare(a, b), ba = dag.compare(b, a);
    ASSERT_EQ(ab == 0, a == b);
    ASSERT_EQ(ab<0, ba> 0);
    if (ab < 0 && dag.compare(b, c) < 0) {
      ASSERT_LT(dag.compare(a, c), 0);
    }
  }
  std::sort(ids.begin(), ids.end(), [&](NodeId a, NodeId b) { return dag.compare(a, b) < 0; });
  for (NodeId i = 0; i + 1 < n; ++i) ASSERT_LT(dag.compare(ids[i], ids[i + 1]), 0);
  // Equal content hash for equal nodes across dags; kinds in canonical order.
  ExprDag other;
  const NodeId p = other.import(s.at("x") + 1);
  const NodeId q = dag.import(1 + s.at("x"));
  EXPECT_EQ(other.content_hash(p), dag.content_hash(q));
  EXPECT_LT(dag.compare(dag.import(numeric(5)), dag.import(s.at("a"))), 0);
}

TEST(DagCopy, CopiesAreIndependent) {
  const Syms s = forward_syms();
  ExprDag dag;
  const NodeId n = dag.import(s.at("x") * s.at("y"));
  ExprDag copy = dag;
  EXPECT_EQ(copy.to_ginac(n), "x*y");
  const NodeId m = copy.import(s.at("z"));
  EXPECT_EQ(copy.to_ginac(m), "z");
  EXPECT_EQ(dag.size() + 1, copy.size());
  ExprDag moved = std::move(copy);
  EXPECT_EQ(moved.to_ginac(m), "z");
}

}  // namespace
}  // namespace hybgen::gen
