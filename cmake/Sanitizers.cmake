# FIBREMSS_SANITIZE: a comma-separated list of sanitizers (e.g. "address,undefined") applied to
# every target below this point, so the library, the CLI and every test run instrumented.
# FIBREMSS_FUZZ (clang only): also instruments everything for libFuzzer and builds tests/fuzz.
set(FIBREMSS_SANITIZE "" CACHE STRING "Sanitizers for all targets, e.g. address,undefined")
option(FIBREMSS_FUZZ "Build the libFuzzer targets in tests/fuzz (clang)" OFF)
if(FIBREMSS_SANITIZE)
  add_compile_options(-fsanitize=${FIBREMSS_SANITIZE} -fno-omit-frame-pointer
                      -fno-sanitize-recover=all)
  add_link_options(-fsanitize=${FIBREMSS_SANITIZE})
  # GCC's instrumentation makes -Wmaybe-uninitialized fire inside libstdc++ (std::regex's
  # std::function), which -Werror would turn into a build failure.
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    add_compile_options(-Wno-maybe-uninitialized)
  endif()
  message(STATUS "FibreMSS: building with -fsanitize=${FIBREMSS_SANITIZE}")
endif()
if(FIBREMSS_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "FIBREMSS_FUZZ needs clang: -DCMAKE_CXX_COMPILER=clang++")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
endif()
