#include "app/cli.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"

namespace nerfar {

ArgParser::ArgParser(std::string command, std::string summary)
    : command_(std::move(command)), summary_(std::move(summary)) {
  Option("--threads", &threads_, "N", "worker threads (default: all cores)");
  Flag("--quiet", &quiet_, "print only errors and results");
  Flag("--verbose", &verbose_, "print more detail (effective options, per-step figures)");
}

void ArgParser::AddOption(Entry entry) { options_.push_back(std::move(entry)); }

void ArgParser::Fail(const std::string& what) const {
  throw InputError("nerfar " + command_ + ": " + what + " (see 'nerfar " + command_ + " --help')");
}

void ArgParser::Flag(const std::string& name, bool* out, const std::string& help) {
  Entry entry{name, "", help, nullptr, out};
  AddOption(std::move(entry));
}

void ArgParser::Option(const std::string& name, std::string* out, const std::string& metavar, const std::string& help) {
  AddOption({name, metavar, help, [out](const std::string& v) { *out = v; }});
}

void ArgParser::Option(const std::string& name, int* out, const std::string& metavar, const std::string& help) {
  AddOption({name, metavar, help, [this, name, out](const std::string& v) {
               char* end = nullptr;
               errno = 0;
               const long value = std::strtol(v.c_str(), &end, 10);
               if (v.empty() || *end != '\0' || errno != 0 || value < -2147483647L || value > 2147483647L)
                 Fail(name + " '" + v + "' is not an integer");
               *out = static_cast<int>(value);
             }});
}

void ArgParser::Option(const std::string& name, double* out, const std::string& metavar, const std::string& help) {
  AddOption({name, metavar, help, [this, name, out](const std::string& v) {
               char* end = nullptr;
               const double value = std::strtod(v.c_str(), &end);
               if (v.empty() || *end != '\0' || !std::isfinite(value)) Fail(name + " '" + v + "' is not a number");
               *out = value;
             }});
}

void ArgParser::Option(const std::string& name, std::vector<std::string>* out, const std::string& metavar,
                       const std::string& help) {
  Entry entry{name, metavar, help, [out](const std::string& v) { out->push_back(v); }};
  entry.repeatable = true;
  AddOption(std::move(entry));
}

void ArgParser::Required(const std::string& name) {
  for (Entry& e : options_)
    if (e.name == name && e.flag == nullptr) {
      e.required = true;
      return;
    }
  throw std::logic_error("ArgParser::Required: no option " + name + " declared for nerfar " + command_);
}

void ArgParser::Positional(const std::string& name, std::string* out, const std::string& help, bool required) {
  positionals_.push_back({name, help, out, nullptr, required});
}

void ArgParser::Positionals(const std::string& name, std::vector<std::string>* out, const std::string& help) {
  positionals_.push_back({name, help, nullptr, out, false});
}

bool ArgParser::Parse(const std::vector<std::string>& args) {
  size_t next_positional = 0;
  std::vector<std::string> seen;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg == "--help" || arg == "-h") {
      std::printf("%s", Help().c_str());
      return false;
    }
    if (arg.size() > 1 && arg[0] == '-' && !(arg.size() > 1 && (std::isdigit(arg[1]) || arg[1] == '.'))) {
      std::string name = arg, value;
      bool has_value = false;
      if (const size_t eq = arg.find('='); eq != std::string::npos) {
        name = arg.substr(0, eq);
        value = arg.substr(eq + 1);
        has_value = true;
      }
      Entry* entry = nullptr;
      for (Entry& e : options_)
        if (e.name == name) entry = &e;
      if (entry == nullptr) Fail("unknown option " + name);
      for (const std::string& s : seen)
        if (s == name && !entry->repeatable) Fail(name + " given twice");
      seen.push_back(name);
      if (entry->flag != nullptr) {
        if (has_value) Fail(name + " takes no value");
        *entry->flag = true;
        continue;
      }
      if (!has_value) {
        if (i + 1 >= args.size()) Fail(name + " needs a value (" + entry->metavar + ")");
        value = args[++i];
      }
      if (entry->required && value.empty()) Fail(name + " is empty (required: " + entry->metavar + ")");
      entry->set(value);
      continue;
    }
    if (next_positional >= positionals_.size()) Fail("unexpected argument '" + arg + "'");
    PositionalEntry& p = positionals_[next_positional];
    if (p.many != nullptr) {
      p.many->push_back(arg);
    } else {
      *p.one = arg;
      ++next_positional;
    }
  }
  for (size_t k = next_positional; k < positionals_.size(); ++k)
    if (positionals_[k].required && positionals_[k].one != nullptr) Fail("missing " + positionals_[k].name);
  std::string missing;
  for (const Entry& e : options_)
    if (e.required && std::find(seen.begin(), seen.end(), e.name) == seen.end())
      missing += (missing.empty() ? "" : ", ") + e.name + " " + e.metavar;
  if (!missing.empty()) Fail("missing " + missing + " (required)");
  if (quiet_ && verbose_) Fail("--quiet and --verbose exclude each other");
  if (threads_ < 0 || threads_ > 1024) Fail("--threads must be 0 (all cores) to 1024");
  SetLogLevel(quiet_ ? LogLevel::kQuiet : (verbose_ ? LogLevel::kVerbose : LogLevel::kNormal));
  SetThreadCount(threads_);
  return true;
}

std::string ArgParser::Help() const {
  std::string usage = "usage: nerfar " + command_;
  for (const PositionalEntry& p : positionals_)
    usage += p.many ? " [" + p.name + "...]" : (p.required ? " " + p.name : " [" + p.name + "]");
  usage += " [options]\n\n" + summary_ + "\n";
  if (!positionals_.empty()) usage += "\narguments:\n";
  for (const PositionalEntry& p : positionals_) {
    std::string left = "  " + p.name;
    left.resize(std::max<size_t>(left.size() + 2, 26), ' ');
    usage += left + p.help + "\n";
  }
  usage += "\noptions:\n";
  for (const Entry& e : options_) {
    std::string left = "  " + e.name + (e.metavar.empty() ? "" : " " + e.metavar);
    left.resize(std::max<size_t>(left.size() + 2, 26), ' ');
    usage += left + e.help + (e.required ? " (required)" : "") + "\n";
  }
  std::string help_line = "  --help";
  help_line.resize(26, ' ');
  usage += help_line + "show this help\n";
  if (!epilog_.empty()) usage += "\n" + epilog_ + "\n";
  return usage;
}

}  // namespace nerfar
