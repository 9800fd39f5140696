#include "core/error.h"

namespace u3mscan {
namespace {
std::string Compose(const std::string& file, const std::string& field, const std::string& expected) {
  std::string message = file;
  if (!field.empty()) message += ": " + field;
  message += ": " + expected;
  return message;
}
}  // namespace

InputError::InputError(std::string file, std::string field, std::string expected)
    : std::runtime_error(Compose(file, field, expected)),
      file_(std::move(file)),
      field_(std::move(field)),
      expected_(std::move(expected)) {}

}  // namespace u3mscan
