// The finite-time coherent sets of hybgen/rt/methods/coherent.hpp (see its comment).

#include "hybgen/rt/methods/coherent.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "hybgen/rt/methods/almost_invariant.hpp"
#include "hybgen/rt/numerics/eigen_solvers.hpp"
#include "set_ranking.hpp"

// See hybgen/rt/core/sparse.hpp: GCC 12's flow-sensitive warnings misfire inside Eigen.
HYBGEN_EIGEN_WARNINGS_PUSH
#include <Eigen/Dense>

namespace hybgen::rt {

CoherentSets coherent_sets(const CsrMatrix& F, std::span<const double> p, int K, std::size_t n_mode,
                           double tol) {
  const auto n = static_cast<std::size_t>(F.rows());
  if (K < 2) throw std::invalid_argument("coherent sets: sets must be at least 2");
  if (static_cast<std::size_t>(F.cols()) != n || p.size() != n)
    throw std::invalid_argument("coherent sets: the transport and the masses disagree in size");
  const auto k = static_cast<std::size_t>(K);
  // q = F p, and both supports.
  std::vector<double> q(n, 0.0);
  for (std::size_t j = 0; j < n; ++j)
    for (CsrMatrix::InnerIterator e(F, static_cast<Eigen::Index>(j)); e; ++e)
      q[j] += e.value() * std::max(p[static_cast<std::size_t>(e.col())], 0.0);
  std::vector<std::size_t> at0, at1;
  const std::vector<std::size_t> node0 = detail::support_of(p, at0),
                                 node1 = detail::support_of(q, at1);
  const std::size_t s0 = node0.size(), s1 = node1.size();
  for (const auto& [size, when] : {std::pair{s0, "initial"}, std::pair{s1, "final"}})
    if (size < k + 1)
      throw std::invalid_argument(std::string("coherent sets: the ") + when + " density lives on " +
                                  std::to_string(size) + " node(s), too few for " +
                                  std::to_string(K) + " sets");
  // L_ji = F_ji √p_i / √q_j on the supports (rows final, columns initial).
  std::vector<Eigen::Triplet<double>> trip;
  for (std::size_t j = 0; j < n; ++j) {
    if (at1[j] == n) continue;
    for (CsrMatrix::InnerIterator e(F, static_cast<Eigen::Index>(j)); e; ++e) {
      const auto i = static_cast<std::size_t>(e.col());
      if (at0[i] == n || e.value() == 0.0) continue;
      trip.emplace_back(static_cast<int>(at1[j]), static_cast<int>(at0[i]),
                        e.value() * std::sqrt(p[i] / q[j]));
    }
  }
  CscMatrix L(static_cast<Eigen::Index>(s1), static_cast<Eigen::Index>(s0));
  L.setFromTriplets(trip.begin(), trip.end());
  L.makeCompressed();
  // Lᵀ L: eigenvalues σ² ∈ [0, 1], clustered near 1 for coherent pieces; shift-invert about
  // 1 + kShift as for the almost-invariant sets.
  const CscMatrix M = CscMatrix(L.transpose() * L).pruned();
  const ComponentEigenPairs pairs =
      largest_eigenpairs_by_component(M, static_cast<Eigen::Index>(k), 1.0 + kShift, tol,
                                      static_cast<Eigen::Index>(kDenseComponent));
  CoherentSets out;
  out.components = pairs.members.size();
  out.converged = pairs.converged;
  if (pairs.values.size() < k)
    throw std::invalid_argument("coherent sets: the eigen-solver found " +
                                std::to_string(pairs.values.size()) +
                                " singular value(s), fewer than " + std::to_string(K));
  // φ_k = v_k/√p (initial rows) over ψ_k = L v_k/(σ_k √q) (final rows), K columns.
  const auto rows0 = static_cast<Eigen::Index>(s0), rows1 = static_cast<Eigen::Index>(s1);
  Eigen::MatrixXd stacked = Eigen::MatrixXd::Zero(rows0 + rows1, static_cast<Eigen::Index>(k));
  for (std::size_t c = 0; c < k; ++c) {
    const auto col = static_cast<Eigen::Index>(c);
    const double sigma = std::sqrt(std::max(pairs.values[c], 0.0));
    out.singular_values.push_back(sigma);
    out.bound += sigma;
    Eigen::VectorXd v = Eigen::VectorXd::Zero(rows0);
    const std::vector<std::size_t>& m = pairs.members[pairs.component[c]];
    for (std::size_t i = 0; i < m.size(); ++i)
      v(static_cast<Eigen::Index>(m[i])) = pairs.vectors[c](static_cast<Eigen::Index>(i));
    const Eigen::VectorXd u = sigma > 0.0 ? Eigen::VectorXd(L * v / sigma)
                                          : Eigen::VectorXd(Eigen::VectorXd::Zero(rows1));
    for (std::size_t i = 0; i < s0; ++i)
      stacked(static_cast<Eigen::Index>(i), col) =
          v(static_cast<Eigen::Index>(i)) / std::sqrt(p[node0[i]]);
    for (std::size_t j = 0; j < s1; ++j)
      stacked(rows0 + static_cast<Eigen::Index>(j), col) =
          u(static_cast<Eigen::Index>(j)) / std::sqrt(q[node1[j]]);
  }
  const detail::Seba basis = detail::seba(stacked);
  out.seba_iterations = basis.iterations;
  // Each supported node to the rotated vector largest at it; pairs ranked by p(A), decreasing
  // (ties: the first node).
  auto argmax = [&](Eigen::Index row) {
    Eigen::Index best = 0;
    basis.rotated.row(row).maxCoeff(&best);
    return static_cast<std::size_t>(best);
  };
  std::vector<double> mass(k, 0.0);
  std::vector<std::size_t> first(k, n);
  for (std::size_t i = 0; i < s0; ++i) {
    const std::size_t c = argmax(static_cast<Eigen::Index>(i));
    mass[c] += p[node0[i]];
    first[c] = std::min(first[c], i);
  }
  const std::vector<std::int32_t> rank = detail::rank_by_mass(mass, first);
  out.initial_label.assign(n, 0);
  out.final_label.assign(n, 0);
  for (std::size_t i = 0; i < s0; ++i)
    out.initial_label[node0[i]] = rank[argmax(static_cast<Eigen::Index>(i))];
  for (std::size_t j = 0; j < s1; ++j)
    out.final_label[node1[j]] = rank[argmax(rows0 + static_cast<Eigen::Index>(j))];
  // Masses, modes, and the mass carried from A_k into B_k.
  const std::size_t modes = std::max<std::size_t>(n_mode, 1), per_mode = n / modes;
  out.sets.assign(k, {});
  for (CoherentPair& a : out.sets)
    a.initial_mode_mass.assign(modes, 0.0), a.final_mode_mass.assign(modes, 0.0);
  auto mode_of = [&](std::size_t i) {
    return per_mode > 0 ? std::min(i / per_mode, modes - 1) : 0;
  };
  for (std::size_t i = 0; i < n; ++i) {
    if (const std::int32_t a = out.initial_label[i]; a > 0) {
      CoherentPair& set = out.sets[static_cast<std::size_t>(a - 1)];
      set.initial_mass += p[i], set.initial_nodes += 1, set.initial_mode_mass[mode_of(i)] += p[i];
    }
    if (const std::int32_t b = out.final_label[i]; b > 0) {
      CoherentPair& set = out.sets[static_cast<std::size_t>(b - 1)];
      set.final_mass += q[i], set.final_nodes += 1, set.final_mode_mass[mode_of(i)] += q[i];
      for (CsrMatrix::InnerIterator e(F, static_cast<Eigen::Index>(i)); e; ++e) {
        const auto from = static_cast<std::size_t>(e.col());
        if (out.initial_label[from] == b) set.carried += e.value() * p[from];
      }
    }
  }
  for (CoherentPair& a : out.sets) {
    a.forward = a.initial_mass > 0.0 ? a.carried / a.initial_mass : 0.0;
    a.backward = a.final_mass > 0.0 ? a.carried / a.final_mass : 0.0;
    out.coherence_sum += std::sqrt(a.forward * a.backward);
  }
  return out;
}

}  // namespace hybgen::rt

HYBGEN_EIGEN_WARNINGS_POP
