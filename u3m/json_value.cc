#include "u3m/json_value.h"

#include <charconv>
#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <unordered_set>

#include "core/error.h"

namespace u3mscan {

JsonValue JsonValue::Bool(bool value) {
  JsonValue v;
  v.type_ = Type::kBool;
  v.bool_ = value;
  return v;
}

JsonValue JsonValue::Number(double value) {
  if (!std::isfinite(value)) throw std::logic_error("JsonValue::Number: not finite");
  if (value == 0.0) value = 0.0;  // no "-0"
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return NumberWithText(value, std::string(buffer, result.ptr));
}

JsonValue JsonValue::NumberWithText(double value, std::string text) {
  JsonValue v;
  v.type_ = Type::kNumber;
  v.number_ = value;
  v.text_ = std::move(text);
  return v;
}

JsonValue JsonValue::String(std::string value) {
  JsonValue v;
  v.type_ = Type::kString;
  v.text_ = std::move(value);
  return v;
}

JsonValue JsonValue::Array() {
  JsonValue v;
  v.type_ = Type::kArray;
  return v;
}

JsonValue JsonValue::Object() {
  JsonValue v;
  v.type_ = Type::kObject;
  return v;
}

const JsonValue* JsonValue::Find(std::string_view key) const {
  if (type_ != Type::kObject) return nullptr;
  for (const Member& m : members_)
    if (m.first == key) return &m.second;
  return nullptr;
}

JsonValue* JsonValue::Find(std::string_view key) {
  return const_cast<JsonValue*>(static_cast<const JsonValue*>(this)->Find(key));
}

void JsonValue::Set(std::string key, JsonValue value) {
  if (type_ != Type::kObject) throw std::logic_error("JsonValue::Set on a non-object");
  if (JsonValue* existing = Find(key)) {
    *existing = std::move(value);
    return;
  }
  members_.emplace_back(std::move(key), std::move(value));
}

bool JsonValue::operator==(const JsonValue& other) const {
  if (type_ != other.type_) return false;
  switch (type_) {
    case Type::kNull: return true;
    case Type::kBool: return bool_ == other.bool_;
    case Type::kNumber:
    case Type::kString: return text_ == other.text_;
    case Type::kArray: return items_ == other.items_;
    case Type::kObject: return members_ == other.members_;
  }
  return false;
}

std::string JsonPointerEscape(std::string_view key) {
  std::string out;
  for (char c : key) {
    if (c == '~') out += "~0";
    else if (c == '/') out += "~1";
    else out += c;
  }
  return out;
}

namespace {

// SAX handler for nlohmann's parser: builds a JsonValue and keeps number spellings. The parser
// itself is iterative, and kMaxJsonDepth bounds the recursion of everything that walks the result.
class DomBuilder {
 public:
  using number_integer_t = nlohmann::json::number_integer_t;
  using number_unsigned_t = nlohmann::json::number_unsigned_t;
  using number_float_t = nlohmann::json::number_float_t;
  using string_t = std::string;
  using binary_t = nlohmann::json::binary_t;

  bool null() { return Add(JsonValue::Null()); }
  bool boolean(bool value) { return Add(JsonValue::Bool(value)); }
  bool number_integer(number_integer_t value) {
    return Add(JsonValue::NumberWithText(static_cast<double>(value), std::to_string(value)));
  }
  bool number_unsigned(number_unsigned_t value) {
    return Add(JsonValue::NumberWithText(static_cast<double>(value), std::to_string(value)));
  }
  bool number_float(number_float_t value, const string_t& text) {
    if (!std::isfinite(value)) return Fail("a number that fits a double, got " + text);
    return Add(JsonValue::NumberWithText(value, text));
  }
  bool string(string_t& value) { return Add(JsonValue::String(std::move(value))); }
  bool binary(binary_t&) { return Fail("JSON text"); }
  bool start_object(std::size_t) { return Open(JsonValue::Object()); }
  bool key(string_t& key) {
    Frame& frame = stack_.back();
    if (!frame.keys.insert(key).second) {
      frame.key = key;
      frame.key_pending = true;
      return Fail("unique keys in an object, got \"" + key + "\" twice");
    }
    frame.key = std::move(key);
    frame.key_pending = true;
    return true;
  }
  bool end_object() { return Close(); }
  bool start_array(std::size_t) { return Open(JsonValue::Array()); }
  bool end_array() { return Close(); }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception& error) {
    std::string message = error.what();
    // Drop nlohmann's "[json.exception.parse_error.101] " prefix: the user needs the rest.
    if (const auto close = message.find("] "); message.rfind("[json.exception", 0) == 0 && close != std::string::npos)
      message = message.substr(close + 2);
    return Fail("valid JSON (" + message + ")");
  }

