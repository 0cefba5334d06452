#pragma once
/// \file atomic_file.hpp
/// Atomic file output: the bytes go to `<path>.tmp.<pid>.<counter>` in the
/// same directory, are flushed and fsync'ed, and only then renamed over
/// `path`. A reader therefore sees either the previous file or the complete
/// new one, never a torn write. Every system call is checked; a failure
/// (full disk, missing directory, ...) throws std::runtime_error naming the
/// destination, e.g. "cannot write 'out/u_0001.npy': No space left on
/// device", removes the temporary file and leaves any previous file intact.

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>

namespace hybgen::rt {

namespace detail {

/// How many DeferredDurability scopes are alive: while any is, commits skip their fsyncs.
inline std::atomic<int> deferred_durability{0};

/// Process-wide counter that makes temporary names unique across threads.
inline std::atomic<unsigned long long> atomic_file_counter{0};

/// The message for a failed system call on `path`: "cannot write 'path': <what>: <errno text>".
inline std::string io_error_message(const std::string& path, std::string_view what, int err) {
  std::string msg = "cannot write '" + path + "': ";
  if (!what.empty()) {
    msg += what;
    msg += ": ";
  }
  msg += std::generic_category().message(err);
  return msg;
}

}  // namespace detail

/// A file being written atomically: construct, `write` any number of times, then
/// `commit`. Destroying it without a successful commit removes the temporary file
/// and leaves the destination untouched.
class AtomicFile {
 public:
  /// Creates the temporary file next to `path`; throws std::runtime_error on failure.
  explicit AtomicFile(std::string path) : path_(std::move(path)) {
    for (int attempt = 0;; ++attempt) {  // retry only if a stale temporary has our name
      tmp_path_ = path_ + ".tmp." + std::to_string(::getpid()) + "." +
                  std::to_string(detail::atomic_file_counter.fetch_add(1));
      fd_ = ::open(tmp_path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
      if (fd_ >= 0) break;
      const int err = errno;
      if (err != EEXIST || attempt >= 100) {
        tmp_path_.clear();
        throw std::runtime_error(detail::io_error_message(path_, "", err));
      }
    }
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  /// Discards the temporary file unless `commit` succeeded.
  ~AtomicFile() { discard(); }

  /// Appends `size` bytes; throws std::runtime_error (and discards the file) on failure.
  void write(const void* data, std::size_t size) {
    if (fd_ < 0) throw std::logic_error("AtomicFile::write after commit or failure: " + path_);
    const char* p = static_cast<const char*>(data);
    while (size > 0) {
      const ::ssize_t n = ::write(fd_, p, size);
      if (n < 0) {
        if (errno == EINTR) continue;
        fail("", errno);
      }
      if (n == 0) fail("", EIO);
      p += n;
      size -= static_cast<std::size_t>(n);
    }
  }
  /// Appends the bytes of `s`.
  void write(std::string_view s) { write(s.data(), s.size()); }

  /// Flushes to stable storage and renames the temporary file over the destination.
  void commit() {
    if (fd_ < 0) throw std::logic_error("AtomicFile::commit twice or after failure: " + path_);
    const bool durable_now = detail::deferred_durability.load() == 0;
    if (durable_now && ::fsync(fd_) != 0) fail("fsync", errno);
    const int fd = std::exchange(fd_, -1);
    if (::close(fd) != 0) fail("close", errno);
    if (::rename(tmp_path_.c_str(), path_.c_str()) != 0) fail("rename", errno);
    committed_ = true;
    if (durable_now) sync_directory();
  }

  /// The destination path.
  const std::string& path() const { return path_; }
  /// The temporary path the bytes go to before `commit`.
  const std::string& temp_path() const { return tmp_path_; }

 private:
  /// Closes and unlinks the temporary file (no-op after a successful commit).
  void discard() noexcept {
    if (fd_ >= 0) ::close(std::exchange(fd_, -1));
    if (!committed_ && !tmp_path_.empty()) {
      ::unlink(tmp_path_.c_str());
      tmp_path_.clear();
    }
  }
  /// Discards the temporary file and throws the error for `err`.
  [[noreturn]] void fail(std::string_view what, int err) {
    discard();
    throw std::runtime_error(detail::io_error_message(path_, what, err));
  }
  /// Best effort: makes the rename itself durable by syncing the directory.
  void sync_directory() const noexcept {
    const std::size_t slash = path_.find_last_of('/');
    const std::string dir =
        slash == std::string::npos ? "." : (slash == 0 ? "/" : path_.substr(0, slash));
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
      ::fsync(dfd);
      ::close(dfd);
    }
  }

  std::string path_;
  std::string tmp_path_;
  int fd_ = -1;
  bool committed_ = false;
};

/// A staging directory whose files become durable together: while a scope is alive,
/// AtomicFile commits skip their two fsyncs (the file's, the directory's), and `commit`
/// makes everything written so far durable with one syncfs(2) on the directory's file
/// system. For a directory that is published as a whole afterwards (hybgen's
/// `OUT.partial-PID`, swapped into place by generator/src/outputs.cpp): a crash before
/// `commit` loses only the staging directory, never a published file. 51 frames of three
/// files each cost 306 fsyncs before; now one call.
class DeferredDurability {
 public:
  /// Defers the fsyncs of every AtomicFile until `commit` (process-wide).
  explicit DeferredDurability(std::string dir) : dir_(std::move(dir)) {
    detail::deferred_durability.fetch_add(1);
  }
  DeferredDurability(const DeferredDurability&) = delete;
  DeferredDurability& operator=(const DeferredDurability&) = delete;
  /// Ends the deferral (without syncing, unless `commit` ran).
  ~DeferredDurability() { detail::deferred_durability.fetch_sub(1); }

  /// Flushes the directory's file system (syncfs reports writeback errors since Linux 5.8);
  /// throws std::runtime_error naming the directory.
  void commit() const {
    const int dfd = ::open(dir_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd < 0) throw std::runtime_error(detail::io_error_message(dir_, "open", errno));
    const int rc = ::syncfs(dfd), err = errno;
    ::close(dfd);
    if (rc != 0) throw std::runtime_error(detail::io_error_message(dir_, "syncfs", err));
  }

 private:
  std::string dir_;
};

/// Writes `size` bytes to `path` atomically (see AtomicFile); throws std::runtime_error.
inline void write_file_atomic(const std::string& path, const void* data, std::size_t size) {
  AtomicFile file(path);
  file.write(data, size);
  file.commit();
}

/// Writes `contents` to `path` atomically (see AtomicFile); throws std::runtime_error.
inline void write_file_atomic(const std::string& path, std::string_view contents) {
  write_file_atomic(path, contents.data(), contents.size());
}

}  // namespace hybgen::rt
