#pragma once
// A small streaming JSON writer for the commands' --json output.

#include <cmath>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace lex3d::cli {

class Json {
 public:
  Json& begin_object(std::string_view key = {}) { return open(key, '{'); }
  Json& end_object() { return close('}'); }
  Json& begin_array(std::string_view key = {}) { return open(key, '['); }
  Json& end_array() { return close(']'); }

  Json& value(std::string_view key, std::string_view v) {
    prefix(key);
    quote(v);
    return *this;
  }
  Json& value(std::string_view key, const char* v) { return value(key, std::string_view(v)); }
  Json& value(std::string_view key, const std::string& v) { return value(key, std::string_view(v)); }
  Json& value(std::string_view key, bool v) {
    prefix(key);
    out_ += v ? "true" : "false";
    return *this;
  }
  Json& value(std::string_view key, double v) {
    prefix(key);
    if (!std::isfinite(v)) {
      out_ += "null";
    } else {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.10g", v);
      out_ += buf;
    }
    return *this;
  }
  Json& value(std::string_view key, float v) { return value(key, static_cast<double>(v)); }
  template <typename I, typename = std::enable_if_t<std::is_integral_v<I> && !std::is_same_v<I, bool>>>
  Json& value(std::string_view key, I v) {
    prefix(key);
    out_ += std::to_string(v);
    return *this;
  }
  /// An array of numbers.
  Json& numbers(std::string_view key, const std::vector<double>& v) {
    begin_array(key);
    for (const double d : v) value({}, d);
    return end_array();
  }

  [[nodiscard]] const std::string& str() const { return out_; }

 private:
  Json& open(std::string_view key, char c) {
    prefix(key);
    out_ += c;
    first_.push_back(true);
    return *this;
  }
  Json& close(char c) {
    first_.pop_back();
    out_ += c;
    return *this;
  }
  void prefix(std::string_view key) {
    if (!first_.empty()) {
      if (!first_.back()) out_ += ',';
      first_.back() = false;
    }
    if (!key.empty()) {
      quote(key);
      out_ += ':';
    }
  }
  void quote(std::string_view s) {
    out_ += '"';
    for (const char ch : s) {
      const auto c = static_cast<unsigned char>(ch);
      if (c == '"' || c == '\\') {
        out_ += '\\';
        out_ += ch;
      } else if (c < 0x20) {
        char buf[8];
        std::snprintf(buf, sizeof buf, "\\u%04x", c);
        out_ += buf;
      } else {
        out_ += ch;
      }
    }
    out_ += '"';
  }

  std::string out_;
  std::vector<bool> first_;
};

}  // namespace lex3d::cli
