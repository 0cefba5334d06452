#pragma once
/// \file mpi_backend.hpp
/// The MPI implementation of hybgen::rt::Backend (core/backend.hpp) over MPI_COMM_WORLD.
/// Sums of doubles are formed in rank order from every rank's values (an allgather), so
/// they are the same bits on every rank, which then take the same decisions; integers are
/// summed by MPI (exact).

#include <mpi.h>

#include "hybgen/rt/core/backend.hpp"

namespace hybgen::rt::mpi {

/// The ranks of MPI_COMM_WORLD (MPI must be initialised for the object's lifetime).
class MpiBackend final : public Backend {
 public:
  /// Read the rank, the size and the ranks on this machine.
  MpiBackend();
  /// "mpi".
  [[nodiscard]] std::string_view name() const override { return "mpi"; }
  /// MPI rank.
  [[nodiscard]] int rank() const override { return rank_; }
  /// MPI size.
  [[nodiscard]] int ranks() const override { return size_; }
  /// Ranks sharing this machine's memory (MPI_COMM_TYPE_SHARED).
  [[nodiscard]] int ranks_here() const override { return here_; }
  using Backend::max;
  using Backend::min;
  using Backend::sum;
  /// MPI_Allreduce, MPI_SUM over int64.
  void sum(std::span<std::int64_t> v) const override;
  /// Every rank's values summed in rank order, on every rank.
  void sum(std::span<double> v) const override;
  /// MPI_Reduce, MPI_SUM over int64, into rank 0.
  void sum_to_root(std::span<std::int64_t> v) const override;
  /// MPI_Allreduce, MPI_SUM over double (exact: one non-zero per element).
  void sum_disjoint(std::span<double> v) const override;
  /// MPI_Reduce, MPI_SUM over double, into rank 0.
  void sum_to_root(std::span<double> v) const override;
  /// MPI_Allreduce, MPI_MAX.
  void max(std::span<double> v) const override;
  /// MPI_Allreduce, MPI_MIN over int64.
  void min(std::span<std::int64_t> v) const override;
  /// MPI_Allgatherv in rank order.
  [[nodiscard]] std::vector<double> all_gather(std::span<const double> part) const override;
  /// MPI_Gatherv in rank order, on rank 0.
  [[nodiscard]] std::vector<double> gather(std::span<const double> part) const override;
  /// MPI_Bcast.
  void broadcast(std::span<std::byte> bytes, int from) const override;
  /// Length, then bytes.
  [[nodiscard]] std::string broadcast(const std::string& s, int from) const override;
  /// A PETSc matrix (petsc_matrix.hpp).
  [[nodiscard]] std::unique_ptr<DistributedMatrix> matrix(OperatorEntries part) const override;
  /// MPI_Reduce_scatter, MPI_SUM over int64, by block_of.
  [[nodiscard]] std::vector<std::int64_t> sum_to_blocks(
      std::span<const std::int64_t> v) const override;
  /// Every rank's ranges, then one MPI_Alltoallv of the pieces to their blocks' owners.
  [[nodiscard]] std::vector<double> sum_to_blocks(std::span<const double> values,
                                                  std::size_t offset, std::size_t n) const override;
  /// The largest gather or all_gather received from the other ranks.
  [[nodiscard]] std::size_t gathered_values() const override { return gathered_; }
  /// NetCDF-4 over MPI-IO (parallel_io.cpp).
  [[nodiscard]] const ParallelIo* parallel_io() const override;

 private:
  /// Every rank's count, on every rank.
  [[nodiscard]] std::vector<std::size_t> counts(std::size_t mine) const;
  int rank_ = 0, size_ = 1, here_ = 1;
  mutable std::size_t gathered_ = 0;  ///< gathered_values(): the largest gather received.
};

/// The MPI implementation of ParallelIo (parallel_io.cpp): parallel NetCDF on
/// MPI_COMM_WORLD.
const ParallelIo& parallel_netcdf();

}  // namespace hybgen::rt::mpi
