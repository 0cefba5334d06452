#pragma once
/// \file step_lines.hpp
/// The check lattice's trapezoid sum of a step integrand, with its jumps located along the
/// lattice's lines.
///
/// The forward flows' integrands (budget/atom.hpp) are steps: u0(x)·c(x), c an integer count
/// (impacts of a guard by t, absorbed by t, …) that jumps across curves of initial points.
/// On a lattice of spacing h the trapezoid sum of such a step is off by Σ over the segments
/// a jump crosses of jump·(s − 1/2)·h·(the transverse weight), s ∈ [0, 1] where the jump
/// falls in its segment: the trapezoid rule puts every jump at its segment's midpoint. In two
/// and more dimensions those errors, one per line a jump crosses, add up to about the jump's
/// length times h, and that sum's distance from the cubature is the floor of the counts' bars
/// (budget/atom.hpp, `collect_step`): 14–60× the errors on 10 of the elastic ball's 48 frames
/// (tests/validation/test_calibration.cpp) with the jumps left where the rule puts them.
///
/// Here every segment along the lattice's last axis whose ends have different counts is
/// halved, and again where its halves' ends differ, breadth first, each level one batch of
/// evaluations, until what the segments left could still be off by is within a target (or a
/// cap on the evaluations): a segment halved L times holds its jump to h·2^(−L), and the sum
/// changes by the refined trapezoid rule's difference, w·ℓ/4·(2 v_m − v_a − v_b) per halving
/// of a segment [a, b] of length ℓ with midpoint m and transverse weight w. The line sums of the
/// step are then exact but for h·2^(−L)-th of their jumps and the smooth part's O(h²); what
/// is left is the transverse rule's error over the line integrals, which are continuous
/// (kinks where a jump's curve is tangent to the lines).
///
/// The counts are compared, not the values: u0 varies along a segment where c does not.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "hybgen/rt/methods/budget/check_points.hpp"

