// The output-directory transaction (generator/src/outputs.cpp): the swap and its fallback
// with each rename failing in turn (injected through RenameOps), what may be replaced, the
// lock, and a transaction that ends without a commit. tests/e2e/test_failures.cpp kills
// real runs mid-swap.

#include "hybgen/gen/outputs.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/rt/io/json_text.hpp"

namespace {

namespace fs = std::filesystem;
using namespace hybgen::gen;

/// A fresh directory for one test.
fs::path fresh(const std::string& name) {
  const fs::path d =
      fs::temp_directory_path() / ("hybgen_test_outputs_" + std::to_string(::getpid())) / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void put(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file) << text;
}

std::string get(const fs::path& file) {
  return fs::exists(file) ? read_file(file.string()) : "<missing>";
}

// Injected renames: the exchange is unsupported (as on a file system without
// RENAME_EXCHANGE), and the rename numbered `fail_at` (1-based) fails with EIO.
int g_calls = 0, g_fail_at = 0, g_fail_from = 0;
int no_exchange(const char*, const char*) {
  errno = EINVAL;
  return -1;
}
int exchange_eio(const char*, const char*) {
  errno = EIO;
  return -1;
}
int flaky_rename(const char* a, const char* b) {
  ++g_calls;
  if (g_calls == g_fail_at || (g_fail_from && g_calls >= g_fail_from)) {
    errno = EIO;
    return -1;
  }
  return std::rename(a, b);
}
const RenameOps kFallback{no_exchange, flaky_rename};

struct Dirs {
  fs::path staging, target, old;
};
Dirs setup(const std::string& name) {
  const fs::path d = fresh(name);
  Dirs s{d / "out.partial-1", d / "out", d / "out.old-1"};
  put(s.staging / "u.npy", "new");
  put(s.target / "u.npy", "old");
  g_calls = 0;
  g_fail_at = 0;
  g_fail_from = 0;
  return s;
}

TEST(Outputs, ExchangeSwapsAndKeepsTheOldUnderTheStagingName) {
  const Dirs d = setup("exchange");
  const SwapResult r = swap_into_place(d.staging, d.target, d.old, true);
  ASSERT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(get(d.target / "u.npy"), "new");
  EXPECT_EQ(get(d.staging / "u.npy"), "old");  // the caller removes it
}

TEST(Outputs, FallbackMovesAsideThenInThenRenamesTheOld) {
  const Dirs d = setup("fallback");
  const SwapResult r = swap_into_place(d.staging, d.target, d.old, true, kFallback);
  ASSERT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(g_calls, 3);
  EXPECT_EQ(get(d.target / "u.npy"), "new");
  EXPECT_EQ(get(d.staging / "u.npy"), "old");
  EXPECT_FALSE(fs::exists(d.old));
}

TEST(Outputs, FallbackFailingToMoveAsideChangesNothing) {
  const Dirs d = setup("aside");
  g_fail_at = 1;
  const SwapResult r = swap_into_place(d.staging, d.target, d.old, true, kFallback);
  EXPECT_NE(r.error.find("cannot move it aside"), std::string::npos) << r.error;
  EXPECT_TRUE(r.stranded.empty());
  EXPECT_EQ(get(d.target / "u.npy"), "old");
  EXPECT_EQ(get(d.staging / "u.npy"), "new");
}

TEST(Outputs, FallbackFailingToMoveInPutsTheOldBack) {
  const Dirs d = setup("back");
  g_fail_at = 2;  // staging -> target
  const SwapResult r = swap_into_place(d.staging, d.target, d.old, true, kFallback);
  EXPECT_NE(r.error.find("cannot move the new outputs into it"), std::string::npos) << r.error;
  EXPECT_TRUE(r.stranded.empty());
  EXPECT_EQ(get(d.target / "u.npy"), "old");  // rolled back
  EXPECT_FALSE(fs::exists(d.old));
}

TEST(Outputs, FallbackFailingTwiceSaysWhereBothSetsAre) {
  const Dirs d = setup("stranded");
  g_fail_from = 2;  // the move in and the move back
  const SwapResult r = swap_into_place(d.staging, d.target, d.old, true, kFallback);
  EXPECT_NE(r.error.find("nor could the previous outputs be moved back"), std::string::npos);
  EXPECT_NE(r.stranded.find(d.old.string()), std::string::npos) << r.stranded;
  EXPECT_NE(r.stranded.find(d.staging.string()), std::string::npos) << r.stranded;
  EXPECT_EQ(get(d.old / "u.npy"), "old");  // both sets intact, where it says
  EXPECT_EQ(get(d.staging / "u.npy"), "new");
}

TEST(Outputs, FallbackFailingAtTheLastRenameStillSucceeds) {
  const Dirs d = setup("last");
  g_fail_at = 3;  // old -> staging name: the new outputs are in place, the old stay as .old-
  const SwapResult r = swap_into_place(d.staging, d.target, d.old, true, kFallback);
  EXPECT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(get(d.target / "u.npy"), "new");
  EXPECT_EQ(get(d.old / "u.npy"), "old");
}

TEST(Outputs, ExchangeFailingOtherwiseIsAnError) {
  const Dirs d = setup("eio");
  const SwapResult r =
      swap_into_place(d.staging, d.target, d.old, true, RenameOps{exchange_eio, flaky_rename});
  EXPECT_NE(r.error.find("cannot exchange"), std::string::npos) << r.error;
  EXPECT_EQ(g_calls, 0);  // no fallback for a real failure
  EXPECT_EQ(get(d.target / "u.npy"), "old");
}

TEST(Outputs, ForeignEntriesByKind) {
  const fs::path d = fresh("foreign");
  put(d / "u_0000.npy", "");
  put(d / "summary.json", "");
  EXPECT_EQ(foreign_entry(d, OutputKind::Run), "");
  put(d / "0_e=1" / "u_0000.npy", "");
  EXPECT_EQ(foreign_entry(d, OutputKind::Run), "0_e=1");  // a run has no subdirectory
  put(d / "sweep.csv", "");
  EXPECT_EQ(foreign_entry(d, OutputKind::Sweep), "");
  put(d / "0_e=1" / "notes.txt", "");
  EXPECT_EQ(foreign_entry(d, OutputKind::Sweep), "0_e=1/notes.txt");
}

TEST(Outputs, TransactionCommitsReplacesAndCleansUp) {
  const fs::path d = fresh("commit");
  const std::string out = (d / "run").string();
  put(d / "run" / "u_0000.npy", "old");
  g_calls = g_fail_at = g_fail_from = 0;
  {
    OutputTransaction tx(out, OutputKind::Run);
    const fs::path s = tx.stage();
    EXPECT_EQ(s.parent_path(), d);
    put(s / "u_0000.npy", "new");
    EXPECT_NE(tx.unchanged().find("are unchanged"), std::string::npos);
    tx.commit(kFallback);  // the fallback path end to end
  }
  EXPECT_EQ(get(d / "run" / "u_0000.npy"), "new");
  for (const auto& e : fs::directory_iterator(d)) {
    const std::string n = e.path().filename().string();
    EXPECT_TRUE(n == "run" || n == "run.lock") << n;  // no staging or old directory left
  }
}

TEST(Outputs, TransactionWithoutCommitLeavesOutAsItWas) {
  const fs::path d = fresh("abort");
  const std::string out = (d / "run").string();
  put(d / "run" / "u_0000.npy", "old");
  fs::path staging;
  {
    OutputTransaction tx(out, OutputKind::Run);
    staging = tx.stage();
    put(staging / "u_0000.npy", "half");
  }  // e.g. the runner failed
  EXPECT_FALSE(fs::exists(staging));
  EXPECT_EQ(get(d / "run" / "u_0000.npy"), "old");
}

TEST(Outputs, TransactionRefusesForeignFilesAndASecondWriter) {
  const fs::path d = fresh("refuse");
  put(d / "run" / "paper.tex", "mine");
  EXPECT_THROW(OutputTransaction((d / "run").string(), OutputKind::Run), UsageError);
  EXPECT_EQ(get(d / "run" / "paper.tex"), "mine");
  put(d / "file", "");
  EXPECT_THROW(OutputTransaction((d / "file").string(), OutputKind::Run), UsageError);

  const OutputTransaction first((d / "locked").string(), OutputKind::Run);
  try {
    const OutputTransaction second((d / "locked").string(), OutputKind::Run);
    FAIL() << "a second transaction on the same directory was allowed";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("another hybgen run"), std::string::npos) << e.what();
  }
}

