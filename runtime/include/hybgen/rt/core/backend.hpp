#pragma once
/// \file backend.hpp
/// The processes a run is spread over, and every operation across them: the one place the
/// methods meet MPI. The methods are templates over the generated model and never include
/// MPI, PETSc or SLEPc; they take a `Backend` and call it where ranks must agree. So the
/// runtime library is compiled once for both backends, and a runner built with
/// `--set backend=mpi` differs only in its entry point and in linking hybgen::mpi
/// (runtime/src/mpi/, the MPI/PETSc/SLEPc implementation of this interface).
///
///  - `SerialBackend` (here): one rank, every collective the identity. The default.
///  - `mpi_backend()` (hybgen/rt/mpi.hpp): MPI_COMM_WORLD, PETSc matrices, SLEPc spectra.
///
/// Work is split by `block_of`: rank r of R owns the items [⌊r·n/R⌋-ish, …) of a list of n
/// (the first n mod R ranks one more); the same partition on every rank, for the particles
/// (their indices), the characteristics (their (mode, node) pairs and cubature points) and
/// the transfer operator (its columns and rows). Sums of integers across ranks are exact,
/// so what a method accumulates in integers (the particles' deposit) is bit-identical for
/// any number of ranks; per-point values computed independently of their neighbours (a
/// characteristic) are too.

#include <algorithm>
#include <complex>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace hybgen::rt {

/// A half-open range [begin, end) of item indices.
struct Block {
  std::size_t begin = 0;  ///< First item.
  std::size_t end = 0;    ///< One past the last item.
  /// Number of items.
  [[nodiscard]] std::size_t size() const { return end - begin; }
};

/// The block of `n` items that rank `rank` of `ranks` owns: n/ranks items each, the first
/// n mod ranks ranks one more. The blocks tile [0, n) in rank order.
inline Block block_of(std::size_t n, int rank, int ranks) {
  const auto R = static_cast<std::size_t>(std::max(ranks, 1));
  const auto r = static_cast<std::size_t>(std::clamp(rank, 0, static_cast<int>(R) - 1));
  const std::size_t q = n / R, rem = n % R;
  const std::size_t begin = r * q + std::min(r, rem);
  return {begin, begin + q + (r < rem ? 1 : 0)};
}

/// One entry of a transfer operator: P_row,col = value (16 bytes; int32 indices, as the CSR
/// matrix's and PETSc's).
struct OperatorEntry {
  std::int32_t row = 0;  ///< Target state (row).
  std::int32_t col = 0;  ///< Source state (column).
  double value = 0.0;    ///< P_row,col.
};

/// One rank's share of a transfer operator P (R × R, on node masses; transfer.hpp): the
/// entries of the columns it assembled, in lists (one per assembling thread, each in any
/// order), handed over as they were made so that no copy of them all is ever needed. Those
/// columns' indices are also the rows and vector entries the rank owns; an entry's row may
/// be any rank's.
struct OperatorEntries {
  std::size_t size = 0;                           ///< R.
  Block owned;                                    ///< Its columns, rows, vector entries.
  std::vector<std::vector<OperatorEntry>> lists;  ///< Every entry of its columns.
};

/// What `DistributedMatrix::eigen` computes: the leading eigenvalues by magnitude and the
/// eigenvector of one real eigenvalue.
struct EigenRequest {
  int n_eigen = 6;             ///< Eigenvalues wanted.
  int ncv = 0;                 ///< Krylov subspace size (0: the solver's default).
  double tol = 1e-10;          ///< Relative residual tolerance.
  int max_iterations = 10000;  ///< Restart cap.
};

