# One place for compiler flags, sanitizers and ccache.
#
#   fl_target_flags(<target>)   adds the project warning set to a target.
#
# Options:
#   FL_SANITIZE=ON      build everything with AddressSanitizer + UBSan
#                       (`./fusionloc test --sanitize` runs the whole suite on it).
#   FL_TSAN=ON          build with ThreadSanitizer (`./fusionloc test --tsan` builds the target
#                       fl_thread_tests and runs the tests labelled `threads` on it).
#   FL_WERROR=ON        turn warnings into errors (CI uses this).
#   FL_FUZZ=ON          clang only: instrument everything for libFuzzer + ASan + UBSan and
#                       add the fuzz targets fl-fuzz-* (tests/fuzz; `./fusionloc fuzz`).

option(FL_SANITIZE "Build with address and undefined-behaviour sanitizers" OFF)
option(FL_TSAN "Build with ThreadSanitizer" OFF)
option(FL_WERROR "Treat compiler warnings as errors" OFF)
option(FL_FUZZ "Build the libFuzzer targets (clang; tests/fuzz)" OFF)

find_program(FL_CCACHE ccache)
if(FL_CCACHE)
  set(CMAKE_CXX_COMPILER_LAUNCHER ${FL_CCACHE})
  set(CMAKE_C_COMPILER_LAUNCHER ${FL_CCACHE})
endif()

# LCM 1.3.1's lcm_coretypes.h decodes doubles through int64_t pointers (type punning). With
# strict aliasing GCC 12 at -O2 can drop the decoded values, so every target turns it off.
add_compile_options(-fno-strict-aliasing)

if(FL_SANITIZE)
  # -fno-sanitize=vptr: UBSan's vptr check misfires inside LCM 1.3.1's header-only callback
  # trampolines (lcm-cpp-impl.hpp cb_func), reporting an invalid object and then crashing a
  # correct program; every other UBSan check stays on.
  add_compile_options(-fsanitize=address,undefined -fno-sanitize=vptr -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined -fno-sanitize=vptr)
  # Eigen turns off its "malloc is already aligned" assumption under ASan, which makes Eigen
  # heap objects allocated inside the (uninstrumented) Ceres library unfreeable from ours;
  # glibc and ASan both return 16-byte aligned memory on x86-64, so keep the assumption.
  add_compile_definitions(EIGEN_MALLOC_ALREADY_ALIGNED=1)
  # GCC 12 with ASan at -O1 reports -Wmaybe-uninitialized inside libstdc++'s <regex> and
  # std::function (46 warnings, none in our code; the same code is clean in the normal build);
  # a known class of false positives under sanitizer instrumentation. Kept as warnings, not
  # errors, when warnings are errors (CI).
  if(FL_WERROR)
    add_compile_options(-Wno-error=maybe-uninitialized)
  endif()
endif()

if(FL_TSAN)
  if(FL_SANITIZE OR FL_FUZZ)
    message(FATAL_ERROR "FL_TSAN=ON cannot be combined with FL_SANITIZE or FL_FUZZ (one sanitizer "
                        "runtime per program): use a separate build folder")
  endif()
  add_compile_options(-fsanitize=thread -fno-omit-frame-pointer)
  add_link_options(-fsanitize=thread)
endif()

if(FL_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "FL_FUZZ=ON needs clang (libFuzzer): configure with "
                        "CC=clang-14 CXX=clang++-14, or use ./fusionloc fuzz")
  endif()
  # Coverage for libFuzzer in every library; ASan and UBSan, UB aborting (a finding) instead of
  # printing and going on. vptr and the Eigen alignment: as FL_SANITIZE above.
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize=vptr
                      -fno-sanitize-recover=undefined -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined -fno-sanitize=vptr)
  add_compile_definitions(EIGEN_MALLOC_ALREADY_ALIGNED=1)
endif()

# fl_programs: every fl-* program; fl_thread_tests: the tests labelled `threads` and every
# program (a test may run programs as processes), what the ThreadSanitizer suite builds.
if(NOT TARGET fl_programs)
  add_custom_target(fl_programs)
  add_custom_target(fl_thread_tests)
  add_dependencies(fl_thread_tests fl_programs)
endif()

function(fl_target_flags target)
  target_compile_options(${target} PRIVATE -Wall -Wextra)
  if(FL_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# fl_executable(<name> SOURCES ... LIBS ...): an fl-<name> program in build/bin.
function(fl_executable name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(fl-${name} ${ARG_SOURCES})
  target_link_libraries(fl-${name} PRIVATE ${ARG_LIBS})
  fl_target_flags(fl-${name})
  add_dependencies(fl_programs fl-${name})
endfunction()

# fl_test(<name> SOURCES ... LIBS ... [LABELS ...] [SERIAL] [THREADS]): a GoogleTest binary
# registered with ctest. SERIAL: its tests run alone (ctest RUN_SERIAL), for live multi-process
# runs whose accuracy must not depend on what else the machine is running. THREADS: the test
# starts threads (its own, or through the programs it runs): labelled `threads` and part of
# the target fl_thread_tests, which the ThreadSanitizer suite builds (`fusionloc test --tsan`).
function(fl_test name)
  cmake_parse_arguments(ARG "SERIAL;THREADS" "TIMEOUT" "SOURCES;LIBS;LABELS" ${ARGN})
  if(ARG_THREADS)
    list(APPEND ARG_LABELS threads)
    add_dependencies(fl_thread_tests ${name})
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    FL_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    FL_BINARY_DIR="${PROJECT_BINARY_DIR}"
    FL_SHARED_DATA_DIR="${FL_SHARED_DATA_DIR}")
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/tests)
  fl_target_flags(${name})
  if(ARG_SERIAL)
    gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES LABELS "${ARG_LABELS}"
                         RUN_SERIAL TRUE)
  else()
    gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES LABELS "${ARG_LABELS}")
  endif()
endfunction()

# fl_add_subdirectories(): adds every sub-folder of the current folder that has a
# CMakeLists.txt, in sorted order (drivers/, estimators/, tools/, tests/ hold one module each).
function(fl_add_subdirectories)
  file(GLOB _subdirs LIST_DIRECTORIES true RELATIVE ${CMAKE_CURRENT_SOURCE_DIR}
       ${CMAKE_CURRENT_SOURCE_DIR}/*)
  list(SORT _subdirs)
  foreach(d ${_subdirs})
    if(IS_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/${d} AND
       EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/${d}/CMakeLists.txt)
      add_subdirectory(${d})
    endif()
  endforeach()
endfunction()
