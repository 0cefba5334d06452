#pragma once
// Shared by the set finders of this directory (almost_invariant.cpp, coherent.cpp): the order
// in which their sets are numbered.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <vector>

namespace hybgen::rt::detail {

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
