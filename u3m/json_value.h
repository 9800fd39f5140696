#pragma once
// JsonValue: a small JSON document model that keeps what a U3M writer must hand back unchanged:
// object keys in their file order and every number's spelling (the text "0.49803921580314639" is
// written back as that text, not as the double nearest to it). The u3m reader parses every file
// into it; foreign `custom` and `metadata` sections are kept as JsonValue and written back verbatim.
//
// ParseJson refuses, with an InputError naming the file and the JSON pointer: syntax errors
// (truncated text, NaN/Infinity literals, comments), duplicate keys in one object, numbers that do
// not fit a double, nesting deeper than kMaxJsonDepth and files larger than kMaxJsonBytes.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace u3mscan {

inline constexpr int kMaxJsonDepth = 128;
inline constexpr std::size_t kMaxJsonBytes = std::size_t{64} << 20;  // a U3M text is kilobytes

class JsonValue {
 public:
  enum class Type { kNull, kBool, kNumber, kString, kArray, kObject };
  using Member = std::pair<std::string, JsonValue>;

  JsonValue() = default;
  static JsonValue Null() { return JsonValue(); }
  static JsonValue Bool(bool value);
  // Shortest text that reads back as `value` ("300", "0.5", "1e-07"). `value` must be finite.
  static JsonValue Number(double value);
  // A number with a given spelling (must be valid JSON number text for `value`).
  static JsonValue NumberWithText(double value, std::string text);
  static JsonValue String(std::string value);
  static JsonValue Array();
  static JsonValue Object();

  Type type() const { return type_; }
  bool is_null() const { return type_ == Type::kNull; }
  bool is_bool() const { return type_ == Type::kBool; }
  bool is_number() const { return type_ == Type::kNumber; }
  bool is_string() const { return type_ == Type::kString; }
  bool is_array() const { return type_ == Type::kArray; }
  bool is_object() const { return type_ == Type::kObject; }

  bool bool_value() const { return bool_; }
  double number() const { return number_; }
  // Number: its spelling in the file. String: the decoded string.
  const std::string& text() const { return text_; }

  const std::vector<JsonValue>& items() const { return items_; }
  std::vector<JsonValue>& items() { return items_; }
  const std::vector<Member>& members() const { return members_; }
  std::vector<Member>& members() { return members_; }

  // Object look-up; nullptr when absent (or not an object).
  const JsonValue* Find(std::string_view key) const;
  JsonValue* Find(std::string_view key);
  // Object: replaces the member `key` in place or appends it at the end.
  void Set(std::string key, JsonValue value);
  void Push(JsonValue value) { items_.push_back(std::move(value)); }

  // Structural equality; numbers compare by spelling, so "1.0" != "1". Key order matters.
  bool operator==(const JsonValue& other) const;

 private:
  Type type_ = Type::kNull;
  bool bool_ = false;
  double number_ = 0.0;
  std::string text_;
  std::vector<JsonValue> items_;
  std::vector<Member> members_;
};

// Parses a whole JSON text. `file` only names the source in error messages.
JsonValue ParseJson(std::string_view text, const std::string& file);

// Serialises with `indent` spaces per level (0 = one line). Numbers are written with their stored
// spelling, strings as UTF-8 with only the escapes JSON requires.
std::string WriteJson(const JsonValue& value, int indent = 4);

// "/material/front/alpha" style pointer segment: escapes '~' and '/' (RFC 6901).
std::string JsonPointerEscape(std::string_view key);

}  // namespace u3mscan