  JsonValue TakeRoot() { return std::move(root_); }
  const std::string& error() const { return error_; }
  const std::string& error_pointer() const { return error_pointer_; }

 private:
  struct Frame {
    JsonValue value;
    std::string key;  // object: key of the member being parsed
    std::unordered_set<std::string> keys;
    bool key_pending = false;  // object: `key` named, its value not complete yet
  };

  std::string Pointer() const {
    std::string pointer;
    for (const Frame& frame : stack_) {
      // Appended piecewise: GCC 12 warns falsely (-Wrestrict) on "/" + std::string temporaries.
      if (frame.value.is_object()) {
        if (!frame.key_pending) continue;  // between members: the object itself is at fault
        pointer += '/';
        pointer += JsonPointerEscape(frame.key);
      } else {
        pointer += '/';
        pointer += std::to_string(frame.value.items().size());
      }
    }
    return pointer;
  }

  bool Fail(std::string expected) {
    if (error_.empty()) {
      error_ = "expected ";
      error_ += expected;
      error_pointer_ = Pointer();
    }
    return false;
  }

  bool Add(JsonValue value) {
    if (stack_.empty()) {
      root_ = std::move(value);
      return true;
    }
    Frame& frame = stack_.back();
    if (frame.value.is_array()) frame.value.Push(std::move(value));
    else {
      frame.value.members().emplace_back(frame.key, std::move(value));
      frame.key_pending = false;
    }
    return true;
  }

  bool Open(JsonValue container) {
    if (static_cast<int>(stack_.size()) >= kMaxJsonDepth)
      return Fail("nesting no deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    stack_.push_back(Frame{std::move(container), {}, {}, false});
    return true;
  }

  bool Close() {
    JsonValue value = std::move(stack_.back().value);
    stack_.pop_back();
    return Add(std::move(value));
  }

  std::vector<Frame> stack_;
  JsonValue root_;
  std::string error_;
  std::string error_pointer_;
};

void AppendString(std::string& out, const std::string& value) {
  out += '"';
  for (unsigned char c : value) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\b': out += "\\b"; break;
      case '\f': out += "\\f"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default:
        if (c < 0x20) {
          static const char* kHex = "0123456789abcdef";
          out += "\\u00";
          out += kHex[c >> 4];
          out += kHex[c & 15];
        } else {
          out += static_cast<char>(c);
        }
    }
  }
  out += '"';
}

void AppendValue(std::string& out, const JsonValue& value, int indent, int level) {
  const auto newline = [&](int lvl) {
    if (indent <= 0) return;
    out += '\n';
    out.append(static_cast<std::size_t>(indent) * lvl, ' ');
  };
  switch (value.type()) {
    case JsonValue::Type::kNull: out += "null"; break;
    case JsonValue::Type::kBool: out += value.bool_value() ? "true" : "false"; break;
    case JsonValue::Type::kNumber: out += value.text(); break;
    case JsonValue::Type::kString: AppendString(out, value.text()); break;
    case JsonValue::Type::kArray: {
      if (value.items().empty()) {
        out += "[]";
        break;
      }
      out += '[';
      bool first = true;
      for (const JsonValue& item : value.items()) {
        if (!first) out += ',';
        first = false;
        newline(level + 1);
        AppendValue(out, item, indent, level + 1);
      }
      newline(level);
      out += ']';
      break;
    }
    case JsonValue::Type::kObject: {
      if (value.members().empty()) {
        out += "{}";
        break;
      }
      out += '{';
      bool first = true;
      for (const auto& [key, member] : value.members()) {
        if (!first) out += ',';
        first = false;
        newline(level + 1);
        AppendString(out, key);
        out += indent > 0 ? ": " : ":";
        AppendValue(out, member, indent, level + 1);
      }
      newline(level);
      out += '}';
      break;
    }
  }
}

}  // namespace

JsonValue ParseJson(std::string_view text, const std::string& file) {
  if (text.size() > kMaxJsonBytes)
    throw InputError(file, "", "expected a JSON text of at most " + std::to_string(kMaxJsonBytes >> 20) + " MiB");
  DomBuilder builder;
  const bool ok = nlohmann::json::sax_parse(text.begin(), text.end(), &builder, nlohmann::json::input_format_t::json,
                                            /*strict=*/true, /*ignore_comments=*/false);
  if (!ok || !builder.error().empty()) {
    throw InputError(file, builder.error_pointer(), builder.error().empty() ? std::string("expected valid JSON") : builder.error());
  }
  return builder.TakeRoot();
}

std::string WriteJson(const JsonValue& value, int indent) {
  std::string out;
  AppendValue(out, value, indent, 0);
  if (indent > 0) out += '\n';
  return out;
}

}  // namespace u3mscan
