// The output-directory transaction (outputs.hpp).

#include "hybgen/gen/outputs.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <vector>

#include "hybgen/gen/errors.hpp"
#include "hybgen/rt/io/run_files.hpp"

namespace hybgen::gen {

namespace fs = std::filesystem;

namespace {

int exchange_paths(const char* a, const char* b) {
  return ::renameat2(AT_FDCWD, a, AT_FDCWD, b, RENAME_EXCHANGE);
}

int rename_path(const char* from, const char* to) {
  return ::rename(from, to);
}

/// Best effort: make renames in `dir` durable.
void sync_directory(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

/// Whether `name` (with extension `ext`) is a file a run writes, or an atomic write's temporary.
bool run_file(const std::string& name, const std::string& ext) {
  return rt::is_run_file_extension(ext) || name.find(".tmp.") != std::string::npos;
}

}  // namespace

bool is_leftover_name(const std::string& entry, const std::string& name) {
  for (const char* kind : {".partial-", ".old-"}) {
    const std::string prefix = name + kind;
    if (entry.size() > prefix.size() && entry.rfind(prefix, 0) == 0 &&
        std::all_of(entry.begin() + static_cast<long>(prefix.size()), entry.end(),
                    [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }))
      return true;
  }
  return false;
}

const RenameOps& system_renames() {
  static const RenameOps ops{exchange_paths, rename_path};
  return ops;
}

SwapResult swap_into_place(const fs::path& staging, const fs::path& target, const fs::path& old,
                           bool had_outputs, const RenameOps& ops) {
  if (had_outputs) {
    if (ops.exchange(staging.c_str(), target.c_str()) == 0) return {};
    if (errno != EINVAL && errno != ENOSYS)
      return {std::string("cannot exchange it with the new outputs: ") + std::strerror(errno), {}};
    if (ops.rename(target.c_str(), old.c_str()) != 0)
      return {std::string("cannot move it aside: ") + std::strerror(errno), {}};
  }
  if (ops.rename(staging.c_str(), target.c_str()) != 0) {
    const std::string err =
        "cannot move the new outputs into it: " + std::string(std::strerror(errno));
    if (had_outputs && ops.rename(old.c_str(), target.c_str()) != 0)
      return {err + "; nor could the previous outputs be moved back (" + std::strerror(errno) + ")",
              "the previous outputs are in '" + old.string() + "', the new ones in '" +
                  staging.string() + "'"};
    return {err, {}};
  }
  if (had_outputs && ops.rename(old.c_str(), staging.c_str()) != 0)
    std::cerr << "hybgen: warning: the previous outputs stay in '" << old.string()
              << "': " << std::strerror(errno) << "\n";
  return {};
}

namespace {

/// The first entry of a run's report assets directory (recursively) that a run did not
/// write, or "".
std::string foreign_asset(const fs::path& dir) {
  std::error_code ec;
  for (const auto& e : fs::recursive_directory_iterator(dir, ec)) {
    if (e.is_directory(ec)) continue;
    if (!e.is_regular_file(ec) || !rt::is_report_asset_extension(e.path().extension().string()))
      return fs::relative(e.path(), dir.parent_path()).string();
  }
  return ec ? dir.filename().string() : "";
}

}  // namespace

std::string foreign_entry(const fs::path& dir, OutputKind kind) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string n = e.path().filename().string();
    const std::string x = e.path().extension().string();
    if (n == rt::kReportAssetsDirectory && e.is_directory(ec) && !e.is_symlink(ec)) {
      if (const std::string f = foreign_asset(e.path()); !f.empty()) return f;
      continue;
    }
    if (kind == OutputKind::Sweep && e.is_directory(ec)) {
      // A point's directory: its own entries must be a run's.
      if (const std::string f = foreign_entry(e.path(), OutputKind::Run); !f.empty())
        return n + "/" + f;
      continue;
    }
    const bool ok = run_file(n, x) || (kind == OutputKind::Sweep && x == ".csv");
    if (!e.is_regular_file(ec) || !ok) return n;
  }
  return ec ? dir.filename().string() : "";
}