/// The eigen-solver's answer (invariant.hpp turns it into the invariant density).
struct EigenAnswer {
  std::vector<std::complex<double>> eigenvalues;  ///< Converged, by decreasing magnitude.
  /// The owned entries of the eigenvector of eigenvalues[lead] (real).
  std::vector<double> vector;
  int lead = -1;           ///< Index of the Perron root in `eigenvalues` (−1: none found).
  long iterations = 0;     ///< Solver iterations.
  bool converged = false;  ///< Whether n_eigen pairs met the tolerance.
  std::string solver;      ///< Which solver ("slepc krylovschur", …).
};

/// The Perron root among `eigenvalues`: the real (|Im λ| ≤ 1e-8·|λ|), non-negative one of
/// largest real part; −1 if there is none. Ties in magnitude (a rotation's e^{±iθ}) never
/// beat it. Used on Spectra's answer (invariant.hpp) and on SLEPc's (runtime/src/mpi/).
inline int perron_index(std::span<const std::complex<double>> eigenvalues) {
  int lead = -1;
  for (std::size_t j = 0; j < eigenvalues.size(); ++j) {
    const std::complex<double> l = eigenvalues[j];
    const double scale = std::max(std::abs(l), 1e-300);
    if (std::abs(l.imag()) <= 1e-8 * scale && l.real() >= 0.0 &&
        (lead < 0 || l.real() > eigenvalues[static_cast<std::size_t>(lead)].real()))
      lead = static_cast<int>(j);
  }
  return lead;
}

/// How the ranks of a run write one file together: NetCDF-4 through parallel HDF5 (MPI-IO).
/// The writers (runtime/src/io/netcdf.cpp) call it through `Backend::parallel_io`; the MPI
/// backend implements it (runtime/src/mpi/parallel_io.cpp) with Debian's parallel NetCDF,
/// which an MPI runner links instead of the serial one (generator/src/build.cpp).
class ParallelIo {
 public:
  virtual ~ParallelIo() = default;
  /// Open the existing NetCDF-4 file `path` for writing on every rank (collective);
  /// returns NetCDF's status, the file's id in `ncid`.
  virtual int open_netcdf(const char* path, int* ncid) const = 0;
  /// Make the writes of variable `var` collective (every rank calls each write, with a
  /// count of zero when it has nothing): what parallel HDF5 needs of compressed variables.
  virtual int collective(int ncid, int var) const = 0;
};

/// A distributed sparse matrix over block-partitioned vectors (owned by the backend).
class DistributedMatrix {
 public:
  virtual ~DistributedMatrix() = default;
  /// y = P x on the owned entries (x and y of length owned.size(); collective).
  virtual void multiply(std::span<const double> x, std::span<double> y) = 0;
  /// Non-zeros of the whole matrix.
  [[nodiscard]] virtual std::size_t nonzeros() const = 0;
  /// Bytes this rank holds for the matrix (its rows and the communication plan).
  [[nodiscard]] virtual std::size_t local_bytes() const = 0;
  /// Vector entries of other ranks this rank receives per mat-vec (its ghost columns).
  [[nodiscard]] virtual std::size_t ghost_entries() const = 0;
  /// The leading eigenvalues and the Perron vector (collective).
  virtual EigenAnswer eigen(const EigenRequest& request) = 0;
};

/// The ranks of a run and the operations across them.
class Backend {
 public:
  virtual ~Backend() = default;
  /// "openmp" or "mpi" (the setting `backend`).
  [[nodiscard]] virtual std::string_view name() const = 0;
  /// This process's rank, 0 … ranks() − 1.
  [[nodiscard]] virtual int rank() const = 0;
  /// Number of ranks.
  [[nodiscard]] virtual int ranks() const = 0;
  /// Ranks on this machine (they share its cores).
  [[nodiscard]] virtual int ranks_here() const = 0;
  /// Whether this is rank 0, which prints and writes the outputs.
  [[nodiscard]] bool root() const { return rank() == 0; }
  /// This rank's block of n items.
  [[nodiscard]] Block block(std::size_t n) const { return block_of(n, rank(), ranks()); }

