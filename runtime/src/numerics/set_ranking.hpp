#pragma once
// Shared by the set finders of this directory (almost_invariant.cpp, coherent.cpp): the nodes
// that carry mass, and the order in which their sets are numbered.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <span>
#include <vector>

#include "hybgen/rt/methods/almost_invariant.hpp"

namespace hybgen::rt::detail {

/// The nodes whose mass `m` is above kMassFloor of the largest, increasing; `at` gets each
/// node's index among them (m.size(): none).
inline std::vector<std::size_t> support_of(std::span<const double> m,
                                           std::vector<std::size_t>& at) {
  double top = 0.0;
  for (const double x : m) top = std::max(top, x);
  at.assign(m.size(), m.size());
  std::vector<std::size_t> node;
  for (std::size_t i = 0; i < m.size(); ++i)
    if (m[i] > kMassFloor * top) at[i] = node.size(), node.push_back(i);
  return node;
}

/// The label, 1 … K, of each of K sets numbered by decreasing `mass`, ties by the smaller
/// `first` (the first node each holds): label[k] is set k's number.
inline std::vector<std::int32_t> rank_by_mass(const std::vector<double>& mass,
                                              const std::vector<std::size_t>& first) {
  std::vector<std::size_t> order(mass.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return mass[a] != mass[b] ? mass[a] > mass[b] : first[a] < first[b];
  });
  std::vector<std::int32_t> label(mass.size());
  for (std::size_t r = 0; r < order.size(); ++r) label[order[r]] = static_cast<std::int32_t>(r) + 1;
  return label;
}

}  // namespace hybgen::rt::detail
