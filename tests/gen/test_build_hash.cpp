// The build cache's memo of file hashes (generator/src/build.cpp, file_sha256): the hash of
// a file is remembered under its size and modification time, and a changed file is hashed
// again, never served a stale hash.

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>

#include "hybgen/gen/build.hpp"
#include "hybgen/gen/hash.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::gen::file_sha256;
using hybgen::gen::sha256_hex;

class BuildHash : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("hybgen_build_hash_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "memo");
    file_ = (dir_ / "lib.a").string();
  }
  void TearDown() override { fs::remove_all(dir_); }
  void write(const std::string& text) { std::ofstream(file_, std::ios::binary) << text; }
  std::size_t memos() const {
    std::size_t n = 0;
    for (const auto& e : fs::directory_iterator(dir_ / "memo")) n += e.is_regular_file() ? 1 : 0;
    return n;
  }
  fs::path dir_;
  std::string file_;
};

TEST_F(BuildHash, RemembersAndNoticesAChange) {
  write("first contents");
  EXPECT_EQ(file_sha256(file_, dir_ / "memo"), sha256_hex("first contents"));
  EXPECT_EQ(memos(), 1u);
  EXPECT_EQ(file_sha256(file_, dir_ / "memo"), sha256_hex("first contents"));  // from the memo
  // The same size, new contents, a later modification time: hashed again.
  write("other contents");
  const auto later = fs::last_write_time(file_) + std::chrono::seconds(2);
  fs::last_write_time(file_, later);
  EXPECT_EQ(file_sha256(file_, dir_ / "memo"), sha256_hex("other contents"));
  // A different size with the time set back: hashed again too.
  write("a longer third contents");
  fs::last_write_time(file_, later);
  EXPECT_EQ(file_sha256(file_, dir_ / "memo"), sha256_hex("a longer third contents"));
  EXPECT_EQ(memos(), 1u);
}

TEST_F(BuildHash, ACorruptMemoIsIgnoredAndAMissingFileIsAnError) {
  write("contents");
  (void)file_sha256(file_, dir_ / "memo");
  for (const auto& e : fs::directory_iterator(dir_ / "memo"))
    std::ofstream(e.path(), std::ios::binary) << "garbage";
  EXPECT_EQ(file_sha256(file_, dir_ / "memo"), sha256_hex("contents"));
  EXPECT_THROW((void)file_sha256((dir_ / "missing.a").string(), dir_ / "memo"), std::exception);
}

}  // namespace
