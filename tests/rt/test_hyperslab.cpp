// hyperslab.hpp: the boxes of a contiguous C-order range (what each rank of a distributed run
// writes of a frame into run.nc) and the chunk shape of a frame. The reference is the
// definition: every flat index of [begin, end) in exactly one box, in increasing order, and
// nothing else; checked by enumerating the boxes' elements, on shapes of 1 to 5 axes and
// every range of a small array.

#include "hybgen/rt/io/hyperslab.hpp"

#include <gtest/gtest.h>

#include <cstddef>
#include <vector>

namespace {

using hybgen::rt::c_order_chunk;
using hybgen::rt::c_order_hyperslabs;
using hybgen::rt::Hyperslab;

/// The flat C-order indices of a box's elements, in C order.
std::vector<std::size_t> flat_indices(const std::vector<std::size_t>& shape, const Hyperslab& h) {
  std::vector<std::size_t> out, idx(shape.size(), 0);
  const std::size_t n = h.size();
  for (std::size_t e = 0; e < n; ++e) {
    std::size_t rem = e, flat = 0;
    for (std::size_t a = shape.size(); a-- > 0;) {
      idx[a] = h.start[a] + rem % h.count[a];
      rem /= h.count[a];
    }
    for (std::size_t a = 0; a < shape.size(); ++a) flat = flat * shape[a] + idx[a];
    out.push_back(flat);
  }
  return out;
}

TEST(Hyperslab, EveryRangeOfSmallArraysIsTiledInOrderByAtMost2NMinus1Boxes) {
  const std::vector<std::vector<std::size_t>> shapes{
      {7}, {3, 4}, {2, 3, 4}, {3, 1, 2, 3}, {2, 2, 3, 2, 2}};
  for (const auto& shape : shapes) {
    std::size_t n = 1;
    for (const std::size_t s : shape) n *= s;
    for (std::size_t b = 0; b <= n; ++b)
      for (std::size_t e = b; e <= n; ++e) {
        const std::vector<Hyperslab> boxes = c_order_hyperslabs(shape, b, e);
        EXPECT_LE(boxes.size(), 2 * shape.size() - 1);
        std::vector<std::size_t> seen;
        for (const Hyperslab& h : boxes) {
          ASSERT_EQ(h.start.size(), shape.size());
          for (std::size_t a = 0; a < shape.size(); ++a) {
            ASSERT_GE(h.count[a], 1u);
            ASSERT_LE(h.start[a] + h.count[a], shape[a]);
          }
          const std::vector<std::size_t> f = flat_indices(shape, h);
          seen.insert(seen.end(), f.begin(), f.end());
        }
        std::vector<std::size_t> want;
        for (std::size_t i = b; i < e; ++i) want.push_back(i);
        ASSERT_EQ(seen, want) << "shape of " << shape.size() << " axes, range [" << b << ", " << e
                              << ")";
      }
  }
}

TEST(Hyperslab, ABlockOfWholeSlicesIsOneBox) {
  const std::vector<std::size_t> shape{10, 4, 5};
  const auto boxes = c_order_hyperslabs(shape, 2 * 20, 7 * 20);
  ASSERT_EQ(boxes.size(), 1u);
  EXPECT_EQ(boxes[0].start, (std::vector<std::size_t>{2, 0, 0}));
  EXPECT_EQ(boxes[0].count, (std::vector<std::size_t>{5, 4, 5}));
}

TEST(Hyperslab, ChunksAreWholeTrailingAxesUpToTheLimit) {
  // Small frames: one chunk.
  EXPECT_EQ(c_order_chunk(std::vector<std::size_t>{75, 75}, 1u << 21),
            (std::vector<std::size_t>{75, 75}));
  // 65^5 doubles (9.3 GB a frame): whole trailing axes while they fit (65^3 = 274625), then
  // 7 slices of the second axis (7 · 274625 ≤ 2^21 < 8 · 274625), one of the first.
  EXPECT_EQ(c_order_chunk(std::vector<std::size_t>{65, 65, 65, 65, 65}, 1u << 21),
            (std::vector<std::size_t>{1, 7, 65, 65, 65}));
  // A last axis longer than the limit is cut itself.
  EXPECT_EQ(c_order_chunk(std::vector<std::size_t>{3, 100}, 16), (std::vector<std::size_t>{1, 16}));
}

}  // namespace
