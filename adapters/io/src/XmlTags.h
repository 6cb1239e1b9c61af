#pragma once
// The tags of an XML text (VTK's .vtp and .pvd files): elements, their attributes and nesting,
// scanned once from start to end, every error naming the file and line.
#include <algorithm>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "fibremss/Error.h"

namespace fibremss::meshio {

/// An element's name="value" attributes.
struct Attributes {
  std::map<std::string, std::string> values;
  std::string get(const std::string& key, const std::string& fallback = "") const {
    const auto found = values.find(key);
    return found == values.end() ? fallback : found->second;
  }
};

inline bool isBlank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n';
}

/// The tags of the XML part of the file (everything before AppendedData's raw bytes).
class TagScanner {
 public:
  TagScanner(const std::string& path, std::string_view xml) : path_(path), xml_(xml) {}

  [[noreturn]] void fail(size_t at, const std::string& what) const {
    throw InputError(path_, "line " + std::to_string(lineAt(at)), what);
  }

  /// The line of byte `at`; counted on from the last call's, so a scan in order stays linear.
  size_t lineAt(size_t at) const {
    at = std::min(at, xml_.size());
    if (at < countedTo_) countedTo_ = 0, line_ = 1;
    line_ += size_t(std::count(xml_.begin() + std::ptrdiff_t(countedTo_),
                               xml_.begin() + std::ptrdiff_t(at), '\n'));
    countedTo_ = at;
    return line_;
  }

  /// Calls open(name, attributes, start, contentBegin, selfClosing) and close(name, start) for
  /// every element in order; checks that they nest.
  template <typename Open, typename Close>
  void scan(Open&& open, Close&& close, bool truncated) {
    std::vector<std::string> stack;
    size_t pos = 0;
    while ((pos = xml_.find('<', pos)) != std::string_view::npos) {
      const size_t start = pos;
      if (xml_.substr(pos, 4) == "<!--") {
        pos = skipPast(pos, "-->");
      } else if (xml_.substr(pos, 2) == "<?" || xml_.substr(pos, 2) == "<!") {
        pos = skipPast(pos, ">");
      } else if (xml_.substr(pos, 2) == "</") {
        const std::string name = readName(pos + 2);
        pos = skipPast(pos, ">");
        if (stack.empty() || stack.back() != name)
          fail(start, "expected </" + (stack.empty() ? std::string("nothing") : stack.back()) +
                          ">, found </" + name + ">");
        stack.pop_back();
        close(name, start);
      } else {
        const std::string name = readName(pos + 1);
        pos += 1 + name.size();
        Attributes attributes;
        bool selfClosing = false;
        readAttributes(pos, attributes, selfClosing);
        if (stack.size() > 64) fail(start, "expected elements nested at most 64 deep");
        open(name, attributes, start, pos, selfClosing);
        if (!selfClosing) stack.push_back(name);
      }
    }
    if (!stack.empty() && !truncated)  // AppendedData's bytes and the closing tags follow
      fail(xml_.size(), "expected </" + stack.back() + ">, found the end of the XML");
  }

 private:
  size_t skipPast(size_t from, std::string_view end) const {
    const size_t at = xml_.find(end, from);
    if (at == std::string_view::npos) fail(from, "expected '" + std::string(end) + "'");
    return at + end.size();
  }

  std::string readName(size_t at) const {
    size_t end = at;
    while (end < xml_.size() && !isBlank(xml_[end]) && xml_[end] != '>' && xml_[end] != '/' &&
           xml_[end] != '=')
      ++end;
    if (end == at) fail(at, "expected an element name after '<'");
    return std::string(xml_.substr(at, end - at));
  }

  /// name="value" pairs up to '>' or '/>'; `pos` ends after the '>'.
  void readAttributes(size_t& pos, Attributes& attributes, bool& selfClosing) const {
    while (true) {
      while (pos < xml_.size() && isBlank(xml_[pos])) ++pos;
      if (pos >= xml_.size()) fail(pos, "expected '>' to end the tag, found the end of the XML");
      if (xml_[pos] == '>') {
        ++pos;
        return;
      }
      if (xml_.substr(pos, 2) == "/>") {
        pos += 2;
        selfClosing = true;
        return;
      }
      const std::string key = readName(pos);
      pos += key.size();
      while (pos < xml_.size() && isBlank(xml_[pos])) ++pos;
      if (pos >= xml_.size() || xml_[pos] != '=') fail(pos, "expected '=' after " + key);
      ++pos;
      while (pos < xml_.size() && isBlank(xml_[pos])) ++pos;
      if (pos >= xml_.size() || (xml_[pos] != '"' && xml_[pos] != '\''))
        fail(pos, "expected a quoted value for " + key);
      const size_t close = xml_.find(xml_[pos], pos + 1);
      if (close == std::string_view::npos) fail(pos, "expected the closing quote of " + key);
      attributes.values[key] = std::string(xml_.substr(pos + 1, close - pos - 1));
      pos = close + 1;
    }
  }

  const std::string& path_;
  std::string_view xml_;
  mutable size_t countedTo_ = 0;  ///< lineAt(): newlines counted up to here
  mutable size_t line_ = 1;       ///< lineAt(): the line at countedTo_
};

}  // namespace fibremss::meshio