OutputTransaction::OutputTransaction(const std::string& out, OutputKind kind) : shown_(out) {
  // OUT as an absolute path without a trailing separator; its siblings share its name.
  target_ = fs::absolute(fs::path(out)).lexically_normal();
  if (target_.filename().empty()) target_ = target_.parent_path();
  if (target_ == target_.root_path())
    throw UsageError("cannot use '" + out + "' as the output directory");
  parent_ = target_.parent_path();
  const std::string name = target_.filename().string();
  std::error_code ec;
  fs::create_directories(parent_, ec);
  if (ec) throw UsageError("cannot create the output directory '" + out + "': " + ec.message());

  // An exclusive, non-blocking flock on OUT.lock: two runs into the same OUT cannot
  // interleave; the second one is refused. The holder unlinks the file before it lets go
  // (release_lock), so no lock file outlives a run. That a lock is held on the file the path
  // names is checked after locking (same device and inode): a run that opened the file just
  // before its holder unlinked it would otherwise hold a lock on a file nobody else sees.
  lock_path_ = (parent_ / (name + ".lock")).string();
  for (int attempt = 0;; ++attempt) {
    lock_fd_ = ::open(lock_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (lock_fd_ < 0)
      throw UsageError("cannot create the lock file '" + lock_path_ + "': " + std::strerror(errno));
    if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      ::close(lock_fd_);
      if (err == EWOULDBLOCK) throw UsageError("another hybgen run is writing to '" + out + "'");
      throw UsageError("cannot lock '" + lock_path_ + "': " + std::strerror(err));
    }
    struct stat held {
    }, named{};
    if (::fstat(lock_fd_, &held) == 0 && ::stat(lock_path_.c_str(), &named) == 0 &&
        held.st_dev == named.st_dev && held.st_ino == named.st_ino)
      break;
    ::close(lock_fd_);  // the holder unlinked it meanwhile: the run it protected has ended
    if (attempt == 8) throw UsageError("cannot lock '" + lock_path_ + "': it keeps being replaced");
  }
  try {
    // OUT is replaced as a whole: refuse anything but a directory of earlier outputs.
    if (fs::exists(target_, ec)) {
      if (!fs::is_directory(target_, ec))
        throw UsageError("the output directory '" + out + "' exists and is not a directory");
      const fs::path cwd = fs::current_path(ec);
      if (!ec && std::mismatch(target_.begin(), target_.end(), cwd.begin(), cwd.end()).first ==
                     target_.end())
        throw UsageError("refusing to replace '" + out +
                         "': it is (or contains) the current directory; choose another --out");
      if (const std::string f = foreign_entry(target_, kind); !f.empty())
        throw UsageError("refusing to replace '" + out + "': it holds '" + f +
                         "', which hybgen did not write " +
                         (kind == OutputKind::Run ? "(a run replaces the whole directory)"
                                                  : "(a sweep replaces the whole directory)") +
                         "; choose another --out");
    }
    // Leftovers of runs that were killed (we hold the lock, so nobody else is using them):
    // staging directories are incomplete and go; an old-outputs directory is complete, and
    // if OUT is missing (a run killed between the fallback's two renames) it is OUT again.
    // Only names this protocol gives (NAME.partial-PID, NAME.old-PID, PID digits) whose contents
    // are outputs: a user's own `results.old-v1` beside OUT is not ours to touch.
    std::vector<fs::path> leftovers;
    for (const auto& e : fs::directory_iterator(parent_, ec)) {
      const std::string n = e.path().filename().string();
      if (!is_leftover_name(n, name) || !e.is_directory(ec)) continue;
      if (const std::string f = foreign_entry(e.path(), kind); !f.empty()) {
        std::cerr << "hybgen: warning: leaving '" << e.path().string() << "' alone: it holds '" << f
                  << "', which hybgen did not write\n";
        continue;
      }
      leftovers.push_back(e.path());
    }
    std::sort(leftovers.begin(), leftovers.end());
    for (const auto& p : leftovers) {
      if (p.filename().string().rfind(name + ".old-", 0) == 0 && !fs::exists(target_, ec) &&
          ::rename(p.c_str(), target_.c_str()) == 0) {
        std::cerr << "hybgen: restored the outputs of an interrupted run from '" << p.string()
                  << "' to '" << out << "'\n";
        continue;
      }
      fs::remove_all(p, ec);
    }
  } catch (...) {
    release_lock();
    throw;
  }
}

void OutputTransaction::release_lock() noexcept {
  if (lock_fd_ < 0) return;
  ::unlink(lock_path_.c_str());  // while held: see the constructor
  ::close(lock_fd_);
  lock_fd_ = -1;
}

OutputTransaction::~OutputTransaction() {
  if (!committed_) abort();
  release_lock();
}

const fs::path& OutputTransaction::stage() {
  const std::string tag = std::to_string(::getpid());
  const std::string name = target_.filename().string();
  staging_ = parent_ / (name + ".partial-" + tag);
  old_ = parent_ / (name + ".old-" + tag);
  std::error_code ec;
  fs::remove_all(staging_, ec);
  if (!ec && !fs::create_directory(staging_, ec) && !ec)
    ec = std::make_error_code(std::errc::file_exists);
  if (ec)
    throw UsageError("cannot create the staging directory '" + staging_.string() +
                     "': " + ec.message());
  had_outputs_ = fs::exists(target_, ec);
  return staging_;
}

std::string OutputTransaction::unchanged() const {
  return had_outputs_ ? "the previous outputs in '" + shown_ + "' are unchanged"
                      : "nothing was written to '" + shown_ + "'";
}

void OutputTransaction::commit(const RenameOps& ops) {
  // Swap: the new outputs into OUT, the old ones (if any) under the staging name, removed.
  if (const SwapResult sw = swap_into_place(staging_, target_, old_, had_outputs_, ops);
      !sw.error.empty()) {
    if (!sw.stranded.empty()) {
      committed_ = true;  // the staging directory holds the only copy of the new outputs
      throw InternalError("cannot replace the outputs in '" + shown_ + "': " + sw.error + "; " +
                          sw.stranded);
    }
    abort();
    throw InternalError("cannot replace the outputs in '" + shown_ + "': " + sw.error + "; " +
                        unchanged());
  }
  committed_ = true;
  sync_directory(parent_);
  std::error_code ec;
  if (had_outputs_ && fs::exists(staging_, ec)) {
    fs::remove_all(staging_, ec);
    if (ec)
      std::cerr << "hybgen: warning: cannot remove the previous outputs '" << staging_.string()
                << "': " << ec.message() << "\n";
  }
}

void OutputTransaction::abort() noexcept {
  if (staging_.empty()) return;
  std::error_code ec;
  fs::remove_all(staging_, ec);
}

}  // namespace hybgen::gen
