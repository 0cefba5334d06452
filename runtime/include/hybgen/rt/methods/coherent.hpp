#pragma once
/// \file coherent.hpp
/// Finite-time coherent sets: K pairs of regions of state × mode, A_k at the initial time and
/// B_k at the final one, such that the mass in A_k is carried into B_k and the mass in B_k came
/// from A_k, both with the highest probability; what stays together over a finite time while
/// it moves, where almost-invariant sets (almost_invariant.hpp) are what stays in place.
///
/// The quantities. F moves node masses over the time interval: mass F_ji·p_i of the initial
/// masses p goes from node i to node j, and q = F p are the final masses (Σ q ≤ Σ p when mass
/// leaves the box). For A at the initial time and B at the final one, the mass carried is
///     T(A, B) = Σ_{i∈A} Σ_{j∈B} F_ji p_i,
/// and the pair's forward ratio T/p(A) is the probability that mass in A ends in B, its
/// backward ratio T/q(B) the probability that mass in B came from A. A pair carried exactly
/// (no mass leaks out of A or into B) has both 1.
///
/// The sets (Froyland, Santitissadeekorn, Monahan, "Transport in time-dependent dynamical
/// systems: finite-time coherent sets", Chaos 20 (2010); Froyland, "An analytic framework for
/// identifying finite-time coherent sets in time-dependent dynamical systems", Physica D 250
/// (2013)). The normalised operator L_ji = F_ji √p_i / √q_j maps √p to √q, so its largest
/// singular value is 1 for a closed system. In these coordinates the indicators
/// x_k = 1_{A_k}√p/√p(A_k) and y_k = 1_{B_k}√q/√q(B_k) of disjoint sets are orthonormal, and
///     y_kᵀ L x_k = T(A_k, B_k)/√(p(A_k) q(B_k)) = √(forward · backward),
/// so (von Neumann's trace inequality) Σ_k √(forward_k · backward_k) ≤ σ₁ + … + σ_K = `bound`:
/// the sum `coherence_sum` of the pairs found is compared with it. The singular vectors give
/// the sets: the right ones v_k of L (eigenvectors of Lᵀ L, on the initial nodes) and the left
/// ones u_k = L v_k/σ_k (on the final nodes), as functions φ_k = v_k/√p and ψ_k = u_k/√q. SEBA
/// (almost_invariant.hpp) rotates the stacked columns [φ_k; ψ_k] by one rotation, so that the
/// k-th rotated vector is the k-th pair at both times, and each node goes to the rotated vector
/// largest at it (at the initial time by the φ rows, at the final time by the ψ rows).
///
/// Exactly coherent pieces. Where the initial nodes fall into pieces whose images never
/// overlap, Lᵀ L is block diagonal and σ = 1 is repeated: the pieces are solved apart
/// (largest_eigenpairs_by_component, numerics/eigen_solvers.hpp), as for almost-invariant sets.
///
/// Nodes whose initial (final) mass is below kMassFloor of the largest belong to no set at
/// that time. The implementation is compiled once, in runtime/src/numerics/coherent.cpp.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "hybgen/rt/core/sparse.hpp"

namespace hybgen::rt {

/// One coherent pair: A at the initial time, B at the final one.
struct CoherentPair {
  double initial_mass = 0.0;      ///< p(A).
  double final_mass = 0.0;        ///< q(B).
  double carried = 0.0;           ///< T(A, B): the mass of A that is in B at the final time.
  double forward = 0.0;           ///< T/p(A): the probability that mass in A ends in B.
  double backward = 0.0;          ///< T/q(B): the probability that mass in B came from A.
  std::size_t initial_nodes = 0;  ///< A's (mode, node) entries.
  std::size_t final_nodes = 0;    ///< B's (mode, node) entries.
  std::vector<double> initial_mode_mass;  ///< p(A) in each mode.
  std::vector<double> final_mode_mass;    ///< q(B) in each mode.
};

/// K coherent pairs of a transport over a time interval (see the file comment).
struct CoherentSets {
  /// Per initial (mode, node) entry, layout [mode][node]: the pair whose A holds it, 1 … K, or 0.
  std::vector<std::int32_t> initial_label;
  /// Per final (mode, node) entry: the pair whose B holds it, 1 … K, or 0.
  std::vector<std::int32_t> final_label;
  std::vector<CoherentPair> sets;       ///< Pair k + 1 is sets[k]; by decreasing p(A).
  std::vector<double> singular_values;  ///< The K largest singular values of L (the first ≤ 1).
  double bound = 0.0;          ///< Σ of `singular_values`: Σ_k √(forward·backward) ≤ bound.
  double coherence_sum = 0.0;  ///< Σ_k √(forward_k · backward_k) of the pairs found.
  std::size_t components = 0;  ///< Pieces of the initial support whose images never overlap.
  bool converged = true;       ///< Whether every eigen-solve met its tolerance.
  long seba_iterations = 0;    ///< SEBA's iterations.
};

/// K coherent pairs of the transport `F` (CSR, rows the final nodes, columns the initial ones:
/// q = F p on node masses; square, the same nodes at both times) from the initial masses `p`
/// (≥ 0, not all 0), node entries in `n_mode` blocks of equal size. Throws
/// std::invalid_argument when K < 2, the sizes disagree, or either support has fewer than
/// K + 1 nodes.
CoherentSets coherent_sets(const CsrMatrix& F, std::span<const double> p, int K, std::size_t n_mode,
                           double tol = 1e-10);

}  // namespace hybgen::rt
