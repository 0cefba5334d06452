#!/usr/bin/env bash
# CI's hardening stage (docs/hardening.md), after the README's test command:
#  1. the test suite under AddressSanitizer + UndefinedBehaviorSanitizer
#     (CMake preset `asan`: hybgen, the tests and every generated runner the
#     tests build), in build-asan/: every unit test, the validation tests that run
#     `hybgen run`, and a chosen five of the end-to-end tests (see below);
#  2. a fuzz smoke run, both harnesses side by side for 25 s (fuzz/run.sh smoke), in
#     build-fuzz/.
# Any sanitizer report fails a test (halt_on_error), any fuzzer finding fails
# the smoke run. Set HYBGEN_SKIP_HARDENING=1 to skip both (local use).
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ "${HYBGEN_SKIP_HARDENING:-}" == 1 ]]; then
  echo "ci-hardening: skipped (HYBGEN_SKIP_HARDENING=1)" >&2
  exit 0
fi
start=$SECONDS
echo "ci-hardening: ASan + UBSan build (preset asan)" >&2
# The MPI backend when its packages are there (the preset's AUTO); in CI, where the README's
# setup installs them, required: its agreement tests below must not drop out unseen.
cmake --preset asan -DHYBGEN_MPI="$([[ "${CI:-}" == true ]] && echo ON || echo AUTO)" >/dev/null
t0=$SECONDS
# Only what this stage runs (the target hybgen_sanitized_suite, tests/CMakeLists.txt): hybgen
# and the runtime its runners link, the unit tests of tests/gen and tests/rt, the validation
# tests that run `hybgen run`, and the end-to-end executables that hold the tests below (with
# the MPI backend, test_mpi.cpp's). The validation tests with hand-written kernel structs and
# the other end-to-end executables are not compiled sanitized (their tests run unsanitized in
# the first stage).
cmake --build --preset asan -j"$(nproc)" --target hybgen_sanitized_suite
echo "ci-hardening: sanitized build in $((SECONDS - t0)) s" >&2
echo "ci-hardening: test suite under ASan + UBSan" >&2
# Every test built above (tests/gen, tests/rt, the front-door tests of tests/validation), and
# five end-to-end tests (label
# e2e) that run the runner's paths the others cannot: every shipped model's generated kernels
# (UBSan on generated code), the paper's configuration, the output transaction under a kill,
# a numerical failure reported by a runner, and a Lie-group model. The other end-to-end tests
# each compile one more sanitized runner (20-60 s) to check a number, a message or an exit
# code whose code paths run sanitized here or in tests/rt; they run unsanitized in the first
# stage. The differential test of derive runs 20 random models here instead of 300 (GiNaC
# under ASan: 300 took 516 s; tests/gen/test_derive_random.cpp, HYBGEN_RANDOM_MODELS), and the
# density-level differential campaign 2 random models instead of 16 (each compiles a sanitized
# runner; tests/validation/test_differential.cpp, HYBGEN_DIFFERENTIAL_MODELS).
t0=$SECONDS
# (The executables left unbuilt above each register a placeholder test,
# <target>_NOT_BUILT, without a label: -E leaves them out. So are the two bouncing-ball runs of
# the time-stepped generator on 257² nodes, which measure its order: the same code runs
# sanitized on the 1-D and 3-D models of TheTimeSteppedGeneratorOnCyclesWallsAndSwitches and in
# tests/rt/test_generator.cpp. Nor is the observables' ball, four 129² runs of the methods
# whose observables run sanitized on the thermostat in tests/validation/test_observables.cpp.
# Nor the crossing switch of test_crossing_shear.cpp and the Heisenberg walls of
# test_heisenberg_walls.cpp, one more sanitized runner each for paths that the transient closed
# forms' runs, the differential models and LieCli.RunHeisenbergOnATinyGrid take sanitized.
# Nor the particles' calibration of test_calibration.cpp, three more sanitized runners and
# 18 runs of 10⁵ particles for the statistics of bars whose code tests/rt/test_particles.cpp
# runs sanitized. Nor the impacts' closed forms of test_impacts.cpp, three more sanitized
# runners and 200000 particles twice, for counts whose code every guarded model's run takes
# sanitized: test_absorbing.cpp's shuttle by all three methods. Nor the campaign's fixed
# models of test_differential.cpp, two more sanitized runners beside the two random ones. Nor
# three runs whose code others take sanitized at a fraction of their cost (2026-12-01, a fresh
# clone's sanitized stage: 107 s, 58 s and 43 s of its 515 s): the characteristics' Zeno atom of
# test_budget_e08.cpp (AdaptiveBudget.ZenoAtomIsTheZenoMass in tests/rt/test_budget.cpp), the
# neuron's observables of test_observables.cpp (the thermostat's, there), and the 3-D clock of
# test_cell_averages.cpp (its 2-D clock and means, there). Nor the coherent pairs' bouncing
# ball of test_coherent.cpp, one more sanitized runner for the code its fold map runs there.
# Nor the Galerkin transfer's closed forms of test_transient_closed_forms.cpp (the paper's
# ball on 257² twice, rotations on 65² and 129²: 256 forward flows per node), whose code
# tests/rt/test_transfer.cpp runs sanitized on 33² nodes. Nor the 141 × 101 product of two
# cycles through hybgen run, by fv (InvariantFv.ProductOfTwoCycles, InvariantErrors' product_fv:
# the same run twice) and hat (product_hat): 86 s of the sanitized stage's tests on 2026-12-01,
# for a generator that Generator.ProductOfTwoCycles (tests/rt/test_generator.cpp) runs sanitized
# on the same system and grid, and a hat scheme the 1-D cycles and the radial fallback run.)
HYBGEN_RANDOM_MODELS=20 HYBGEN_DIFFERENTIAL_MODELS=2 ctest --preset asan --output-on-failure -LE e2e \
  -E '_NOT_BUILT$|TheTimeSteppedGeneratorOnTheBall|TheTimeSteppedGeneratorSaysHowFarOff|TheElasticBallKeepsItsMeanEnergy|CrossingShear|HeisenbergWalls|Calibration\.|Impacts\.|TheModelsTheCampaignFoundStayFixed|CharacteristicsAtomIsTheZenoMass|TheNeuronsSpikingCycle|AThreeDimensionalClockThatContractsTwoWays|TwoBlobsOfABouncingBall|TheGalerkinTransfer|InvariantFv\.ProductOfTwoCycles|NoDecayIsClaimed/product_'
