#pragma once
/// \file limits.hpp
/// Resource limits of the symbolic stage (docs/hardening.md, "Derivation limits").
///
/// Symbolic work can blow up on a short input: (x+y+z+w)^4096 is 9 nodes but
/// expands to 1.2·10^10 terms, a 10×10 symbolic inverse has millions. derive
/// therefore runs under three limits and, when one is hit, ends with a located
/// model error (exit 1) that names the object being derived, the limit and the
/// `--set` key that raises it — never a hang or an out-of-memory kill:
///  - `max_expr_nodes`: no derived expression may exceed this many tree nodes
///    (`expr_size`), checked on every simplified result;
///  - `max_expand_terms`: `simplify` does not expand an expression whose
///    expansion is estimated (`expanded_terms`) above this many terms — it
///    keeps the unexpanded, exact form instead (simplification is optional);
///  - `derive_seconds`: a wall-clock budget, checked between GiNaC operations
///    (cooperative) and, in the command-line tool, by a watchdog that ends
///    the process cleanly when one operation alone overruns it (nothing has
///    been written by then: outputs are written after derive, atomically).

#include <ginac/ginac.h>

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/source.hpp"
#include "hybgen/rt/settings.hpp"

namespace hybgen::gen {

/// The limits of one derivation (defaults from the settings table,
/// runtime/include/hybgen/rt/settings.hpp; `--set KEY=VALUE` overrides them).
struct DeriveLimits {
  /// Largest derived expression, in tree nodes.
  std::size_t max_expr_nodes = static_cast<std::size_t>(rt::setting_number("max_expr_nodes"));
  /// Largest estimated expansion simplify attempts.
  double max_expand_terms = rt::setting_number("max_expand_terms");
  /// Wall-clock budget of derive.
  double derive_seconds = rt::setting_number("derive_seconds");
};

/// A limit was hit; derive turns it into a located ModelError naming the object.
class LimitExceeded : public Error {
 public:
  /// Construct from what was exceeded (without the object).
  explicit LimitExceeded(const std::string& message) : Error(message, ExitCode::ModelError) {}
};

/// Estimated number of terms of expand(e) for polynomial structure: sums add,
/// products multiply, (k terms)^n gives C(n+k−1, k−1) monomials, and so does
/// (k terms)^(n + x) (expand splits off the factor ^n); the largest such
/// estimate over all subexpressions (function arguments are expanded too).
/// An upper estimate; saturates at 1e300, which it also returns when expand
/// would compute an exact numeric power past kMaxExactBits (a^(n + x), a a
/// number: expand computes a^n).
double expanded_terms(const GiNaC::ex& e);

/// Bounds of exact arithmetic. GiNaC computes a numeric power a^n exactly, so
/// an exponent of 10^17 is a hang, whether written (findings F1, F2), folded
/// by expand (a^(n+x) = a^n·a^x) or met when a symbolic exponent is
/// evaluated at an exact point (finding F8: (2/5)^(10^56·I) at I = 37/41).
inline constexpr int kMaxExponent = 4096;
/// Largest exactly computed numeric power, in bits (numerator + denominator).
inline constexpr double kMaxExactBits = 65536;

/// Size of the exact number a in bits (numerator + denominator, real + imaginary
/// part); 0 for a floating-point number.
double exact_bits(const GiNaC::numeric& a);

/// Whether GiNaC would compute a^x exactly at a cost past kMaxExactBits: a
/// exact with |a| ≠ 0, 1, x rational and exact_bits(a)·|x| > kMaxExactBits.
bool exact_power_too_large(const GiNaC::numeric& a, const GiNaC::numeric& x);

/// An upper bound of the bits of the exact numbers GiNaC computes in a^x, per
/// unit of the rational exponent x: a number gives exact_bits(a); b^r (r a
/// number) gives exact_bits_per_power(b)·|r|, since (b^r)^x folds to b^(r·x)
/// and, b a number, its integer part is computed; a product gives the sum
/// over its factors, since an integer power distributes over them (finding
/// F12: 2^409.6 is 2^409·2^(3/5), whose 4096th power holds 2^(409·4096));
/// anything else (symbols, sums, functions) 0.
double exact_bits_per_power(const GiNaC::ex& a);

/// An upper bound of |c| where c is the constant term of expand(e): numbers
/// give their absolute value, sums add, products multiply, positive integer
/// powers raise; symbols, functions, constants and other powers give 0 (for
/// expand they are atoms). expand(a^e) computes a^c when e expands to c + …
double expanded_constant_bound(const GiNaC::ex& e);

/// The limits in force on this thread while a derivation runs, and the object
/// being derived (for messages). Scoped: constructing one activates it,
/// destroying it restores the previous state.
class LimitScope {
 public:
  /// Activate `limits` on this thread, with the deadline starting now.
  explicit LimitScope(const DeriveLimits& limits);
  /// Restore the previous scope (if any).
  ~LimitScope();
  LimitScope(const LimitScope&) = delete;             ///< Not copyable.
  LimitScope& operator=(const LimitScope&) = delete;  ///< Not assignable.

