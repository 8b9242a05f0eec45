// Command-line parsing shared by every subcommand: declared flags, options and
// positionals with help text; strict (unknown flags and bad values are usage
// errors, exit 2); `--help` prints the generated help. An option declared
// Required is marked "(required)" in the help and its absence is a usage
// error naming it. The common options
// --threads, --quiet and --verbose are added to every command.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace nerfar {

class ArgParser {
 public:
  ArgParser(std::string command, std::string summary);

  void Flag(const std::string& name, bool* out, const std::string& help);
  void Option(const std::string& name, std::string* out, const std::string& metavar, const std::string& help);
  void Option(const std::string& name, int* out, const std::string& metavar, const std::string& help);
  void Option(const std::string& name, double* out, const std::string& metavar, const std::string& help);
  // Repeatable option collecting every value (e.g. --set key=value).
  void Option(const std::string& name, std::vector<std::string>* out, const std::string& metavar,
              const std::string& help);
  // Marks a declared option as one the command cannot run without.
  void Required(const std::string& name);
  void Positional(const std::string& name, std::string* out, const std::string& help, bool required = true);
  // Any number of trailing positionals.
  void Positionals(const std::string& name, std::vector<std::string>* out, const std::string& help);
  // Free text appended to --help (examples, notes).
  void Epilog(const std::string& text) { epilog_ = text; }

  // Parses args (without the program and command names). Returns false when
  // --help was given (help already printed to stdout); throws InputError
  // "nerfar COMMAND: what is wrong" on bad usage, after applying the common options.
  bool Parse(const std::vector<std::string>& args);
  std::string Help() const;

 private:
  struct Entry {
    std::string name, metavar, help;
    std::function<void(const std::string&)> set;  // options
    bool* flag = nullptr;
    bool repeatable = false;
    bool required = false;
  };
  struct PositionalEntry {
    std::string name, help;
    std::string* one = nullptr;
    std::vector<std::string>* many = nullptr;
    bool required = true;
  };
  void AddOption(Entry entry);
  [[noreturn]] void Fail(const std::string& what) const;

  std::string command_, summary_, epilog_;
  std::vector<Entry> options_;
  std::vector<PositionalEntry> positionals_;
  int threads_ = 0;
  bool quiet_ = false, verbose_ = false;
};

}  // namespace nerfar
