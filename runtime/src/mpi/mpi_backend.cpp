// The MPI backend (mpi_backend.hpp).

#include "mpi_backend.hpp"

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "petsc_matrix.hpp"

namespace hybgen::rt::mpi {

namespace {

/// MPI takes int counts: larger buffers go in pieces of at most this many elements.
constexpr std::size_t kPiece = std::size_t{1} << 28;

/// Throw on an MPI error (MPI's default handler aborts first; kept for MPI_ERRORS_RETURN).
void check(int status, const char* what) {
  if (status != MPI_SUCCESS) throw std::runtime_error(std::string("MPI: ") + what + " failed");
}

/// Counts and displacements as int, refusing what int cannot hold.
std::vector<int> as_int(const std::vector<std::size_t>& v) {
  std::vector<int> out;
  for (const std::size_t x : v) {
    if (x > static_cast<std::size_t>(std::numeric_limits<int>::max()))
      throw std::length_error(
          "MPI: a gather of more than 2^31 values (split the run over more ranks)");
    out.push_back(static_cast<int>(x));
  }
  return out;
}

/// Where each rank's part starts in the concatenation of parts of sizes `n`; `total` gets
/// the concatenation's size.
std::vector<std::size_t> offsets(const std::vector<std::size_t>& n, std::size_t& total) {
  std::vector<std::size_t> at;
  total = 0;
  for (const std::size_t x : n) {
    at.push_back(total);
    total += x;
  }
  return at;
}

}  // namespace

MpiBackend::MpiBackend() {
  check(MPI_Comm_rank(MPI_COMM_WORLD, &rank_), "MPI_Comm_rank");
  check(MPI_Comm_size(MPI_COMM_WORLD, &size_), "MPI_Comm_size");
  MPI_Comm node;
  check(MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank_, MPI_INFO_NULL, &node),
        "MPI_Comm_split_type");
  check(MPI_Comm_size(node, &here_), "MPI_Comm_size");
  MPI_Comm_free(&node);
}

void MpiBackend::sum(std::span<std::int64_t> v) const {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, v.size() - at));
    check(MPI_Allreduce(MPI_IN_PLACE, v.data() + at, n, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD),
          "MPI_Allreduce");
  }
}

void MpiBackend::sum(std::span<double> v) const {
  if (size_ == 1 || v.empty()) return;
  // Rank order, the same on every rank: MPI's own reductions may associate differently on
  // different ranks, and ranks that disagree in the last bit take different branches.
  const std::size_t most = gathered_;  // a sum's exchange is not a gather of a field
  const std::vector<double> all = all_gather(v);
  gathered_ = most;
  for (std::size_t j = 0; j < v.size(); ++j) {
    double s = 0.0;
    for (int r = 0; r < size_; ++r) s += all[static_cast<std::size_t>(r) * v.size() + j];
    v[j] = s;
  }
}

void MpiBackend::sum_to_root(std::span<std::int64_t> v) const {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, v.size() - at));
    void* send = rank_ == 0 ? MPI_IN_PLACE : v.data() + at;
    check(MPI_Reduce(send, v.data() + at, n, MPI_INT64_T, MPI_SUM, 0, MPI_COMM_WORLD),
          "MPI_Reduce");
  }
}

void MpiBackend::sum_disjoint(std::span<double> v) const {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, v.size() - at));
    check(MPI_Allreduce(MPI_IN_PLACE, v.data() + at, n, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD),
          "MPI_Allreduce");
  }
}

void MpiBackend::sum_to_root(std::span<double> v) const {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, v.size() - at));
    void* send = rank_ == 0 ? MPI_IN_PLACE : v.data() + at;
    check(MPI_Reduce(send, v.data() + at, n, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD), "MPI_Reduce");
  }
}

void MpiBackend::max(std::span<double> v) const {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, v.size() - at));
    check(MPI_Allreduce(MPI_IN_PLACE, v.data() + at, n, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD),
          "MPI_Allreduce");
  }
}

void MpiBackend::min(std::span<std::int64_t> v) const {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, v.size() - at));
    check(MPI_Allreduce(MPI_IN_PLACE, v.data() + at, n, MPI_INT64_T, MPI_MIN, MPI_COMM_WORLD),
          "MPI_Allreduce");
  }
}

std::vector<std::size_t> MpiBackend::counts(std::size_t mine) const {
  std::vector<std::uint64_t> all(static_cast<std::size_t>(size_));
  const std::uint64_t m = mine;
  check(MPI_Allgather(&m, 1, MPI_UINT64_T, all.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD),
        "MPI_Allgather");
  return {all.begin(), all.end()};
}

std::vector<double> MpiBackend::all_gather(std::span<const double> part) const {
  const std::vector<std::size_t> n = counts(part.size());
  std::size_t total = 0;
  const std::vector<std::size_t> at = offsets(n, total);
  std::vector<double> all(total);
  gathered_ = std::max(gathered_, total - part.size());
  const std::vector<int> ni = as_int(n), ati = as_int(at);
  check(MPI_Allgatherv(part.data(), ni[static_cast<std::size_t>(rank_)], MPI_DOUBLE, all.data(),
                       ni.data(), ati.data(), MPI_DOUBLE, MPI_COMM_WORLD),
        "MPI_Allgatherv");
  return all;
}

