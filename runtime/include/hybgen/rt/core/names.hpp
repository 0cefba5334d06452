#pragma once
/// \file names.hpp
/// What a model's indices are called in messages: the state dimension as a compile-time size,
/// mode and guard names, and a state written with its variables' names.

#include <array>
#include <cstddef>
#include <ostream>

#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Dimension N of a model's state, as a compile-time size.
template <class M>
inline constexpr std::size_t state_dim_v = static_cast<std::size_t>(M::n_state);

/// Name of mode `m` of M for messages, or "?" when `m` is no mode index.
template <HybridModel M>
const char* mode_name(int m) {
  return m >= 0 && m < M::n_mode ? M::mode_names[static_cast<std::size_t>(m)] : "?";
}

/// Name of guard `g` of M for messages, or "?" when `g` is no guard index.
template <HybridModel M>
const char* guard_name(int g) {
  return g >= 0 && g < M::n_guard ? M::guard_names[static_cast<std::size_t>(g)] : "?";
}

/// Writes the state x as "(x = 0, p = -2)" with M's state names, at os's precision.
template <HybridModel M>
void write_state(std::ostream& os, const std::array<double, state_dim_v<M>>& x) {
  os << '(';
  for (std::size_t i = 0; i < x.size(); ++i)
    os << (i ? ", " : "") << M::state_names[i] << " = " << x[i];
  os << ')';
}

}  // namespace hybgen::rt
