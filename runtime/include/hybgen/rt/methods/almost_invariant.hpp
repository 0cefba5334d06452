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
///
/// The implementation is compiled once, in runtime/src/numerics/almost_invariant.cpp.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "hybgen/rt/core/sparse.hpp"

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
Seba seba(const Eigen::MatrixXd& V);

}  // namespace detail

/// K almost-invariant sets of the operator whose matrix is `P` (CSR, rows the destinations:
/// M' = P M on node masses), with invariant masses `mu` (Σ = 1, ≥ 0 up to rounding), node
/// entries in `n_mode` blocks of equal size (see the file comment). Throws
/// std::invalid_argument when K < 2 or the support has fewer than K + 1 nodes.
AlmostInvariantSets almost_invariant_sets(const CsrMatrix& P, std::span<const double> mu, int K,
                                          std::size_t n_mode, double tol = 1e-10);

}  // namespace hybgen::rt