std::vector<double> MpiBackend::gather(std::span<const double> part) const {
  const std::vector<std::size_t> n = counts(part.size());
  std::size_t total = 0;
  const std::vector<std::size_t> at = offsets(n, total);
  std::vector<double> all(rank_ == 0 ? total : 0);
  if (rank_ == 0) gathered_ = std::max(gathered_, total - part.size());
  const std::vector<int> ni = as_int(n), ati = as_int(at);
  check(MPI_Gatherv(part.data(), ni[static_cast<std::size_t>(rank_)], MPI_DOUBLE, all.data(),
                    ni.data(), ati.data(), MPI_DOUBLE, 0, MPI_COMM_WORLD),
        "MPI_Gatherv");
  return all;
}

void MpiBackend::broadcast(std::span<std::byte> bytes, int from) const {
  for (std::size_t at = 0; at < bytes.size(); at += kPiece) {
    const auto n = static_cast<int>(std::min(kPiece, bytes.size() - at));
    check(MPI_Bcast(bytes.data() + at, n, MPI_BYTE, from, MPI_COMM_WORLD), "MPI_Bcast");
  }
}

std::string MpiBackend::broadcast(const std::string& s, int from) const {
  std::uint64_t n = s.size();
  check(MPI_Bcast(&n, 1, MPI_UINT64_T, from, MPI_COMM_WORLD), "MPI_Bcast");
  std::string out = rank_ == from ? s : std::string(n, '\0');
  broadcast(std::as_writable_bytes(std::span<char>(out.data(), out.size())), from);
  return out;
}

std::unique_ptr<DistributedMatrix> MpiBackend::matrix(OperatorEntries part) const {
  return std::make_unique<PetscMatrix>(std::move(part));
}

std::vector<std::int64_t> MpiBackend::sum_to_blocks(std::span<const std::int64_t> v) const {
  std::vector<std::size_t> n(static_cast<std::size_t>(size_));
  for (int r = 0; r < size_; ++r)
    n[static_cast<std::size_t>(r)] = block_of(v.size(), r, size_).size();
  const std::vector<int> ni = as_int(n);
  std::vector<std::int64_t> mine(n[static_cast<std::size_t>(rank_)]);
  check(MPI_Reduce_scatter(v.data(), mine.data(), ni.data(), MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD),
        "MPI_Reduce_scatter");
  return mine;
}

std::vector<double> MpiBackend::sum_to_blocks(std::span<const double> values, std::size_t offset,
                                              std::size_t n) const {
  // Every rank's range [offset, offset + size), then the pieces that fall in each block.
  std::vector<std::uint64_t> mine{offset, values.size()},
      ranges(2 * static_cast<std::size_t>(size_));
  check(MPI_Allgather(mine.data(), 2, MPI_UINT64_T, ranges.data(), 2, MPI_UINT64_T, MPI_COMM_WORLD),
        "MPI_Allgather");
  auto overlap = [](std::size_t a0, std::size_t a1, Block b) {
    const std::size_t lo = std::max(a0, b.begin), hi = std::min(a1, b.end);
    return hi > lo ? Block{lo, hi} : Block{lo, lo};
  };
  const auto R = static_cast<std::size_t>(size_);
  const Block own = block(n);
  std::vector<std::size_t> send_n(R), send_at(R), recv_n(R), recv_at(R);
  std::size_t recv_total = 0;
  for (std::size_t r = 0; r < R; ++r) {
    const Block s =
        overlap(offset, offset + values.size(), block_of(n, static_cast<int>(r), size_));
    send_n[r] = s.size();
    send_at[r] = s.begin - std::min(s.begin, offset);
    const Block g = overlap(ranges[2 * r], ranges[2 * r] + ranges[2 * r + 1], own);
    recv_n[r] = g.size();
    recv_at[r] = recv_total;
    recv_total += g.size();
  }
  std::vector<double> received(recv_total);
  const std::vector<int> sn = as_int(send_n), sa = as_int(send_at), rn = as_int(recv_n),
                         ra = as_int(recv_at);
  check(MPI_Alltoallv(values.data(), sn.data(), sa.data(), MPI_DOUBLE, received.data(), rn.data(),
                      ra.data(), MPI_DOUBLE, MPI_COMM_WORLD),
        "MPI_Alltoallv");
  // In rank order: 0 + the first contribution, + the next, … (one contribution: exact).
  std::vector<double> out(own.size(), 0.0);
  for (std::size_t r = 0; r < R; ++r) {
    const Block g = overlap(ranges[2 * r], ranges[2 * r] + ranges[2 * r + 1], own);
    for (std::size_t i = 0; i < g.size(); ++i)
      out[g.begin - own.begin + i] += received[recv_at[r] + i];
  }
  return out;
}

const ParallelIo* MpiBackend::parallel_io() const {
  return &parallel_netcdf();
}

}  // namespace hybgen::rt::mpi
