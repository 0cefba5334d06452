#pragma once
/// \file sparse.hpp
/// The runtime's sparse matrices: Eigen's compressed storage, included here once with the
/// diagnostics that GCC 12 reports inside Eigen's headers silenced.

// GCC 12's flow-sensitive warnings (null-dereference, use-after-free, maybe-uninitialized
// with AVX-512) misfire inside Eigen's and Spectra's headers after inlining, despite
// -isystem: HYBGEN_EIGEN_WARNINGS_PUSH silences them for what follows, up to
// HYBGEN_EIGEN_WARNINGS_POP (here around Eigen's headers; in runtime/src/numerics/*.cpp
// around the whole file, where the solvers are instantiated).
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 12
#define HYBGEN_EIGEN_WARNINGS_PUSH                                                        \
  _Pragma("GCC diagnostic push") _Pragma("GCC diagnostic ignored \"-Wnull-dereference\"") \
      _Pragma("GCC diagnostic ignored \"-Wmaybe-uninitialized\"")                         \
          _Pragma("GCC diagnostic ignored \"-Wuse-after-free\"")
#else
#define HYBGEN_EIGEN_WARNINGS_PUSH \
  _Pragma("GCC diagnostic push") _Pragma("GCC diagnostic ignored \"-Wnull-dereference\"")
#endif
/// Ends HYBGEN_EIGEN_WARNINGS_PUSH.
#define HYBGEN_EIGEN_WARNINGS_POP _Pragma("GCC diagnostic pop")

HYBGEN_EIGEN_WARNINGS_PUSH
#include <Eigen/SparseCore>
HYBGEN_EIGEN_WARNINGS_POP

namespace hybgen::rt {

/// Compressed sparse rows, as a transfer operator's matrix is stored (row j holds what node j
/// receives: M' = P M on node masses), with int32 column indices and row pointers: each
/// mat-vec streams 8 + 4 bytes per nonzero and 4 per row (int64 indices would add a third).
using CsrMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

/// Compressed sparse columns (Eigen's default), as the generator's matrices are stored.
using CscMatrix = Eigen::SparseMatrix<double>;

}  // namespace hybgen::rt
