#pragma once
/// \file model_texts.hpp
/// Model files that several tests write, each once.

namespace hybgen::testing {

/// A thermostat whose switch `off` says 'decreasing' where the heating flow crosses T = 2
/// increasing: well formed, but the guard never fires, which check warns about at the
/// direction word (line 11, column 14). tests/gen/test_frontend.cpp, tests/e2e/test_cli.cpp.
inline constexpr const char* kWrongWayThermostat = R"(model wrong_way
state T
mode heat {
  T' = 4 - T
}
mode cool {
  T' = -T
}
guard off {
  from heat to cool
  when T = 2 decreasing
  reset identity
}
guard on {
  from cool to heat
  when T = 1 decreasing
  reset identity
}
simulation {
  domain T in [0.5, 2.5]
  initial heat: 1
}
)";

}  // namespace hybgen::testing
