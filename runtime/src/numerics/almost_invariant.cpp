// The almost-invariant sets of hybgen/rt/methods/almost_invariant.hpp (see its comment).

#include "hybgen/rt/methods/almost_invariant.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>

#include "hybgen/rt/numerics/eigen_solvers.hpp"
#include "set_ranking.hpp"

// See hybgen/rt/core/sparse.hpp: GCC 12's flow-sensitive warnings misfire inside Eigen and
// Spectra, whose solvers this file instantiates.
HYBGEN_EIGEN_WARNINGS_PUSH
#include <Eigen/Dense>

namespace hybgen::rt {

namespace detail {

Seba seba(const Eigen::MatrixXd& V_in) {
  const Eigen::Index p = V_in.rows(), r = V_in.cols();
  Eigen::MatrixXd V =
      Eigen::HouseholderQR<Eigen::MatrixXd>(V_in).householderQ() * Eigen::MatrixXd::Identity(p, r);
  // A constant vector thresholds to a constant one or to nothing; a deterministic tilt of
  // 1e-12 breaks the tie (the reference code adds noise of that size).
  for (Eigen::Index j = 0; j < r; ++j)
    if (V.col(j).maxCoeff() - V.col(j).minCoeff() < 1e-14)
      for (Eigen::Index i = 0; i < p; ++i)
        V(i, j) += 1e-12 * (static_cast<double>(i) / static_cast<double>(p) - 0.5);
  const double mu = 0.99 / std::sqrt(static_cast<double>(p));
  Eigen::MatrixXd R = Eigen::MatrixXd::Identity(r, r), S(p, r);
  Seba out;
  for (out.iterations = 1; out.iterations <= 5000; ++out.iterations) {
    const Eigen::MatrixXd Z = V * R.transpose();
    for (Eigen::Index j = 0; j < r; ++j) {
      for (Eigen::Index i = 0; i < p; ++i) {
        const double z = Z(i, j), m = std::max(std::fabs(z) - mu, 0.0);
        S(i, j) = z < 0.0 ? -m : m;
      }
      const double n = S.col(j).norm();
      if (n > 0.0) S.col(j) /= n;
    }
    // The rotation nearest S in the span of V: the polar factor of Sᵀ V.
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(S.transpose() * V,
                                          Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::MatrixXd next = svd.matrixU() * svd.matrixV().transpose();
    const double change = (next - R).norm();
    R = next;
    if (change <= 1e-14) break;
  }
  out.iterations = std::min<long>(out.iterations, 5000);
  Eigen::MatrixXd Z = V * R.transpose();
  for (Eigen::Index j = 0; j < r; ++j) {
    const double sign = S.col(j).sum() < 0.0 ? -1.0 : 1.0;
    S.col(j) *= sign, Z.col(j) *= sign;
    if (const double m = S.col(j).maxCoeff(); m > 0.0) S.col(j) /= m;
    if (const double m = Z.col(j).maxCoeff(); m > 0.0) Z.col(j) /= m;
  }
  std::vector<Eigen::Index> order(static_cast<std::size_t>(r));
  std::iota(order.begin(), order.end(), Eigen::Index{0});
  std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) {
    return S.col(a).minCoeff() > S.col(b).minCoeff();
  });
  out.sparse.resize(p, r), out.rotated.resize(p, r);
  for (Eigen::Index j = 0; j < r; ++j) {
    out.sparse.col(j) = S.col(order[static_cast<std::size_t>(j)]);
    out.rotated.col(j) = Z.col(order[static_cast<std::size_t>(j)]);
  }
  return out;
}

}  // namespace detail