namespace hybgen::rt::detail {

/// Most halvings of a segment by `locate_steps`: a jump held to 2^(−10) of the lattice's
/// spacing.
inline constexpr int kMaxStepHalvings = 10;

/// Whether the counts of two points differ: their V counts (integers, as doubles) differ in a
/// slot by more than 1/2.
inline bool counts_differ(const double* a, const double* b, std::size_t V) {
  for (std::size_t q = 0; q < V; ++q)
    if (std::fabs(a[q] - b[q]) > 0.5) return true;
  return false;
}

/// Corrects `sums` (V slots, the trapezoid sums over the lattice `x`) for the jumps of the
/// steps along the lattice's last axis (see the file's comment).
///  * x: the lattice's points in C order (the last axis fastest), `shape` per axis; `spacing`
///    per axis; `lo`, `hi` the box whose faces carry half weights (as budget/check_points.hpp,
///    `fine_lattice`).
///  * v: 2V values per point: the V values of the integrand, then the V counts.
///  * eval(points, out): out ← 2V values per point, as v; false on a failure (the sums keep
///    what was located before it).
///  * target: enough located: halving stops once, in every slot, the most the segments left
///    can be off, Σ w·ℓ/2·|v_b − v_a| (a jump anywhere in [a, b]), is at most `target`.
///  * max_evals: the most points evaluated in all.
/// Returns the number of points evaluated.
template <std::size_t N, class Eval>
std::size_t locate_steps(std::span<const std::array<double, N>> x,
                         const std::array<std::size_t, N>& shape,
                         const std::array<double, N>& spacing, const std::array<double, N>& lo,
                         const std::array<double, N>& hi, std::span<const double> v, std::size_t V,
                         Eval&& eval, double target, std::size_t max_evals,
                         std::vector<double>& sums) {
  std::size_t count = 1;
  for (const std::size_t n : shape) count *= n;
  if (V == 0 || count != x.size() || v.size() != 2 * V * x.size() || shape[N - 1] < 2) return 0;
  const std::size_t W = 2 * V;
  // The points halving created that the segments still end on, after the lattice's: index
  // P + j is new point j.
  const std::size_t P = x.size();
  std::vector<std::array<double, N>> nx;
  std::vector<double> nv;
  auto point = [&](std::size_t i) -> const std::array<double, N>& {
    return i < P ? x[i] : nx[i - P];
  };
  auto values = [&](std::size_t i) -> const double* {
    return i < P ? v.data() + i * W : nv.data() + (i - P) * W;
  };
  struct Segment {
    std::size_t a, b;  // its ends (point indices)
    double w;          // transverse weight
  };
  std::vector<Segment> segments;
  const std::size_t n_last = shape[N - 1];
  for (std::size_t line = 0; line < P; line += n_last) {
    // The transverse weight: the spacings of the other axes, halved on the box's faces.
    double w = 1.0;
    for (std::size_t a = 0; a + 1 < N; ++a)
      w *= trapezoid_factor(x[line][a], lo[a], hi[a], spacing[a]);
    for (std::size_t i = line; i + 1 < line + n_last; ++i)
      if (counts_differ(values(i) + V, values(i + 1) + V, V)) segments.push_back({i, i + 1, w});
  }
  std::size_t used = 0;
  std::vector<std::array<double, N>> mids;
  std::vector<double> mv;
  std::vector<double> left(V);
  for (int level = 0; level < kMaxStepHalvings && !segments.empty(); ++level) {
    std::fill(left.begin(), left.end(), 0.0);
    for (const Segment& g : segments) {
      const double half = 0.5 * g.w * (point(g.b)[N - 1] - point(g.a)[N - 1]);
      const double *va = values(g.a), *vb = values(g.b);
      for (std::size_t q = 0; q < V; ++q) left[q] += half * std::fabs(vb[q] - va[q]);
    }
    if (*std::max_element(left.begin(), left.end()) <= target) break;
    if (used + segments.size() > max_evals) break;
    mids.resize(segments.size());
    for (std::size_t s = 0; s < segments.size(); ++s) {
      mids[s] = point(segments[s].a);
      mids[s][N - 1] = 0.5 * (point(segments[s].a)[N - 1] + point(segments[s].b)[N - 1]);
    }
    mv.assign(mids.size() * W, 0.0);
    if (!eval(std::span<const std::array<double, N>>(mids), mv)) break;
    used += mids.size();
    const std::size_t first = P + nx.size();
    nx.insert(nx.end(), mids.begin(), mids.end());
    nv.insert(nv.end(), mv.begin(), mv.end());
    std::vector<Segment> next;
    for (std::size_t s = 0; s < segments.size(); ++s) {
      const Segment& g = segments[s];
      const std::size_t m = first + s;
      const double len = point(g.b)[N - 1] - point(g.a)[N - 1];
      const double *va = values(g.a), *vb = values(g.b), *vm = values(m);
      for (std::size_t q = 0; q < V; ++q)
        sums[q] += g.w * 0.25 * len * (2.0 * vm[q] - va[q] - vb[q]);
      if (counts_differ(va + V, vm + V, V)) next.push_back({g.a, m, g.w});
      if (counts_differ(vm + V, vb + V, V)) next.push_back({m, g.b, g.w});
    }
    segments = std::move(next);
    // Only the new points that the next level's segments end on are kept: at most two per
    // segment, not every point evaluated so far.
    std::vector<std::size_t> renumber(nx.size(), SIZE_MAX);
    std::vector<std::array<double, N>> kx;
    std::vector<double> kv;
    for (Segment& g : segments)
      for (std::size_t* end : {&g.a, &g.b}) {
        if (*end < P) continue;
        std::size_t& r = renumber[*end - P];
        if (r == SIZE_MAX) {
          r = P + kx.size();
          kx.push_back(nx[*end - P]);
          kv.insert(kv.end(), nv.begin() + static_cast<std::ptrdiff_t>((*end - P) * W),
                    nv.begin() + static_cast<std::ptrdiff_t>((*end - P + 1) * W));
        }
        *end = r;
      }
    nx = std::move(kx);
    nv = std::move(kv);
  }
  return used;
}

}  // namespace hybgen::rt::detail