  /// Element-wise sum over ranks, in place, on every rank (exact for integers).
  virtual void sum(std::span<std::int64_t> v) const = 0;
  /// Element-wise sum over ranks, in place, on every rank (in rank order: the same bits on
  /// every rank, for a given number of ranks).
  virtual void sum(std::span<double> v) const = 0;
  /// Element-wise sum over ranks into rank 0's `v` (others' `v` unspecified afterwards).
  virtual void sum_to_root(std::span<std::int64_t> v) const = 0;
  /// Element-wise sum over ranks, in place, on every rank, of values that are 0 on every
  /// rank but at most one (each a value one rank holds): exact in any order (0 + x = x), so
  /// a reduction tree serves, whose memory does not grow with the ranks as `sum`'s does.
  virtual void sum_disjoint(std::span<double> v) const = 0;
  /// Element-wise sum over ranks into rank 0's `v` (others' `v` unspecified afterwards), by
  /// a reduction tree: the same bits for the same ranks, not necessarily `sum`'s. For what
  /// only rank 0 shows (the pictures' marginals), where every rank's copy would not scale.
  virtual void sum_to_root(std::span<double> v) const = 0;
  /// Element-wise maximum over ranks, in place, on every rank.
  virtual void max(std::span<double> v) const = 0;
  /// Element-wise minimum over ranks, in place, on every rank.
  virtual void min(std::span<std::int64_t> v) const = 0;
  /// Every rank's `part` concatenated in rank order, on every rank.
  [[nodiscard]] virtual std::vector<double> all_gather(std::span<const double> part) const = 0;
  /// Every rank's `part` concatenated in rank order, on rank 0 (empty elsewhere).
  [[nodiscard]] virtual std::vector<double> gather(std::span<const double> part) const = 0;
  /// Rank `from`'s bytes into every rank's `bytes` (same length everywhere).
  virtual void broadcast(std::span<std::byte> bytes, int from) const = 0;
  /// Rank `from`'s string on every rank.
  [[nodiscard]] virtual std::string broadcast(const std::string& s, int from) const = 0;
  /// The distributed matrix of every rank's columns (collective); nullptr: this backend
  /// keeps operators in one process (the methods then build their own CSR matrix).
  [[nodiscard]] virtual std::unique_ptr<DistributedMatrix> matrix(OperatorEntries part) const = 0;

  /// The element-wise sum over ranks of `v` (the same length n on every rank), as this
  /// rank's block `block(n)` of it (exact: integers).
  [[nodiscard]] virtual std::vector<std::int64_t> sum_to_blocks(
      std::span<const std::int64_t> v) const = 0;
  /// A vector of n values spread over the ranks by `block(n)`: every rank contributes its
  /// `values` at [offset, offset + values.size()) (the ranges may overlap; the sum is
  /// formed in rank order) and receives its own block of the sum, zero where nobody wrote.
  [[nodiscard]] virtual std::vector<double> sum_to_blocks(std::span<const double> values,
                                                          std::size_t offset,
                                                          std::size_t n) const = 0;
  /// The most values this rank received in one gather (`gather`, `all_gather`; not the sums'
  /// own exchanges) so far: what summary.json reports (gathered_values_per_rank), so that a
  /// test sees a frame gathered where none should be.
  [[nodiscard]] virtual std::size_t gathered_values() const { return 0; }
  /// Writing one file from every rank (nullptr: one process writes alone).
  [[nodiscard]] virtual const ParallelIo* parallel_io() const { return nullptr; }

  /// Sum of one value over ranks.
  [[nodiscard]] double sum(double x) const {
    sum(std::span<double>(&x, 1));
    return x;
  }
  /// Sum of one integer over ranks.
  [[nodiscard]] std::int64_t sum(std::int64_t x) const {
    sum(std::span<std::int64_t>(&x, 1));
    return x;
  }
  /// Maximum of one value over ranks.
  [[nodiscard]] double max(double x) const {
    max(std::span<double>(&x, 1));
    return x;
  }
  /// Minimum of one integer over ranks.
  [[nodiscard]] std::int64_t min(std::int64_t x) const {
    min(std::span<std::int64_t>(&x, 1));
    return x;
  }
  /// Whether `flag` holds on any rank.
  [[nodiscard]] bool any(bool flag) const { return sum(std::int64_t{flag ? 1 : 0}) > 0; }
};

