// A transfer operator as a PETSc matrix, and its spectrum by SLEPc (petsc_matrix.hpp).

#include "petsc_matrix.hpp"

#include <mpi.h>
#include <slepceps.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace hybgen::rt::mpi {

namespace {

/// Throw on a PETSc or SLEPc error code, naming the call.
void ok(PetscErrorCode status, const char* what) {
  if (status != 0)
    throw std::runtime_error(std::string("PETSc: ") + what + " failed (error " +
                             std::to_string(static_cast<int>(status)) + ")");
}

/// As PetscInt, refusing what PETSc's 32-bit indices cannot hold.
PetscInt as_index(std::size_t n) {
  if (n > static_cast<std::size_t>(std::numeric_limits<PetscInt>::max()))
    throw std::length_error("PETSc: more than 2^31 unknowns (PETSc is built with 32-bit indices)");
  return static_cast<PetscInt>(n);
}

/// The owner of row r under block_of(n, ·, R): the first n mod R blocks hold one row more.
struct RowOwner {
  std::size_t q, rem, big;
  RowOwner(std::size_t n, std::size_t R) : q(n / R), rem(n % R), big(n % R * (n / R + 1)) {}
  [[nodiscard]] std::size_t operator()(std::size_t r) const {
    return r < big ? r / (q + 1) : rem + (r - big) / q;
  }
};

/// Sort the entries [b, e) of a row by column (a row holds a few hundred at most).
void sort_row(PetscInt* col, PetscScalar* val, std::size_t b, std::size_t e,
              std::vector<std::pair<PetscInt, PetscScalar>>& row) {
  row.clear();
  for (std::size_t k = b; k < e; ++k) row.emplace_back(col[k], val[k]);
  std::sort(row.begin(), row.end());
  for (std::size_t k = b; k < e; ++k) col[k] = row[k - b].first, val[k] = row[k - b].second;
}

}  // namespace

