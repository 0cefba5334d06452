// The translation unit that builds a test directory's precompiled headers
// (tests/CMakeLists.txt, hybgen_add_tests); the headers come from the build's forced include.
