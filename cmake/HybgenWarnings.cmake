# hybgen::warnings — an interface target that carries the project's warning
# flags; link it PRIVATE to every target we build from our own sources.
add_library(hybgen_warnings INTERFACE)
add_library(hybgen::warnings ALIAS hybgen_warnings)
target_compile_options(hybgen_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  -Wnon-virtual-dtor -Wold-style-cast -Wcast-align -Woverloaded-virtual
  -Wnull-dereference -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough)
if(HYBGEN_WERROR)
  target_compile_options(hybgen_warnings INTERFACE -Werror)
endif()
