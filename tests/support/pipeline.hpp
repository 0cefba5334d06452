#pragma once
/// \file pipeline.hpp
/// The front end (hybgen/gen/frontend.hpp) for tests that start from model text: the
/// stages `hybgen derive` runs, without the watchdog and without --set.

#include <string>

#include "hybgen/gen/frontend.hpp"

namespace hybgen::testing {

/// A model's source, its checked (for Lie-group models: reduced) Model and its IR.
struct Pipeline : gen::Frontend {
  /// Run the stages on `text`, shown as `path` in messages; throws ModelError.
  Pipeline(const std::string& path, const std::string& text,
           gen::ReduceTarget target = gen::ReduceTarget::Reduced)
      : gen::Frontend(gen::SourceText(path, text), options(target)) {}

 private:
  static gen::FrontendOptions options(gen::ReduceTarget target) {
    gen::FrontendOptions o;
    o.target = target;
    return o;
  }
};

}  // namespace hybgen::testing