void PetscMatrix::assemble_rows(OperatorEntries& part, int ranks) {
  const std::size_t n = part.size;
  const auto R = static_cast<std::size_t>(ranks);
  const RowOwner owner(n, R);
  int me = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &me);
  const auto self = static_cast<std::size_t>(me);
  // 1. In each list, this rank's rows first (in place); the others' entries, usually a thin
  //    layer of ghost rows, are packed by destination into one buffer and sent.
  std::vector<std::size_t> local(part.lists.size());
  std::vector<int> send_count(R, 0), recv_count(R, 0), send_at(R, 0), recv_at(R, 0);
  for (std::size_t t = 0; t < part.lists.size(); ++t) {
    auto& list = part.lists[t];
    const auto mid = std::partition(list.begin(), list.end(), [&](const OperatorEntry& e) {
      return owner(static_cast<std::size_t>(e.row)) == self;
    });
    local[t] = static_cast<std::size_t>(mid - list.begin());
    for (auto it = mid; it != list.end(); ++it)
      ++send_count[owner(static_cast<std::size_t>(it->row))];
  }
  if (MPI_Alltoall(send_count.data(), 1, MPI_INT, recv_count.data(), 1, MPI_INT,
                   PETSC_COMM_WORLD) != MPI_SUCCESS)
    throw std::runtime_error("MPI: MPI_Alltoall failed");
  std::size_t sent = 0, received = 0;
  for (std::size_t k = 0; k < R; ++k) {
    send_at[k] = static_cast<int>(sent);
    recv_at[k] = static_cast<int>(received);
    sent += static_cast<std::size_t>(send_count[k]);
    received += static_cast<std::size_t>(recv_count[k]);
    if (sent > static_cast<std::size_t>(std::numeric_limits<int>::max()) ||
        received > static_cast<std::size_t>(std::numeric_limits<int>::max()))
      throw std::length_error(
          "PETSc: more than 2^31 entries to exchange on one rank (use more ranks)");
  }
  // This rank's rows hold its own entries and those received: PETSc's 32-bit row pointers
  // must count them all. Agreed: no rank may leave the collectives below alone.
  std::size_t own = received;
  for (const std::size_t l : local) own += l;
  int too_many = own > static_cast<std::size_t>(std::numeric_limits<PetscInt>::max()) ? 1 : 0;
  if (MPI_Allreduce(MPI_IN_PLACE, &too_many, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD) != MPI_SUCCESS)
    throw std::runtime_error("MPI: MPI_Allreduce failed");
  if (too_many)
    throw std::length_error(
        "PETSc: more than 2^31 entries in one rank's rows (PETSc's 32-bit indices: use more "
        "ranks, or Debian's petsc64-dev)");
  std::vector<OperatorEntry> in(received);
  {
    std::vector<OperatorEntry> out(sent);
    std::vector<int> at = send_at;
    for (std::size_t t = 0; t < part.lists.size(); ++t)
      for (std::size_t k = local[t]; k < part.lists[t].size(); ++k) {
        const OperatorEntry& e = part.lists[t][k];
        out[static_cast<std::size_t>(at[owner(static_cast<std::size_t>(e.row))]++)] = e;
      }
    MPI_Datatype entry = MPI_DATATYPE_NULL;
    MPI_Type_contiguous(static_cast<int>(sizeof(OperatorEntry)), MPI_BYTE, &entry);
    MPI_Type_commit(&entry);
    const int status =
        MPI_Alltoallv(out.data(), send_count.data(), send_at.data(), entry, in.data(),
                      recv_count.data(), recv_at.data(), entry, PETSC_COMM_WORLD);
    MPI_Type_free(&entry);
    if (status != MPI_SUCCESS) throw std::runtime_error("MPI: MPI_Alltoallv failed");
  }
  // 2. This rank's rows split as PETSc keeps them: the "diagonal" block (columns it owns,
  //    local indices) and the "off-diagonal" one (global columns), each CSR with its
  //    columns sorted. Built straight from the lists and the received entries; PETSc uses
  //    these arrays as they are (MatCreateMPIAIJWithSplitArrays): no further copy.
  const Block mine = owned_;
  const std::size_t rows = mine.size();
  di_.assign(rows + 1, 0);
  oi_.assign(rows + 1, 0);
  auto each = [&](auto&& f) {
    for (std::size_t t = 0; t < part.lists.size(); ++t)
      for (std::size_t k = 0; k < local[t]; ++k) f(part.lists[t][k]);
    for (const OperatorEntry& e : in) f(e);
  };
  auto diagonal = [&](const OperatorEntry& e) {
    const auto c = static_cast<std::size_t>(e.col);
    return c >= mine.begin && c < mine.end;
  };
  each([&](const OperatorEntry& e) {
    ++(diagonal(e) ? di_ : oi_)[static_cast<std::size_t>(e.row) - mine.begin + 1];
  });
  for (std::size_t r = 0; r < rows; ++r) di_[r + 1] += di_[r], oi_[r + 1] += oi_[r];
  dj_.resize(static_cast<std::size_t>(di_[rows]));
  da_.resize(dj_.size());
  oj_.resize(static_cast<std::size_t>(oi_[rows]));
  oa_.resize(oj_.size());
  {
    // Each list freed once it is written: the lists and the arrays are not both whole at once
    // (a thread's list runs through the columns, and so the rows, roughly in order).
    std::vector<PetscInt> d_at(di_.begin(), di_.end() - 1), o_at(oi_.begin(), oi_.end() - 1);
    auto put = [&](const OperatorEntry& e) {
      const std::size_t r = static_cast<std::size_t>(e.row) - mine.begin;
      if (diagonal(e)) {
        const auto k = static_cast<std::size_t>(d_at[r]++);
        dj_[k] = static_cast<PetscInt>(static_cast<std::size_t>(e.col) - mine.begin);
        da_[k] = e.value;
      } else {
        const auto k = static_cast<std::size_t>(o_at[r]++);
        oj_[k] = e.col;
        oa_[k] = e.value;
      }
    };
    for (std::size_t t = 0; t < part.lists.size(); ++t) {
      for (std::size_t k = 0; k < local[t]; ++k) put(part.lists[t][k]);
      std::vector<OperatorEntry>().swap(part.lists[t]);
    }
    for (const OperatorEntry& e : in) put(e);
  }
  std::vector<OperatorEntry>().swap(in);
  part = OperatorEntries{};
  std::vector<std::pair<PetscInt, PetscScalar>> row;
  for (std::size_t r = 0; r < rows; ++r) {
    sort_row(dj_.data(), da_.data(), static_cast<std::size_t>(di_[r]),
             static_cast<std::size_t>(di_[r + 1]), row);
    sort_row(oj_.data(), oa_.data(), static_cast<std::size_t>(oi_[r]),
             static_cast<std::size_t>(oi_[r + 1]), row);
  }
}

PetscMatrix::PetscMatrix(OperatorEntries part) : owned_(part.owned) {
  const PetscInt n = as_index(part.size), local = as_index(part.owned.size());
  int ranks = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &ranks);
  // Each row to its owner, then the matrix on the owned rows' split arrays: their counts
  // are exact (nothing preallocated by guess, nothing inserted one by one), and PETSc keeps
  // the arrays rather than a copy of them.
  assemble_rows(part, ranks);
  ok(MatCreateMPIAIJWithSplitArrays(PETSC_COMM_WORLD, local, local, n, n, di_.data(), dj_.data(),
                                    da_.data(), oi_.data(), oj_.data(), oa_.data(), &a_),
     "MatCreateMPIAIJWithSplitArrays");
  ok(VecCreateMPIWithArray(PETSC_COMM_WORLD, 1, local, n, nullptr, &x_), "VecCreateMPIWithArray");
  ok(VecCreateMPIWithArray(PETSC_COMM_WORLD, 1, local, n, nullptr, &y_), "VecCreateMPIWithArray");
}

PetscMatrix::~PetscMatrix() {
  VecDestroy(&x_);
  VecDestroy(&y_);
  MatDestroy(&a_);
}

