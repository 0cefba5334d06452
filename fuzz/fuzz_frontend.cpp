// libFuzzer harness over the whole front end: SourceText (validate) -> parse
// -> check -> derive, and for Lie-group models parse -> check_lie -> reduce
// (reduced and unreduced) -> derive, with the resource caps of
// frontend_pipeline.hpp.
//
// Expected: success, or a hybgen::gen::Error that is not an InternalError
// (a model error, exit 1, or a usage error). A finding is anything else: an
// InternalError (exit 70), any other exception, a crash, an ASan/UBSan
// report, a leak, or a hang (run with -timeout=10; fuzz/run.sh does).

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string_view>

#include "frontend_pipeline.hpp"
#include "hybgen/gen/errors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    (void)hybgen::fuzz::run_frontend(text);
  } catch (const hybgen::gen::InternalError& e) {
    std::fprintf(stderr, "fuzz_frontend: internal error (exit 70): %s\n", e.what());
    std::abort();
  } catch (const hybgen::gen::Error&) {
    // expected: the model is wrong, and hybgen said so
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_frontend: unexpected exception: %s\n", e.what());
    std::abort();
  } catch (...) {
    std::fprintf(stderr, "fuzz_frontend: unexpected non-standard exception\n");
    std::abort();
  }
  return 0;
}
