// The density-level differential campaign: random runnable models
// (tests/support/random_run_model.hpp) go through the whole pipeline — `hybgen run` parses,
// checks, derives, emits, compiles and runs them by characteristics — and every node of every
// frame and mode is compared with an independent backward tracer written in the test
// (tests/support/independent_tracer.hpp: the model's expression trees, RK4, Newton inverses,
// dual numbers; nothing from hybgen).
//
// Per model: hybgen's density u_h and the tracer's u_r at every node, frame (t = 0, t_end/2,
// t_end) and mode where the tracer can decide (TraceFlags::unsure leaves out nodes on a jump
// and tangent crossings); a disagreement is |u_h − u_r| > 1e-6 (max u_r over the frame) +
// 1e-6 |u_r|. hybgen's error is its ODE tolerance (1e-10, docs/methods.md); the tracer's is
// RK4 at ≥ 400 steps per unit time (below 1e-8 on these flows). A run must end (600 s) with
// exit 0, or refuse the model with exit 1 (a model error) or 3 (a numerical failure such as a
// pre-flight refusal) and a message — anything else (a usage error, a build failure, an
// internal error, a crash, a time-out) is a disagreement too.
//
// One line per model (seed, states, modes, guards, reset families, nodes compared and left
// out, resets the tracer crossed, the largest difference), one line per disagreement, and
// the last line `N models, K disagreements`. HYBGEN_DIFFERENTIAL_MODELS (default 16) and
// HYBGEN_DIFFERENTIAL_SEED (default 1, the first seed) choose the models;
// scripts/differential.sh N runs N of them. A failing model's file stays in
// build/validation_differential/models/ for `hybgen run`.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"
#include "support/independent_tracer.hpp"
#include "support/random_run_model.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::IndependentTracer;
using hybgen::testing::RandomRunModel;
using hybgen::testing::TraceFlags;

const fs::path kWork = hybgen::testing::e2e_dir("validation_differential");
const hybgen::testing::Hybgen hybgen_cli{kWork / "cache"};

long env_or(const char* name, long fallback) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? std::strtol(v, nullptr, 10) : fallback;
}

const char* kind_name(hybgen::testing::RunResetKind k) {
  switch (k) {
    case hybgen::testing::RunResetKind::Identity:
      return "identity";
    case hybgen::testing::RunResetKind::Affine:
      return "affine";
    case hybgen::testing::RunResetKind::Triangular:
      return "triangular";
    case hybgen::testing::RunResetKind::Restitution:
      return "restitution";
  }
  return "?";
}

/// The outcome of one model.
struct Outcome {
  int disagreements = 0;
  bool refused = false;
};

/// The line of `text` that gives a failure ("numerical failure:", "error:"), or "".
std::string first_error_line(const std::string& text) {
  for (const char* key : {"numerical failure:", "error:"}) {
    const std::size_t at = text.find(key);
    if (at == std::string::npos) continue;
    const std::size_t nl = text.rfind('\n', at);
    const std::size_t start = nl == std::string::npos ? 0 : nl + 1;
    const std::size_t end = text.find('\n', at);
    return text.substr(start, end == std::string::npos ? std::string::npos : end - start);
  }
  return "";
}

