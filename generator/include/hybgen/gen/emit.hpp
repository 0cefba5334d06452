#pragma once
/// \file emit.hpp
/// Stage 4 (emit): HybridSystem IR -> generated sources (a C++ kernel header
/// satisfying hybgen::rt::HybridModel, and a Markdown derivation report).
/// Everything printed goes through hybgen's own deterministic DAG printer:
/// the same model gives the same bytes. The renderings of `hybgen derive` are in
/// render.hpp.

#include <string>

#include "hybgen/gen/model.hpp"

namespace hybgen::gen {

/// The generated sources of one model.
struct GeneratedFiles {
  std::string header_name;  ///< "<model>.hpp"
  std::string header;       ///< Kernel header text.
  std::string report_name;  ///< "report.md"
  std::string report;       ///< Derivation report (Markdown with LaTeX).
  int n_state = 0;          ///< State dimension of the model (the builder's choice of runtime).
  int n_guard = 0;          ///< Guards of the model (the builder's choice of runtime).
};

/// Generator version string (provenance headers, cache keys).
const char* generator_version();

/// Stage 4: emit the kernel header and the report of a derived system.
GeneratedFiles emit(const HybridSystem& sys);

/// Write `files` into `dir` (created if needed), each atomically.
void write_generated(const GeneratedFiles& files, const std::string& dir);

/// C++ identifier for the model's struct (the model name, sanitised).
std::string model_struct_name(const std::string& model_name);

}  // namespace hybgen::gen