void PetscMatrix::multiply(std::span<const double> x, std::span<double> y) {
  // PETSc reads x only; VecPlaceArray takes a non-const pointer.
  ok(VecPlaceArray(x_, const_cast<double*>(x.data())), "VecPlaceArray");
  ok(VecPlaceArray(y_, y.data()), "VecPlaceArray");
  ok(MatMult(a_, x_, y_), "MatMult");
  ok(VecResetArray(x_), "VecResetArray");
  ok(VecResetArray(y_), "VecResetArray");
}

std::size_t PetscMatrix::nonzeros() const {
  MatInfo info;
  ok(MatGetInfo(a_, MAT_GLOBAL_SUM, &info), "MatGetInfo");
  return static_cast<std::size_t>(info.nz_used);
}

std::size_t PetscMatrix::ghost_entries() const {
  PetscBool mpiaij = PETSC_FALSE;
  ok(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(a_), MATMPIAIJ, &mpiaij),
     "PetscObjectTypeCompare");
  if (!mpiaij) return 0;
  Mat diagonal = nullptr, off = nullptr;
  const PetscInt* map = nullptr;
  ok(MatMPIAIJGetSeqAIJ(a_, &diagonal, &off, &map), "MatMPIAIJGetSeqAIJ");
  PetscInt rows = 0, cols = 0;
  ok(MatGetSize(off, &rows, &cols), "MatGetSize");
  return static_cast<std::size_t>(cols);
}

std::size_t PetscMatrix::local_bytes() const {
  // This rank's rows are the split arrays PETSc uses in place (it does not copy them): the
  // two CSR blocks with their row pointers. A mat-vec receives the ghost entries into a
  // vector of their own, through a map of their global indices.
  return (dj_.size() + oj_.size()) * (sizeof(PetscScalar) + sizeof(PetscInt)) +
         (di_.size() + oi_.size()) * sizeof(PetscInt) +
         ghost_entries() * (sizeof(PetscScalar) + sizeof(PetscInt));
}

EigenAnswer PetscMatrix::eigen(const EigenRequest& request) {
  EigenAnswer answer;
  EPS eps = nullptr;
  Vec start = nullptr, vector = nullptr;
  ok(EPSCreate(PETSC_COMM_WORLD, &eps), "EPSCreate");
  try {
    ok(EPSSetOperators(eps, a_, nullptr), "EPSSetOperators");
    ok(EPSSetProblemType(eps, EPS_NHEP), "EPSSetProblemType");
    ok(EPSSetWhichEigenpairs(eps, EPS_LARGEST_MAGNITUDE), "EPSSetWhichEigenpairs");
    ok(EPSSetDimensions(eps, request.n_eigen, request.ncv > 0 ? request.ncv : PETSC_DEFAULT,
                        PETSC_DEFAULT),
       "EPSSetDimensions");
    ok(EPSSetTolerances(eps, request.tol, request.max_iterations), "EPSSetTolerances");
    ok(MatCreateVecs(a_, &start, &vector), "MatCreateVecs");
    ok(VecSet(start, 1.0), "VecSet");
    ok(EPSSetInitialSpace(eps, 1, &start), "EPSSetInitialSpace");
    ok(EPSSetFromOptions(eps), "EPSSetFromOptions");
    ok(EPSSolve(eps), "EPSSolve");
    PetscInt converged = 0, iterations = 0, wanted = 0, ncv = 0, mpd = 0;
    ok(EPSGetConverged(eps, &converged), "EPSGetConverged");
    ok(EPSGetIterationNumber(eps, &iterations), "EPSGetIterationNumber");
    ok(EPSGetDimensions(eps, &wanted, &ncv, &mpd), "EPSGetDimensions");
    EPSType type = nullptr;
    ok(EPSGetType(eps, &type), "EPSGetType");
    answer.solver = std::string("slepc ") + (type ? type : "?");
    answer.iterations = static_cast<long>(iterations);
    answer.converged = converged >= wanted;
    for (PetscInt j = 0; j < converged; ++j) {
      PetscScalar re = 0.0, im = 0.0;
      ok(EPSGetEigenvalue(eps, j, &re, &im), "EPSGetEigenvalue");
      answer.eigenvalues.emplace_back(re, im);
    }
    answer.lead = perron_index(answer.eigenvalues);
    if (answer.lead >= 0) {
      ok(EPSGetEigenvector(eps, answer.lead, vector, nullptr), "EPSGetEigenvector");
      const PetscScalar* v = nullptr;
      ok(VecGetArrayRead(vector, &v), "VecGetArrayRead");
      answer.vector.assign(v, v + owned_.size());
      ok(VecRestoreArrayRead(vector, &v), "VecRestoreArrayRead");
    }
  } catch (...) {
    VecDestroy(&start);
    VecDestroy(&vector);
    EPSDestroy(&eps);
    throw;
  }
  VecDestroy(&start);
  VecDestroy(&vector);
  EPSDestroy(&eps);
  return answer;
}

}  // namespace hybgen::rt::mpi
