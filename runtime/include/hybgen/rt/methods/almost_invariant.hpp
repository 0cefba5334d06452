#pragma once
/// \file almost_invariant.hpp
/// Almost-invariant sets of a closed system from its transfer operator (transfer.hpp) and
/// invariant masses (invariant.hpp): K regions of state × mode whose mass stays in them over
/// one step with the highest probability.
///
/// The quantities. P moves node masses one step h: M' = P M, so mass P_jc·μ_c goes from node
/// c to node j, and the invariant masses μ (P μ = μ, Σ μ = 1) weight the nodes. The
/// invariance ratio of a set A of nodes is the probability that invariant mass in A is still
/// in A one step later,
///     ρ(A) = μ(A ∩ P⁻¹A)/μ(A) = Σ_{c∈A} Σ_{j∈A} P_jc μ_c / Σ_{c∈A} μ_c ∈ [0, 1],
/// 1 for an invariant set. Over n steps the mass in A that stays is about ρ(A)ⁿ of it, so
/// −ln ρ(A)/h is the rate at which mass leaves A per unit time.
///
/// The sets (Froyland, "Statistically optimal almost-invariant sets", Physica D 200 (2005)).
/// P is not self-adjoint, and a flow's rotations give it complex eigenvalues whose vectors
/// have no sign structure. Its reversibilisation does: with the transition probabilities
/// T_cj = P_jc (row c: where the mass of c goes) and their time reversal with respect to μ,
/// T̂_cj = μ_j T_jc / μ_c, R = (T + T̂)/2 is a Markov chain reversible with respect to μ, and
/// for every set ρ_R(A) = ρ_T(A) (Σ_{A×A} μ_c T̂_cj = Σ_{A×A} μ_j T_jc). R is self-adjoint in
/// L²(μ); S = D^{1/2} R D^{−1/2} (D = diag μ) is the symmetric matrix
///     S_cj = (√(μ_c/μ_j) T_cj + √(μ_j/μ_c) T_jc) / 2,
/// with real eigenvalues 1 = λ₁ ≥ λ₂ ≥ … ≥ −1 and orthonormal eigenvectors ψ_k; the functions
/// φ_k = ψ_k/√μ are R's eigenfunctions. For any K disjoint sets, the indicators 1_{A_k}/√μ(A_k)
/// are orthonormal in L²(μ) and ρ(A_k) = ⟨1_{A_k}, R 1_{A_k}⟩_μ/μ(A_k), so (Ky Fan)
///     Σ_k ρ(A_k) ≤ λ₁ + … + λ_K = `bound`:
/// the sum of the ratios of the sets found is compared with it (how near the best K sets they
/// are). The sets come from the K leading eigenfunctions by SEBA (Froyland, Rock, Sakellariou,
/// "Sparse eigenbasis approximation", CNSNS 77 (2019)): the rotation of their span whose
/// soft-thresholded vectors are sparsest. Each node of the support belongs to the rotated
/// eigenfunction (before the thresholding, each scaled to a maximum of 1) that is largest at
/// it: a partition of the support, which leaves no node of a rotation's transition zone
/// unassigned (the thresholded vectors are 0 there). For K = 2 this is the sign structure of
/// φ₂ shifted by the rotation (φ₁ is constant).
///
/// Exactly invariant pieces. Where the support falls into pieces between which no mass moves
/// in either direction (two cycles), S is block diagonal and λ = 1 is repeated; a Krylov
/// solver started from one vector finds one vector of that eigenspace only. So the nodes are
/// first split into the connected components of S's graph, each solved on its own (Spectra's
/// Lanczos in shift-invert mode, or a dense solver below kDenseComponent nodes), and the K largest
/// eigenvalues taken over all of them, each vector zero outside its component.
///
/// Nodes whose invariant mass is below kMassFloor of the largest carry no invariant mass
/// (transients): they belong to no set.

// See transfer.hpp: GCC 12's flow-sensitive warnings misfire inside Eigen/Spectra.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 12
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuse-after-free"
#endif
#include <Spectra/MatOp/SparseSymShiftSolve.h>
#include <Spectra/SymEigsShiftSolver.h>
#include <Eigen/Dense>
#include <Eigen/Sparse>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace hybgen::rt {

