#pragma once
/// \file render.hpp
/// `hybgen derive`'s renderings of a derived system (render.cpp): the equations as text,
/// as LaTeX the way the paper writes them, and as the JSON of docs/design.md. Everything
/// printed goes through hybgen's own deterministic DAG printer (dag.hpp): the same model
/// gives the same bytes.

#include <nlohmann/json.hpp>

#include <string>

#include "hybgen/gen/model.hpp"

namespace hybgen::gen {

/// `hybgen derive --format text`.
std::string derive_text(const HybridSystem& sys);

/// `hybgen derive --format latex`: the PDE and jump conditions as the paper writes them.
std::string derive_latex(const HybridSystem& sys);

/// `derive --format latex --standalone`: derive_latex as a document pdflatex compiles
/// (article, amsmath), with the state and the parameter values.
std::string derive_latex_document(const HybridSystem& sys);

/// `hybgen derive --format json` (docs/design.md contract).
nlohmann::ordered_json derive_json(const HybridSystem& sys);

}  // namespace hybgen::gen
