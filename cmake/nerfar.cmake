# Helpers that keep each module's CMakeLists to a few lines.
#
# nerfar_add_library(NAME sg SRCS a.cpp b.cpp DEPS nerfar_core [PRIVATE_DEPS Eigen3::Eigen])
#   One static library per module folder, target nerfar_<NAME>. DEPS are public
#   (its headers need them), PRIVATE_DEPS are used in .cpp files only.
# nerfar_add_test(NAME sg SRCS sg_test.cpp DEPS nerfar_sg [LABELS unit] [SKIPPABLE Suite.Test...])
#   One GoogleTest program per module, registered with ctest under its labels.
#   Tests that may skip (GTEST_SKIP: the shared scenes absent, a model file
#   not installed) are named in SKIPPABLE: each gets a ctest entry of its own,
#   NAME/Suite.Test, which ctest reports as Skipped when it skips (the test
#   main's exit code 77, tests/support/main.cpp); the program's entry runs
#   the other tests and fails if one of them skips.

function(nerfar_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SRCS;DEPS;PRIVATE_DEPS" ${ARGN})
  set(target nerfar_${ARG_NAME})
  add_library(${target} STATIC ${ARG_SRCS})
  target_include_directories(${target} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${target} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
endfunction()

function(nerfar_add_test)
  cmake_parse_arguments(ARG "" "NAME" "SRCS;DEPS;LABELS;SKIPPABLE" ${ARGN})
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  set(target ${ARG_NAME}_test)
  add_executable(${target} ${ARG_SRCS})
  target_link_libraries(${target} PRIVATE ${ARG_DEPS} nerfar_test_support GTest::gtest GTest::gmock)
  # One ctest entry per program: suites share expensive fixtures (a trained
  # tiny NeRF, a baked field) that a process per test would rebuild each time.
  set(others "")
  if(ARG_SKIPPABLE)
    list(JOIN ARG_SKIPPABLE ":" joined)
    set(others "--gtest_filter=-${joined}")
  endif()
  add_test(NAME ${ARG_NAME} COMMAND ${target} ${others})
  set_tests_properties(${ARG_NAME} PROPERTIES LABELS "${ARG_LABELS}"
    ENVIRONMENT "NERFAR_SOURCE_DIR=${PROJECT_SOURCE_DIR}")
  foreach(test IN LISTS ARG_SKIPPABLE)
    add_test(NAME ${ARG_NAME}/${test} COMMAND ${target} --gtest_filter=${test})
    set_tests_properties(${ARG_NAME}/${test} PROPERTIES LABELS "${ARG_LABELS}" SKIP_RETURN_CODE 77
      ENVIRONMENT "NERFAR_SOURCE_DIR=${PROJECT_SOURCE_DIR}")
  endforeach()
endfunction()