TEST(Outputs, NoLockFileOutlivesATransaction) {
  // OUT.lock is unlinked by its holder before it lets go, whether the transaction commits,
  // aborts or is refused after locking (a foreign file in OUT); a run that meanwhile opened
  // the unlinked file does not take a lock on it (outputs.cpp checks the inode it locked).
  const fs::path d = fresh("lockfile");
  {
    OutputTransaction tx((d / "run").string(), OutputKind::Run);
    EXPECT_TRUE(fs::exists(d / "run.lock"));
    put(tx.stage() / "u_0000.npy", "new");
    tx.commit();
  }
  EXPECT_FALSE(fs::exists(d / "run.lock"));
  { const OutputTransaction tx((d / "aborted").string(), OutputKind::Run); }
  EXPECT_FALSE(fs::exists(d / "aborted.lock"));
  put(d / "foreign" / "paper.tex", "mine");
  EXPECT_THROW(OutputTransaction((d / "foreign").string(), OutputKind::Run), UsageError);
  EXPECT_FALSE(fs::exists(d / "foreign.lock"));
}

TEST(Outputs, TransactionRestoresTheOutputsOfARunKilledMidSwap) {
  // A run killed between the fallback's renames left OUT missing, the complete old set as
  // OUT.old-<pid> and a staging directory: the next transaction restores the first and
  // removes the second.
  const fs::path d = fresh("restore");
  put(d / "run.old-4242" / "u_0000.npy", "old");
  put(d / "run.partial-4242" / "u_0000.npy", "half");
  const OutputTransaction tx((d / "run").string(), OutputKind::Run);
  EXPECT_EQ(get(d / "run" / "u_0000.npy"), "old");
  EXPECT_FALSE(fs::exists(d / "run.old-4242"));
  EXPECT_FALSE(fs::exists(d / "run.partial-4242"));
}

