#pragma once
/// \file hyperslab.hpp
/// Pieces of an N-dimensional array in C order (last axis fastest), as the NetCDF/HDF5
/// writers address them: a contiguous range of flat indices as boxes (hyperslabs), and the
/// chunk shape of a large frame.
///
/// A rank of a distributed run holds a contiguous range of a frame's flat indices
/// (core/backend.hpp, block_of); netcdf.cpp writes it as the boxes `c_order_hyperslabs`
/// returns. Invariant: the boxes tile [begin, end) exactly, in increasing flat order, and
/// there are at most 2N − 1 of them.

#include <algorithm>
#include <cstddef>
#include <span>
#include <vector>

namespace hybgen::rt {

/// A box of an N-dimensional array: [start[a], start[a] + count[a]) on each axis a.
struct Hyperslab {
  std::vector<std::size_t> start;  ///< First index per axis.
  std::vector<std::size_t> count;  ///< Extent per axis.
  /// Number of elements.
  [[nodiscard]] std::size_t size() const {
    std::size_t n = 1;
    for (const std::size_t c : count) n *= c;
    return n;
  }
};

/// The boxes that tile the flat C-order range [begin, end) of an array of `shape`, in
/// increasing order: a partial run of the slowest axis' first slice, whole slices, and a
/// partial last slice, recursively (at most 2N − 1 boxes; none for an empty range).
inline std::vector<Hyperslab> c_order_hyperslabs(std::span<const std::size_t> shape,
                                                 std::size_t begin, std::size_t end) {
  std::vector<Hyperslab> out;
  if (begin >= end || shape.empty()) return out;
  const std::size_t N = shape.size();
  if (N == 1) {
    out.push_back({{begin}, {end - begin}});
    return out;
  }
  std::size_t inner = 1;
  for (std::size_t a = 1; a < N; ++a) inner *= shape[a];
  const std::span<const std::size_t> rest = shape.subspan(1);
  // The boxes of [b, e) inside slice i of the slowest axis.
  auto within = [&](std::size_t i, std::size_t b, std::size_t e) {
    for (const Hyperslab& h : c_order_hyperslabs(rest, b, e)) {
      Hyperslab g{{i}, {1}};
      for (std::size_t a = 0; a < h.start.size(); ++a)
        g.start.push_back(h.start[a]), g.count.push_back(h.count[a]);
      out.push_back(std::move(g));
    }
  };
  std::size_t i0 = begin / inner, i1 = end / inner;
  const std::size_t r0 = begin % inner, r1 = end % inner;
  if (i0 == i1) {
    within(i0, r0, r1);
    return out;
  }
  if (r0 != 0) within(i0++, r0, inner);
  if (i1 > i0) {
    Hyperslab whole{{i0}, {i1 - i0}};
    for (std::size_t a = 1; a < N; ++a) whole.start.push_back(0), whole.count.push_back(shape[a]);
    out.push_back(std::move(whole));
  }
  if (r1 != 0) within(i1, 0, r1);
  return out;
}

/// The chunk shape of an array of `shape` holding at most `max_values` values (at least one
/// per axis): whole trailing axes while they fit, then as many slices of the next axis as
/// fit, 1 on the slower axes. Depends only on the shape, so a file has the same chunks
/// whatever the number of ranks that wrote it.
inline std::vector<std::size_t> c_order_chunk(std::span<const std::size_t> shape,
                                              std::size_t max_values) {
  std::vector<std::size_t> chunk(shape.size(), 1);
  std::size_t size = 1;
  for (std::size_t a = shape.size(); a-- > 0;) {
    const std::size_t n = std::max<std::size_t>(shape[a], 1);
    if (size * n <= max_values) {
      chunk[a] = n;
      size *= n;
      continue;
    }
    chunk[a] = std::max<std::size_t>(1, max_values / size);
    break;
  }
  return chunk;
}

}  // namespace hybgen::rt
