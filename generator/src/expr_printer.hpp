#pragma once
/// \file expr_printer.hpp
/// GiNaC expressions printed through one expression DAG (dag.hpp), so that the same
/// expression prints the same text in every run: the printer of the kernel emitter
/// (emit.cpp) and of `hybgen derive`'s renderings (render.cpp). Internal to the generator
/// library: not a public header.

#include <ginac/ginac.h>

#include <map>
#include <string>

#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/model.hpp"

namespace hybgen::gen {

/// Prints GiNaC expressions deterministically through one DAG.
class ExprPrinter {
 public:
  /// A printer with the model's TeX names of its symbols.
  explicit ExprPrinter(const Model& m) : tex_(m.tex) {}
  /// `e` in GiNaC input syntax (ExprDag::to_ginac).
  std::string ginac(const GiNaC::ex& e) { return dag_.to_ginac(dag_.import(e)); }
  /// `e` in LaTeX (ExprDag::to_latex).
  std::string latex(const GiNaC::ex& e) { return dag_.to_latex(dag_.import(e), tex_); }
  /// The node of `e` in the printer's dag (for emit_c_block).
  NodeId node(const GiNaC::ex& e) { return dag_.import(e); }
  /// The printer's dag.
  ExprDag& dag() { return dag_; }
  /// "+ latex" / "- latex(-e)" for a term of a sum.
  std::string signed_term(const GiNaC::ex& e) {
    std::string s = latex(e);
    if (!GiNaC::is_a<GiNaC::add>(e) && !s.empty() && s[0] == '-') return " - " + latex(-e);
    if (GiNaC::is_a<GiNaC::add>(e)) return " + \\left(" + s + "\\right)";
    return " + " + s;
  }

 private:
  ExprDag dag_;
  std::map<std::string, std::string> tex_;
};

}  // namespace hybgen::gen