/// One process: every collective is the identity.
class SerialBackend final : public Backend {
 public:
  /// "openmp".
  [[nodiscard]] std::string_view name() const override { return "openmp"; }
  /// 0.
  [[nodiscard]] int rank() const override { return 0; }
  /// 1.
  [[nodiscard]] int ranks() const override { return 1; }
  /// 1.
  [[nodiscard]] int ranks_here() const override { return 1; }
  using Backend::max;
  using Backend::min;
  using Backend::sum;
  /// Identity.
  void sum(std::span<std::int64_t>) const override {}
  /// Identity.
  void sum(std::span<double>) const override {}
  /// Identity.
  void sum_to_root(std::span<std::int64_t>) const override {}
  /// Identity.
  void sum_to_root(std::span<double>) const override {}
  /// Identity.
  void sum_disjoint(std::span<double>) const override {}
  /// Identity.
  void max(std::span<double>) const override {}
  /// Identity.
  void min(std::span<std::int64_t>) const override {}
  /// A copy of `part`.
  [[nodiscard]] std::vector<double> all_gather(std::span<const double> part) const override {
    return {part.begin(), part.end()};
  }
  /// A copy of `part`.
  [[nodiscard]] std::vector<double> gather(std::span<const double> part) const override {
    return {part.begin(), part.end()};
  }
  /// Identity.
  void broadcast(std::span<std::byte>, int) const override {}
  /// `s`.
  [[nodiscard]] std::string broadcast(const std::string& s, int) const override { return s; }
  /// nullptr: the methods keep their CSR matrix.
  [[nodiscard]] std::unique_ptr<DistributedMatrix> matrix(OperatorEntries) const override {
    return nullptr;
  }
  /// A copy of `v`.
  [[nodiscard]] std::vector<std::int64_t> sum_to_blocks(
      std::span<const std::int64_t> v) const override {
    return {v.begin(), v.end()};
  }
  /// `values` at `offset` in n zeros.
  [[nodiscard]] std::vector<double> sum_to_blocks(std::span<const double> values,
                                                  std::size_t offset,
                                                  std::size_t n) const override {
    std::vector<double> out(n, 0.0);
    for (std::size_t i = 0; i < values.size() && offset + i < n; ++i) out[offset + i] += values[i];
    return out;
  }
};

/// The first failure over all ranks: each rank passes the index of its own first failure
/// (`none` if it had none) and that failure; every rank gets back the smallest index and, if
/// some rank failed, that failure (copied from the rank that owns it). Methods report the
/// failure of the smallest index, so the message does not depend on the number of ranks.
/// `message`, if given, travels with it.
template <class Failure>
std::int64_t agree_first_failure(const Backend& b, std::int64_t first, Failure& failure,
                                 std::int64_t none, std::string* message = nullptr) {
  static_assert(std::is_trivially_copyable_v<Failure>, "a failure crosses ranks as bytes");
  if (b.ranks() == 1) return first;
  const std::int64_t global = b.min(first);
  if (global == none) return none;
  const std::int64_t owner = b.min(first == global ? std::int64_t{b.rank()} : b.ranks());
  b.broadcast(std::as_writable_bytes(std::span<Failure>(&failure, 1)), static_cast<int>(owner));
  if (message) *message = b.broadcast(*message, static_cast<int>(owner));
  return global;
}

/// The process-wide serial backend (the default of every method's options).
inline const Backend& serial_backend() {
  static const SerialBackend b;
  return b;
}

}  // namespace hybgen::rt