/// Nodes with invariant mass below this fraction of the largest belong to no set.
inline constexpr double kMassFloor = 1e-10;
/// The shift-invert solver's σ − 1 (see almost_invariant_sets).
inline constexpr double kShift = 1e-3;
/// Components of S's graph with fewer nodes are solved by a dense eigen-solver.
inline constexpr std::size_t kDenseComponent = 400;
/// A transfer operator whose leading eigenvalue is below 1 − kOpenSystem loses mass: the
/// system has no invariant density to split (a closed one's is 1 to the solver's tolerance,
/// 1e-10: its columns sum to 1).
inline constexpr double kOpenSystem = 1e-8;
/// The factor on the difference of a set's mass or ratio from its counterpart's on the halved
/// grid: the escape rate's (escape.hpp), for a first-order scheme.
inline constexpr double kAlmostInvariantErrorFactor = 2.0;

/// One almost-invariant set.
struct AlmostInvariantSet {
  double mass = 0.0;              ///< μ(A): its invariant mass (of unit total).
  double ratio = 0.0;             ///< ρ(A) = μ(A ∩ P⁻¹A)/μ(A) over one step.
  std::size_t nodes = 0;          ///< Its (mode, node) entries.
  std::vector<double> mode_mass;  ///< μ(A) in each mode.
};

/// K almost-invariant sets of a transfer operator (see the file comment).
struct AlmostInvariantSets {
  /// Per (mode, node) entry, layout [mode][node]: the set it belongs to, 1 … K, or 0.
  std::vector<std::int32_t> label;
  std::vector<AlmostInvariantSet> sets;  ///< Set k + 1 is sets[k]; by decreasing mass.
  /// The K largest eigenvalues of the reversibilised chain (the first is 1).
  std::vector<double> eigenvalues;
  double bound = 0.0;          ///< Σ of `eigenvalues`: Σ_k ρ(A_k) ≤ bound.
  double unassigned = 0.0;     ///< Invariant mass in no set (label 0).
  std::size_t components = 0;  ///< Pieces of the support between which no mass moves.
  /// Those of them that are invariant (their chain's leading eigenvalue 1 to kOpenSystem):
  /// more than one, and the invariant density is not unique.
  std::size_t invariant_pieces = 0;
  bool converged = true;     ///< Whether every eigen-solve met its tolerance.
  long seba_iterations = 0;  ///< SEBA's iterations.
};

namespace detail {

/// What SEBA (see the file comment) makes of a basis, its columns sorted by decreasing minimum
/// of `sparse` (the most reliable first).
struct Seba {
  Eigen::MatrixXd sparse;   ///< The sparse vectors, each of maximum 1.
  Eigen::MatrixXd rotated;  ///< The rotated basis V Rᵀ before thresholding, each of maximum 1.
  long iterations = 0;      ///< Iterations taken.
};

/// SEBA on the columns of V (orthonormalised first).
inline Seba seba(const Eigen::MatrixXd& V_in) {
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

/// Connected components of the graph of the symmetric sparse S: component index per row.
inline std::vector<std::size_t> components(const Eigen::SparseMatrix<double>& S,
                                           std::size_t* count) {
  const auto n = static_cast<std::size_t>(S.rows());
  std::vector<std::size_t> comp(n, n);
  std::vector<std::size_t> stack;
  std::size_t c = 0;
  for (std::size_t s = 0; s < n; ++s) {
    if (comp[s] != n) continue;
    comp[s] = c;
    stack.push_back(s);
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      for (Eigen::SparseMatrix<double>::InnerIterator e(S, static_cast<Eigen::Index>(i)); e; ++e) {
        const auto j = static_cast<std::size_t>(e.row());
        if (comp[j] == n && e.value() != 0.0) comp[j] = c, stack.push_back(j);
      }
    }
    ++c;
  }
  *count = c;
  return comp;
}

}  // namespace detail