# The MPI backend's agreement of one and two ranks on the ball (every method's distributed
# path: characteristics, particles, the transfer operator on PETSc, the invariant density by
# SLEPc) and a failure found on either rank; the same tests on three more models, whose code is
# the same, run unsanitized in the first stage. Without leak checks under mpiexec
# (tests/support/e2e.hpp, kMpiEnv). (gtest_discover_tests names a parameterised test with its
# parameter: "…/ball  # GetParam() = ball".)
e2e='Cli\.RunEveryShippedModelOnASmallGrid|Cli\.BouncingBallPaperConfigurationMatchesClosedForm'
e2e+='|NothingLost\.OutputsOfARunKilledMidSwapAreRestored|NumericalFailure\.NonFiniteFlowAndDivergence'
e2e+='|LieCli\.RunHeisenbergOnATinyGrid'
e2e+='|Models/MpiAgreement\.[A-Za-z]+/ball  # GetParam\(\) = ball|Mpi\.AFailureIsFoundOnceWhicheverRankHitIt'
ctest --preset asan --output-on-failure --no-tests=error -L e2e -R "^($e2e)$"
echo "ci-hardening: sanitized tests in $((SECONDS - t0)) s" >&2
echo "ci-hardening: fuzz smoke" >&2
fuzz/run.sh smoke
echo "ci-hardening: done in $((SECONDS - start)) s" >&2
