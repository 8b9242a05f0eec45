// Running the `nerfar` binary from a test: the program's CMake target
// defines NERFAR_BINARY as the binary's path (target_compile_definitions).
#pragma once

#include <string>

#include "tests/support/support.h"

#ifndef NERFAR_BINARY
#error "NERFAR_BINARY must name the nerfar binary (target_compile_definitions in the test's CMakeLists.txt)"
#endif

namespace nerfar::testing {

// The command line `nerfar ARGUMENTS`.
inline std::string Nerfar(const std::string& arguments) { return std::string(NERFAR_BINARY) + " " + arguments; }

// Runs `nerfar ARGUMENTS` through the shell: its exit code and output.
inline CommandResult RunNerfar(const std::string& arguments) { return RunCommand(Nerfar(arguments)); }

}  // namespace nerfar::testing