/// K almost-invariant sets of the operator whose matrix is `P` (CSR, rows the destinations:
/// M' = P M on node masses), with invariant masses `mu` (Σ = 1, ≥ 0 up to rounding), node
/// entries in `n_mode` blocks of equal size (see the file comment). Throws
/// std::invalid_argument when K < 2 or the support has fewer than K + 1 nodes.
template <class Csr>
AlmostInvariantSets almost_invariant_sets(const Csr& P, std::span<const double> mu, int K,
                                          std::size_t n_mode, double tol = 1e-10) {
  const auto n = static_cast<std::size_t>(P.rows());
  if (K < 2) throw std::invalid_argument("almost-invariant sets: sets must be at least 2");
  if (mu.size() != n) throw std::invalid_argument("almost-invariant sets: mu has the wrong size");
  AlmostInvariantSets out;
  out.label.assign(n, 0);
  // The support: nodes with invariant mass; index in it per node (n: none).
  double top = 0.0;
  for (const double m : mu) top = std::max(top, m);
  std::vector<std::size_t> at(n, n), node;
  for (std::size_t i = 0; i < n; ++i)
    if (mu[i] > kMassFloor * top) at[i] = node.size(), node.push_back(i);
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
    for (typename Csr::InnerIterator e(P, static_cast<Eigen::Index>(j)); e; ++e) {
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
  // Per component, its leading eigenpairs.
  std::vector<std::size_t> comp = detail::components(S, &out.components);
  std::vector<std::vector<std::size_t>> members(out.components);
  for (std::size_t i = 0; i < s; ++i) members[comp[i]].push_back(i);
  struct Pair {
    double lambda;
    std::size_t component;
    Eigen::VectorXd vector;  // on the component's members
  };
  std::vector<Pair> pairs;
  for (std::size_t c = 0; c < out.components; ++c) {
    const std::vector<std::size_t>& m = members[c];
    const auto size = static_cast<Eigen::Index>(m.size());
    std::vector<std::size_t> local(s, s);
    for (std::size_t i = 0; i < m.size(); ++i) local[m[i]] = i;
    std::vector<Eigen::Triplet<double>> t;
    for (const std::size_t i : m)
      for (Eigen::SparseMatrix<double>::InnerIterator e(S, static_cast<Eigen::Index>(i)); e; ++e)
        t.emplace_back(static_cast<int>(local[static_cast<std::size_t>(e.row())]),
                       static_cast<int>(local[i]), e.value());
    Eigen::SparseMatrix<double> Sc(size, size);
    Sc.setFromTriplets(t.begin(), t.end());
    const Eigen::Index want = std::min<Eigen::Index>(static_cast<Eigen::Index>(k), size);
    if (m.size() < kDenseComponent || size <= 2 * want + 1) {
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es{Eigen::MatrixXd(Sc)};
      for (Eigen::Index q = 0; q < want; ++q)
        pairs.push_back({es.eigenvalues()(size - 1 - q), c, es.eigenvectors().col(size - 1 - q)});
    } else {
      // Shift-invert about σ = 1 + kShift, above every eigenvalue (S is similar to a
      // (sub)stochastic chain): the eigenvalues near 1 that almost-invariant sets make, which
      // cluster within 1e-5 of each other on a diffusive operator (Lanczos stalls there), map
      // to the well separated 1/(λ − σ).
      Spectra::SparseSymShiftSolve<double> op(Sc);
      const Eigen::Index ncv = std::min<Eigen::Index>(size, std::max<Eigen::Index>(4 * want, 20));
      Spectra::SymEigsShiftSolver<Spectra::SparseSymShiftSolve<double>> eigs(op, want, ncv,
                                                                             1.0 + kShift);
      const Eigen::VectorXd start = Eigen::VectorXd::Ones(size);
      eigs.init(start.data());
      eigs.compute(Spectra::SortRule::LargestMagn, 1000, tol, Spectra::SortRule::LargestAlge);
      if (eigs.info() != Spectra::CompInfo::Successful) {
        out.converged = false;
        continue;
      }
      for (Eigen::Index q = 0; q < want; ++q)
        pairs.push_back({eigs.eigenvalues()(q), c, eigs.eigenvectors().col(q)});
    }
  }
  for (const Pair& p : pairs)
    if (p.lambda > 1.0 - kOpenSystem) ++out.invariant_pieces;
  if (pairs.size() < k)
    throw std::invalid_argument("almost-invariant sets: the eigen-solver found " +
                                std::to_string(pairs.size()) + " eigenvalue(s), fewer than " +
                                std::to_string(K));
  std::stable_sort(pairs.begin(), pairs.end(),
                   [](const Pair& a, const Pair& b) { return a.lambda > b.lambda; });
  // The eigenfunctions φ = ψ/√μ on the support, K columns.
  Eigen::MatrixXd phi =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(s), static_cast<Eigen::Index>(k));
  for (std::size_t q = 0; q < k; ++q) {
    const std::vector<std::size_t>& m = members[pairs[q].component];
    for (std::size_t i = 0; i < m.size(); ++i)
      phi(static_cast<Eigen::Index>(m[i]), static_cast<Eigen::Index>(q)) =
          pairs[q].vector(static_cast<Eigen::Index>(i)) / std::sqrt(mu[node[m[i]]]);
    out.eigenvalues.push_back(pairs[q].lambda);
    out.bound += pairs[q].lambda;
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
  std::vector<std::size_t> order(k);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return mass[a] != mass[b] ? mass[a] > mass[b] : first[a] < first[b];
  });
  std::vector<std::int32_t> rank(k);
  for (std::size_t q = 0; q < k; ++q) rank[order[q]] = static_cast<std::int32_t>(q) + 1;
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
    for (typename Csr::InnerIterator e(P, static_cast<Eigen::Index>(j)); e; ++e)
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