AlmostInvariantSets almost_invariant_sets(const CsrMatrix& P, std::span<const double> mu, int K,
                                          std::size_t n_mode, double tol) {
  const auto n = static_cast<std::size_t>(P.rows());
  if (K < 2) throw std::invalid_argument("almost-invariant sets: sets must be at least 2");
  if (mu.size() != n) throw std::invalid_argument("almost-invariant sets: mu has the wrong size");
  AlmostInvariantSets out;
  out.label.assign(n, 0);
  // The support: nodes with invariant mass; index in it per node (n: none).
  std::vector<std::size_t> at;
  const std::vector<std::size_t> node = detail::support_of(mu, at);
  const std::size_t s = node.size();
  const auto k = static_cast<std::size_t>(K);
  if (s < k + 1)
    throw std::invalid_argument("almost-invariant sets: the invariant density lives on " +
                                std::to_string(s) + " node(s), too few for " + std::to_string(K) +
                                " sets");
  // S = (A + Aᵀ)/2 with A_cj = √(μ_c/μ_j) T_cj = √(μ_c/μ_j) P_jc on the support.
  std::vector<Eigen::Triplet<double>> trip;
  for (std::size_t j = 0; j < n; ++j) {
    if (at[j] == n) continue;
    for (CsrMatrix::InnerIterator e(P, static_cast<Eigen::Index>(j)); e; ++e) {
      const auto c = static_cast<std::size_t>(e.col());
      if (at[c] == n || e.value() == 0.0) continue;
      const double a = 0.5 * std::sqrt(mu[c] / mu[j]) * e.value();
      trip.emplace_back(static_cast<int>(at[c]), static_cast<int>(at[j]), a);
      trip.emplace_back(static_cast<int>(at[j]), static_cast<int>(at[c]), a);
    }
  }
  Eigen::SparseMatrix<double> S(static_cast<Eigen::Index>(s), static_cast<Eigen::Index>(s));
  S.setFromTriplets(trip.begin(), trip.end());
  S.makeCompressed();
  // Per component of S's graph, its leading eigenpairs. Shift-invert about σ = 1 + kShift above
  // kDenseComponent nodes: σ lies above every eigenvalue (S is similar to a (sub)stochastic
  // chain), and the eigenvalues near 1 that almost-invariant sets make, which cluster within
  // 1e-5 of each other on a diffusive operator (plain Lanczos stalls there), map to the well
  // separated 1/(λ − σ).
  const ComponentEigenPairs pairs =
      largest_eigenpairs_by_component(S, static_cast<Eigen::Index>(k), 1.0 + kShift, tol,
                                      static_cast<Eigen::Index>(kDenseComponent));
  out.components = pairs.members.size();
  out.converged = pairs.converged;
  for (const double lambda : pairs.values)
    if (lambda > 1.0 - kOpenSystem) ++out.invariant_pieces;
  if (pairs.values.size() < k)
    throw std::invalid_argument("almost-invariant sets: the eigen-solver found " +
                                std::to_string(pairs.values.size()) +
                                " eigenvalue(s), fewer than " + std::to_string(K));
  // The eigenfunctions φ = ψ/√μ on the support, K columns.
  Eigen::MatrixXd phi =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(s), static_cast<Eigen::Index>(k));
  for (std::size_t q = 0; q < k; ++q) {
    const std::vector<std::size_t>& m = pairs.members[pairs.component[q]];
    for (std::size_t i = 0; i < m.size(); ++i)
      phi(static_cast<Eigen::Index>(m[i]), static_cast<Eigen::Index>(q)) =
          pairs.vectors[q](static_cast<Eigen::Index>(i)) / std::sqrt(mu[node[m[i]]]);
    out.eigenvalues.push_back(pairs.values[q]);
    out.bound += pairs.values[q];
  }
  const detail::Seba basis = detail::seba(phi);
  out.seba_iterations = basis.iterations;
  // Each node of the support to the rotated vector largest at it (each of maximum 1).
  std::vector<std::int32_t> raw(s, 0);
  for (std::size_t i = 0; i < s; ++i) {
    Eigen::Index best = 0;
    basis.rotated.row(static_cast<Eigen::Index>(i)).maxCoeff(&best);
    raw[i] = static_cast<std::int32_t>(best) + 1;
  }
  // Masses, then the sets in order of decreasing mass (ties: the first node).
  std::vector<double> mass(k, 0.0);
  std::vector<std::size_t> first(k, n);
  for (std::size_t i = 0; i < s; ++i)
    if (raw[i] > 0) {
      const auto q = static_cast<std::size_t>(raw[i] - 1);
      mass[q] += mu[node[i]];
      first[q] = std::min(first[q], i);
    }
  const std::vector<std::int32_t> rank = detail::rank_by_mass(mass, first);
  for (std::size_t i = 0; i < s; ++i)
    if (raw[i] > 0) out.label[node[i]] = rank[static_cast<std::size_t>(raw[i] - 1)];
  // Each set's mass, modes and ratio Σ_{c∈A} Σ_{j∈A} P_jc μ_c / μ(A).
  const std::size_t per_mode = n / std::max<std::size_t>(n_mode, 1);
  out.sets.assign(k, {});
  for (AlmostInvariantSet& a : out.sets) a.mode_mass.assign(std::max<std::size_t>(n_mode, 1), 0.0);
  std::vector<double> stay(k, 0.0);
  double total = 0.0;
  for (std::size_t j = 0; j < n; ++j) {
    total += std::max(mu[j], 0.0);
    const std::int32_t a = out.label[j];
    if (a == 0) continue;
    AlmostInvariantSet& set = out.sets[static_cast<std::size_t>(a - 1)];
    set.mass += mu[j];
    set.nodes += 1;
    set.mode_mass[per_mode > 0 ? j / per_mode : 0] += mu[j];
    for (CsrMatrix::InnerIterator e(P, static_cast<Eigen::Index>(j)); e; ++e)
      if (out.label[static_cast<std::size_t>(e.col())] == a)
        stay[static_cast<std::size_t>(a - 1)] += e.value() * mu[static_cast<std::size_t>(e.col())];
  }
  double assigned = 0.0;
  for (std::size_t q = 0; q < k; ++q) {
    out.sets[q].ratio = out.sets[q].mass > 0.0 ? stay[q] / out.sets[q].mass : 0.0;
    assigned += out.sets[q].mass;
  }
  out.unassigned = std::max(total - assigned, 0.0);
  return out;
}

}  // namespace hybgen::rt

HYBGEN_EIGEN_WARNINGS_POP
