#pragma once
/// \file petsc_matrix.hpp
/// A transfer operator as a PETSc matrix (MATAIJ over MPI_COMM_WORLD), its rows distributed
/// by the blocks of core/backend.hpp, and its spectrum by SLEPc.
///
/// Assembly: each rank holds the columns it assembled (OperatorColumns). Every entry goes to
/// the rank that owns its row in one MPI_Alltoallv; each rank compresses its rows (CSR, the
/// columns of a row sorted) and PETSc builds the matrix from them
/// (MatCreateMPIAIJWithArrays), counting the entries of every row as it copies them: the
/// preallocation is exact, nothing is guessed and nothing is inserted one by one. The
/// columns are freed once packed and the packed entries once sent: the peak per rank is
/// about 28 bytes per entry (measured as a run's peak resident size: bench/mpi_scaling.sh).
///
/// Spectrum: SLEPc's EPS on the matrix, non-Hermitian, largest magnitude, start vector all
/// ones (as Spectra's in invariant.hpp), then EPSSetFromOptions, so that -eps_type,
/// -eps_ncv, -eps_tol, … on the command line or in $PETSC_OPTIONS override the defaults.

#include <petscmat.h>

#include "hybgen/rt/core/backend.hpp"

namespace hybgen::rt::mpi {

/// A distributed transfer operator (collective construction).
class PetscMatrix final : public DistributedMatrix {
 public:
  /// Assemble from every rank's columns (collective; throws std::runtime_error on a PETSc
  /// error and std::length_error beyond PETSc's 32-bit indices).
  explicit PetscMatrix(OperatorColumns part);
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
  Mat a_ = nullptr;
  Vec x_ = nullptr, y_ = nullptr;  // views of the caller's arrays during multiply
  Block owned_{};
};

}  // namespace hybgen::rt::mpi
