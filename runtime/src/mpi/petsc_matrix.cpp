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

/// One entry on its way to the rank that owns its row.
struct Entry {
  std::int32_t row, col;
  double value;
};

/// Every entry of `part` sent to the rank owning its row (one MPI_Alltoallv), as the CSR
/// rows of this rank's block: row pointers (local rows), global columns sorted within each
/// row, values. `part` is emptied on the way, the entries sent freed before the rows are
/// built: the peak is ≈ 28 bytes per entry of this rank (its columns as sent, then its
/// rows as received and compressed), against 12 per entry of the finished matrix.
void exchange_rows(OperatorColumns& part, int ranks, std::vector<PetscInt>& ptr,
                   std::vector<PetscInt>& col, std::vector<PetscScalar>& val) {
  const std::size_t n = part.size;
  const auto R = static_cast<std::size_t>(ranks);
  // The owner of row r under block_of: the first n mod R blocks hold one row more.
  const std::size_t q = n / R, rem = n % R, big = rem * (q + 1);
  auto owner = [&](std::size_t r) { return r < big ? r / (q + 1) : rem + (r - big) / q; };
  std::vector<int> send_count(R, 0), recv_count(R, 0), send_at(R, 0), recv_at(R, 0);
  for (const std::int32_t r : part.row) ++send_count[owner(static_cast<std::size_t>(r))];
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
  std::vector<Entry> out(sent);
  {
    std::vector<int> at = send_at;
    for (std::size_t c = 0; c < part.owned.size(); ++c)
      for (std::size_t k = part.start[c]; k < part.start[c + 1]; ++k) {
        const auto r = static_cast<std::size_t>(part.row[k]);
        out[static_cast<std::size_t>(at[owner(r)]++)] = {
            part.row[k], static_cast<std::int32_t>(part.owned.begin + c), part.value[k]};
      }
  }
  const Block mine = part.owned;
  part = OperatorColumns{};  // packed: free the columns
  MPI_Datatype entry = MPI_DATATYPE_NULL;
  MPI_Type_contiguous(static_cast<int>(sizeof(Entry)), MPI_BYTE, &entry);
  MPI_Type_commit(&entry);
  std::vector<Entry> in(received);
  const int status = MPI_Alltoallv(out.data(), send_count.data(), send_at.data(), entry, in.data(),
                                   recv_count.data(), recv_at.data(), entry, PETSC_COMM_WORLD);
  MPI_Type_free(&entry);
  if (status != MPI_SUCCESS) throw std::runtime_error("MPI: MPI_Alltoallv failed");
  std::vector<Entry>().swap(out);
  // CSR of the owned rows: count, prefix sum, scatter, then sort each row by column.
  const std::size_t rows = mine.size();
  ptr.assign(rows + 1, 0);
  for (const Entry& e : in) ++ptr[static_cast<std::size_t>(e.row) - mine.begin + 1];
  for (std::size_t r = 0; r < rows; ++r) ptr[r + 1] += ptr[r];
  col.resize(received);
  val.resize(received);
  std::vector<PetscInt> at(ptr.begin(), ptr.end() - 1);
  for (const Entry& e : in) {
    const auto k = static_cast<std::size_t>(at[static_cast<std::size_t>(e.row) - mine.begin]++);
    col[k] = e.col;
    val[k] = e.value;
  }
  std::vector<Entry>().swap(in);
  std::vector<std::pair<PetscInt, PetscScalar>> row;
  for (std::size_t r = 0; r < rows; ++r) {
    const auto b = static_cast<std::size_t>(ptr[r]), e = static_cast<std::size_t>(ptr[r + 1]);
    row.clear();
    for (std::size_t k = b; k < e; ++k) row.emplace_back(col[k], val[k]);
    std::sort(row.begin(), row.end());
    for (std::size_t k = b; k < e; ++k) col[k] = row[k - b].first, val[k] = row[k - b].second;
  }
}

}  // namespace

PetscMatrix::PetscMatrix(OperatorColumns part) : owned_(part.owned) {
  const PetscInt n = as_index(part.size), local = as_index(part.owned.size());
  int ranks = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &ranks);
  // Each row to its owner, then the matrix from the owned rows: PETSc counts the entries of
  // every row as it copies them (exact preallocation, nothing guessed).
  std::vector<PetscInt> ptr, col;
  std::vector<PetscScalar> val;
  exchange_rows(part, ranks, ptr, col, val);
  ok(MatCreateMPIAIJWithArrays(PETSC_COMM_WORLD, local, local, n, n, ptr.data(), col.data(),
                               val.data(), &a_),
     "MatCreateMPIAIJWithArrays");
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
  // MatInfo::memory is not tracked by an optimised PETSc: count it. This rank's rows are
  // two CSR blocks (the columns it owns, and the rest, compressed to the ghost columns it
  // reads), each with its row pointers; a mat-vec receives the ghost entries into a vector
  // of their own, through a map of their global indices.
  MatInfo info;
  ok(MatGetInfo(a_, MAT_LOCAL, &info), "MatGetInfo");
  const auto entries = static_cast<std::size_t>(info.nz_allocated);
  return entries * (sizeof(PetscScalar) + sizeof(PetscInt)) +
         2 * (owned_.size() + 1) * sizeof(PetscInt) +
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
