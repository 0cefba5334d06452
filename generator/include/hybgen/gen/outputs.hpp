#pragma once
/// \file outputs.hpp
/// The output directory of a run or a sweep, replaced as a whole or not at all.
///
/// A run writes into a fresh staging directory `OUT.partial-<pid>` beside OUT; only when it
/// succeeds is the staging directory swapped into place (swap_into_place) and the old
/// outputs removed. A failed or interrupted run removes the staging directory and leaves
/// OUT as it was. The lock `OUT.lock` serialises runs into the same OUT; a run that finds
/// OUT missing but a complete `OUT.old-<pid>` of a run killed mid-swap restores it first.
/// Invariant: a `.old-` directory is always a complete set of outputs, and at every
/// instant either OUT holds a complete set (old or new) or, between the two renames of the
/// fallback, the old set is `.old-` and the next run restores it; what is under a
/// `.partial-` name is never restored, so it may be deleted in place.

#include <filesystem>
#include <string>

namespace hybgen::gen {

/// The renames swap_into_place uses, replaceable so that a test can make each one fail.
struct RenameOps {
  /// Exchange two paths atomically (renameat2 RENAME_EXCHANGE); 0 or -1 with errno.
  int (*exchange)(const char* a, const char* b);
  /// rename(2); 0 or -1 with errno.
  int (*rename)(const char* from, const char* to);
};

/// The system's renames.
const RenameOps& system_renames();

/// How swap_into_place ended.
struct SwapResult {
  std::string error;     ///< Empty on success.
  std::string stranded;  ///< Where the outputs are when a failed rollback left OUT missing.
};

/// Put the finished `staging` directory in the place of `target` (which holds earlier
/// outputs when `had_outputs`); on success the old outputs, if any, are under the staging
/// name, to be removed. The exchange leaves no instant without target; the fallback (a
/// file system without RENAME_EXCHANGE: EINVAL or ENOSYS) moves target to `old`, staging to
/// target, then `old` to the staging name, and moves `old` back if the second rename fails.
SwapResult swap_into_place(const std::filesystem::path& staging,
                           const std::filesystem::path& target, const std::filesystem::path& old,
                           bool had_outputs, const RenameOps& ops = system_renames());

/// What an output directory holds, which decides what may be replaced.
enum class OutputKind {
  Run,    ///< Files of one run: .npy, .png, .vti, .json.
  Sweep,  ///< sweep.csv, sweep.json and one subdirectory of run files per point.
};

/// The first entry of `dir` that `kind`'s outputs cannot have written (a subdirectory of a
/// run, any other file than its outputs or an atomic write's temporary), "" if none.
std::string foreign_entry(const std::filesystem::path& dir, OutputKind kind);

/// Whether `entry` is a name the protocol gives a leftover of OUT = `name`: NAME.partial-PID
/// or NAME.old-PID with PID all digits.
bool is_leftover_name(const std::string& entry, const std::string& name);

/// One output directory, staged and then swapped in (the file comment's protocol).
/// Construction takes the lock and checks OUT; stage() creates the staging directory;
/// commit() swaps it in. Destroyed without a commit, it removes the staging directory.
class OutputTransaction {
 public:
  /// Lock OUT (`out`, shown as the user wrote it), refuse an OUT that is not a directory of
  /// earlier `kind` outputs or holds the current directory, and clear the leftovers of
  /// killed runs. Throws UsageError.
  OutputTransaction(const std::string& out, OutputKind kind);
  /// Removes the staging directory unless committed; releases the lock.
  ~OutputTransaction();
  OutputTransaction(const OutputTransaction&) = delete;             ///< One owner.
  OutputTransaction& operator=(const OutputTransaction&) = delete;  ///< One owner.

  /// Create the (empty) staging directory and return it. Throws UsageError.
  const std::filesystem::path& stage();
  /// The staging directory (after stage()).
  [[nodiscard]] const std::filesystem::path& staging() const { return staging_; }
  /// OUT as the user wrote it.
  [[nodiscard]] const std::string& shown() const { return shown_; }
  /// "the previous outputs in 'OUT' are unchanged" or "nothing was written to 'OUT'".
  [[nodiscard]] std::string unchanged() const;
  /// Swap the staging directory into place and remove the old outputs. Throws
  /// InternalError (saying where the outputs are) if the swap fails.
  void commit(const RenameOps& ops = system_renames());
  /// Remove the staging directory now (idempotent, never throws).
  void abort() noexcept;

 private:
  std::string shown_;
  std::filesystem::path target_, parent_, staging_, old_;
  /// Unlink OUT.lock and release it (idempotent).
  void release_lock() noexcept;

  std::string lock_path_;  ///< OUT.lock beside OUT.
  int lock_fd_ = -1;
  bool had_outputs_ = false;
  bool committed_ = false;
};

}  // namespace hybgen::gen
