#pragma once
/// \file pipeline.hpp
/// The front half of hybgen's compiler for tests that start from model text:
/// parse -> (check | check_lie -> reduce) -> derive, as `hybgen derive` runs it.

#include <string>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/gen/reduce.hpp"

namespace hybgen::testing {

/// A model's source, its checked (for Lie-group models: reduced) Model and its IR.
/// Invariant: sys.model points at this object's model (hence no copies).
struct Pipeline {
  gen::SourceText src;    ///< The model text.
  gen::Model model;       ///< The checked model (the reduced or unreduced system for `lie`).
  gen::HybridSystem sys;  ///< The derived IR.
  /// Run the stages on `text`, shown as `path` in messages; throws ModelError.
  Pipeline(const std::string& path, const std::string& text,
           gen::ReduceTarget target = gen::ReduceTarget::Reduced)
      : src(path, text) {
    const gen::ModelAst ast = gen::parse(src);
    model = gen::is_lie_model(ast) ? gen::reduce(gen::check_lie(ast, src), src, target)
                                   : gen::check(ast, src);
    sys = gen::derive(model, src);
    sys.model = &model;
  }
  Pipeline(const Pipeline&) = delete;             ///< sys.model would dangle.
  Pipeline& operator=(const Pipeline&) = delete;  ///< sys.model would dangle.
};

}  // namespace hybgen::testing
