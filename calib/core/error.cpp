#include "calib/core/error.h"

namespace nerfar {

void Problems::Add(const std::string& where, const std::string& what) {
  // Appending (not operator+) sidesteps a GCC 12 -Wrestrict false positive.
  std::string item = where;
  if (!item.empty()) item.append(": ");
  item.append(what);
  items_.push_back(std::move(item));
}

void Problems::ThrowIfAny() const {
  if (items_.empty()) return;
  std::string message;
  for (const std::string& item : items_) {
    if (!message.empty()) message += '\n';
    message += source_ + ": " + item;
  }
  throw InputError(message);
}

void ThrowInputError(const std::string& source, const std::string& what) {
  std::string message = source;
  if (!message.empty()) message.append(": ");
  message.append(what);
  throw InputError(message);
}

namespace detail {
void FailCheck(const char* file, int line, const std::string& message) {
  throw InvariantError(std::string(file) + ":" + std::to_string(line) + ": " + message);
}
}  // namespace detail

}  // namespace nerfar
