// Resource limits of the symbolic stage; see limits.hpp.

#include "hybgen/gen/limits.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "hybgen/gen/derive.hpp"

namespace hybgen::gen {

namespace {

thread_local LimitScope* g_scope = nullptr;

/// The object most recently named by any scope, for the watchdog's message.
std::mutex g_object_mutex;
std::string g_object = "the model";
SourceLoc g_object_loc{1, 1};

constexpr double kInf = 1e300;

/// C(n+k−1, k−1), the number of monomials of (k terms)^n, saturating at kInf.
double multinomial_terms(double n, double k) {
  const double log_c = std::lgamma(n + k) - std::lgamma(k) - std::lgamma(n + 1);
  return log_c > std::log(kInf) ? kInf : std::exp(log_c);
}

/// Estimate for e itself (not the maximum over its subexpressions).
double own_terms(const GiNaC::ex& e) {
  if (GiNaC::is_a<GiNaC::add>(e)) {
    double s = 0;
    for (std::size_t i = 0; i < e.nops(); ++i) s += own_terms(e.op(i));
    return std::min(s, kInf);
  }
  if (GiNaC::is_a<GiNaC::mul>(e)) {
    double p = 1;
    for (std::size_t i = 0; i < e.nops(); ++i) p = std::min(p * own_terms(e.op(i)), kInf);
    return p;
  }
  if (GiNaC::is_a<GiNaC::power>(e)) {
    const double k = own_terms(e.op(0));
    if (GiNaC::is_a<GiNaC::numeric>(e.op(1))) {
      if (GiNaC::ex_to<GiNaC::numeric>(e.op(1)).is_pos_integer() && k > 1)
        return multinomial_terms(GiNaC::ex_to<GiNaC::numeric>(e.op(1)).to_double(), k);
      return k;
    }
    // expand(a^(c + x)) = a^c · a^x: a^c is computed exactly when a is a
    // number (finding F8), and expanded when a is a sum.
    const double c = expanded_constant_bound(e.op(1));
    if (c < 1) return k;
    if (GiNaC::is_a<GiNaC::numeric>(e.op(0)))
      return exact_bits(GiNaC::ex_to<GiNaC::numeric>(e.op(0))) * c > kMaxExactBits ? kInf : 1;
    return k > 1 ? multinomial_terms(std::floor(c), k) : k;
  }
  return 1;  // symbols, numbers, functions (their arguments are estimated on their own)
}

}  // namespace

double exact_bits(const GiNaC::numeric& a) {
  if (!a.info(GiNaC::info_flags::crational)) return 0;
  auto bits = [](const GiNaC::numeric& r) {
    return r.is_zero() ? 0.0 : static_cast<double>(r.numer().int_length() + r.denom().int_length());
  };
  return bits(a.real()) + bits(a.imag());
}

bool exact_power_too_large(const GiNaC::numeric& a, const GiNaC::numeric& x) {
  if (!x.is_rational() || !a.info(GiNaC::info_flags::crational) || a.is_zero() ||
      GiNaC::abs(a).is_equal(1))
    return false;
  return exact_bits(a) * GiNaC::abs(x).to_double() > kMaxExactBits;
}

double exact_bits_per_power(const GiNaC::ex& a) {
  if (GiNaC::is_a<GiNaC::numeric>(a)) return exact_bits(GiNaC::ex_to<GiNaC::numeric>(a));
  if (GiNaC::is_a<GiNaC::power>(a) && GiNaC::is_a<GiNaC::numeric>(a.op(1)))
    return std::min(exact_bits_per_power(a.op(0)) *
                        GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(a.op(1))).to_double(),
                    kInf);
  if (GiNaC::is_a<GiNaC::mul>(a)) {
    double s = 0;
    for (std::size_t i = 0; i < a.nops(); ++i) s += exact_bits_per_power(a.op(i));
    return std::min(s, kInf);
  }
  return 0;
}

double expanded_constant_bound(const GiNaC::ex& e) {
  if (GiNaC::is_a<GiNaC::numeric>(e))
    return std::min(GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(e)).to_double(), kInf);
  if (GiNaC::is_a<GiNaC::add>(e)) {
    double s = 0;
    for (std::size_t i = 0; i < e.nops(); ++i) s += expanded_constant_bound(e.op(i));
    return std::min(s, kInf);
  }
  if (GiNaC::is_a<GiNaC::mul>(e)) {
    double p = 1;
    for (std::size_t i = 0; i < e.nops() && p > 0; ++i)
      p = std::min(p * expanded_constant_bound(e.op(i)), kInf);
    return p;
  }
  if (GiNaC::is_a<GiNaC::power>(e) && GiNaC::is_a<GiNaC::numeric>(e.op(1)) &&
      GiNaC::ex_to<GiNaC::numeric>(e.op(1)).is_pos_integer()) {
    const double b = expanded_constant_bound(e.op(0));
    return b == 0 ? 0
                  : std::min(std::pow(b, GiNaC::ex_to<GiNaC::numeric>(e.op(1)).to_double()), kInf);
  }
  return 0;
}

