// libFuzzer harness over `hybgen run --set KEY=VALUE` values: parse_grid and
// apply_overrides on a fixed checked model (fuzz/overrides_pipeline.hpp says
// what is expected and what is a finding).

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <string_view>

#include "hybgen/gen/errors.hpp"
#include "overrides_pipeline.hpp"

namespace {

[[noreturn]] void finding(const char* what, const std::string& detail) {
  std::fprintf(stderr, "fuzz_overrides: %s: %s\n", what, detail.c_str());
  std::abort();
}

template <class F>
void expect_clean(const char* stage, F&& f) {
  try {
    const std::string wrong = f();
    if (!wrong.empty()) finding("silently wrong", std::string(stage) + ": " + wrong);
  } catch (const hybgen::gen::InternalError& e) {
    finding("internal error (exit 70)", std::string(stage) + ": " + e.what());
  } catch (const hybgen::gen::Error&) {
    // expected: a bad --set value, reported as such
  } catch (const std::exception& e) {
    finding("unexpected exception", std::string(stage) + ": " + e.what());
  } catch (...) {
    finding("unexpected non-standard exception", stage);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > hybgen::fuzz::kMaxOverrideBytes) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)hybgen::fuzz::overrides_base_model();
  expect_clean("parse_grid", [&] { return hybgen::fuzz::run_parse_grid(text); });
  expect_clean("apply_overrides", [&] { return hybgen::fuzz::run_overrides(text); });
  return 0;
}
