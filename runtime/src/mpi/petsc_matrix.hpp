#pragma once
/// \file petsc_matrix.hpp
/// A transfer operator as a PETSc matrix (MATAIJ over MPI_COMM_WORLD), its rows distributed
/// by the blocks of core/backend.hpp, and its spectrum by SLEPc.
///
/// Assembly: each rank holds the entries of the columns it assembled, in its threads' lists
/// (OperatorEntries). In each list the entries of its own rows are moved to the front (in
/// place); only the others' (the ghost rows near the block's ends) are packed and sent, in
/// one MPI_Alltoallv. Each rank then writes its rows straight into the two CSR blocks PETSc
/// keeps (the columns it owns, and the others), counted exactly, columns sorted, and frees
/// the lists chunk by chunk; PETSc takes those arrays as they are
/// (MatCreateMPIAIJWithSplitArrays), so the matrix is never copied. Peak per rank: the
/// entries (16 bytes each) overlapping the split arrays (12 bytes each) as they are written,
/// and 16 + 16 bytes more for each entry of another rank's rows (sent, and received by that
/// rank): 37 bytes per entry measured for gl2 at 11^5 on 2 ranks, against 12-14 for the
/// finished matrix (a run's peak resident size: bench/mpi_scaling.sh, docs/distributed.md).
///
/// Spectrum: SLEPc's EPS on the matrix, non-Hermitian, largest magnitude, start vector all
/// ones (as Spectra's in invariant.hpp), then EPSSetFromOptions, so that -eps_type,
/// -eps_ncv, -eps_tol, … on the command line or in $PETSC_OPTIONS override the defaults.

#include <petscmat.h>

#include <vector>

#include "hybgen/rt/core/backend.hpp"

namespace hybgen::rt::mpi {

/// A distributed transfer operator (collective construction).
class PetscMatrix final : public DistributedMatrix {
 public:
  /// Assemble from every rank's columns (collective; throws std::runtime_error on a PETSc
  /// error and std::length_error beyond PETSc's 32-bit indices).
  explicit PetscMatrix(OperatorEntries part);
  /// Frees the matrix and its work vectors.
  ~PetscMatrix() override;
  PetscMatrix(const PetscMatrix&) = delete;             ///< One owner.
  PetscMatrix& operator=(const PetscMatrix&) = delete;  ///< One owner.
  /// y = P x on the owned entries (MatMult; collective).
  void multiply(std::span<const double> x, std::span<double> y) override;
  /// MatGetInfo, global sum of the non-zeros used.
  [[nodiscard]] std::size_t nonzeros() const override;
  /// This rank's rows (values, column indices, row pointers) and ghost buffers.
  [[nodiscard]] std::size_t local_bytes() const override;
  /// The columns of the off-diagonal block (MatMPIAIJGetSeqAIJ).
  [[nodiscard]] std::size_t ghost_entries() const override;
  /// SLEPc's leading eigenpairs (collective).
  EigenAnswer eigen(const EigenRequest& request) override;

 private:
  /// This rank's rows from every rank's entries into the split arrays below (collective).
  void assemble_rows(OperatorEntries& part, int ranks);
  Mat a_ = nullptr;
  Vec x_ = nullptr, y_ = nullptr;  // views of the caller's arrays during multiply
  Block owned_{};
  // The owned rows as PETSc uses them (it does not copy them): the diagonal block (row
  // pointers, local columns, values) and the off-diagonal one (global columns). Declared
  // before nothing that outlives them: the destructor frees the matrix first.
  std::vector<PetscInt> di_, dj_, oi_, oj_;
  std::vector<PetscScalar> da_, oa_;
};

}  // namespace hybgen::rt::mpi