/// Run model `seed` through hybgen and compare every decidable node with the tracer.
Outcome check_model(std::uint64_t seed) {
  const auto t0 = std::chrono::steady_clock::now();
  const RandomRunModel r = hybgen::testing::random_run_model(seed);
  const auto& m = r.model;
  const std::string name = "random_run_" + std::to_string(seed);
  const std::string path = hybgen::testing::write_model_file(kWork, name + ".model", m.text);
  const fs::path out = kWork / "runs" / name;
  fs::remove_all(out);
  const auto res = hybgen_cli("run '" + path + "' --quiet --out '" + out.string() +
                                  "' --set method=characteristics --set outputs=npy",
                              "timeout 600 env");
  std::string kinds;
  for (const auto k : r.kinds) kinds += std::string(kinds.empty() ? "" : "+") + kind_name(k);
  std::printf("model %llu: %zu-D, %zu modes, %zu guards (%s), t_end %g: ",
              static_cast<unsigned long long>(seed), m.states.size(), m.modes.size(),
              m.guards.size(), kinds.c_str(), r.t_end);
  Outcome o;
  using hybgen::rt::exit_status;
  using hybgen::rt::ExitCode;
  if (res.code == exit_status(ExitCode::ModelError) ||
      res.code == exit_status(ExitCode::Numerical)) {
    o.refused = true;
    std::printf("refused (exit %d): %s\n", res.code, first_error_line(res.out).c_str());
    if (first_error_line(res.out).empty()) {
      std::printf("  disagreement: a refusal without a message\n");
      o.disagreements = 1;
    }
    return o;
  }
  if (res.code != 0) {
    std::printf(
        "FAILED (exit %d%s)\n%s\n  disagreement: the run did not end as documented "
        "(%s)\n",
        res.code, res.code == 124 ? ", timed out after 600 s" : "", res.out.c_str(), path.c_str());
    o.disagreements = 1;
    return o;
  }
  const nlohmann::json s = hybgen::testing::read_json_file(out / "summary.json");
  const IndependentTracer tracer(r);
  const std::size_t n = m.states.size();
  std::size_t total = 1;
  for (int g : r.grid) total *= static_cast<std::size_t>(g);
  long compared = 0, unsure = 0, resets = 0;
  std::map<std::string, long> why;  // the tracer's reasons for leaving nodes out
  double worst = 0;
  for (std::size_t k = 0; k < s["times"].size(); ++k) {
    const double t = s["times"][k].get<double>();
    for (std::size_t mode = 0; mode < m.modes.size(); ++mode) {
      char frame[96];
      if (m.modes.size() == 1)
        std::snprintf(frame, sizeof frame, "u_%04zu.npy", k);
      else
        std::snprintf(frame, sizeof frame, "u_%04zu_%s.npy", k, m.modes[mode].name.c_str());
      const std::vector<double> uh = hybgen::rt::read_npy((out / frame).string()).data;
      if (uh.size() != total) {
        std::printf("\n  disagreement: %s has %zu values, the grid %zu nodes\n", frame, uh.size(),
                    total);
        ++o.disagreements;
        continue;
      }
      std::vector<double> ur(total, 0.0);
      std::vector<char> skip(total, 0);
      double scale = 0;
      std::vector<double> x(n);
      for (std::size_t node = 0; node < total; ++node) {
        std::size_t rem = node;
        for (std::size_t a = n; a-- > 0;) {
          const int i = static_cast<int>(rem % static_cast<std::size_t>(r.grid[a]));
          rem /= static_cast<std::size_t>(r.grid[a]);
          x[a] = m.lo[a] + (m.hi[a] - m.lo[a]) * i / (r.grid[a] - 1);
        }
        TraceFlags f;
        ur[node] = tracer.density(static_cast<int>(mode), x, t, f);
        resets += f.resets;
        skip[node] = f.unsure ? 1 : 0;
        if (f.unsure) ++why[f.why];
        if (!f.unsure) scale = std::max(scale, std::fabs(ur[node]));
      }
      int shown = 0;
      for (std::size_t node = 0; node < total; ++node) {
        if (skip[node]) {
          ++unsure;
          continue;
        }
        ++compared;
        const double d = std::fabs(uh[node] - ur[node]);
        worst = std::max(worst, scale > 0 ? d / scale : d);
        if (d > 1e-6 * scale + 1e-6 * std::fabs(ur[node]) || !std::isfinite(uh[node])) {
          ++o.disagreements;
          if (shown++ < 3) {
            std::size_t rem = node;
            std::string at;
            for (std::size_t a = n; a-- > 0;) {
              const int i = static_cast<int>(rem % static_cast<std::size_t>(r.grid[a]));
              rem /= static_cast<std::size_t>(r.grid[a]);
              char b[48];
              std::snprintf(b, sizeof b, "%s=%.6g%s", m.states[a].c_str(),
                            m.lo[a] + (m.hi[a] - m.lo[a]) * i / (r.grid[a] - 1),
                            at.empty() ? "" : ", ");
              at = b + at;
            }
            std::printf("\n  disagreement: mode %s, t = %g, (%s): hybgen %.10g, tracer %.10g",
                        m.modes[mode].name.c_str(), t, at.c_str(), uh[node], ur[node]);
          }
        }
      }
    }
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (o.disagreements > 0) std::printf("\n  (%s)\n  ", path.c_str());
  std::string reasons;
  for (const auto& [reason, count] : why)
    reasons += (reasons.empty() ? " (" : "; ") + std::to_string(count) + ": " + reason;
  if (!reasons.empty()) reasons += ")";
  std::printf(
      "%ld nodes compared, %ld left out%s, %ld resets crossed, largest difference "
      "%.1e of the frame's maximum, %d disagreements, %.1f s\n",
      compared, unsure, reasons.c_str(), resets, worst, o.disagreements, secs);
  std::fflush(stdout);
  return o;
}

TEST(Differential, RandomModelsAgreeWithAnIndependentTracer) {
  const long count = env_or("HYBGEN_DIFFERENTIAL_MODELS", 16);
  const long first = env_or("HYBGEN_DIFFERENTIAL_SEED", 1);
  ASSERT_GE(count, 1);
  long bad = 0, refused = 0;
  for (long i = 0; i < count; ++i) {
    const Outcome o = check_model(static_cast<std::uint64_t>(first + i));
    bad += o.disagreements > 0 ? 1 : 0;
    refused += o.refused ? 1 : 0;
  }
  std::printf("%ld models, %ld disagreements (%ld refused with a message)\n", count, bad, refused);
  EXPECT_EQ(bad, 0);
  // A campaign whose models hybgen mostly refuses tests nothing.
  EXPECT_LE(refused * 2, count);
}

}  // namespace
