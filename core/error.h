#pragma once
// InputError: the expected failure for bad user input (a manifest, an image, a U3M file).
// Its message always names the file, the field (a JSON pointer where there is one) and what was
// expected, so an operator can fix the input without reading code. Broken invariants inside the
// program throw std::logic_error instead.

#include <stdexcept>
#include <string>

namespace u3mscan {

class InputError : public std::runtime_error {
 public:
  // file: path as the user gave it; field: JSON pointer ("/frames/3/exposure_s") or a name
  // ("IFD0/ImageWidth"), empty when the whole file is at fault; expected: what would have been
  // right ("a positive number of seconds, got -0.5").
  InputError(std::string file, std::string field, std::string expected);

  const std::string& file() const { return file_; }
  const std::string& field() const { return field_; }
  const std::string& expected() const { return expected_; }

 private:
  std::string file_;
  std::string field_;
  std::string expected_;
};

}  // namespace u3mscan