double expanded_terms(const GiNaC::ex& e) {
  double worst = own_terms(e);
  for (std::size_t i = 0; i < e.nops(); ++i) worst = std::max(worst, expanded_terms(e.op(i)));
  return worst;
}

LimitScope::LimitScope(const DeriveLimits& limits)
    : limits_(limits),
      deadline_(std::chrono::steady_clock::now() +
                std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                    std::chrono::duration<double>(std::min(limits.derive_seconds, 1e9)))),
      previous_(g_scope) {
  g_scope = this;
}

LimitScope::~LimitScope() {
  g_scope = previous_;
}

void LimitScope::object(std::string what, SourceLoc loc) {
  what_ = std::move(what);
  loc_ = loc;
  const std::lock_guard<std::mutex> lock(g_object_mutex);
  g_object = what_;
  g_object_loc = loc_;
}

void LimitScope::rethrow_at_object(const SourceText& src) const {
  const std::string at = "deriving " + what_ + ": ";
  try {
    throw;
  } catch (const LimitExceeded& e) {
    throw src.error(loc_, at + e.what());
  } catch (const std::bad_alloc&) {
    throw src.error(loc_, at + "out of memory (the symbolic expressions grew too large)");
  } catch (const std::domain_error& e) {
    // GiNaC differentiates b^e with a symbolic e as b^e·(e'·log b + e·b'·b^(-1)),
    // so for b = 0 it meets 0^(-1) however the model meant 0^e (fuzz finding F11).
    throw src.error(loc_, at + "it is singular (" + e.what() +
                              "), e.g. 0^e with a symbolic exponent e, or a pole");
  }
}

LimitScope* LimitScope::current() {
  return g_scope;
}

void LimitScope::check_time() {
  if (!g_scope || std::chrono::steady_clock::now() < g_scope->deadline_) return;
  char secs[32];
  std::snprintf(secs, sizeof secs, "%g", g_scope->limits_.derive_seconds);
  throw LimitExceeded(std::string("the derivation took longer than derive_seconds = ") + secs +
                      " s (raise it with --set derive_seconds=S)");
}

void LimitScope::check_size(const GiNaC::ex& e) {
  if (!g_scope) return;
  const std::size_t n = expr_size(e);
  if (n > g_scope->limits_.max_expr_nodes)
    throw LimitExceeded(
        "an expression has " + std::to_string(n) +
        " nodes, more than max_expr_nodes = " + std::to_string(g_scope->limits_.max_expr_nodes) +
        " (raise it with --set max_expr_nodes=N)");
}

bool LimitScope::may_expand(const GiNaC::ex& e) {
  return !g_scope || expanded_terms(e) <= g_scope->limits_.max_expand_terms;
}

struct Watchdog::State {
  std::mutex mutex;
  std::condition_variable cv;
  bool done = false;
  std::thread thread;
};

double watchdog_seconds(double derive_seconds) {
  return 1.5 * derive_seconds + 5;
}

Watchdog::Watchdog(std::string file, double derive_seconds, double fire_after)
    : state_(std::make_unique<State>()) {
  State* s = state_.get();
  const double seconds = fire_after < 0 ? watchdog_seconds(derive_seconds) : fire_after;
  s->thread = std::thread([s, file = std::move(file), derive_seconds, seconds] {
    std::unique_lock<std::mutex> lock(s->mutex);
    const auto limit = std::chrono::duration<double>(std::min(seconds, 1e9));
    if (s->cv.wait_for(lock, limit, [s] { return s->done; })) return;
    std::string what;
    SourceLoc loc;
    {
      const std::lock_guard<std::mutex> olock(g_object_mutex);
      what = g_object;
      loc = g_object_loc;
    }
    std::fprintf(stderr,
                 "%s:%d:%d: error: deriving %s took longer than %g s, inside one symbolic "
                 "operation (derive_seconds = %g s, and the one operation that overruns it is "
                 "given 50 %% + 5 s more; raise it with --set derive_seconds=S, or simplify the "
                 "model)\n",
                 file.c_str(), loc.line, loc.col, what.c_str(), seconds, derive_seconds);
    std::fflush(stderr);
    ::_exit(static_cast<int>(ExitCode::ModelError));
  });
}

Watchdog::~Watchdog() {
  {
    const std::lock_guard<std::mutex> lock(state_->mutex);
    state_->done = true;
  }
  state_->cv.notify_all();
  state_->thread.join();
}

}  // namespace hybgen::gen
