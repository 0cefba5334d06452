#pragma once
/// \file setting_edges.hpp
/// The values at the edges of every numeric setting's range (runtime/include/hybgen/rt/
/// settings.hpp, the settings table): the smallest and the largest it admits, and the values
/// just outside. Shared by the fuzzing regression that puts them through the overrides
/// (tests/gen/test_fuzz_regressions.cpp) and the end-to-end test that runs them
/// (tests/e2e/test_setting_edges.cpp).

#include <cmath>
#include <limits>
#include <vector>

#include "hybgen/rt/settings.hpp"

namespace hybgen::testing {

/// A value of a setting, and whether its range admits it.
struct EdgeValue {
  double value;  ///< The value.
  bool inside;   ///< Whether the range admits it.
};

/// The smallest and largest admitted values of a numeric setting, and the values just outside
/// (empty for a setting that is not a number).
inline std::vector<EdgeValue> edge_values(const rt::SettingSpec& spec) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const bool integer = spec.type == rt::SettingType::integer;
  if (!integer && spec.type != rt::SettingType::real) return {};
  const double lo_in = !spec.lo_open ? spec.lo
                       : integer     ? spec.lo + 1
                                     : std::nextafter(spec.lo, kInf);
  const double below = spec.lo_open ? spec.lo
                       : integer    ? spec.lo - 1
                                    : std::nextafter(spec.lo, -kInf);
  // (hi + 1 is hi itself at 2^53, the seed's largest: the next double then.)
  const double above =
      integer && spec.hi + 1 > spec.hi ? spec.hi + 1 : std::nextafter(spec.hi, kInf);
  return {{lo_in, true}, {spec.hi, true}, {below, false}, {above, false}};
}

}  // namespace hybgen::testing
