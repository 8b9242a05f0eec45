// How nerfar fails. There are two kinds of failure and they never mix:
//
// * Bad input (a file, a flag, a JSON key, a camera frame) is expected. A reader
//   collects every problem it finds into a Problems list, each as
//   "path: what is wrong (what was expected)", and throws one InputError that
//   lists them all. The CLI maps it to exit code 2.
// * A broken invariant is a bug. NERFAR_CHECK* print both sides of the failed
//   comparison and throw InvariantError (so tests can catch it). Exit code 1.
//
// Anything else that fails at run time (a disk full while writing) throws
// std::runtime_error with the path named; exit code 1. The live loop catches
// all of these per frame and never lets one end the program.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace nerfar {

class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& message) : std::runtime_error(message) {}
};

class InvariantError : public std::logic_error {
 public:
  explicit InvariantError(const std::string& message) : std::logic_error(message) {}
};

// Collects the problems of one input (a file, a flag set) so that the user sees
// all of them at once rather than one per run.
class Problems {
 public:
  explicit Problems(std::string source) : source_(std::move(source)) {}

  // `where` is a JSON pointer, a line number or a field name; may be empty.
  void Add(const std::string& where, const std::string& what);
  bool empty() const { return items_.empty(); }
  const std::vector<std::string>& items() const { return items_; }
  const std::string& source() const { return source_; }
  // Throws InputError listing every problem, if there is any.
  void ThrowIfAny() const;

 private:
  std::string source_;
  std::vector<std::string> items_;
};

// Throws InputError("source: what").
[[noreturn]] void ThrowInputError(const std::string& source, const std::string& what);

namespace detail {
[[noreturn]] void FailCheck(const char* file, int line, const std::string& message);

template <typename A, typename B>
std::string DescribeComparison(const char* expr_a, const char* op, const char* expr_b, const A& a, const B& b) {
  std::ostringstream out;
  out << "check failed: " << expr_a << ' ' << op << ' ' << expr_b << " (" << a << " vs " << b << ')';
  return out.str();
}
}  // namespace detail

}  // namespace nerfar

#define NERFAR_CHECK(cond)                                                                \
  do {                                                                                    \
    if (!(cond)) ::nerfar::detail::FailCheck(__FILE__, __LINE__, "check failed: " #cond); \
  } while (0)

#define NERFAR_CHECK_OP(a, op, b)                                                                           \
  do {                                                                                                      \
    const auto& nerfar_a_ = (a);                                                                            \
    const auto& nerfar_b_ = (b);                                                                            \
    if (!(nerfar_a_ op nerfar_b_))                                                                          \
      ::nerfar::detail::FailCheck(__FILE__, __LINE__,                                                       \
                                  ::nerfar::detail::DescribeComparison(#a, #op, #b, nerfar_a_, nerfar_b_)); \
  } while (0)

#define NERFAR_CHECK_EQ(a, b) NERFAR_CHECK_OP(a, ==, b)
#define NERFAR_CHECK_NE(a, b) NERFAR_CHECK_OP(a, !=, b)
#define NERFAR_CHECK_LT(a, b) NERFAR_CHECK_OP(a, <, b)
#define NERFAR_CHECK_LE(a, b) NERFAR_CHECK_OP(a, <=, b)
#define NERFAR_CHECK_GT(a, b) NERFAR_CHECK_OP(a, >, b)
#define NERFAR_CHECK_GE(a, b) NERFAR_CHECK_OP(a, >=, b)