  /// Name the object now being derived, e.g. "the hybrid Jacobian of guard 'ground'".
  void object(std::string what, SourceLoc loc);
  /// The object now being derived.
  [[nodiscard]] const std::string& what() const { return what_; }
  /// Where that object was written.
  [[nodiscard]] SourceLoc loc() const { return loc_; }
  /// For a catch block around a derivation: rethrow the exception in flight as a
  /// ModelError located at the object being derived when the model caused it — a
  /// limit hit (LimitExceeded), memory exhausted (std::bad_alloc), or a singularity
  /// GiNaC met (std::domain_error, its pole_error: 0^(-1) in the derivative of 0^e,
  /// log(0)); rethrow anything else unchanged.
  [[noreturn]] void rethrow_at_object(const SourceText& src) const;

  /// The active scope of this thread, or nullptr outside a derivation.
  static LimitScope* current();
  /// Throw LimitExceeded if the active scope's deadline has passed.
  static void check_time();
  /// Throw LimitExceeded if e has more nodes than the active scope allows.
  static void check_size(const GiNaC::ex& e);
  /// Whether expand(e) is within the active scope's term limit (true outside a scope).
  static bool may_expand(const GiNaC::ex& e);

  /// The limits.
  [[nodiscard]] const DeriveLimits& limits() const { return limits_; }

 private:
  DeriveLimits limits_;
  std::chrono::steady_clock::time_point deadline_;
  std::string what_ = "the model";
  SourceLoc loc_{1, 1};
  LimitScope* previous_;
};

/// Seconds after which the watchdog ends a derivation whose budget is `derive_seconds`:
/// 1.5 · derive_seconds + 5 (the budget itself is enforced between operations).
double watchdog_seconds(double derive_seconds);

/// A watchdog for one operation that cannot be interrupted (a single GiNaC
/// call): if it is still alive `fire_after` seconds after construction, it
/// prints `FILE:LINE:COL: error: deriving OBJECT took longer than T s ...`
/// (with the setting derive_seconds) to stderr and ends the process with exit 1.
/// For the command-line tool only (nothing is written before derive ends, so
/// ending the process loses nothing).
class Watchdog {
 public:
  /// Arm the watchdog for `file` under the setting `derive_seconds`, firing after
  /// `fire_after` seconds (negative, the default: watchdog_seconds(derive_seconds)).
  Watchdog(std::string file, double derive_seconds, double fire_after = -1);
  /// Disarm it.
  ~Watchdog();
  Watchdog(const Watchdog&) = delete;             ///< Not copyable.
  Watchdog& operator=(const Watchdog&) = delete;  ///< Not assignable.

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace hybgen::gen