TEST(Outputs, LeftoverNamesAreThoseTheProtocolGives) {
  EXPECT_TRUE(is_leftover_name("run.old-123", "run"));
  EXPECT_TRUE(is_leftover_name("run.partial-7", "run"));
  EXPECT_FALSE(is_leftover_name("run.old-v1", "run"));  // a user's backup
  EXPECT_FALSE(is_leftover_name("run.partial-", "run"));
  EXPECT_FALSE(is_leftover_name("run.partial-12a", "run"));
  EXPECT_FALSE(is_leftover_name("runs.old-12", "run"));
}

TEST(Outputs, AUsersDirectoryBesideOutIsLeftAlone) {
  // `results.old-v1` is the user's, and `run.old-99` holds a file hybgen did not write: the
  // transaction neither removes nor restores them.
  const fs::path d = fresh("beside");
  put(d / "run.old-v1" / "u_0000.npy", "mine");
  put(d / "run.old-99" / "notes.txt", "mine too");
  {
    OutputTransaction tx((d / "run").string(), OutputKind::Run);
    put(tx.stage() / "u_0000.npy", "new");
    tx.commit();
  }
  EXPECT_EQ(get(d / "run.old-v1" / "u_0000.npy"), "mine");
  EXPECT_EQ(get(d / "run.old-99" / "notes.txt"), "mine too");
  EXPECT_EQ(get(d / "run" / "u_0000.npy"), "new");
}

TEST(JsonText, ScalarArraysStayOnOneLineAndTheTextParsesBack) {
  // The files a run writes: dump(2)'s layout, a flat array on one line (a81ba15 wrote
  // summary.json one number per line, 709 lines for the shipped ball).
  const nlohmann::json j = {{"times", {0.0, 0.1, 1.0 / 3.0}},
                            {"model", "ball"},
                            {"empty", nlohmann::json::array()},
                            {"none", nlohmann::json::object()},
                            {"grid", {{"axes", {{{"name", "x"}, {"n", 75}}, {{"name", "p"}}}}}},
                            {"flags", {true, nullptr, "a\"b"}}};
  const std::string text = hybgen::rt::json_file_text(j);
  EXPECT_EQ(nlohmann::json::parse(text), j);  // doubles round-trip: 1/3 exactly
  EXPECT_NE(text.find("\"times\": [0.0, 0.1, 0.3333333333333333]"), std::string::npos) << text;
  EXPECT_NE(text.find("\"flags\": [true, null, \"a\\\"b\"]"), std::string::npos) << text;
  EXPECT_NE(text.find("\"empty\": []"), std::string::npos) << text;
  EXPECT_NE(text.find("\"none\": {}"), std::string::npos) << text;
  // Arrays of objects keep one element per line, indented as dump(2) would.
  EXPECT_NE(text.find("\"axes\": [\n      {\n        \"n\": 75,"), std::string::npos) << text;
  EXPECT_EQ(text.back(), '\n');
  // An ordered_json keeps its order (sweep.json's rows follow sweep.csv's columns).
  nlohmann::ordered_json row;
  row["point"] = 0;
  row["dir"] = "0_e=0.5";
  row["e"] = 0.5;
  EXPECT_EQ(hybgen::rt::json_file_text(row),
            "{\n  \"point\": 0,\n  \"dir\": \"0_e=0.5\",\n  \"e\": 0.5\n}\n");
}

}  // namespace
